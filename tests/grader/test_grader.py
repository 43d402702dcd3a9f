"""The grader's parts: trajectory checks, reference files, scoring of hand-ins, and a batch on the test course."""

from __future__ import annotations

import json
import re
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from conftest import IN_CI, need_program
from grader.scoring import compare
from grader.scoring.references import REFERENCES as COURSE_REFERENCES
from grader.scoring.references import Reference, differences, main as references_main, spec_hash
from grader.scoring.score import Expected, score_exercise
from grader_helpers import ASSIGNMENT, FIXTURE, REFERENCES, make_course, read_csv, snakekit, submit
from snakekit.trajectory import Trajectory, side_sweep

REPO = Path(__file__).resolve().parents[2]


# --- grader.scoring.compare -----------------------------------------------------------------------------


def test_task2_sweep_passes_every_check():
    ref = side_sweep()
    checks = [compare.point_count(ref, 500), compare.rate(ref, 10.0), compare.limits(ref), compare.sweep_count(ref, 50),
              compare.home(ref), compare.smoothness(ref, ref),
              compare.tracking(ref, ref, max_tol=1e-6, rms_tol=1e-6)]
    assert [c.fraction for c in checks] == [1.0] * 7


def test_tracking_error_names_joint_time_and_amount():
    ref = side_sweep()
    p = ref.positions.copy()
    p[200, 2] += 0.05  # joint 3 at t = 20 s
    c = compare.tracking(Trajectory(ref.times, p), ref, max_tol=0.01, rms_tol=0.01)
    assert "joint 3 at t=20.00 s is +0.05 rad" in c.message and "tolerance 0.01 rad" in c.message
    # max error 0.05 = 5x tol -> falloff (0.05-0.01)/(0.1-0.01) -> 0.556 on max, RMS 0.05/sqrt(500) within tol
    assert c.fraction == pytest.approx((4 + 0.5 * (1 - 0.04 / 0.09) + 0.5) / 5)


def test_time_alignment_ignores_a_start_offset():
    ref = side_sweep()
    late = Trajectory(ref.times + 3.0, ref.positions)
    assert compare.tracking(late, ref, max_tol=1e-9, rms_tol=1e-9).fraction == 1.0


def test_rate_recognises_100_hz_and_a_start_at_1():
    ref = side_sweep()
    fast = compare.rate(Trajectory(ref.times / 10, ref.positions), 10.0)
    assert fast.fraction == 0.5 and "100 Hz where 10 Hz was asked" in fast.message
    late = compare.rate(Trajectory(ref.times + 1.0, ref.positions), 10.0)
    assert late.fraction == 0.75 and "starts at 1 instead of 0" in late.message


def test_sweeps_and_home_count_like_a_person():
    short = side_sweep(points=500, sweeps=40)
    assert compare.count_sweeps(short.positions) == 40
    c = compare.sweep_count(short, 50)
    assert c.fraction == pytest.approx(0.8) and "sweeps: 40, expected 50" in c.message
    t = np.arange(500) / 10
    not_home = Trajectory(t, np.repeat((0.2 * np.sin(2 * np.pi * t / 10))[:, None], 5, 1))
    h = compare.home(not_home)
    assert h.fraction == 0.5 and "does not return home" in h.message


def test_limits_and_smoothness_give_partial_credit_with_numbers():
    ref = side_sweep()
    p = ref.positions.copy()
    p[100:105, 0] = 1.6  # beyond +1.57 rad, and a jump
    bad = Trajectory(ref.times, p)
    lim = compare.limits(bad)
    assert lim.fraction == pytest.approx(1 - 6 / 500)  # 5 points beyond, and the step down after them
    assert lim.message.startswith("limits: 3 stretch(es) beyond a limit, at 6 of 500 points; ")
    assert ("worst position: joint 1 at t=10.000 s: position +1.6000 rad (limit +1.5700), beyond it from "
            "t=10.000 to 10.400 s (5 points); 0.03 rad over") in lim.message
    assert "worst velocity: joint 1 at t=10.000 s: velocity +16.9653 rad/s (limit +1.5000); 15.47 rad/s over" in lim.message
    sm = compare.smoothness(bad, ref)
    assert sm.fraction == 0.0 and "joint 1 at t=" in sm.message


# --- references ------------------------------------------------------------------------------


def test_reference_file_holds_how_to_judge_not_the_expected_results(tmp_path):
    ref = Reference.load(REFERENCES / f"{ASSIGNMENT}.npz")
    assert ref.meta["spec_hash"] == spec_hash() and ref.meta["assignment"] == ASSIGNMENT
    assert ref.exercises["ex2_sweep_test"]["kind"] == "run"
    assert ref.exercises["ex1_tool_xy_test"] == {"kind": "values", "outputs": ["value"],
                                                 "tolerances": {"rtol": 1e-9, "atol": 1e-12}}
    assert ref.exercises["ex2_sweep_test"]["tolerances"]["max"] >= 2 * np.pi / 4096   # one encoder tick at least
    again = Reference.load(ref.save(tmp_path / "r.npz"))
    assert again.meta == ref.meta and differences(ref, again) == []
    with np.load(tmp_path / "r.npz", allow_pickle=False) as z:  # the header only: no results to find
        assert z.files == ["__meta__"]


def test_fixture_reference_is_current_where_its_course_keeps_it():
    assert REFERENCES == FIXTURE / "references"  # no --out: a course's references are its own references/
    assert references_main([ASSIGNMENT, "--course", str(FIXTURE), "--check"]) == 0


