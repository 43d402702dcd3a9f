"""Test cells run as released: an edited test cell or metadata an editor stripped never costs points.

Every kind of change to a test cell (edited, deleted, duplicated, un-locked, its points changed, its
type changed, an extra graded cell, every cell's nbgrader metadata stripped) is put back as the
release has it, for every lesson of the course and the test course, and named for the TA. One
batch of the test course then grades an edited and a stripped submission as the good one.
"""

from __future__ import annotations

import copy
from pathlib import Path

import nbformat
import pytest

from conftest import need_program
from grader.course.assignment import load_assignment, tampered_cells
from grader.course.restore import release_order, restore
from grader_helpers import ASSIGNMENT, GOOD, REFERENCES, make_course, read_csv, snakekit, submit

REPO = Path(__file__).resolve().parents[2]
LESSONS = sorted(p.name for p in (REPO / "course" / "source").iterdir() if (p / f"{p.name}.ipynb").exists())


def _gid(c):
    return c.get("metadata", {}).get("nbgrader", {}).get("grade_id")


@pytest.fixture(scope="module")
def course(tmp_path_factory):
    return make_course(tmp_path_factory.mktemp("restore"))


@pytest.fixture(scope="module")
def lessons(tmp_path_factory):
    """Every lesson of the course released into a scratch copy: (course, {lesson: released notebook})."""
    import shutil

    from grader.course.folder import generate

    root = tmp_path_factory.mktemp("lessons") / "course"
    shutil.copytree(REPO / "course", root, ignore=shutil.ignore_patterns(
        "release", "submitted", "autograded", "feedback", "gradebook.db", "*.npz", "backups", "collected"))
    out = {}
    for lesson in LESSONS:
        generate(root, root, lesson)
        out[lesson] = nbformat.read(root / "release" / lesson / f"{lesson}.ipynb", as_version=4)
    return root, out


def _test_ids(nb):
    return [_gid(c) for c in nb.cells if c.get("metadata", {}).get("nbgrader", {}).get("grade")]


def _sources(nb):
    return [(c.cell_type, _gid(c), c.source) for c in nb.cells]


def _strip(nb):
    for c in nb.cells:
        c.metadata.pop("nbgrader", None)


def _edit_all(nb):
    for c in nb.cells:
        if c.get("metadata", {}).get("nbgrader", {}).get("grade"):
            c.source += "\nprint('debug')"


def _unlock_all(nb):
    for c in nb.cells:
        if c.get("metadata", {}).get("nbgrader", {}).get("grade"):
            c.metadata.nbgrader["locked"] = False
            c.metadata.nbgrader["points"] = 100


def _delete_all(nb):
    nb.cells = [c for c in nb.cells if not c.get("metadata", {}).get("nbgrader", {}).get("grade")]


def _duplicate_all(nb):
    cells = []
    for c in nb.cells:
        cells.append(c)
        if c.get("metadata", {}).get("nbgrader", {}).get("grade"):
            twin = copy.deepcopy(c)
            twin["id"] = "twin-" + c["id"][:20]
            cells.append(twin)
    nb.cells = cells


EDITS = {"stripped metadata": (_strip, "its nbgrader metadata was lost"), "edited": (_edit_all, "edited: run as released"),
         "un-locked, points changed": (_unlock_all, "its nbgrader metadata changed"),
         "deleted": (_delete_all, "deleted: put back as released"),
         "duplicated": (_duplicate_all, "duplicated: run once, as released")}


@pytest.mark.parametrize("kind", sorted(EDITS))
@pytest.mark.parametrize("lesson", LESSONS)
def test_every_test_cell_of_every_lesson_is_put_back_as_released(lessons, lesson, kind):
    root, released = lessons
    a = load_assignment(root, lesson, None)
    change, said = EDITS[kind]
    nb = copy.deepcopy(released[lesson])
    change(nb)
    got, fixed = restore(nb, a, lesson, release_order(root, lesson, lesson))
    tests = _test_ids(released[lesson])
    assert _test_ids(got) == tests
    want = {_gid(c): c.source for c in released[lesson].cells if _gid(c) in tests}
    assert {_gid(c): c.source for c in got.cells if _gid(c) in tests} == want
    assert tampered_cells(got, a, lesson) == {}
    assert set(fixed) >= set(tests) and all(said in fixed[g] for g in tests), fixed
    if kind == "stripped metadata":   # the answer cells are found again too, so they are graded and replaced
        answers = [_gid(c) for c in released[lesson].cells if c.metadata.get("nbgrader", {}).get("solution")]
        assert [_gid(c) for c in got.cells if c.metadata.get("nbgrader", {}).get("solution")] == answers
        assert _sources(got) == _sources(released[lesson])


def test_a_notebook_as_released_is_left_as_it_is(lessons):
    root, released = lessons
    for lesson in LESSONS:
        a = load_assignment(root, lesson, None)
        got, fixed = restore(released[lesson], a, lesson, release_order(root, lesson, lesson))
        assert fixed == {} and got == released[lesson], lesson


def test_a_graded_cell_the_release_does_not_have_is_not_graded(course):
    a = load_assignment(course, ASSIGNMENT, None)
    nb = nbformat.read(course / "release" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)
    extra = nbformat.v4.new_code_cell("pass", metadata={"nbgrader": {"grade": True, "grade_id": "mine_test",
                                                                       "points": 50, "solution": False,
                                                                       "locked": True, "schema_version": 3}})
    nb.cells.append(extra)
    got, fixed = restore(nb, a, ASSIGNMENT, release_order(course, ASSIGNMENT, ASSIGNMENT))
    assert fixed == {"mine_test": "a test cell the assignment does not have: not graded"}
    assert "nbgrader" not in got.cells[-1].metadata


def test_an_edited_and_a_stripped_submission_score_as_the_good_one_and_the_ta_is_told(course, tmp_path):
    need_program("unshare")

    def debug_print(nb):
        cell = next(c for c in nb.cells if _gid(c) == "ex2_sweep_test")
        cell.source += "\nprint(sweep)"

    submit(course, "good")
    submit(course, "eegger", edit=debug_print)
    submit(course, "iito", edit=_strip)
    r = snakekit("grade", ASSIGNMENT, "--course", course, "--references", REFERENCES, "--timeout", "120")
    assert r.returncode == 0, r.stderr[-3000:]
    rows = read_csv(course / f"grades-{ASSIGNMENT}.csv")
    assert (rows["good"]["status"], float(rows["good"]["score"])) == ("graded", 7.0)
    for student, said, shown in (("eegger", "ex2_sweep_test: edited: run as released",
                                  "exercise 2 my_sweep: edited: run as released"),  # as the page's table names it
                                 ("iito", "its nbgrader metadata was lost", "its nbgrader metadata was lost")):
        row = rows[student]
        assert (row["status"], float(row["score"])) == ("tests restored", 7.0), row
        assert said in row["detail"]
        page = (course / "feedback" / student / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()
        assert "(tests restored)" in page and shown in page and "<td>2 my_sweep</td>" in page, page[-3000:]
    ran = nbformat.read(course / "autograded" / "eegger" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)
    assert "print(sweep)" not in next(c for c in ran.cells if _gid(c) == "ex2_sweep_test").source  # as released
    assert set(GOOD) <= {_gid(c) for c in ran.cells}
