"""Four classes of hand-written submissions graded as a TA grades them: fair ranges, more right never less.

Lessons 02 and 03 (values lessons, 30 and 31 submissions), lesson 04 (trajectories, 32) and lesson
06 (the Task 2 lesson, 34), each graded in one batch with ``snakekit grade --jobs 2``. Every
submission must score inside the range a fair human grader gives it
(``tests/grader/class_submissions/lesson0*.py``, with the reason) with the CSV status the TA must see
(``graded``, or ``tests restored`` for an edited test cell, ``timeout`` for an infinite loop), and a
submission that did at least as much right as another must not score less.

The grader before hidden cases were drawn per batch fails many of these ranges (its scores are in
``tests/grader/class_submissions/BEFORE.md``), so the suite grades the classes only once ``NEW_GRADER``
is True; ``SNAKEKIT_CLASS_GRADES=1`` grades them anyway (``-k lesson06`` for one class). The
hidden cases are drawn anew for every batch; a failure names the batch's seed, and
``SNAKEKIT_CLASS_SEED=<seed>`` draws them again.

``python tests/grader/test_class_grades.py [02_jacobian|03_inverse_kinematics|04_trajectories|06_coded_sweep ...]``
grades the classes and prints each student's score against its range, as a Markdown table.
"""

from __future__ import annotations

import csv
import os
import re
import sys
import time
import warnings
from pathlib import Path

import nbformat
import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(1, str(HERE.parent))  # tests/conftest.py, also when run as a script

from class_submissions import exercise_of, hand_in, points, score_range  # noqa: E402
from class_submissions import lesson02, lesson03, lesson04, lesson06  # noqa: E402
from conftest import copy_course  # noqa: E402
from grader_helpers import snakekit  # noqa: E402

#: the grader of issue 20 (partial credit that follows the work) grades the classes in the suite
NEW_GRADER = True
RUN = NEW_GRADER or os.environ.get("SNAKEKIT_CLASS_GRADES") == "1"

REPO = HERE.parents[1]
CLASSES = {m.LESSON: m for m in (lesson02, lesson03, lesson04, lesson06)}
IDS = [f"lesson{lesson[:2]}" for lesson in sorted(CLASSES)]


def grade_class(lesson: str, tmp: Path) -> dict:
    """Hand in the whole class of ``lesson`` into a copy of the course and grade it in one batch.

    Returns {"rows": {student: (score, max_score, status)}, "exercises": {student: {ex: score}},
    "seconds": wall time of ``snakekit grade``, "stderr": its stderr's tail}.
    """
    from nbgrader.api import Gradebook

    module = CLASSES[lesson]
    course = tmp / "course"
    copy_course(course)
    for student in module.STUDENTS:
        hand_in(course, lesson, student)
    # a loaded machine must not turn a right notebook into a timeout: 300 s a notebook, not 120
    command = ["grade", lesson, "--course", str(course), "--jobs", "2", "--timeout", "300"]
    if getattr(module, "CELL_TIMEOUT", None):   # a class with an infinite loop waits this long for it, twice
        command += ["--cell-timeout", str(module.CELL_TIMEOUT)]
    if os.environ.get("SNAKEKIT_CLASS_SEED"):   # the hidden cases of an earlier batch, drawn again
        command += ["--seed", os.environ["SNAKEKIT_CLASS_SEED"]]
    started = time.monotonic()
    r = snakekit(*command)   # the TA's command, in this process (its fork server serves the next class too)
    seconds = time.monotonic() - started
    assert r.returncode == 0, f"snakekit grade {lesson} exited {r.returncode}:\n{r.stderr[-3000:]}"
    seed = re.search(r"drawn with seed (\d+)", r.stderr)
    with open(course / f"grades-{lesson}.csv", newline="") as f:
        read = list(csv.DictReader(f))
    rows = {row["student"]: (float(row["score"]), float(row["max_score"]), row["status"]) for row in read}
    details = {row["student"]: row["detail"] for row in read}
    exercises = {}
    with Gradebook(f"sqlite:///{course / 'gradebook.db'}") as gb:
        for student in module.STUDENTS:
            try:
                nb = gb.find_submission_notebook(lesson, lesson, student.name)
            except Exception:   # not in the gradebook: the CSV row says why
                continue
            per = {}
            for g in nb.grades:
                ex = exercise_of(g.name)
                per[ex] = per.get(ex, 0.0) + float(g.score or 0.0)
            exercises[student.name] = per
    pages = {path.parts[-3]: path.read_text() for path in (course / "feedback").glob(f"*/{lesson}/*.html")}
    return {"course": course, "rows": rows, "details": details, "exercises": exercises, "seconds": seconds, "pages": pages,
            "seed": seed and seed.group(1), "late": [line for line in r.stderr.splitlines() if "reply never came" in line]}


