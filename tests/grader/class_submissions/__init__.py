"""Classes of hand-written submissions, with the score range a fair human grader would give each.

A :class:`Student` is one submission: the answer cells they wrote (by grade id; a cell they
did not write keeps the release's ``raise NotImplementedError``), what they did in one line,
and per exercise the share of its points a fair grader gives (an exercise not named: full
marks), and optionally an edit of the notebook beyond its answer cells (a test cell changed, metadata
an editor stripped). Ranges are shares of each exercise's points, so they hold when the points of a lesson
are rebalanced; the lesson's floor for a single mistake (lesson 06: 10 of 18) is a share of
its total. A :class:`Pair` says one submission is at least as right as another, so it must
score at least as much (or more, when ``strict``).

``lesson02`` and ``lesson03`` (values lessons), ``lesson04`` (trajectories) and ``lesson06`` (the
Task 2 lesson) hold the classes;
``tests/grader/test_class_grades.py`` grades them with ``snakekit grade`` and checks every range
and pair.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import nbformat

REPO = Path(__file__).resolve().parents[3]  # tests/grader/class_submissions/ -> the repository


@dataclass(frozen=True)
class Student:
    name: str
    did: str                      # what they did, as a TA would note it
    answers: dict                 # answer cell grade id -> the source they wrote
    why: str                      # why the range is fair, in one line
    credit: dict = field(default_factory=dict)   # exercise ("6.3") -> (low, high) share of its points
    single_slip: bool = False     # exactly one mistake: the lesson's floor for one slip applies
    edit: Callable | None = None  # what else they did to the notebook: edit(nb), after the answers are in
    status: str = "graded"        # the CSV's status the TA must see ("tests restored", "timeout")


@dataclass(frozen=True)
class Pair:
    better: str                   # the student who did at least as much right ...
    worse: str                    # ... as this one
    why: str
    strict: bool = False          # better must score more, not only as much


def wrote_all(good: dict, ids: dict, name, did, why, credit=None, single_slip=False, edit=None, status="graded",
              **cells) -> Student:
    """A student who wrote every exercise: ``good`` but for ``cells`` (``T1=source``; ``ids`` maps
    T1... to the answer cells' grade ids)."""
    return Student(name, did, {**good, **{ids[k]: v for k, v in cells.items()}}, why, credit or {}, single_slip, edit,
                   status)


def wrote_some(name, did, why, credit, answers) -> Student:
    """A student who wrote only the answer cells in ``answers`` (the others: not written)."""
    return Student(name, did, answers, why, credit)


def right_first(correct: list, students: list) -> list:
    """The pairs every class holds: a right solution scores at least as much as any other submission."""
    return [Pair(c, s.name, "a right solution scores at least as much as any other") for c in correct
            for s in students if s.name not in correct]


def exercise_of(grade_id: str) -> str:
    """'ex06_3_task2_test' -> '6.3'."""
    m = re.match(r"ex0*(\d+)_(\d+)_", grade_id)
    return f"{m.group(1)}.{m.group(2)}"


def points(lesson: str) -> dict:
    """Points per exercise, from the release's graded test cells: {'6.1': 2.0, ...}."""
    nb = nbformat.read(REPO / "notebooks" / f"{lesson}.ipynb", as_version=4)
    out = {}
    for c in nb.cells:
        meta = c.metadata.get("nbgrader", {})
        if meta.get("grade") and meta.get("points"):
            ex = exercise_of(meta["grade_id"])
            out[ex] = out.get(ex, 0.0) + float(meta["points"])
    return out


def score_range(student: Student, pts: dict, slip_floor: float = 0.0) -> tuple[float, float]:
    """The (low, high) points a fair grader gives ``student``, for the lesson's ``pts``."""
    for ex in student.credit:
        assert ex in pts, f"{student.name}: no exercise {ex} in the lesson ({sorted(pts)})"
    low = sum(student.credit.get(ex, (1.0, 1.0))[0] * p for ex, p in pts.items())
    high = sum(student.credit.get(ex, (1.0, 1.0))[1] * p for ex, p in pts.items())
    if student.single_slip:
        low = max(low, slip_floor * sum(pts.values()))
    return low, max(low, high)


def hand_in(course: Path, lesson: str, student: Student) -> None:
    """Put ``student``'s answer cells into the released notebook, in ``course/submitted``."""
    nb = nbformat.read(REPO / "notebooks" / f"{lesson}.ipynb", as_version=4)
    ids = set()
    for c in nb.cells:
        gid = c.metadata.get("nbgrader", {}).get("grade_id")
        if gid in student.answers:
            c.source = student.answers[gid]
            ids.add(gid)
    assert ids == set(student.answers), f"{student.name}: no answer cell {set(student.answers) - ids}"
    if student.edit:
        student.edit(nb)
    folder = course / "submitted" / student.name / lesson
    folder.mkdir(parents=True)
    nbformat.write(nb, folder / f"{lesson}.ipynb")
