"""What a student reads in the grader's box and the page's score table, for every exercise of the course: the
exercise named as its lesson names it ("6.3 task2_sweep"), a hidden case shown as a call of the student's own
function with its arguments named as that function names them (numbers to 4 significant digits, a short array
whole, a long one with its brackets closed), a result of the wrong kind named as such (never as an error of the
student's function), scores with at most 2 decimals, and a composite graded with the lesson's own parts saying
each detail once and what its rows describe.

No notebook runs here (as in test_graded_words.py): the hidden cases are drawn from each cases module, and the
page is built from the lesson's source notebook with the verdicts the grader would keep.
"""

from __future__ import annotations

import html
import re
import runpy

import numpy as np
import pytest

from grader.course.gradebook import ExerciseGrade, SubmissionScores
from grader.feedback import scores
from grader.scoring import rerun
from grader.scoring.references import REFERENCES, Reference
from grader.scoring.score import ExerciseScore, Expected, handed_in_function, score_exercise
from grader.scoring.wording import wording
from snakekit import SPEC
from tests.conftest import need
from tests.grader.test_graded_words import COURSE, EXERCISES, _lesson, _want, _wrongs, lesson_signatures

LESSONS = sorted({lesson for lesson, _ in EXERCISES})


def _expected(lesson: str, gid: str, seed: int = 5):
    tests, _ = _lesson(lesson)
    meta = Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]
    cases = runpy.run_path(str(COURSE / "cases" / f"{lesson}.py"))[gid](np.random.default_rng(seed), SPEC)
    results = [_want(gid, meta["kind"], meta["outputs"], args) for args in cases]
    handed = handed_in_function(gid, tests[gid])
    words = wording(gid, tests[gid], handed, lesson_signatures(lesson))
    return Expected(gid, meta["kind"], cases, results, meta["tolerances"], handed, words)


def _called(message: str, function: str) -> str:
    """The hidden case a message names: from the student's function's name to the ": " that ends the case."""
    at = message.index(f"{function}(")
    return message[at:message.index(": ", at)]


def _inside(text: str, at: int) -> str:
    """What the brackets opening at ``text[at]`` hold."""
    depth = 0
    for k in range(at, len(text)):
        depth += {"(": 1, "[": 1, ")": -1, "]": -1}.get(text[k], 0)
        if depth == 0:
            return text[at + 1:k]
    raise AssertionError(f"the bracket at {at} of {text!r} is never closed")


def _significant(number: str) -> int:
    digits = re.sub(r"e[-+]?\d+$", "", number).lstrip("-").replace(".", "").lstrip("0")
    return len(digits)


