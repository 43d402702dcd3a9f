"""A composite whose part fails its check is told to fix the part, not a mistake of its own.

When an exercise built on earlier ones (``checks.Exercise(..., builds_on=...)``) fails while a part fails its
own check, the part's slip explains the failure (:func:`snakekit.verdicts.composite_note`): a mistake hint of the
composite's own would name a mistake the student did not make (2.3's "w is 0 at a bent pose: det(J^T J)..." for
a right 2.3 on a 2.1 that does not accumulate its angles). The same words reach the graded feedback
(``grader.scoring.verdict.with_local_check``), which then adds no guess of its own either.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest
from nbformat.v4 import new_code_cell, new_output

from grader.scoring.score import ExerciseScore
from grader.scoring.verdict import LOCAL, with_local_check
from snakekit import checks
from snakekit.errors import CheckFailed
from snakekit.verdicts import BUILDS_ON, CAUSES, PASSED, composite_note
from tests.conftest import need

ROOT = Path(__file__).resolve().parents[2]
COURSE = ROOT / "course"
LESSONS = sorted(p.name for p in (COURSE / "source").iterdir() if (p / f"{p.name}.ipynb").exists())


def _composites() -> list:
    """Every composite of the course as its check cell declares it: (lesson, number, name, parts, cell source)."""
    nbformat = need("nbformat")
    out = []
    for lesson in LESSONS:
        nb = nbformat.read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4)
        for c in nb.cells:
            if not c.metadata.get("nbgrader", {}).get("grade"):
                continue
            for node in ast.walk(ast.parse(c.source)):
                if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "Exercise" and \
                        any(k.arg == "builds_on" for k in node.keywords):
                    parts = ast.literal_eval(next(k.value for k in node.keywords if k.arg == "builds_on"))
                    out.append((lesson, node.args[0].value, node.args[1].value, tuple(parts), c.source))
    return out


COMPOSITES = _composites()


def _hints(source: str) -> list[str]:
    """The mistake hints a check cell gives: the keys of its ``mistakes=`` dicts (literal ones) and the hint
    arguments of its ``ex.fail`` / ``ex.true`` calls (literal strings)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") in ("close", "fail", "true"):
            for k in node.keywords:
                if k.arg == "mistakes" and isinstance(k.value, ast.Dict):
                    found += [key.value for key in k.value.keys if isinstance(key, ast.Constant)]
            at = {"fail": 1, "true": 2}.get(node.func.attr)
            if at is not None and len(node.args) > at and isinstance(node.args[at], ast.Constant):
                found.append(node.args[at].value)
    return [h for h in found if isinstance(h, str) and h]


@pytest.fixture(autouse=True)
def _fresh_verdicts(fresh_verdicts):
    """The kernel's verdicts as they were after each test here (tests/conftest.py)."""


def _said(ex, how: str, hint: str) -> str:
    mistake = np.array([0.25, 0.5])
    with pytest.raises(CheckFailed) as e:
        if how == "close":
            ex.close(mistake, [1.0, 2.0], what="result", unit="m", mistakes={hint: mistake})
        elif how == "true":
            ex.true(False, "the result is not what the exercise asks", hint)
        else:
            ex.fail("`f` raised TypeError when called with [0, 0]: list indices must be integers or slices, not tuple",
                    hint)
    return str(e.value)


def test_the_course_has_composites_and_their_checks_give_hints():
    assert {(n, parts) for _, n, _, parts, _ in COMPOSITES} == {("2.3", ("2.1",)), ("4.3", ("4.1",)),
                                                                 ("6.3", ("6.1", "6.2"))}
    assert all(_hints(source) for *_, source in COMPOSITES)


@pytest.mark.parametrize("how", ["close", "true", "fail"])
@pytest.mark.parametrize("lesson, number, name, parts, source", COMPOSITES, ids=[c[1] for c in COMPOSITES])
def test_a_composite_whose_part_fails_its_check_gives_none_of_its_own_hints(lesson, number, name, parts, source, how):
    for hint in _hints(source):
        ex = checks.Exercise(number, name, builds_on=parts)
        for part in parts:
            PASSED[part] = True
        assert CheckFailed.hint_of(_said(ex, how, hint)) == hint   # its parts right: its own hint, as ever
        PASSED[parts[-1]] = False
        said = _said(ex, how, hint)
        assert "Hint:" not in said and hint not in said, said
        failing = [p for p in parts if not PASSED[p]]
        assert said.endswith(composite_note(number, failing)), said
        # the message's sentence ends before the note begins, and the graded feedback says the same, with no hint
        assert re.search(r"[.!?:]\n" + re.escape(composite_note(number, failing)), said), said
        cell = new_code_cell("ex.close(...)")
        cell.outputs = [new_output("error", ename="CheckFailed", evalue=said, traceback=[])]
        graded = with_local_check(ExerciseScore("ex_test", 0.0, 2.0, "scored", "1 of 8 hidden cases wrong; the "
                                                "first: f(): rate: the first point is at t=1 s, expected 0 s. Hint: "
                                                "the time vector starts at 1 instead of 0."), cell).message
        assert LOCAL in graded and "Hint:" not in graded and composite_note(number, failing) in graded, graded


def test_a_right_manipulability_on_a_planar_jacobian_that_does_not_accumulate_is_told_to_fix_2_1():
    """The case a student met: lesson 2's own cells, its 2.1 with q_i for q_1 + ... + q_i, its 2.3 right."""
    nbformat = need("nbformat")
    nb = nbformat.read(COURSE / "source" / "02_jacobian" / "02_jacobian.ipynb", as_version=4)
    cells = {c.metadata.get("nbgrader", {}).get("grade_id", c.get("id")): c.source for c in nb.cells
             if c.cell_type == "code"}
    namespace = {"__name__": "lesson02"}
    exec("\n".join(line for line in cells["02-code-02"].splitlines() if not line.startswith("%")), namespace)
    exec("def planar_jacobian(q):\n    down = lambda v: np.cumsum(v[::-1])[::-1]\n"
         "    return np.vstack([down(-L * np.sin(q)), down(L * np.cos(q)), np.ones(len(q))])", namespace)
    with pytest.raises(CheckFailed) as e:
        exec(cells["ex02_1_planar_jacobian_test"], namespace)
    assert "not accumulated" in CheckFailed.hint_of(str(e.value))
    exec(cells["ex02_3_manipulability"], namespace)
    with pytest.raises(CheckFailed) as e:
        exec(cells["ex02_3_manipulability_test"], namespace)
    said = str(e.value)
    assert "Hint:" not in said and "det(J^T J)" not in said, said
    assert said.endswith(composite_note("2.3", ["2.1"])), said