def _describe(student, result, pts) -> str:
    score, max_score, status = result["rows"].get(student.name, (float("nan"), float("nan"), "no row"))
    per = result["exercises"].get(student.name, {})
    parts = ", ".join(f"{ex} {per.get(ex, 0):g}/{p:g}" for ex, p in sorted(pts.items()))
    return f"{student.name} ({student.did}): {score:g}/{max_score:g} [{status}; {parts}]"


def _batch(result) -> str:
    seed = result.get("seed")
    return f" (hidden cases of seed {seed}: SNAKEKIT_CLASS_SEED={seed} draws them again)" if seed else ""


def range_failures(module, result) -> list[str]:
    """One line per student outside the fair range (or not graded), naming what they did."""
    pts = points(module.LESSON)
    total = sum(pts.values())
    out = []
    for s in module.STUDENTS:
        low, high = score_range(s, pts, module.SLIP_FLOOR)
        score, max_score, status = result["rows"].get(s.name, (None, None, "no row in the CSV"))
        if status != s.status or max_score != total:
            out.append(f"{_describe(s, result, pts)}: status {status!r} (expected {s.status!r}), max {max_score} "
                       f"(the lesson has {total:g}): "
                       f"{result.get('details', {}).get(s.name, '')}")
        elif not low - 1e-9 <= score <= high + 1e-9:
            out.append(f"{_describe(s, result, pts)}: a fair grader gives {low:g} to {high:g}: {s.why}")
    return out


def pair_failures(module, result) -> list[str]:
    """One line per pair where the submission that did more right scored less."""
    by_name = {s.name: s for s in module.STUDENTS}
    pts = points(module.LESSON)
    score = {name: row[0] for name, row in result["rows"].items()}
    out = []
    for p in module.PAIRS:
        a, b = score.get(p.better), score.get(p.worse)
        if a is None or b is None or a < b or (p.strict and a == b):
            out.append(f"{_describe(by_name[p.better], result, pts)} should score {'more than' if p.strict else 'at least'}"
                       f" {_describe(by_name[p.worse], result, pts)}: {p.why}")
    return out


needs_new_grader = pytest.mark.skipif(not RUN, reason="the classes' ranges need the grader of issue 20: set "
                                      "NEW_GRADER (or SNAKEKIT_CLASS_GRADES=1)")


@pytest.mark.parametrize("lesson", sorted(CLASSES), ids=IDS)
def test_each_class_has_30_submissions_with_ranges_reasons_and_cells_of_the_release(lesson):
    module = CLASSES[lesson]
    names = [s.name for s in module.STUDENTS]
    assert len(names) >= 30 and len(set(names)) == len(names)
    release = nbformat.read(REPO / "notebooks" / f"{lesson}.ipynb", as_version=4)
    cells = {c.metadata.get("nbgrader", {}).get("grade_id") for c in release.cells}
    pts = points(lesson)
    for s in module.STUDENTS:
        assert s.did and s.why, s.name
        assert set(s.answers) <= cells, f"{s.name}: {set(s.answers) - cells} is not an answer cell of the release"
        assert set(s.credit) <= set(pts), f"{s.name}: {set(s.credit) - set(pts)} is not an exercise of the lesson"
        assert all(0 <= lo <= hi <= 1 for lo, hi in s.credit.values()), s.name
    by_name = {s.name: s for s in module.STUDENTS}
    for p in module.PAIRS:
        assert {p.better, p.worse} <= set(names) and p.better != p.worse, p
        # a pair must not contradict the two ranges
        high = score_range(by_name[p.better], pts, module.SLIP_FLOOR)[1]
        low = score_range(by_name[p.worse], pts, module.SLIP_FLOOR)[0]
        assert high > low or (high == low and not p.strict), f"{p}: {p.better} can reach {high}, {p.worse} {low}"