@pytest.mark.parametrize("path", sorted(COURSE_REFERENCES.glob("*.npz")), ids=lambda p: p.stem)
def test_course_references_are_current(path):
    # as a developer runs it (in-process under pytest's captured output, lesson 00's kernel,
    # which starts the meshcat viewer, was seen to stall)
    r = subprocess.run([sys.executable, "-m", "grader.scoring.references", path.stem, "--check"], capture_output=True,
                       text=True, cwd=REPO, timeout=900,
                       env={**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"})
    assert r.returncode == 0 and f"{path.name} is current" in r.stdout, r.stderr[-3000:]


def test_stale_reference_is_reported(tmp_path, capsys):
    ref = Reference.load(REFERENCES / f"{ASSIGNMENT}.npz")
    meta = json.loads(json.dumps(ref.meta))
    meta["exercises"]["ex1_tool_xy_test"]["tolerances"]["atol"] = 1e-6
    Reference(ref.assignment, meta).save(tmp_path / f"{ASSIGNMENT}.npz")
    assert references_main([ASSIGNMENT, "--course", str(FIXTURE), "--out", str(tmp_path), "--check"]) == 1
    assert "ex1_tool_xy_test tolerance atol: 1e-06 -> 1e-12" in capsys.readouterr().err


def test_a_changed_cases_module_makes_the_reference_stale(tmp_path):
    course = tmp_path / "course"
    shutil.copytree(FIXTURE, course, ignore=shutil.ignore_patterns("references", "__pycache__"))
    ref = Reference.load(REFERENCES / f"{ASSIGNMENT}.npz")
    assert ref.source_changed(course) is False
    path = course / "cases" / f"{ASSIGNMENT}.py"
    path.write_text(path.read_text().replace("range(8)", "range(9)"))
    assert ref.source_changed(course) is True


# --- scoring a hand-in, case by case ---------------------------------------------------------------


def _xy(q):
    from snakekit import tool_pose_2d

    return {"value": np.asarray(tool_pose_2d(q)[:2])}


@pytest.fixture(scope="module")
def xy_cases():
    qs = [(np.random.default_rng(k).uniform(-1.5, 1.5, 5),) for k in range(4)]
    return Expected("ex1_tool_xy_test", "values", qs, [_xy(*a) for a in qs], {"rtol": 1e-9, "atol": 1e-12}, "tool_xy")


def test_values_scored_case_by_case_naming_the_call(xy_cases):
    good = [_xy(*a) for a in xy_cases.cases]
    assert score_exercise("ex1_tool_xy_test", good, xy_cases, 2.0).score == 2.0
    good[2] = {"value": good[2]["value"] + [0.0, 1e-3]}
    s = score_exercise("ex1_tool_xy_test", good, xy_cases, 2.0)
    q = xy_cases.cases[2][0]
    assert s.score == 1.5 and s.message.startswith("1 of 4 hidden cases wrong; the first: tool_xy([")
    assert f"{q[0]:.4g}" in s.message and "the result[1] is " in s.message and "off by 0.001" in s.message


def test_a_forgotten_return_and_an_error_are_said_in_plain_words(xy_cases):
    s = score_exercise("ex1_tool_xy_test", ["returned None"] * 4, xy_cases, 2.0)
    assert s.score == 0 and "tool_xy returned None: did you forget `return`?" in s.message
    s = score_exercise("ex1_tool_xy_test", ["returned None from tool_xy"] * 4, xy_cases, 2.0)
    assert s.score == 0 and "tool_xy returned None: did you forget `return`?" in s.message
    s = score_exercise("ex1_tool_xy_test", ["IndexError: index 5 is out of bounds"] * 4, xy_cases, 2.0)
    assert "your function raised IndexError: index 5 is out of bounds" in s.message
    s = score_exercise("ex1_tool_xy_test", ["ShortcutError: this exercise asks you to write it yourself"] * 4,
                       xy_cases, 2.0)
    assert "tool_xy(" in s.message and "asks you to write it yourself" in s.message and "ShortcutError" not in s.message


def test_nan_shape_and_a_wrong_count_of_results(xy_cases):
    s = score_exercise("ex1_tool_xy_test", [{"value": np.array([np.nan, 0.0])}] * 4, xy_cases, 2.0)
    assert s.score == 0 and "the result[0] is nan: every value must be a finite number" in s.message
    s = score_exercise("ex1_tool_xy_test", [{"value": np.zeros(3)}] * 4, xy_cases, 2.0)
    assert "has shape (3,), expected (2,)" in s.message
    s = score_exercise("ex1_tool_xy_test", [{"value": np.zeros(2)}] * 3, xy_cases, 2.0)
    assert s.status == "inconsistent" and "3 results for the 4 hidden cases" in s.message
    s = score_exercise("ex1_tool_xy_test", None, xy_cases, 2.0)
    assert s.status == "missing" and s.message.startswith("nothing was handed in")


def test_an_instructor_exception_asks_for_the_same_type():
    e = Expected("ex9_f_test", "values", [(1.0,), (-1.0,)], [{"value": np.array(1.0)}, "ValueError: out of reach"],
                 function="f")
    assert score_exercise("ex9_f_test", [{"value": np.array(1.0)}, "ValueError: too far"], e, 2).score == 2
    s = score_exercise("ex9_f_test", [{"value": np.array(1.0)}, {"value": np.array(0.0)}], e, 2)
    assert s.score == 1 and "f(-1) must raise ValueError" in s.message and "returned a result" in s.message
    s = score_exercise("ex9_f_test", [{"value": np.array(1.0)}, "TypeError: bad"], e, 2)
    assert s.score == 1 and "your function raised TypeError: bad" in s.message


def _run_case(points=60, rate=10.0, sweeps=2, amplitude=0.2, start=0.0):
    import snakekit

    t = np.arange(points) / rate + start
    a = amplitude * np.sin(2 * np.pi * sweeps * (t - start) / (t[-1] - start))
    a[-1] = 0.0
    traj = snakekit.Trajectory(t, np.repeat(a[:, None], 5, axis=1))
    with snakekit.make_robot("sim") as robot:
        run = robot.run(Trajectory(t - start, traj.positions))
    return dict(times=traj.times, positions=traj.positions, measured_times=run.measured.times,
                measured_positions=run.measured.positions)


@pytest.fixture(scope="module")
def run_case():
    ref = Reference.load(REFERENCES / f"{ASSIGNMENT}.npz")
    want = _run_case()
    return Expected("ex2_sweep_test", "run", [(60, 10.0, 2, 0.2)], [want],
                    ref.exercises["ex2_sweep_test"]["tolerances"], "graded_run"), want


def test_run_scored_from_its_checks(run_case):
    e, good = run_case
    assert score_exercise("ex2_sweep_test", [good], e, 4.0).score == 4.0
    late = dict(good, measured_positions=good["measured_positions"] + 0.01)  # 0.01 rad = 6.5 ticks off
    s = score_exercise("ex2_sweep_test", [late], e, 4.0)
    # 8 of 10 weight pass; the run check: max and RMS 0.01 rad vs 0.00153 / 0.00077 tolerances
    f = 0.5 * compare.falloff(0.01, 0.00153398, 0.0153398) + 0.5 * compare.falloff(0.01, 0.00076699, 0.0076699)
    assert s.score == pytest.approx(4.0 * (8 + 2 * f) / 10, abs=1e-3)
    assert "graded_run(60, 10, 2, 0.2): run vs reference: largest measured angle error joint 1" in s.message


def test_a_slip_in_one_part_keeps_the_points_of_the_others(run_case):
    """Times from 0.1 s (a slip in the send times): count, sweeps, limits, home, smoothness keep their points."""
    e, _ = run_case
    slipped = _run_case(start=0.1)
    s = score_exercise("ex2_sweep_test", [slipped], e, 4.0)
    names = {c.name: c.fraction for c in s.checks}
    assert names["points"] == names["sweeps"] == names["limits"] == names["home"] == names["smoothness"] == 1.0
    assert names["rate"] == 0.75 and "the first point is at t=0.1 s, expected 0 s" in s.message
    assert 2.0 <= s.score < 4.0
    no_run = {k: v for k, v in slipped.items() if not k.startswith("measured")}  # the simulator refused it
    s2 = score_exercise("ex2_sweep_test", [no_run], e, 4.0)
    assert s2.score < s.score and "the arm made no run of it" in s2.message


# --- a batch on the test course ----------------------------------------------------------------


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    need_program("unshare")
    tmp = tmp_path_factory.mktemp("batch")
    course = make_course(tmp)
    submit(course, "alice")
    submit(course, "bob", {"ex1_tool_xy": "def tool_xy(q):\n    return np.array([0.3315, 0.0]) + 0 * q[:2]",
                           "ex2_sweep": "def my_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):\n"
                                        "    t = np.arange(points) / (10 * rate)\n"
                                        "    a = amplitude * np.sin(2 * np.pi * sweeps * t / t[-1])\n"
                                        "    a[-1] = 0.0\n"
                                        "    return snakekit.Trajectory(t, np.repeat(a[:, None], 5, 1))"})

    def grade(*extra):
        return snakekit("grade", ASSIGNMENT, "--course", course, "--references", REFERENCES, "--timeout", "60", *extra)

    first = grade("--seed", "20261124")
    csv1 = (course / f"grades-{ASSIGNMENT}.csv").read_text()
    second = grade("--seed", "20261124")
    csv2 = (course / f"grades-{ASSIGNMENT}.csv").read_text()
    third = grade()
    csv3 = (course / f"grades-{ASSIGNMENT}.csv").read_text()
    return {"course": course, "first": first, "second": second, "third": third, "csv1": csv1, "csv2": csv2,
            "csv3": csv3}


def test_batch_writes_csv_with_scores(graded):
    assert graded["first"].returncode == 0, graded["first"].stderr[-3000:]
    rows = read_csv(graded["course"] / f"grades-{ASSIGNMENT}.csv")
    assert list(next(iter(rows.values())))[:5] == ["student", "assignment", "score", "max_score", "status"]
    assert (rows["alice"]["score"], rows["alice"]["status"]) == ("7", "graded")
    # bob: ex1 0 (every hidden case wrong); ex3 passes in the kernel (its visible check only);
    # ex2: his sweep at 10x the rate breaks the velocity limit, so it is not run: the trajectory's
    # own checks (points, sweeps, home) keep their points
    assert rows["bob"]["status"] == "graded" and 1 < float(rows["bob"]["score"]) < 4


def test_the_seed_repeats_a_batch_and_an_unchanged_attempt_keeps_its_cases(graded):
    """--seed grades at that seed; a batch without it grades the attempts already graded (the same
    notebooks) at the seed they met (grader.scoring.draws: a regrade changes no grade no one
    touched); a new attempt's fresh draw: tests/grader/test_grader_regrade.py."""
    assert "hidden cases drawn with seed 20261124" in graded["first"].stderr
    assert graded["second"].returncode == 0 and graded["csv2"] == graded["csv1"]   # the same cases: the same grades
    assert graded["third"].returncode == 0, graded["third"].stderr[-3000:]
    assert "hidden cases drawn with seed 20261124" in graded["third"].stderr
    assert graded["csv3"] == graded["csv1"]
    assert read_csv(graded["course"] / f"grades-{ASSIGNMENT}.csv")["alice"]["score"] == "7"


def test_scores_land_in_nbgraders_gradebook(graded):
    from nbgrader.api import Gradebook

    with Gradebook(f"sqlite:///{graded['course'] / 'gradebook.db'}", "snakekit-test-course") as gb:
        assert gb.find_submission(ASSIGNMENT, "alice").score == 7.0
        bob = gb.find_submission(ASSIGNMENT, "bob")
        assert bob.score == float(read_csv(graded["course"] / f"grades-{ASSIGNMENT}.csv")["bob"]["score"])
        assert gb.find_grade("ex1_tool_xy_test", ASSIGNMENT, ASSIGNMENT, "bob").auto_score == 0.0
    con = sqlite3.connect(graded["course"] / "gradebook.db")
    assert con.execute("SELECT COUNT(*) FROM submitted_assignment").fetchone()[0] == 2  # twice, not duplicated


def test_progress_shows_done_left_failed(graded):
    err = graded["first"].stderr
    assert "0/2: done 0, left 2, 0 with problems" in err and "2/2: done 2, left 0, 0 with problems" in err


def test_feedback_has_verdicts_and_plots_but_no_hidden_tests(graded):
    import nbformat

    from grader.feedback.scrub import hidden_lines

    html = (graded["course"] / "feedback" / "bob" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()
    assert "Grader: 1 tool_xy: 0 / 2 points" in html
    assert "8 of 8 hidden cases wrong; the first: tool_xy(q=[" in html
    assert "Hz where" in html and "Hz was asked" in html and "the arm made no run of it" in html
    plots = len([t for t in re.findall(r"<img\b[^>]*>", html)
                 if 'src="data:image/png;base64,' in t and 'alt="No description has been provided for this image"' in t])
    assert plots == 1  # bob's sweep against the reference
    src = nbformat.read(FIXTURE / "source" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)
    solution = [line.strip() for c in src.cells if c.metadata.get("nbgrader", {}).get("solution")
                for line in c.source.splitlines() if line.strip() and not line.strip().startswith(("#", "def", '"""'))]
    assert solution and not [line for line in solution if line in html]   # the instructor's code stays out
    assert not hidden_lines(c.source for c in src.cells)                  # no hidden tests left to show
    assert "Traceback" not in html


def test_exit_code_2_for_bad_arguments(tmp_path):
    def run(*args):
        return snakekit("grade", *args)

    r = run("t1_sweep", "--course", str(tmp_path / "nowhere"))
    assert r.returncode == 2 and "no course folder" in r.stderr
    r = run("no_such_lesson", "--course", str(FIXTURE))
    assert r.returncode == 2 and "the course has: t1_sweep" in r.stderr
    r = run("t1_sweep", "--course", str(FIXTURE), "--jobs", "0")
    assert r.returncode == 2 and "--jobs must be at least 1" in r.stderr


def test_exit_code_1_when_the_grader_fails(tmp_path):
    course = make_course(tmp_path)
    submit(course, "alice")
    refs = tmp_path / "refs"
    refs.mkdir()
    (refs / f"{ASSIGNMENT}.npz").write_bytes(b"not a zip")
    r = snakekit("grade", ASSIGNMENT, "--course", course, "--references", refs)
    assert r.returncode == 1 and "not a readable reference file" in r.stderr


def test_grader_depends_only_on_trajectory_model_and_run():
    code = ("import sys, grader.batch, grader.commands.grade, grader.scoring.score, grader.scoring.references, "
            "grader.feedback.notebook, grader.feedback.exporter; "
            "print(sorted(m for m in sys.modules if m.startswith('snakekit')))")
    mods = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True).stdout
    for banned in ("snakekit.viewer", "snakekit.sim", "snakekit.hardware", "snakekit.emulator", "snakekit.widgets",
                   "snakekit.servo"):
        assert f"'{banned}'" not in mods


@pytest.mark.parametrize("name", ["grader.scoring.compare", "grader.feedback.scrub", "grader.feedback.mathml",
                                  "grader.markup", "grader.scoring.score", "grader.feedback.scores", "grader.scoring.verdict",
                                  "grader.files"])
def test_docstring_examples(name):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0 and result.attempted > 0


def test_kernel_verdict_hides_a_hidden_tests_message():
    """A test cell without a reference keeps nbgrader's verdict, but only a visible check's words."""
    from nbformat.v4 import new_code_cell, new_notebook, new_output

    from grader.course.assignment import TestCell
    from grader.scoring.verdict import kernel_score

    src = "check(f)\n### BEGIN HIDDEN TESTS\nassert f(7) == 49, 'f(7) should be 49'\n### END HIDDEN TESTS\n"
    cell = new_code_cell(src, execution_count=5, metadata={"nbgrader": {"grade_id": "t", "grade": True}})
    nb = new_notebook(cells=[cell])
    info = TestCell("t", "nb", 2.0, src, "code")

    def fails_at(line):
        cell.outputs = [new_output("error", ename="AssertionError", evalue="f(7) should be 49",
                                   traceback=[f"\x1b[36mCell In[5], line {line}\x1b[0m", "AssertionError"])]
        return kernel_score("t", info, nb)

    hidden = fails_at(3)
    assert (hidden.score, hidden.max_score) == (0.0, 2.0)
    assert hidden.message.startswith("a hidden test failed (AssertionError).") and "49" not in hidden.message
    assert fails_at(1).message == "a visible check failed: AssertionError: f(7) should be 49"
    cell.outputs = []
    assert kernel_score("t", info, nb).score == 2.0


def test_only_the_sandboxs_own_gradebook_copy_skips_waiting_for_the_disk(tmp_path):
    """The worker's course copy is deleted after the run: its SQLite need not sync; a fresh process still does."""
    code = ("import sys, sqlalchemy as sa\n"
            "if sys.argv[1] == 'worker':\n    from grader.sandbox.inside.worker import _throwaway_gradebook; _throwaway_gradebook()\n"
            "with sa.create_engine(f'sqlite:///{sys.argv[2]}').connect() as c:\n"
            "    print(c.exec_driver_sql('PRAGMA synchronous').scalar(), c.exec_driver_sql('PRAGMA journal_mode').scalar())")
    out = {who: subprocess.run([sys.executable, "-c", code, who, str(tmp_path / f"{who}.db")], capture_output=True,
                               text=True, cwd=REPO, check=True).stdout.split() for who in ("worker", "grader")}
    assert out == {"worker": ["0", "memory"], "grader": ["2", "delete"]}  # OFF / MEMORY; SQLite's FULL / DELETE


def test_feedback_plot_drawn_once_for_the_same_run_and_again_for_any_other(monkeypatch):
    from collections import OrderedDict

    from grader.feedback import plot

    drawn = []
    draw = plot._draw
    monkeypatch.setattr(plot, "_draw", lambda curves, title: drawn.append(title) or draw(curves, title))
    monkeypatch.setattr(plot, "_plots", OrderedDict())
    monkeypatch.setattr(plot, "PLOT_CACHE", 2)
    t = np.arange(60) / 10.0
    q = 0.2 * np.sin(t)[:, None] * np.ones((1, 5))
    first = plot.plot_png({"measured": (t, q), "reference measured": (t, q.copy())}, "ex")
    again = plot.plot_png({"measured": (t.copy(), q.copy()), "reference measured": (t, q)}, "ex")
    assert first[:8] == b"\x89PNG\r\n\x1a\n" and again == first and drawn == ["ex"]
    moved = q.copy()
    moved[40, 3] = np.nextafter(moved[40, 3], 1.0)  # one joint, one sample, one bit
    plot.plot_png({"measured": (t, moved), "reference measured": (t, q)}, "ex")
    assert drawn == ["ex", "ex"]
    moved[40, 3] += 0.05
    other = plot.plot_png({"measured": (t, moved), "reference measured": (t, q)}, "ex")
    assert drawn == ["ex", "ex", "ex"] and other != first  # its zoom now points at joint 4
    assert len(plot._plots) == 2  # the oldest plot let go: drawing it again below draws it anew
    assert plot.plot_png({"measured": (t, q), "reference measured": (t, q)}, "ex") == first
    assert drawn == ["ex", "ex", "ex", "ex"]


def test_feedback_html_is_what_nbconverts_own_exporter_writes(tmp_path):
    """The feedback exporter keeps its filters' results between pages; the pages stay what the exporter writes
    without them (nbconvert's, with math as MathML)."""
    from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output

    from grader.feedback import exporter

    def page(student):
        code = new_code_cell(f"x = np.arange(3)  # {student}\nprint(x)", execution_count=1)
        code.outputs = [new_output("display_data", data={"text/html": f"<b>{student}</b>"})]
        verdict = new_code_cell("", metadata={"tags": ["grader-verdict"]})
        verdict.outputs = [new_output("display_data", data={"text/html": "<div>Grader: 1 / 2 points</div>"})]
        nb = new_notebook(cells=[new_markdown_cell("# Lesson\n\n$q_1$ and `code`"), code, verdict])
        nb.metadata = {"language_info": {"name": "python"}}
        return nb

    plain = exporter.exporter_class()(config=exporter.exporter_config())  # with no results kept
    for student in ("ann", "ben", "ann"):
        nb = page(student)
        written = exporter.write_html(nb, tmp_path / f"{student}.html").read_text()
        assert written == plain.from_notebook_node(nb)[0]
        assert f"<b>{student}</b>" in written and f"# {student}" in written
        assert "<math display=\"inline\"><mrow><msub><mi>q</mi><mn>1</mn></msub></mrow></math>" in written


@pytest.mark.parametrize("chunks", [["speeds: [0.58 0.61] -> 3 too fast\n"], ["speeds: [0.58 ", "0.61] -> 3 too fast\n"],
                                    ["speeds: [0.58 0.61]", " -> 3 ", "too fast\n"]])
def test_a_print_flushed_in_pieces_makes_the_same_page(tmp_path, chunks):
    """A kernel sends one print as one stream output or several, as it flushed on a quiet or a busy
    machine: the page is the same, with the line whole (a regrade's page is the same page)."""
    from nbformat.v4 import new_code_cell, new_notebook, new_output

    from grader.feedback import exporter

    def page(parts):
        code = new_code_cell("print(speeds)", execution_count=1, id="speeds")
        code.outputs = [new_output("stream", name="stdout", text=t) for t in parts]
        nb = new_notebook(cells=[code])
        nb.metadata = {"language_info": {"name": "python"}}
        return exporter.write_html(nb, tmp_path / f"{len(parts)}.html").read_text()

    written = page(chunks)
    assert written == page(["speeds: [0.58 0.61] -> 3 too fast\n"])
    assert "speeds: [0.58 0.61] -&gt; 3 too fast" in written


def test_a_feedback_page_is_what_nbconvert_writes_with_its_alt_texts_and_tabindexes():
    """The page is written without nbconvert's last pass (BeautifulSoup over the whole page, most of a
    page's time); parsed, it is the page nbconvert writes: images without alt text get nbconvert's, the
    cells' input and output areas a tabindex, and nothing else changes."""
    import base64

    from bs4 import BeautifulSoup
    from nbconvert import HTMLExporter
    from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output

    from grader.feedback import exporter as feedback

    png = ("iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNk+M9QDwADhgGAWjR9awAAAABJRU5ErkJggg==")
    assert base64.b64decode(png).startswith(b"\x89PNG")
    code = new_code_cell("import numpy as np\nplt.plot([1, 2])", execution_count=3)
    code.outputs = [new_output("display_data", data={"image/png": png, "text/plain": "<Figure>"}),
                    new_output("stream", name="stdout", text="<div> is text, not a tag; it's \"quoted\" & done\n"),
                    new_output("display_data", data={"text/html": '<img src="x.png" alt="mine"><img src="y.png">'})]
    verdict = new_code_cell("", metadata={"tags": ["grader-verdict"]})
    verdict.outputs = [new_output("display_data", data={"text/html": "<div class='v'>Grader: 1 / 2 points</div>"})]
    nb = new_notebook(cells=[new_markdown_cell("# Lesson\n\n![the arm](data:image/png;base64," + png + ")\n\n$q_1$"),
                             code, verdict])
    nb.metadata = {"language_info": {"name": "python"}}
    exporter = feedback.exporter_class()(config=feedback.exporter_config())
    ours = exporter.from_notebook_node(nb)[0]
    theirs = HTMLExporter.from_notebook_node(exporter, nb)[0]  # nbconvert's own, BeautifulSoup pass included
    parsed = str(BeautifulSoup(ours, features="html.parser"))
    assert feedback._STYLE.sub("", parsed) == feedback._STYLE.sub("", theirs)  # the style sheets: comments out
    assert ours.count('tabindex="0"') == theirs.count('tabindex="0"') >= 4
    assert ours.count('alt="No description has been provided for this image"') == 2  # the plot, y.png
    assert 'alt="mine"' in ours
    assert "&lt;div&gt; is text, not a tag; it's \"quoted\" &amp; done" in ours  # as nbconvert's page has it
    assert "&lt;div&gt; is text, not a tag; it's \"quoted\" &amp; done" in theirs


def test_a_trajectory_is_held_only_to_the_properties_its_reference_has():
    """A sampled move (not a sweep, not home to home) is not asked for sweeps or home."""
    t = np.arange(11) / 10.0
    r = np.clip(t / 1.0, 0, 1)
    move = np.outer(10 * r ** 3 - 15 * r ** 4 + 6 * r ** 5, [0.3, -0.2, 0.4, 0.1, 0.5])
    e = Expected("ex04_3_sample_10hz_test", "trajectory", [(np.zeros(5), move[-1], 1.0, 10.0)],
                 [{"times": t, "positions": move}], {"max": 1e-12, "rms": 1e-12}, "sample_10hz")
    s = score_exercise(e.grade_id, [{"times": t, "positions": move}], e, 3)
    assert s.score == 3 and {c.name for c in s.checks} == {"points", "rate", "limits", "smoothness",
                                                            "commanded vs reference"}
    late = score_exercise(e.grade_id, [{"times": t + 0.1, "positions": move}], e, 3)
    assert late.score < 3 and "the first point is at t=0.1 s, expected 0 s" in late.message


# --- grader.scoring.rules: rules that judge a case by a property -----------------------------------


def _tip(q, l1, l2):
    return [l1 * np.cos(q[0]) + l2 * np.cos(q[0] + q[1]), l1 * np.sin(q[0]) + l2 * np.sin(q[0] + q[1])]


def test_two_link_ik_judged_by_the_tip_and_the_elbow_order():
    l1, l2, q = 0.12, 0.09, np.array([0.4, 1.1])
    x, y = _tip(q, l1, l2)
    q1b = np.arctan2(y, x) + (np.arctan2(y, x) - q[0])          # the other elbow reaches the same tip
    both = np.array([q, [q1b, -q[1]]])
    case = (x, y, l1, l2)
    e = Expected("ex03_1_two_link_ik_test", "values", [case, (0.5, 0.0, l1, l2)],
                 [{"value": both}, "ValueError: the target is out of reach"], {"rtol": 1e-9, "atol": 1e-9}, "two_link_ik")
    gid = e.grade_id
    out_of_reach = "ValueError: (0.5, 0) m is beyond the arm's reach"
    assert score_exercise(gid, [{"value": both}, out_of_reach], e, 4).score == 4
    assert score_exercise(gid, [{"value": both + [2 * np.pi, 0]}, out_of_reach], e, 4).score == 4  # q1 + 2 pi: right
    swapped = score_exercise(gid, [{"value": both[::-1]}, out_of_reach], e, 4)
    # both tips right, the order asked wrong: half of that case (each elbow a quarter, the order the other half)
    assert swapped.score == 3 and "row 0 is the solution with q2 >= 0" in swapped.message
    degrees = score_exercise(gid, [{"value": np.degrees(both)}, out_of_reach], e, 4)
    assert degrees.score == 2 and "put the tip" in degrees.message and "(tolerance 1e-09 m)" in degrees.message


def test_ik_solutions_judged_by_the_graders_own_kinematics():
    from snakekit import tool_pose_2d

    q = np.array([0.3, -0.2, 0.5, 0.1, -0.4])
    target = np.asarray(tool_pose_2d(q)[:2])
    e = Expected("ex03_3_ik_loop_test", "values", [(target,)], [{"value": q + 0.0}], {"rtol": 0.0, "atol": 1e-5},
                 "solve_ik")
    other = q.copy()
    other[4] += 2 * np.pi     # the same tool point, but beyond the joint limits
    assert score_exercise(e.grade_id, [{"value": q}], e, 4).score == 4
    assert "outside the joint limits" in score_exercise(e.grade_id, [{"value": other}], e, 4).message
    home = score_exercise(e.grade_id, [{"value": np.zeros(5)}], e, 4)
    assert home.score == 0 and "put the tool 0." in home.message and "from the target" in home.message


def _loop_from(target, q):
    """The lesson's loop written out here: the kit's DLS step (as graded_ik uses it), clamped, until within 1e-6 m."""
    from snakekit import SPEC, tool_pose_2d
    from snakekit.kinematics import dls_step

    for _ in range(200):
        if np.linalg.norm(target - tool_pose_2d(q)[:2]) < 1e-6:
            return q
        q = np.clip(dls_step(q, target), SPEC.lower, SPEC.upper)
    return None


def test_an_ik_solution_from_a_start_that_decides_it_lies_near_that_start():
    """From a zigzag start q0 near a solution the loop ends near q0; a loop that ignores q0 (from home) reaches the
    target too, bent another way, and loses the case, with what to do."""
    q0 = np.array([0.6, 0.9, -1.0, 0.8, -0.9])
    target = np.array([0.19, 0.23])
    started, ignored = _loop_from(target, q0), _loop_from(target, np.zeros(5))
    assert np.abs(started - q0).max() < 0.25 and np.abs(ignored - q0).max() > 1.0
    e = Expected("ex03_3_ik_loop_test", "values", [(target, q0)], [{"value": started}], {"rtol": 0.0, "atol": 1e-5},
                 "solve_ik")
    assert score_exercise(e.grade_id, [{"value": started}], e, 4).score == 4
    wrong = score_exercise(e.grade_id, [{"value": ignored}], e, 4)
    far = np.abs(ignored - q0)
    assert wrong.score == 0 and wrong.message.endswith(
        f"q={np.round(ignored, 4).tolist()} is {far.max():.3g} rad from the start q0 at joint {int(far.argmax()) + 1}; a "
        "loop that starts at q0 ends within 0.5 rad of it here. Start from q0 when it is given: q = np.zeros(5) if q0 "
        "is None else np.asarray(q0, dtype=float)."), wrong.message


def test_task1_judged_by_where_each_move_ends():
    from snakekit import tool_pose_2d

    finals = np.array([[0.3, -0.2, 0.5, 0.1, -0.4], [0.0, 0.2, 0.2, 0.2, 0.2]])
    targets = np.array([tool_pose_2d(q) for q in finals]) + [0.001, 0.0, 0.004]   # 1 mm, 4 mrad short: settled
    e = Expected("ex03_4_task1_test", "values", [(targets,)], [{"value": finals}], {"rtol": 0.0, "atol": 0.003},
                 "graded_task1")
    assert score_exercise(e.grade_id, [{"value": finals}], e, 2).score == 2
    # a move that ends on the point but turned another way (the heading left out, or given in degrees)
    turned = targets + [0.0, 0.0, 0.3]
    t = Expected(e.grade_id, "values", [(turned,)], [{"value": finals}], e.tolerances, "graded_task1")
    s = score_exercise(e.grade_id, [{"value": finals}], t, 2)
    assert s.score == 0 and "ended with the tool's heading at" in s.message and \
        "Each target is (x, y, heading), the heading in radians: pass all three" in s.message, s.message
    s = score_exercise(e.grade_id, [{"value": finals[:1]}], e, 2)
    assert s.score == 0 and "returned shape (1, 5), expected (2, 5)" in s.message
    # the lesson's form: the poses task1 returned, and where the recorded moves ended
    poses = np.array([tool_pose_2d(q) for q in finals])
    e = Expected(e.grade_id, "values", e.cases, [{"final_q": finals, "poses": poses}], e.tolerances, "graded_task1")
    assert score_exercise(e.grade_id, [{"final_q": finals, "poses": poses}], e, 2).score == 2
    angles = score_exercise(e.grade_id, [{"final_q": finals, "poses": finals}], e, 2)   # angles for poses
    assert angles.score == 0 and "returned shape (2, 5), expected (2, 3)" in angles.message
    # ...said as the notebook's check says it: what the result looks like, and what the exercise asks
    assert "This looks like joint angles (5 numbers a move), and the exercise asks for tool poses (x, y, θ)" \
        in angles.message
    points = score_exercise(e.grade_id, [{"final_q": finals, "poses": poses[:, :2]}], e, 2)
    assert "This looks like tool points (x, y) without the heading" in points.message
    lied = score_exercise(e.grade_id, [{"final_q": finals, "poses": poses[::-1]}], e, 2)
    assert lied.score == 0 and "but the arm measured (" in lied.message
    # the targets themselves, 1 mm from where the arm ended (within the 3 mm a move may end off): not what is asked
    aimed = score_exercise(e.grade_id, [{"final_q": finals, "poses": targets}], e, 2)
    x, y, heading = (f"{v:.4f}" for v in targets[0])
    mx, my, mh = (f"{v:.4f}" for v in poses[0])
    assert aimed.score == 0 and aimed.message.endswith(
        f"task1 returned the pose ({x} m, {y} m, {heading} rad) for move 1, but the arm measured ({mx} m, {my} m, "
        f"{mh} rad) at its end (tolerance 1e-06). These are the targets you set, not where the arm ended: return the "
        "pose it measured, snakekit.tool_pose_2d(run.measured.positions[-1]), for each move."), aimed.message


def run_in_sandbox(script: str, tmp_path: Path) -> tuple[int, str]:
    """``python -c script`` in a sandbox whose writable folder is ``tmp_path/work``: its exit code
    and output."""
    from grader.sandbox import namespaces as sandbox

    work = tmp_path / "work"
    work.mkdir()
    with open(tmp_path / "out.txt", "w") as out:
        outcome = sandbox.run([sys.executable, "-c", script], workdir=work, env={"PATH": "/usr/bin:/bin"},
                              limits=sandbox.Limits(wall=60), stdout=out, stderr=subprocess.STDOUT)
    return outcome.returncode, (tmp_path / "out.txt").read_text()


def test_a_kit_installed_under_tmp_is_seen_inside_the_sandbox(tmp_path, monkeypatch):
    """A clone under /tmp (its venv and packages there) stays visible past the private /tmp."""
    need_program("unshare")
    from grader.sandbox import namespaces as sandbox

    kit = tmp_path / "kit"  # pytest's tmp_path lies under /tmp
    kit.mkdir()
    (kit / "marker.txt").write_text("the kit is here")
    assert str(kit).startswith("/tmp/")
    binds = sandbox.default_binds()
    monkeypatch.setattr(sandbox, "default_binds", lambda: binds + [str(kit)])
    script = (f"import os; print(open({str(kit / 'marker.txt')!r}).read()); "
              "open('/tmp/scratch', 'w').write('x'); print(sorted(os.listdir('/tmp')))")
    returncode, text = run_in_sandbox(script, tmp_path)
    assert returncode == 0, text
    assert "the kit is here" in text
    assert not (Path("/tmp") / "scratch").exists() or (Path("/tmp") / "scratch").read_text() != "x"  # private /tmp


def test_the_instructors_course_beside_the_venv_is_not_seen_inside_the_sandbox(tmp_path):
    """The grader's image keeps the instructor's course, solutions included, in /opt/snakekit/course,
    beside its venv in /opt/venv: a submission's code must not read it (it could run the solution)."""
    need_program("unshare")
    if not os.access("/opt", os.W_OK):
        if IN_CI:
            pytest.fail("this test writes a folder under /opt (as the grader's image has one): run it as root")
        pytest.skip("needs to write a folder under /opt")
    probe = Path(tempfile.mkdtemp(prefix="snakekit-course-", dir="/opt"))
    try:
        (probe / "solution.txt").write_text("BEGIN SOLUTION")
        probe.chmod(0o755)
        (probe / "solution.txt").chmod(0o644)
        script = (f"import os; print('seen' if os.path.exists({str(probe / 'solution.txt')!r}) else 'not seen'); "
                  "import snakekit, grader; print('kit', snakekit.__name__)")
        returncode, text = run_in_sandbox(script, tmp_path)
        assert returncode == 0, text
        assert text.split() == ["not", "seen", "kit", "snakekit"], text
    finally:
        shutil.rmtree(probe, ignore_errors=True)


# --- the warm fork server ----------------------------------------------------------------------


def _probe(nb):
    """A first cell that records what the kernel had imported before the notebook's own imports."""
    import nbformat

    nb.cells.insert(0, nbformat.v4.new_code_cell(
        "import sys, os\nprint('preloaded:', 'mujoco' in sys.modules, 'pinocchio' in sys.modules, 'uid', os.getuid())\n"
        # the server's preloaded objects are frozen (gc.freeze): the notebook's own garbage is still collected
        # by the collector on its own, as in a fresh kernel
        "class _Loop:\n    freed = 0\n    def __del__(self):\n        _Loop.freed += 1\n"
        "for _ in range(20000):\n    _loop = _Loop()\n    _loop.me = _loop\n"
        "print('loops freed:', _Loop.freed > 0)"))


def _grade_in_process(course, *, warm: bool, monkeypatch):
    from grader import batch
    from grader.sandbox import runner

    if not warm:
        monkeypatch.setattr(runner.Runner, "start_fork_server", lambda self, base: None)
    used = {}
    real_execute = runner.Runner.execute

    def execute(self, work, student, **kw):
        used[student] = self.server is not None
        return real_execute(self, work, student, **kw)

    monkeypatch.setattr(runner.Runner, "execute", execute)
    results = batch.Grader(course, ASSIGNMENT, jobs=2, timeout=60, references=REFERENCES, seed=5).run()
    monkeypatch.undo()
    printed = {}
    for r in results:
        nb_path = course / "autograded" / r.student / ASSIGNMENT / f"{ASSIGNMENT}.ipynb"
        if not nb_path.exists():
            continue
        out = "".join(o.get("text", "") for o in nbformat_read(nb_path).cells[0].get("outputs", []))
        printed[r.student] = out.strip()
    return {r.student: (r.status, r.score, [(e.grade_id, e.score) for e in r.exercises]) for r in results}, used, printed


def nbformat_read(path):
    import nbformat

    return nbformat.read(path, as_version=4)


def test_warm_and_fresh_sandboxes_give_the_same_grades(tmp_path, monkeypatch):
    """Kernels forked from the warm server grade exactly like kernels started afresh, and start warm."""
    need_program("unshare")
    grades, used, printed = {}, {}, {}
    for warm in (True, False):
        course = make_course(tmp_path / ("warm" if warm else "fresh"))
        submit(course, "alice", edit=_probe)
        submit(course, "bob", {"ex1_tool_xy": "def tool_xy(q):\n    return np.array([0.3315, 0.0]) + 0 * q[:2]"},
               edit=_probe)
        submit(course, "carol", {"ex2_sweep": "import os\nos._exit(1)"}, edit=_probe)
        grades[warm], used[warm], printed[warm] = _grade_in_process(course, warm=warm, monkeypatch=monkeypatch)
    assert grades[True] == grades[False]
    assert grades[True]["alice"][:2] == ("graded", 7.0) and grades[True]["carol"][0] == "kernel died"
    assert set(used[True].values()) == {True} and set(used[False].values()) == {False}
    sandbox_uid = __import__("pwd").getpwnam("snakekit-grader").pw_uid if os.geteuid() == 0 else os.getuid()
    want_uid = sandbox_uid if os.geteuid() == 0 else 0  # without root: uid 0 inside the user namespace
    assert printed[True]["alice"] == f"preloaded: True True uid {want_uid}\nloops freed: True"
    assert printed[False]["alice"] == f"preloaded: False False uid {want_uid}\nloops freed: True"


def test_batches_of_one_process_share_its_fork_server_and_grade_alike(tmp_path, monkeypatch):
    """A process that grades several batches (the test suite's, a script that calls Grader more than once) starts
    its warm fork server once: the second batch's sandboxes are forked from the server the first started, which stays
    alive between them; with the process's servers stopped, a third batch starts a new one. The three grade alike."""
    need_program("unshare")
    from grader import batch
    from grader.sandbox import runner

    real_execute, used = runner.Runner.execute, []

    def execute(self, work, student, **kw):
        used[-1].add(self.server.proc.pid if self.server is not None else None)
        assert self.server is None or self.server.proc.poll() is None
        return real_execute(self, work, student, **kw)

    monkeypatch.setattr(runner.Runner, "execute", execute)
    built = []  # matplotlib's font list built for a batch: none, each copies the one its server made as it started
    real_run = runner.subprocess.run
    monkeypatch.setattr(runner.subprocess, "run", lambda argv, *a, **kw: (built.append(argv), real_run(argv, *a, **kw))[1])
    grades = []
    for k in range(3):
        if k == 2:
            runner._close_all()   # as at the process's exit: its servers stop, their folders go
        used.append(set())
        course = make_course(tmp_path / f"batch{k}")
        submit(course, "alice")
        submit(course, "bob", {"ex1_tool_xy": "def tool_xy(q):\n    return np.array([0.3315, 0.0]) + 0 * q[:2]"})
        results = batch.Grader(course, ASSIGNMENT, jobs=1, timeout=60, references=REFERENCES, seed=5).run()
        grades.append({r.student: (r.status, r.score) for r in results})
    assert [len(u) for u in used] == [1, 1, 1] and None not in set.union(*used), used
    assert used[0] == used[1] != used[2], used
    assert not [argv for argv in built if "matplotlib.font_manager" in " ".join(map(str, argv))], built
    assert grades[0] == grades[1] == grades[2] and grades[0]["alice"] == ("graded", 7.0), grades
    assert grades[0]["bob"][0] == "graded" and grades[0]["bob"][1] < 7.0, grades


def test_fork_server_that_cannot_start_says_why(tmp_path):
    from grader.sandbox.forkserver import ForkServer

    server = ForkServer({"PATH": "/usr/bin:/bin", "PYTHONPATH": str(tmp_path / "nothing"),
                         "SNAKEKIT_FORKSERVER_PRELOAD": "no_such_module_anywhere"})
    with pytest.raises(RuntimeError, match="the grader's fork server did not start: ModuleNotFoundError: No module named 'no_such_module_anywhere'"):
        server.wait_ready()
    assert server.proc.poll() is not None  # not left running


@pytest.mark.parametrize("module", ["snakekit.checks", "ipywidgets", "snakekit.widgets", "matplotlib_inline.backend_inline"])
def test_a_fork_server_told_to_preload_a_module_that_sets_up_its_importers_shell_refuses(tmp_path, module):
    """Such a module (warmkernel.SET_UP_AT_IMPORT) would set up no graded kernel's shell: no note on a missing name,
    no widgets' comm target, no figure as a picture. The server says so and does not start (the grader then starts
    each sandbox afresh: same grades)."""
    from grader.sandbox.forkserver import ForkServer
    from grader.sandbox.inside.warmkernel import SET_UP_AT_IMPORT

    assert module in SET_UP_AT_IMPORT
    server = ForkServer({"PATH": f"{Path(sys.executable).parent}:/usr/bin:/bin", "SNAKEKIT_FORKSERVER_PRELOAD": module,
                         "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "HOME": str(tmp_path)})
    with pytest.raises(RuntimeError, match=rf"the grader's fork server did not start: RuntimeError: preloading imported "
                                           rf".*{re.escape(module)}.*which set up the shell that imports them"):
        server.wait_ready()
    assert server.proc.poll() is not None  # not left running


def test_a_fork_server_that_ends_mid_batch_is_started_again_and_every_student_is_graded(tmp_path, monkeypatch, capfd):
    """The batch's fork server killed (as the system's out-of-memory killer would) after the reference
    run and after each student's sandbox: the next sandbox starts it again and says so; every student gets
    the grade a batch without the kill gives."""
    need_program("unshare")
    import signal

    from grader import batch
    from grader.sandbox import runner

    course = make_course(tmp_path / "killed")
    submit(course, "alice")
    submit(course, "bob", {"ex1_tool_xy": "def tool_xy(q):\n    return np.array([0.3315, 0.0]) + 0 * q[:2]"})
    real_execute = runner.Runner.execute
    servers, killed = [], []

    def execute(self, work, student, **kw):
        if self.server is not None and self.server.proc.poll() is None:
            servers.append(self.server)
            os.kill(self.server.proc.pid, signal.SIGKILL)   # gone before this sandbox is handed to it
            self.server.proc.wait()
            killed.append(student)
        return real_execute(self, work, student, **kw)

    monkeypatch.setattr(runner.Runner, "execute", execute)
    results = batch.Grader(course, ASSIGNMENT, jobs=1, timeout=60, references=REFERENCES, seed=5).run()
    monkeypatch.undo()
    got = {r.student: (r.status, r.score) for r in results}
    err = capfd.readouterr().err
    assert len(killed) >= 2 and servers[0].restarts == len(killed), (killed, [s.restarts for s in servers])
    assert err.count("snakekit grade: the grader's fork server ended (signal SIGKILL); starting it again") == len(killed), err
    fresh = make_course(tmp_path / "fresh")
    submit(fresh, "alice")
    submit(fresh, "bob", {"ex1_tool_xy": "def tool_xy(q):\n    return np.array([0.3315, 0.0]) + 0 * q[:2]"})
    want = {r.student: (r.status, r.score)
            for r in batch.Grader(fresh, ASSIGNMENT, jobs=1, timeout=60, references=REFERENCES, seed=5).run()}
    assert got == want and got["alice"] == ("graded", 7.0) and got["bob"][0] == "graded", (got, want)


def _descendants(pid: int) -> set[int]:
    """Every process below ``pid`` (from /proc's children lists)."""
    out, todo = set(), [pid]
    while todo:
        p = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{p}/task")
        except OSError:
            continue
        for t in tasks:
            try:
                kids = Path(f"/proc/{p}/task/{t}/children").read_text().split()
            except OSError:
                continue
            for k in map(int, kids):
                if k not in out:
                    out.add(k)
                    todo.append(k)
    return out


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


class _SleepingBatch:
    """`snakekit grade` started as a TA starts it, on a course whose one student's cell sleeps for 300 s, with a
    temporary root of its own (the sandbox's user passes through it, as through /tmp). Entered: the sleeping cell
    runs (``seen``: the grader's processes by then); left: every one of them killed and the root removed."""

    def __init__(self, tmp_path: Path, name: str):
        need_program("unshare")
        self.course = make_course(tmp_path / "course")
        submit(self.course, "sleeper", {"ex1_tool_xy": "import time\ntime.sleep(300)\ndef tool_xy(q):\n    return q[:2]"})
        self.tmp = Path(tempfile.mkdtemp(prefix=f"snakekit-{name}-"))
        os.chmod(self.tmp, 0o711)
        self.env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
                    "TMPDIR": str(self.tmp)}
        self.command = [sys.executable, "-m", "snakekit.cli", "grade", ASSIGNMENT, "--course", str(self.course),
                        "--jobs", "1", "--references", str(REFERENCES)]
        self.grade, self.seen = None, set()

    def __enter__(self):
        import time

        self.grade = subprocess.Popen([*self.command, "--timeout", "600"], env=self.env, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and self.grade.poll() is None:
            self.seen |= _descendants(self.grade.pid)
            # the server, its helpers, a supervisor, the sandbox's PID 1 and its kernel: the sleeping cell runs
            if len(self.seen) >= 5 and any("ipykernel" in _cmdline(p) or _depth(p, self.grade.pid) >= 4
                                           for p in self.seen):
                break
            time.sleep(0.2)
        time.sleep(2.0)
        self.seen |= _descendants(self.grade.pid)
        assert self.grade.poll() is None and len(self.seen) >= 4, (self.grade.poll(), self.seen,
                                                                   self.grade.stderr.read()[-2000:])
        return self

    def left_running(self) -> dict:
        """The grader's processes still running 30 s after it ended (none, as soon as they are gone)."""
        import time

        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and any(_alive(p) for p in self.seen):
            time.sleep(0.2)
        return {p: _cmdline(p) for p in self.seen if _alive(p)}

    def folders(self) -> list[str]:
        return sorted(p.name for p in self.tmp.iterdir())

    def __exit__(self, *exc):
        import signal

        for p in _descendants(self.grade.pid) | self.seen:
            try:
                os.kill(p, signal.SIGKILL)
            except OSError:
                pass
        if self.grade.poll() is None:
            self.grade.kill()
            self.grade.wait()
        shutil.rmtree(self.tmp, ignore_errors=True)
        return False


def test_a_grader_killed_mid_batch_leaves_no_sandbox_running(tmp_path):
    """`snakekit grade` killed with SIGKILL (the TA's `kill -9`, the out-of-memory killer) while a
    student's cell sleeps for 300 s: its fork server, the sandbox's supervisor, the sandbox and the
    student's kernel all end within seconds, not at the notebook's 600 s deadline that nobody is left
    to enforce. The folders it had in the temporary root (copies of the students' notebooks) are removed by
    the TA's next `snakekit grade`, which leaves none of its own."""
    import signal

    with _SleepingBatch(tmp_path, "killed") as batch:
        os.kill(batch.grade.pid, signal.SIGKILL)
        batch.grade.wait()
        left = batch.left_running()
        assert not left, f"still running after the grader was killed: {left}"
        killed = batch.folders()
        # the batch's folder and its fork server's: nobody was left to remove them
        assert [n.rsplit("-", 1)[0] for n in killed] == ["snakekit-forkserver", "snakekit-grade"], killed
        # the TA grades again (the sleeper's cell fixed): the killed grader's folders go, and this one's
        submit(batch.course, "sleeper")
        again = subprocess.run([*batch.command, "--timeout", "120"], env=batch.env, capture_output=True, text=True,
                               timeout=600)
        assert again.returncode == 0, again.stderr[-2000:]
        assert read_csv(batch.course / f"grades-{ASSIGNMENT}.csv")["sleeper"]["status"] == "graded"
        assert batch.folders() == [], (killed, batch.folders())


def test_a_grader_stopped_with_sigterm_stops_as_on_ctrl_c_and_leaves_nothing(tmp_path):
    """`kill PID` (SIGTERM: the TA's `kill`, a shutdown, a hub culling the server) stops `snakekit grade` as Ctrl-C
    does: the sandbox and its kernel end, it says who is left and how to grade them, its folders go, exit 143."""
    import signal

    with _SleepingBatch(tmp_path, "terminated") as batch:
        batch.grade.send_signal(signal.SIGTERM)
        _, err = batch.grade.communicate(timeout=60)
        assert batch.grade.returncode == 143, err[-2000:]
        assert "interrupted; 0 submission(s) graded before it are in the gradebook" in err, err[-2000:]
        assert "--student sleeper" in err, err[-2000:]
        assert not batch.left_running()
        assert batch.folders() == []


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _depth(pid: int, top: int) -> int:
    """How many parents up ``top`` is from ``pid`` (0 when it is not an ancestor)."""
    n = 0
    while pid not in (0, 1, top):
        try:
            pid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except OSError:
            return 0
        n += 1
    return n if pid == top else 0


def test_a_cell_whose_reply_never_comes_counts_as_finished_once_its_kernel_is_idle(tmp_path, monkeypatch):
    """About once in 2,000 notebooks a kernel ran a cell to its end (IOPub: its outputs, then idle) and
    its execute_reply never arrived: the notebook waited out its whole timeout. The worker gives the
    reply LATE_REPLY s after the idle, then takes the cell as finished with the outputs it sent (an
    error stays an error) and goes on; result.json lists those cells."""
    import nbformat
    from jupyter_core.utils import run_sync

    from grader.sandbox.inside import worker
    from snakekit import kernel_client

    monkeypatch.setattr(kernel_client, "LATE_REPLY", 1.0)
    monkeypatch.setattr(worker, "_late", [])
    execute = next(s for s in worker._with_deadline(120, 15) if s.__name__ == "DeadlineExecute")

    class LosesReplies(execute):
        """The shell channel loses the execute_reply of each cell that asks for it."""

        async def async_execute_cell(self, cell, cell_index, **kw):
            if "lose my reply" not in cell.source:
                return await super().async_execute_cell(cell, cell_index, **kw)
            channel = self.kc.shell_channel
            get = channel.get_msg

            async def losing(*a, **k):
                msg = await get(*a, **k)
                while msg["msg_type"] == "execute_reply":
                    msg = await get(*a, **k)
                return msg

            channel.get_msg = losing
            try:
                return await super().async_execute_cell(cell, cell_index, **kw)
            finally:
                del channel.get_msg

        execute_cell = run_sync(async_execute_cell)   # nbclient binds its own at class level

    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(src) for src in (
        "x = 6 * 7\nprint('first', x)",
        "# lose my reply\nprint('second', x + 1)",
        "# lose my reply\nprint('third', x + 2)\nraise ValueError('kept as the cell error')",
        "print('fourth', x + 3)")])
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    LosesReplies(timeout=15, kernel_name="python3").preprocess(nb, {"metadata": {"path": str(tmp_path)}})
    text = ["".join(o.get("text", "") for o in c.outputs if o.output_type == "stream") for c in nb.cells]
    assert text == ["first 42\n", "second 43\n", "third 44\n", "fourth 45\n"]
    assert [o.ename for o in nb.cells[2].outputs if o.output_type == "error"] == ["ValueError"]
    assert not any(o.output_type == "error" for c in (nb.cells[0], nb.cells[1], nb.cells[3]) for o in c.outputs)
    assert [c.execution_count for c in nb.cells] == [1, 2, 3, 4]
    # taken as finished after LATE_REPLY: had a lost reply been waited for as long as the cell's
    # limit (15 s), the cell would have been stopped by the clock, with an error, and not listed
    assert [d["cell"] for d in worker._late] == [1, 2]


def test_the_ta_is_told_where_a_lost_reply_was_taken_as_finished(tmp_path, capsys):
    from grader.batch import late_replies

    (tmp_path / "result.json").write_text(json.dumps({"success": True, "late_replies": [
        {"notebook": "03_inverse_kinematics", "cell": 17, "id": "03-code-17"}]}))
    late_replies(tmp_path, "fy")
    assert capsys.readouterr().err == (
        "snakekit grade: fy: the kernel finished 03_inverse_kinematics cell 17 but its reply never came; taken as "
        "finished after 5 s (the grade is not affected)\n")
    for written in ('{"success": true}', '{"late_replies": [{"cell": "x"}]}', "not json"):
        (tmp_path / "result.json").write_text(written)      # nothing late, or what a sandbox wrote instead
        late_replies(tmp_path, "fy")
        assert capsys.readouterr().err == ""


def test_only_the_folders_of_an_ended_grader_are_removed(tmp_path):
    """The folders a grader leaves behind when killed go at the next batch; a running grader's stay, and so do
    folders with no stamp, of another name, or reached through a link."""
    import time

    from grader.sandbox.runner import OWNER, _started, grader_folder, remove_leftovers

    ended = subprocess.Popen(["true"])
    ended.wait()
    running = subprocess.Popen(["sleep", "60"])
    try:
        time.sleep(0.1)
        stamps = {
            "snakekit-grade-ended": f"{ended.pid} {_started(os.getpid())}",           # its process is gone
            "snakekit-forkserver-ended": f"{ended.pid} ",                             # the same, no start time known
            "snakekit-grade-running": f"{running.pid} {_started(running.pid)}",       # its grader runs
            "snakekit-forkserver-running": f"{running.pid} ",
            "snakekit-grade-reused": f"{running.pid} {int(_started(running.pid)) - 7}",  # the pid, given again
            "snakekit-grade-ours": f"{os.getpid()} {_started(os.getpid())}",           # this very process
            "snakekit-killed-ended": f"{ended.pid} ",                                 # not a grader's name
        }
        for name, stamp in stamps.items():
            (tmp_path / name).mkdir()
            (tmp_path / name / OWNER).write_text(stamp + "\n")
            (tmp_path / name / "notebook.ipynb").write_text("{}")
        (tmp_path / "snakekit-grade-unstamped").mkdir()          # being made: no stamp yet
        theirs = tmp_path / "snakekit-grade-theirs"               # another user's, their grader ended
        theirs.mkdir()
        (theirs / OWNER).write_text(f"{ended.pid} \n")
        if os.getuid() == 0:   # as a user, the folder stays this user's: it goes too (below)
            os.chown(theirs, 65534, -1)
        away = tmp_path / "away"
        away.mkdir()
        (away / OWNER).write_text(f"{ended.pid} \n")
        (tmp_path / "snakekit-grade-link").symlink_to(away)
        removed = remove_leftovers(tmp_path)
        gone = ["snakekit-forkserver-ended", "snakekit-grade-ended", "snakekit-grade-reused"]
        if os.getuid() != 0:
            gone = sorted([*gone, theirs.name])
        assert sorted(p.name for p in removed) == gone
        assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
            {*stamps, "snakekit-grade-unstamped", "away", "snakekit-grade-link"} - set(gone)
            | ({theirs.name} if os.getuid() == 0 else set()))
        assert (away / OWNER).exists()
        made = grader_folder("snakekit-grade-", tmp_path)     # a new batch's folder: stamped with this process
        assert (made / OWNER).read_text().split() == [str(os.getpid()), _started(os.getpid())]
        assert remove_leftovers(tmp_path) == [] and made.is_dir()
    finally:
        running.kill()
        running.wait()
