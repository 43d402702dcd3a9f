"""The course graded as a TA does it (lessons 06 and 01): notebooks in course/submitted/, one command."""

from __future__ import annotations

import re
from pathlib import Path

import nbformat
import numpy as np
import pytest

import snakekit

from conftest import copy_course, need_program
from grader_helpers import read_csv
from grader_helpers import snakekit as command

REPO = Path(__file__).resolve().parents[2]
LESSON = "06_coded_sweep"


def _solutions(lesson=LESSON):
    nb = nbformat.read(REPO / "course" / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    return {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells
            if c.metadata.get("nbgrader", {}).get("solution")}


def _hand_in(course: Path, student: str, answers: dict, lesson=LESSON) -> None:
    nb = nbformat.read(REPO / "notebooks" / f"{lesson}.ipynb", as_version=4)  # what the student was given
    for c in nb.cells:
        gid = c.metadata.get("nbgrader", {}).get("grade_id")
        if gid in answers:
            c.source = answers[gid]
    folder = course / "submitted" / student / lesson
    folder.mkdir(parents=True)
    nbformat.write(nb, folder / f"{lesson}.ipynb")


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    need_program("unshare")
    tmp = tmp_path_factory.mktemp("course06")
    course = tmp / "course"
    copy_course(course)
    sol = _solutions()
    _hand_in(course, "ana", sol)
    # right for the visible cases (10 Hz), wrong for the hidden rates
    _hand_in(course, "dan", {**sol, "ex06_1_sweep_times": "def sweep_times(points, rate):\n"
                                                          "    return np.arange(points) / 10.0"})
    _hand_in(course, "eve", {})  # handed in untouched
    r = command("grade", LESSON, "--course", course)
    return course, r


def test_a_ta_gets_grades_csv_and_feedback(graded):
    course, r = graded
    assert r.returncode == 0, r.stderr[-3000:]
    assert "hidden cases drawn with seed" in r.stderr
    rows = read_csv(course / f"grades-{LESSON}.csv")
    assert {s: (rows[s]["max_score"], rows[s]["status"]) for s in rows} == {
        "ana": ("18", "graded"), "dan": ("18", "graded"), "eve": ("18", "graded")}
    assert (rows["ana"]["score"], rows["eve"]["score"]) == ("18", "0")
    # one slip in 6.1: it loses 6.1's points and a share of what builds on it, never all of it
    assert 10 <= float(rows["dan"]["score"]) < 18
    for s in rows:
        assert (course / "feedback" / s / LESSON / f"{LESSON}.html").exists()
        ran = nbformat.read(course / "autograded" / s / LESSON / f"{LESSON}.ipynb", as_version=4)
        assert not any("BEGIN HIDDEN TESTS" in c.source for c in ran.cells)  # no notebook has hidden tests


def test_a_wrong_case_is_named_with_its_call_and_numbers(graded):
    course, _ = graded
    html = (course / "feedback" / "dan" / LESSON / f"{LESSON}.html").read_text()
    assert "Grader: 6.1 sweep_times: 0 / 2 points" in html or "Grader: 6.1 sweep_times: 0." in html
    assert "hidden cases wrong; the first: sweep_times(" in html and "expected" in html and "tolerance" in html


def test_a_slip_in_61_is_graded_again_with_the_lessons_own_61_and_the_feedback_says_so_in_one_line(graded):
    course, _ = graded
    html = (course / "feedback" / "dan" / LESSON / f"{LESSON}.html").read_text()
    # dan's 6.3 at the hidden rates is built on his 10 Hz times: with the lesson's 6.1 it is right
    assert re.search(r"graded with the lesson(&#39;|&#x27;|')s own 6.1 in place of yours: 7 of 7 "
                     r"\(with yours: [0-9.]+, the run below\)", html), html[:3000]
    assert 16 <= float(read_csv(course / f"grades-{LESSON}.csv")["dan"]["score"]) < 18   # all but (most of) 6.1


def test_an_untouched_notebook_is_told_what_is_missing(graded):
    course, _ = graded
    html = (course / "feedback" / "eve" / LESSON / f"{LESSON}.html").read_text()
    assert "Grader: 6.1 sweep_times: 0 / 2 points" in html
    assert "hidden cases wrong; the first: sweep_times(" in html and "your function raised" in html


def test_task2_feedback_plots_the_run_against_the_reference(graded):
    course, _ = graded
    html = (course / "feedback" / "ana" / LESSON / f"{LESSON}.html").read_text()
    assert "Grader: 6.3 task2_sweep:" in html and "every check passed in every hidden case" in html
    assert any('src="data:image/png;base64,' in t and 'alt="No description has been provided for this image"' in t
               for t in re.findall(r"<img\b[^>]*>", html))


def test_grading_keeps_task2_at_the_spec_values_for_the_lab(graded):
    course, _ = graded
    with np.load(course / "autograded" / "ana" / LESSON / "lab" / "ex06_3_task2_test.npz", allow_pickle=False) as z:
        assert np.allclose(z["positions"], snakekit.side_sweep().positions, atol=1e-12)
    assert not (course / "autograded" / "eve" / LESSON / "lab" / "ex06_3_task2_test.npz").exists()  # nothing returned


# --- lesson 01: scored out of the kernel too, so patching numpy and the checks earns nothing ----

LESSON01 = "01_forward_kinematics"
CHEAT = ("import numpy\n"
         "numpy.allclose = lambda *a, **k: True                  # patch numpy\n"
         "checks.Exercise.close = lambda self, *a, **k: None     # and the checks: every comparison passes\n"
         "def planar_fk(q):\n"
         "    return np.zeros(3)\n")


@pytest.fixture(scope="module")
def graded01(tmp_path_factory):
    need_program("unshare")
    tmp = tmp_path_factory.mktemp("course01")
    course = tmp / "course"
    copy_course(course)
    sol = _solutions(LESSON01)
    _hand_in(course, "ana", sol, LESSON01)
    _hand_in(course, "mal", {**sol, "ex01_1_planar_fk": CHEAT}, LESSON01)
    r = command("grade", LESSON01, "--course", course)
    return course, r


def test_lesson01_patching_numpy_and_the_checks_scores_0_for_that_exercise(graded01):
    course, r = graded01
    assert r.returncode == 0, r.stderr[-3000:]
    rows = read_csv(course / f"grades-{LESSON01}.csv")
    # ex01_1 (4 points) is the one cheated on; ex01_2 (3) and ex01_3 (1) are the instructor's
    assert {s: (rows[s]["score"], rows[s]["max_score"], rows[s]["status"]) for s in rows} == {
        "ana": ("8", "8", "graded"), "mal": ("4", "8", "graded")}
    # in the kernel the patched checks passed: nbgrader alone would have given the 4 points
    ran = nbformat.read(course / "autograded" / "mal" / LESSON01 / f"{LESSON01}.ipynb", as_version=4)
    test = next(c for c in ran.cells if c.metadata.get("nbgrader", {}).get("grade_id") == "ex01_1_planar_fk_test")
    assert not [o for o in test.outputs if o.output_type == "error"]
    html = (course / "feedback" / "mal" / LESSON01 / f"{LESSON01}.html").read_text()
    assert "Grader: 1.1 planar_fk: 0 / 4 points" in html
    assert "hidden cases wrong; the first: planar_fk(" in html
