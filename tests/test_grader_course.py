"""The course's lesson 06 graded as a TA does it: notebooks in course/submitted/, one command."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

from conftest import need_program
from grader_helpers import read_csv

REPO = Path(__file__).resolve().parent.parent
LESSON = "06_coded_sweep"


def _solutions():
    nb = nbformat.read(REPO / "course" / "source" / LESSON / f"{LESSON}.ipynb", as_version=4)
    return {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells
            if c.metadata.get("nbgrader", {}).get("solution")}


def _hand_in(course: Path, student: str, answers: dict) -> None:
    nb = nbformat.read(REPO / "notebooks" / f"{LESSON}.ipynb", as_version=4)  # what the student was given
    for c in nb.cells:
        gid = c.metadata.get("nbgrader", {}).get("grade_id")
        if gid in answers:
            c.source = answers[gid]
    folder = course / "submitted" / student / LESSON
    folder.mkdir(parents=True)
    nbformat.write(nb, folder / f"{LESSON}.ipynb")


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    need_program("unshare")
    tmp = tmp_path_factory.mktemp("course06")
    course = tmp / "course"
    shutil.copytree(REPO / "course", course, ignore=shutil.ignore_patterns(
        "release", "submitted", "autograded", "feedback", "gradebook.db", "*.npz", ".nbgrader.log"))
    sol = _solutions()
    _hand_in(course, "ana", sol)
    # right for the visible cases (10 Hz), wrong for the hidden rates
    _hand_in(course, "dan", {**sol, "ex06_1_sweep_times": "def sweep_times(points, rate):\n"
                                                          "    return np.arange(points) / 10.0"})
    _hand_in(course, "eve", {})  # handed in untouched
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "grade", LESSON, "--course", str(course)],
                       capture_output=True, text=True, timeout=900, cwd=REPO)
    return course, r


def test_a_ta_gets_grades_csv_and_feedback(graded):
    course, r = graded
    assert r.returncode == 0, r.stderr[-3000:]
    rows = read_csv(course / f"grades-{LESSON}.csv")
    assert {s: (rows[s]["score"], rows[s]["max_score"], rows[s]["status"]) for s in rows} == {
        "ana": ("18", "18", "graded"), "dan": ("16", "18", "graded"), "eve": ("0", "18", "graded")}
    for s in rows:
        assert (course / "feedback" / s / LESSON / f"{LESSON}.html").exists()
        ran = nbformat.read(course / "autograded" / s / LESSON / f"{LESSON}.ipynb", as_version=4)
        assert any("BEGIN HIDDEN TESTS" in c.source for c in ran.cells)  # for the TA: as it ran


def test_failed_hidden_test_feedback_says_what_and_where_without_the_test(graded):
    course, _ = graded
    html = (course / "feedback" / "dan" / LESSON / f"{LESSON}.html").read_text()
    assert "Grader: ex06_1_sweep_times_test: 0 / 2 points" in html
    assert "sweep_times: 6 of 6 hidden cases wrong; first at input (485, 60.8922): entry 1 is 0.1, expected 0.0164225" in html
    src = nbformat.read(course / "source" / LESSON / f"{LESSON}.ipynb", as_version=4)
    from grader.feedback import hidden_lines

    secret = hidden_lines(c.source for c in src.cells)
    assert secret and not [line for line in secret if line in html]
    # the hidden test's own failure message (printed in the kernel) does not reach the student
    ran = (course / "autograded" / "dan" / LESSON / f"{LESSON}.ipynb").read_text()
    assert "send times[484] at points=485" in ran and "send times[484]" not in html


def test_stopped_at_a_visible_check_feedback_repeats_that_check(graded):
    course, _ = graded
    html = (course / "feedback" / "eve" / LESSON / f"{LESSON}.html").read_text()
    assert ("Grader: ex06_1_sweep_times_test: 0 / 2 points</b><br/>nothing was handed in: the test cell stopped at a "
            "visible check, before the hidden tests ran. It said: CheckFailed: exercise 6.1 sweep_times: `sweep_times` "
            "is not written yet") in html


def test_task2_feedback_plots_the_run_against_the_reference(graded):
    course, _ = graded
    html = (course / "feedback" / "ana" / LESSON / f"{LESSON}.html").read_text()
    assert "Grader: ex06_3_task2_test: 10 / 10 points" in html
    assert 'alt="No description has been provided for this image" class="" src="data:image/png;base64,' in html