@pytest.mark.parametrize("lesson, gid", EXERCISES, ids=[g for _, g in EXERCISES])
def test_a_hidden_case_reads_as_a_call_of_the_students_own_function(lesson, gid):
    e = _expected(lesson, gid)
    w = e.words()
    params = lesson_signatures(lesson)[w.function]
    at = next(k for k, (args, r) in enumerate(zip(e.cases, e.results)) if isinstance(r, dict) and args)
    wrong = [_wrongs(r)[0] if isinstance(r, dict) else r for r in e.results]
    said = score_exercise(gid, wrong, e, 1.0).message
    if w.params and not w.given:   # the test cell calls the function its own way: the case's values, named
        assert re.search(rf"{w.function} at the hidden case {w.params[0]}=", said), f"{gid}: {said}"
        return
    case = _called(said, w.function) if said.count(f"{w.function}(") else pytest.fail(f"{gid}: {said}")
    # each argument is named as the student's function names it, or (an argument the test cell builds, a run
    # from a sweep's values) by that name alone, with what it was built of after the call
    inner = _inside(case, len(w.function))
    named = re.findall(r"(?:^|, )([A-Za-z_]\w*)(?==|,|$)", inner)
    assert named and set(named) <= set(params), f"{gid}: {case!r} names {named}; {w.function} takes {params}"
    if not w.params:   # the case is the function's own arguments: every one of them named, in order
        assert named == list(params[:len(e.cases[at])]), (gid, case)
    # numbers as a student reads them: a measured value to at most 4 significant digits (a whole count, such as
    # a stamp in nanoseconds, stays whole), every bracket closed
    numbers = re.findall(r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?", re.sub(r"\(shape \([\d, ]+\)\)|\(\d+ values\)", "", case))
    whole = {str(int(v)) for a in e.cases[at] for v in np.ravel(a) if np.asarray(a).dtype.kind in "iu"}
    assert all(_significant(n) <= 4 for n in numbers if n not in whole), f"{gid}: {case}"
    for left, right in ("()", "[]"):
        assert case.count(left) == case.count(right), f"{gid}: {case}"
    # a short array (a 5-angle q) whole: each of its numbers, to 4 digits
    first = e.cases[next(k for k, r in enumerate(e.results) if isinstance(r, dict))]
    for a in first:
        if isinstance(a, np.ndarray) and a.ndim == 1 and 1 < a.size <= 8 and a.dtype.kind == "f":
            assert all(f"{x:.4g}" in case for x in a), f"{gid}: {a} in {case}"


@pytest.mark.parametrize("lesson, gid", EXERCISES, ids=[g for _, g in EXERCISES])
def test_a_result_the_test_cell_cannot_use_is_the_wrong_kind_not_an_error_of_the_function(lesson, gid):
    e = _expected(lesson, gid)
    fn = e.words().function
    said = score_exercise(gid, [f"returned tuple from {fn}" if isinstance(r, dict) else r for r in e.results],
                          e, 1.0).message
    assert f"{fn} should return a " in said and "got tuple" in said or f"{fn} returned a tuple" in said, said
    assert "raised" not in said and "AttributeError" not in said, said


def test_the_test_cells_own_error_on_a_students_result_is_handed_in_as_the_wrong_kind(tmp_path, monkeypatch):
    """In the kernel: a helper of the test cell that stumbles on what the student's function returned hands in
    the kind it got; an error raised inside the student's function stays that error."""
    import sys

    from snakekit import checks
    from snakekit.handin import decode_results

    main = sys.modules["__main__"]

    def task2_sweep(points):
        if points < 0:
            raise AttributeError("my own slip")
        return np.arange(points), np.zeros((points, 5))

    def graded_run(points):
        sweep = task2_sweep(points)
        return {"times": sweep.times}

    monkeypatch.setattr(main, "task2_sweep", task2_sweep, raising=False)
    monkeypatch.setattr(checks, "fetch_cases", lambda path, gid: [(3,), (-1,)])
    monkeypatch.setenv("SNAKEKIT_HANDIN_DIR", str(tmp_path))
    monkeypatch.setenv("SNAKEKIT_CASES", str(tmp_path / "cases.sock"))
    assert checks.Exercise("6.3", "task2_sweep").hand_in("ex06_3_task2_test", graded_run) == 2
    got = decode_results((tmp_path / "ex06_3_task2_test.npz").read_bytes())
    assert got == ["returned tuple from task2_sweep", "AttributeError: my own slip"]


def _page_text(lesson: str, score_of) -> tuple[str, dict]:
    """The text of a page of ``lesson`` whose every exercise scored ``score_of(max_score)``, and its test cells."""
    nbformat = need("nbformat")
    nb = nbformat.read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    tests = {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells
             if c.metadata.get("nbgrader", {}).get("grade") and c.cell_type == "code"}
    points = {c.metadata["nbgrader"]["grade_id"]: float(c.metadata["nbgrader"]["points"]) for c in nb.cells
              if c.metadata.get("nbgrader", {}).get("grade")}
    grades = tuple(ExerciseGrade(g, lesson, points[g], score_of(points[g])) for g in tests)
    numbers = SubmissionScores("ana", lesson, sum(points.values()), sum(g.score for g in grades), 0.0, 0.0, grades)
    kept = ("graded", "", None, None, [ExerciseScore(g.grade_id, g.score, g.max_score, "scored", "1 of 3 hidden cases "
                                                     "wrong.") for g in grades], {})
    page = scores.page(nb, numbers, lesson, tests, kept=kept)
    text = [page.cells[0].source]   # the score table, and the grader's boxes (not the notebook's own code)
    for c in page.cells:
        if "grader-verdict" in c.metadata.get("tags", []):
            text += [str(o.get("data", {}).get("text/html", "")) for o in c.get("outputs", [])]
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", "\n".join(text))).split()), tests


@pytest.mark.parametrize("lesson", LESSONS)
def test_the_page_names_every_exercise_as_its_lesson_does_with_at_most_two_decimals(lesson):
    text, tests = _page_text(lesson, lambda m: m * 2 / 3)
    for gid, source in tests.items():
        number, name = re.search(r"checks\.Exercise\(\s*[\"']([\w.]+)[\"']\s*,\s*[\"'](\w+)[\"']", source).groups()
        assert gid not in text, f"{lesson}: the page names the test cell {gid}"
        assert text.count(f"{number} {name}") >= 2, f"{lesson}: {number} {name} is not in the table and the box"
    # every score on the page: at most 2 decimals (2/3 of 4 points: 2.67, not 2.6667)
    assert not re.search(r"\d\.\d{3,} /", text), re.search(r".{40}\d\.\d{3,} /.{20}", text).group(0)
    assert re.search(r"\b\d+\.\d{2} / \d+", text)


def _composites():
    out = []
    for lesson in LESSONS:
        depends = runpy.run_path(str(COURSE / "cases" / f"{lesson}.py")).get("DEPENDS", {})
        out += [(lesson, gid, parts) for gid, parts in depends.items()]
    return out


COMPOSITES = _composites()


def _late_start(r):
    """A hand-in made with a part that slips (6.1's times start at 1/rate): a late start, away from home, and
    so no run (the arm refuses a trajectory that does not start where it stands)."""
    if not isinstance(r, dict):
        return r
    out = {n: a + 0.1 for n, a in r.items() if not n.startswith("measured")}
    return {**r, **out} if "positions" not in r else out


@pytest.mark.parametrize("lesson, gid, parts", COMPOSITES, ids=[g for _, g, _ in COMPOSITES])
def test_a_composite_graded_with_the_lessons_own_part_says_each_detail_once(lesson, gid, parts):
    from grader.feedback.notebook import _verdict_cell

    e = _expected(lesson, gid)
    first = score_exercise(gid, [_late_start(r) for r in e.results], e, 7.0)
    assert first.score < 7.0, first
    graded = rerun.better(first, ExerciseScore(gid, 7.0, 7.0, "scored", "all right"), parts)
    assert graded.score == 7.0
    tests, _ = _lesson(lesson)
    cell = _verdict_cell(graded, "x", b"\x89PNG" if e.kind != "values" else None)
    text = " ".join(html.unescape(re.sub(r"<[^>]+>", " ", cell.outputs[0]["data"]["text/html"])).split())
    own = " and ".join(sorted({rerun.exercise(p) for p in parts}))
    assert f"graded with the lesson's own {own} in place of yours: 7 of 7 (with yours: " in text, text
    # each detail said once: no sentence of the box twice
    sentences = [s for s in re.split(r"(?<=[.)])\s+", text) if len(s) > 30]
    twice = {s for s in sentences if sentences.count(s) > 1}
    assert not twice, f"{gid}: said twice: {sorted(twice)[0]}"
    if e.kind != "values":   # the rows of checks under a full-marks header say whose run they describe
        assert f"The rows below describe the run with your own {own} (it scored " in text, text
        assert "the points above come from the run with the lesson's own" in text
        if e.kind == "run":   # and why the arm made no run of it
            assert "the arm made no run of it: it starts with joint 1 at +0.1000 rad, away from home" in text, text
            assert "measured_" not in text and "in your result" not in text, text


def _templated():
    """The values a check names by a value of its case (``what=f"lag of joint {joint + 1}"``, where ``joint`` is one
    of the case's values, as the test cell's hand-in helper names them)."""
    out = []
    for lesson, gid in EXERCISES:
        source = _lesson(lesson)[0][gid]
        w = wording(gid, source, handed_in_function(gid, source))
        out += [(lesson, gid, p.template) for p in w.parts if p.template and w.params
                and set(re.findall(r"[A-Za-z_]\w*", "".join(re.findall(r"\{([^{}]+)\}", p.template)))) <= set(w.params)]
    return out


TEMPLATED = _templated()


@pytest.mark.parametrize("lesson, gid, template", TEMPLATED, ids=[g for _, g, _ in TEMPLATED])
def test_a_value_the_check_names_by_its_case_is_named_by_the_hidden_case(lesson, gid, template):
    """6.4's check says "lag of joint 3": graded, the lag is named by the hidden case's joint, not "lag of joint"."""
    e = _expected(lesson, gid)
    k = next(k for k, r in enumerate(e.results) if isinstance(r, dict))
    said = score_exercise(gid, [_wrongs(r)[0] if isinstance(r, dict) else r for r in e.results], e, 1.0).message
    name = eval(f"f{template!r}", {}, dict(zip(e.words().params, e.cases[k])))   # the check's own f-string
    assert re.search(rf"{re.escape(name)}\b", said), f"{gid}: {name!r} not in {said}"


def test_an_error_message_is_handed_in_whole_or_cut_at_a_sentence():
    from snakekit.errors import LimitError
    from snakekit.handin import decode_results, encode_results

    one = ("joint 2 at t=0.100 s: velocity +52.6992 rad/s (limit +1.5000), beyond it from t=0.100 to 0.300 s "
           "(3 points) ") * 8 + "Nothing was sent to the robot."
    long = "A sentence about the trajectory's limits, said once. " * 60
    got = decode_results(encode_results([LimitError(one), LimitError(long)]))
    assert got[0] == f"LimitError: {one}"     # 700 characters: whole (it was cut at 500, mid-word)
    assert got[1].endswith("said once. (the rest of the message left out)") and len(got[1]) < len(long)


def _labelled():
    out = []
    for lesson, gid in EXERCISES:
        source = _lesson(lesson)[0][gid]
        out += [(lesson, gid, p) for p in wording(gid, source, handed_in_function(gid, source)).parts if p.labels]
    return out


LABELLED = _labelled()


@pytest.mark.parametrize("lesson, gid, part", LABELLED, ids=[f"{g}-{p.what}" for _, g, p in LABELLED])
@pytest.mark.parametrize("rows", [0, 2], ids=["1-D", "rows"])
def test_a_wrong_entry_is_named_by_its_label_and_unit_locally_and_graded(lesson, gid, part, rows):
    """A check's ``labels`` name the entries of a value, or the columns of its rows (4.4: time, joint, kind):
    "violations[0] time is 0.1 s, expected 0.2 s", the same words in the notebook and on the page."""
    from snakekit import checks
    from snakekit.errors import CheckFailed
    from grader.scoring.score import _compare_case
    from snakekit.closeness import entry_name

    w = wording(gid, _lesson(lesson)[0][gid])
    shape = (rows, len(part.labels)) if rows else (len(part.labels),)
    for column, label in enumerate(part.labels):
        want = np.ones(shape)
        got = want.copy()
        got[(0, column) if rows else column] = 2.0
        unit = part.unit_at((column,))
        # "tool heading", "violations[0] time"; a name that is a phrase has the entry first ("x of tip of solution")
        name = entry_name(part.what, (0, column) if rows else (column,), 2 if rows else 1, part.labels)
        assert label in name and part.what in name, name
        shown = f"is 2{' ' + unit if unit else ''}, expected 1{' ' + unit if unit else ''}"
        key = "_".join(part.what.split())   # a result named in the part's words (3.4 compares two: pose and tool)
        graded = _compare_case(w, {key: got}, {key: want}, {"rtol": 1e-9, "atol": 1e-12})
        assert f"{name} {shown}" in graded, graded
        with pytest.raises(CheckFailed) as local:
            checks.Exercise("9.9", "f").close(got, want, what=part.what, labels=part.labels, unit=part.unit)
        assert f"{name} {shown}" in str(local.value), str(local.value)


MOTIONS = [(lesson, gid) for lesson, gid in EXERCISES
           if Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]["kind"] != "values"]


@pytest.mark.parametrize("lesson, gid", MOTIONS, ids=[g for _, g in MOTIONS])
def test_a_motion_of_another_size_says_not_judged_once(lesson, gid):
    """A sweep that ignores its arguments (500 goals wherever): every check but the count is "not judged", said
    once in the box, not once per check."""
    from grader.feedback.notebook import _verdict_cell

    e = _expected(lesson, gid)
    wrong = [{n: (np.arange(500) / 10.0 if "times" in n else np.zeros((500, 5))) for n in r} if isinstance(r, dict)
             else r for r in e.results]
    s = score_exercise(gid, wrong, e, 7.0)
    cell = _verdict_cell(s, "x", b"\x89PNG")
    text = " ".join(html.unescape(re.sub(r"<[^>]+>", " ", cell.outputs[0]["data"]["text/html"])).split())
    assert s.message.count("not judged") >= 1 and text.count("not judged") == 1, text
