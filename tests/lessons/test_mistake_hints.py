"""A known mistake's hint names that mistake and only it: over every hint of the catalogue (every
``mistakes=`` of every check the lessons run, recorded as the instructor's lesson runs), the value the
mistake gives gets its hint, and an answer wrong for another reason (the expected value moved by three
tolerances away from the mistake's) does not.

The graded feedback shows the hint the notebook's own check gave (``grader.scoring.verdict.with_local_check``;
tests/grader/test_hints_graded.py grades every mistake of tests/lessons/test_no_solution.py), so what holds
here holds graded too.
"""

from __future__ import annotations

import pickle
import shutil

import nbformat
import numpy as np
import pytest

from snakekit import checks
from snakekit.errors import CheckFailed
from tests.conftest import need
from tests.lessons.test_notebooks import ROOT

COURSE = ROOT / "course" / "source"
LESSONS = sorted(p.name for p in COURSE.iterdir() if (p / f"{p.name}.ipynb").exists())

#: Run first in the lesson's kernel: every check with known mistakes is recorded (what it compared, with which
#: tolerance, and each mistake's value as plain numbers) before it runs as usual.
RECORDER = '''
import pickle as _pickle
import numpy as _np
import snakekit.checks as _checks

_recorded, _close = [], _checks.Exercise.close

def _plain(value):
    if isinstance(value, _checks.scaled):
        return ("times", float(value))
    if isinstance(value, _checks.within):
        return ("within", (value.value, value.spread))
    if isinstance(value, _checks.either):
        return ("either", [_np.asarray(v, dtype=float) for v in value])
    return ("value", _np.asarray(value, dtype=float))

def _recording_close(self, got, expected, **options):
    if options.get("mistakes"):
        kept = {k: v for k, v in options.items() if k not in ("mistakes", "where")}
        own = [hint for hint, value in options["mistakes"].items() if value is got]   # recognised from the result itself
        _recorded.append((self.number, self.name, str(options.get("where")), _np.asarray(expected, dtype=float), kept,
                          [(hint, *_plain(value)) for hint, value in options["mistakes"].items() if hint not in own]))
        with open(_RECORDED, "wb") as _f:
            _pickle.dump(_recorded, _f)
    return _close(self, got, expected, **options)

_checks.Exercise.close = _recording_close
'''


@pytest.fixture(scope="module", params=LESSONS)
def catalogue(request, tmp_path_factory, monkeypatch_module):
    """The checks with known mistakes that one instructor lesson runs: (lesson, recorded calls)."""
    from tests.lessons.test_notebooks import execute

    need("nbclient")
    lesson = request.param
    work = tmp_path_factory.mktemp(f"hints{lesson[:2]}")
    source = work / "source"
    shutil.copytree(COURSE / lesson, source)
    nb = nbformat.read(source / f"{lesson}.ipynb", as_version=4)
    nb.cells.insert(0, nbformat.v4.new_code_cell(f"_RECORDED = {str(work / 'recorded.pkl')!r}\n" + RECORDER))
    nbformat.write(nb, source / f"{lesson}.ipynb")
    execute(source / f"{lesson}.ipynb", work / "run", monkeypatch_module)
    path = work / "recorded.pkl"
    return lesson, (pickle.loads(path.read_bytes()) if path.exists() else [])


@pytest.fixture(scope="module")
def monkeypatch_module():
    with pytest.MonkeyPatch.context() as mp:
        yield mp


def _values(kind, value, expected, number, name, options, mistakes):
    """The wrong answers a mistake gives here (one half its spread from a ``within`` value). A value that passes the
    check is no mistake at this case and is left out: a mistake may give the right answer at some cases, and a check
    that recognises a mistake from the student's own result (3.1: where the tip lands) records the right answer."""
    values = {"times": lambda: [expected * value], "either": lambda: value, "within": lambda: [value[0] + value[1] / 2]}.get(
        kind, lambda: [value])()
    return [v for v in values if _hint_of(number, name, v, expected, options, _mistakes(mistakes)) is not None]


def _mistakes(recorded):
    made = {"times": checks.scaled, "either": lambda v: checks.either(*v), "within": lambda v: checks.within(*v)}
    return {hint: made.get(kind, lambda v: v)(value) for hint, kind, value in recorded}


def _hint_of(number, name, got, expected, options, mistakes) -> str | None:
    """The hint the check gives ``got`` ("" when none; None when it passes)."""
    try:
        checks.Exercise(number, name).close(got, expected, mistakes=mistakes, **options)
    except CheckFailed as e:
        return " ".join(CheckFailed.hint_of(str(e)).split())
    return None


def _bound(expected, options):
    return np.maximum(options.get("tol", 0.0) + options.get("rtol", 1e-9) * np.abs(expected), checks.ZERO)


def test_every_lesson_s_checks_name_known_mistakes(catalogue):
    lesson, recorded = catalogue
    assert recorded, f"{lesson}: no check with known mistakes ran"


def test_the_value_a_known_mistake_gives_gets_its_hint(catalogue):
    lesson, recorded = catalogue
    shown = {}
    for number, name, where, expected, options, mistakes in recorded:
        for hint, kind, value in mistakes:
            values = _values(kind, value, expected, number, name, options, mistakes)
            shown.setdefault((number, hint), False)
            for v in values:
                said = _hint_of(number, name, v, expected, options, _mistakes(mistakes))
                assert said == " ".join(hint.split()), \
                    f"{lesson} {number} at {where}: the mistake's value {v} should get {hint!r}, got {said!r}"
                shown[number, hint] = True
    # a mistake may give the right answer at one case (np.linspace at a whole number of goal periods), not at all
    never = [key for key, ok in shown.items() if not ok and key[0] != "3.1"]   # 3.1: recognised from where the tip lands
    assert not never, f"{lesson}: these mistakes' values pass every check that names them: {never}"


def test_an_answer_wrong_for_another_reason_does_not_get_a_mistake_s_hint(catalogue):
    lesson, recorded = catalogue
    for number, name, where, expected, options, mistakes in recorded:
        bound = _bound(expected, options)
        for hint, kind, value in mistakes:
            values = [np.asarray(v, dtype=float) for v in _values(kind, value, expected, number, name, options, mistakes)]
            for v in values:
                wrong = _wrong(expected, v, np.maximum(bound, value[1] if kind == "within" else 0.0), values)
                said = _hint_of(number, name, wrong, expected, options, _mistakes(mistakes))
                assert said is not None, f"{lesson} {number} at {where}: {wrong} passes"
                assert said != " ".join(hint.split()), \
                    f"{lesson} {number} at {where}: {wrong}, three tolerances or more from the answer, is told {hint!r}"


def _wrong(expected, value, bound, values):
    """The expected answer moved by three tolerances or more (``bound``, each entry's), on the side away from the
    mistake's ``value``, and more than two tolerances from each of the mistake's ``values``: wrong, and not that
    mistake. (The spread of a ``within`` mistake counts as its tolerance.)"""
    away = -np.sign(value - expected) if value.shape == expected.shape else np.ones_like(expected)
    away = np.where(away == 0, 1.0, away)
    for k in (3, 4, 5, 6):
        for side in (away, -away):
            wrong = expected + k * bound * side
            if all(v.shape != wrong.shape or np.abs(wrong - v).max() > 2 * bound.max() for v in values):
                return wrong
    raise AssertionError(f"no wrong answer a few tolerances from {expected} stays clear of the mistake's {values}")