@pytest.fixture(scope="module", params=sorted(CLASSES), ids=IDS)
def graded(request, graded_classes):
    from conftest import need_program

    need_program("unshare")
    lesson = request.param
    result = graded_classes(lesson)   # shared with tests/grader/test_report.py
    hangs = {s.name for s in CLASSES[lesson].STUDENTS if s.status == "timeout"}   # an infinite loop runs twice
    again = sorted(n for n, d in result["details"].items()
                   if ("second run" in d or "both of its runs" in d) and n not in hangs)
    print(f"\n{lesson}: {len(CLASSES[lesson].STUDENTS)} submissions graded in {result['seconds']:.1f} s"
          + (f"; stopped by the clock in a first run and run again: {', '.join(again)}" if again else ""))
    if result["late"]:   # a kernel's lost reply, taken as finished: said where CI's summary shows it
        warnings.warn(f"{lesson}: " + "\n".join(result["late"]), stacklevel=1)
    if again:   # a stall of the machine, not of the students: said where CI's summary shows it
        warnings.warn(f"{lesson}: a first run stopped by the clock ({result['seconds']:.0f} s for the class):\n"
                      + "\n".join(f"  {n}: {result['details'][n]}" for n in again), stacklevel=1)
    return CLASSES[lesson], result


@needs_new_grader
def test_every_submission_scores_in_the_range_a_fair_grader_gives(graded):
    module, result = graded
    _none(range_failures(module, result), f"of {len(module.STUDENTS)} out of range", result)


@needs_new_grader
def test_more_right_never_scores_less(graded):
    module, result = graded
    _none(pair_failures(module, result), f"of {len(module.PAIRS)} pairs broken", result)


def test_no_page_of_the_class_loads_anything(graded):
    """Each student's page works offline: the lesson's live 3D view (an iframe to the kernel that
    graded it) and anything else that loads an address are one line saying what they were."""
    module, result = graded
    assert len(result["pages"]) >= len([s for s in module.STUDENTS if s.name in result["exercises"]]) > 0
    loads = {name: m.group(0) for name, page in result["pages"].items()
             if (m := re.search(r"<(script|link|iframe|img)[^>]+(src|href)=[\"'](?!data:)[^\"']*", page))}
    assert not loads, f"{len(loads)} pages load an address: {loads}"
    # an address, in any form ("http" alone also turns up by chance inside a plot's base64 data)
    assert not [name for name, page in result["pages"].items() if re.search(r"https?:/", page)]


def _none(failures: list, what: str, result) -> None:
    assert not failures, f"{len(failures)} {what}{_batch(result)}:\n" + "\n".join(failures)


def table(module, result) -> str:
    """A Markdown table: student, what they did, score/max, the fair range, in range."""
    pts = points(module.LESSON)
    lines = [f"### {module.LESSON} ({len(module.STUDENTS)} submissions, graded in {result['seconds']:.0f} s"
             f"{'' if not result.get('seed') else ', hidden cases of seed ' + result['seed']}, "
             f"points {', '.join(f'{ex}: {p:g}' for ex, p in sorted(pts.items()))})", "",
             "| student | what they did | score | per exercise | fair range | why | in range |",
             "|---|---|---|---|---|---|---|"]
    for s in module.STUDENTS:
        low, high = score_range(s, pts, module.SLIP_FLOOR)
        score, max_score, status = result["rows"].get(s.name, (float("nan"), float("nan"), "no row"))
        per = result["exercises"].get(s.name, {})
        inside = status == s.status and low - 1e-9 <= score <= high + 1e-9
        lines.append(f"| {s.name} | {s.did} | {score:g}/{max_score:g}{'' if status == 'graded' else f' ({status})'} | "
                     f"{' '.join(f'{per.get(ex, 0):g}' for ex in sorted(pts))} | {low:g}-{high:g} | {s.why} | "
                     f"{'yes' if inside else '**no**'} |")
    broken = pair_failures(module, result)
    lines += ["", f"Pairs (more right never scores less): {len(module.PAIRS) - len(broken)} of {len(module.PAIRS)} hold."]
    lines += [f"- {b}" for b in broken]
    return "\n".join(lines)


if __name__ == "__main__":
    import tempfile

    for lesson in sys.argv[1:] or sorted(CLASSES):
        with tempfile.TemporaryDirectory() as tmp:
            print(table(CLASSES[lesson], grade_class(lesson, Path(tmp))), "\n", flush=True)
