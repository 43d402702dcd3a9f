"""The grader's parts: trajectory checks, reference files, scoring of hand-ins, and a batch on the test course."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import need_program
from grader import compare
from grader.references import REFERENCES as COURSE_REFERENCES
from grader.references import Reference, differences, main as references_main, spec_hash
from grader.score import score_exercise
from grader_helpers import ASSIGNMENT, FIXTURE, REFERENCES, make_course, read_csv, submit
from snakekit.trajectory import Trajectory, side_sweep

REPO = Path(__file__).resolve().parent.parent


# --- grader.compare -----------------------------------------------------------------------------


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


def test_values_partial_credit_per_case():
    expected = np.arange(10.0).reshape(5, 2)
    got = expected.copy()
    got[3, 1] += 1e-3
    c = compare.values(got, expected, rtol=1e-9, atol=1e-12, what="xy", inputs=np.arange(5.0))
    assert c.fraction == pytest.approx(0.8)
    assert "1 of 5 hidden cases wrong; first at input 3: entry 1 is 7.001, expected 7" in c.message
    assert compare.values(got.T, expected, rtol=0, atol=1, what="xy").message.endswith("transpose?")


# --- references ------------------------------------------------------------------------------


def test_reference_file_round_trip_keeps_header_and_arrays(tmp_path):
    ref = Reference.load(REFERENCES / f"{ASSIGNMENT}.npz")
    assert ref.meta["spec_hash"] == spec_hash() and ref.meta["assignment"] == ASSIGNMENT
    assert ref.exercises["ex2_sweep_test"]["kind"] == "run"
    assert ref.exercises["ex1_tool_xy_test"]["inputs"] == ["in_q"]
    again = Reference.load(ref.save(tmp_path / "r.npz"))
    assert again.meta == ref.meta and differences(ref, again) == []
    with np.load(tmp_path / "r.npz", allow_pickle=False) as z:  # plain arrays, no pickles
        assert set(z.files) >= {"__meta__", "ex1_tool_xy_test/in_q", "ex2_sweep_test/measured_positions"}


def test_fixture_reference_is_current():
    assert references_main([ASSIGNMENT, "--course", str(FIXTURE), "--out", str(REFERENCES), "--check"]) == 0


@pytest.mark.parametrize("path", sorted(COURSE_REFERENCES.glob("*.npz")), ids=lambda p: p.stem)
def test_course_references_are_current(path):
    # as a developer runs it (in-process under pytest's captured output, lesson 00's kernel,
    # which starts the meshcat viewer, was seen to stall)
    r = subprocess.run([sys.executable, "-m", "grader.references", path.stem, "--check"], capture_output=True,
                       text=True, cwd=REPO, timeout=900,
                       env={**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"})
    assert r.returncode == 0 and f"{path.name} is current" in r.stdout, r.stderr[-3000:]


def test_stale_reference_is_reported(tmp_path, capsys):
    ref = Reference.load(REFERENCES / f"{ASSIGNMENT}.npz")
    arrays = {g: dict(d) for g, d in ref.arrays.items()}
    arrays["ex1_tool_xy_test"]["xy"] = arrays["ex1_tool_xy_test"]["xy"] + 1e-6
    Reference(ref.assignment, ref.meta, arrays).save(tmp_path / f"{ASSIGNMENT}.npz")
    assert references_main([ASSIGNMENT, "--course", str(FIXTURE), "--out", str(tmp_path), "--check"]) == 1
    assert "ex1_tool_xy_test/xy: values moved by up to 1e-06" in capsys.readouterr().err


# --- scoring a hand-in ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def ref():
    return Reference.load(REFERENCES / f"{ASSIGNMENT}.npz")


def test_inputs_other_than_the_hidden_ones_score_zero(ref):
    h = {k: v.copy() for k, v in ref.arrays["ex1_tool_xy_test"].items()}
    h["in_q"][0, 0] += 0.5
    s = score_exercise("ex1_tool_xy_test", h, ref, 2.0)
    assert (s.score, s.status) == (0.0, "inconsistent") and "hidden input 'in_q'" in s.message


def test_nan_and_missing_handins_score_zero_with_a_reason(ref):
    h = {k: v.copy() for k, v in ref.arrays["ex1_tool_xy_test"].items()}
    h["xy"][2, 1] = np.nan
    s = score_exercise("ex1_tool_xy_test", h, ref, 2.0)
    assert s.score == 0 and "NaN or infinity (first at index (2, 1))" in s.message
    assert score_exercise("ex1_tool_xy_test", None, ref, 2.0).status == "missing"


def test_run_scored_from_its_checks(ref):
    good = ref.arrays["ex2_sweep_test"]
    assert score_exercise("ex2_sweep_test", dict(good), ref, 4.0).score == 4.0
    late = dict(good, measured_positions=good["measured_positions"] + 0.01)  # 0.01 rad = 6.5 ticks off
    s = score_exercise("ex2_sweep_test", late, ref, 4.0)
    # 8 of 10 weight pass; the run check: max and RMS 0.01 rad vs 0.00153 / 0.00077 tolerances
    f = 0.5 * compare.falloff(0.01, 0.00153398, 0.0153398) + 0.5 * compare.falloff(0.01, 0.00076699, 0.0076699)
    assert s.score == pytest.approx(4.0 * (8 + 2 * f) / 10, abs=1e-3)
    assert "run vs reference: largest measured angle error joint 1" in s.message


# --- a batch on the test course ----------------------------------------------------------------


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    need_program("unshare")
    tmp = tmp_path_factory.mktemp("batch")
    course = make_course(tmp)
    submit(course, "alice")
    submit(course, "bob", {"ex1_tool_xy": "def tool_xy(q):\n    return np.array([0.3315, 0.0]) + 0 * q[:2]",
                           "ex2_sweep": "def my_sweep():\n    t = np.arange(500) / 100\n"
                                        "    a = 0.2 * np.sin(2 * np.pi * t / (t[-1] / 50))\n"
                                        "    return snakekit.Trajectory(t, np.repeat(a[:, None], 5, 1))"})

    def grade():
        return subprocess.run([sys.executable, "-m", "snakekit.cli", "grade", ASSIGNMENT, "--course", str(course),
                               "--references", str(REFERENCES), "--timeout", "60"],
                              capture_output=True, text=True, timeout=600, cwd=REPO)

    first = grade()
    csv1 = (course / f"grades-{ASSIGNMENT}.csv").read_text()
    second = grade()
    return {"course": course, "first": first, "second": second, "csv1": csv1}


def test_batch_writes_csv_with_scores(graded):
    assert graded["first"].returncode == 0, graded["first"].stderr[-3000:]
    rows = read_csv(graded["course"] / f"grades-{ASSIGNMENT}.csv")
    assert list(next(iter(rows.values())))[:5] == ["student", "assignment", "score", "max_score", "status"]
    assert (rows["alice"]["score"], rows["alice"]["status"]) == ("7", "graded")
    # bob: ex1 0 (every hidden case wrong); ex3 fails in the kernel (100 Hz is too fast);
    # ex2 0.25 * 4 = 1 for... computed from the checks below
    assert rows["bob"]["status"] == "graded" and 0 < float(rows["bob"]["score"]) < 3


def test_same_submission_graded_twice_gets_the_same_score(graded):
    assert graded["second"].returncode == 0
    assert (graded["course"] / f"grades-{ASSIGNMENT}.csv").read_text() == graded["csv1"]


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
    assert "0/2: done 0, left 2, failed 0" in err and "2/2: done 2, left 0, failed 0" in err


def test_feedback_has_verdicts_and_plots_but_no_hidden_tests(graded):
    import nbformat

    from grader.feedback import hidden_lines

    html = (graded["course"] / "feedback" / "bob" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()
    assert "Grader: ex1_tool_xy_test: 0 / 2 points" in html
    assert "8 of 8 hidden cases wrong" in html
    assert "100 Hz where 10 Hz was asked" in html
    plots = html.count('alt="No description has been provided for this image" class="" src="data:image/png;base64,')
    assert plots == 1  # bob's sweep against the reference
    src = nbformat.read(FIXTURE / "source" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)
    secret = hidden_lines(c.source for c in src.cells)
    assert secret and not [line for line in secret if line in html]
    assert "hidden tool_xy cases differ" not in html  # the hidden assertion's message
    assert "Traceback" not in html


def test_exit_code_2_for_bad_arguments(tmp_path):
    def run(*args):
        return subprocess.run([sys.executable, "-m", "snakekit.cli", "grade", *args], capture_output=True, text=True,
                              cwd=REPO, timeout=120)

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
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "grade", ASSIGNMENT, "--course", str(course),
                        "--references", str(refs)], capture_output=True, text=True, cwd=REPO, timeout=300)
    assert r.returncode == 1 and "not a readable reference file" in r.stderr


def test_grader_depends_only_on_trajectory_model_and_run():
    code = ("import sys, grader.batch, grader.cli, grader.score, grader.feedback, grader.references; "
            "print(sorted(m for m in sys.modules if m.startswith('snakekit')))")
    mods = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True).stdout
    for banned in ("snakekit.viewer", "snakekit.sim", "snakekit.hardware", "snakekit.emulator", "snakekit.widgets",
                   "snakekit.servo"):
        assert f"'{banned}'" not in mods


@pytest.mark.parametrize("name", ["grader.compare", "grader.feedback", "grader.score"])
def test_docstring_examples(name):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0 and result.attempted > 0


def test_kernel_verdict_hides_a_hidden_tests_message():
    """A test cell without a reference keeps nbgrader's verdict, but only a visible check's words."""
    from nbformat.v4 import new_code_cell, new_notebook, new_output

    from grader.batch import Grader, _Cell

    src = "check(f)\n### BEGIN HIDDEN TESTS\nassert f(7) == 49, 'f(7) should be 49'\n### END HIDDEN TESTS\n"
    cell = new_code_cell(src, execution_count=5, metadata={"nbgrader": {"grade_id": "t", "grade": True}})
    nb = new_notebook(cells=[cell])
    info = _Cell("t", "nb", 2.0, src, "code")

    def fails_at(line):
        cell.outputs = [new_output("error", ename="AssertionError", evalue="f(7) should be 49",
                                   traceback=[f"\x1b[36mCell In[5], line {line}\x1b[0m", "AssertionError"])]
        return Grader._kernel_score("t", info, nb)

    hidden = fails_at(3)
    assert (hidden.score, hidden.max_score) == (0.0, 2.0)
    assert hidden.message.startswith("a hidden test failed (AssertionError).") and "49" not in hidden.message
    assert fails_at(1).message == "a visible check failed: AssertionError: f(7) should be 49"
    cell.outputs = []
    assert Grader._kernel_score("t", info, nb).score == 2.0


def test_only_the_sandboxs_own_gradebook_copy_skips_waiting_for_the_disk(tmp_path):
    """The worker's course copy is deleted after the run: its SQLite need not sync; a fresh process still does."""
    code = ("import sys, sqlalchemy as sa\n"
            "if sys.argv[1] == 'worker':\n    from grader.worker import _throwaway_gradebook; _throwaway_gradebook()\n"
            "with sa.create_engine(f'sqlite:///{sys.argv[2]}').connect() as c:\n"
            "    print(c.exec_driver_sql('PRAGMA synchronous').scalar(), c.exec_driver_sql('PRAGMA journal_mode').scalar())")
    out = {who: subprocess.run([sys.executable, "-c", code, who, str(tmp_path / f"{who}.db")], capture_output=True,
                               text=True, cwd=REPO, check=True).stdout.split() for who in ("worker", "grader")}
    assert out == {"worker": ["0", "memory"], "grader": ["2", "delete"]}  # OFF / MEMORY; SQLite's FULL / DELETE


def test_feedback_plot_drawn_once_for_the_same_run_and_again_for_any_other(monkeypatch):
    from collections import OrderedDict

    from grader import feedback

    drawn = []
    draw = feedback._draw
    monkeypatch.setattr(feedback, "_draw", lambda curves, title: drawn.append(title) or draw(curves, title))
    monkeypatch.setattr(feedback, "_plots", OrderedDict())
    monkeypatch.setattr(feedback, "PLOT_CACHE", 2)
    t = np.arange(60) / 10.0
    q = 0.2 * np.sin(t)[:, None] * np.ones((1, 5))
    first = feedback.plot_png({"measured": (t, q), "reference measured": (t, q.copy())}, "ex")
    again = feedback.plot_png({"measured": (t.copy(), q.copy()), "reference measured": (t, q)}, "ex")
    assert first[:8] == b"\x89PNG\r\n\x1a\n" and again == first and drawn == ["ex"]
    moved = q.copy()
    moved[40, 3] = np.nextafter(moved[40, 3], 1.0)  # one joint, one sample, one bit
    feedback.plot_png({"measured": (t, moved), "reference measured": (t, q)}, "ex")
    assert drawn == ["ex", "ex"]
    moved[40, 3] += 0.05
    other = feedback.plot_png({"measured": (t, moved), "reference measured": (t, q)}, "ex")
    assert drawn == ["ex", "ex", "ex"] and other != first  # its zoom now points at joint 4
    assert len(feedback._plots) == 2  # the oldest plot let go: drawing it again below draws it anew
    assert feedback.plot_png({"measured": (t, q), "reference measured": (t, q)}, "ex") == first
    assert drawn == ["ex", "ex", "ex", "ex"]


def test_feedback_html_is_what_nbconverts_own_exporter_writes(tmp_path):
    """The feedback exporter keeps its filters' results between pages; the pages stay what the exporter writes
    without them (nbconvert's, with math as MathML)."""
    from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output

    from grader import feedback

    def page(student):
        code = new_code_cell(f"x = np.arange(3)  # {student}\nprint(x)", execution_count=1)
        code.outputs = [new_output("display_data", data={"text/html": f"<b>{student}</b>"})]
        verdict = new_code_cell("", metadata={"tags": ["grader-verdict"]})
        verdict.outputs = [new_output("display_data", data={"text/html": "<div>Grader: 1 / 2 points</div>"})]
        nb = new_notebook(cells=[new_markdown_cell("# Lesson\n\n$q_1$ and `code`"), code, verdict])
        nb.metadata = {"language_info": {"name": "python"}}
        return nb

    plain = feedback.exporter_class()(config=feedback.exporter_config())  # with no results kept
    for student in ("ann", "ben", "ann"):
        nb = page(student)
        written = feedback.write_html(nb, tmp_path / f"{student}.html").read_text()
        assert written == plain.from_notebook_node(nb)[0]
        assert f"<b>{student}</b>" in written and f"# {student}" in written
        assert "<math display=\"inline\"><mrow><msub><mi>q</mi><mn>1</mn></msub></mrow></math>" in written


# --- grader.exercises: rules that recompute what a hidden test judges ---------------------------


def _course_ref(name):
    return Reference.load(COURSE_REFERENCES / f"{name}.npz")


def test_two_link_ik_judged_by_the_tip_and_the_elbow_order():
    gid, ref = "ex03_1_two_link_ik_test", _course_ref("03_inverse_kinematics")
    h = dict(ref.arrays[gid])
    assert score_exercise(gid, h, ref, 4).score == 4
    # other angles that reach the same tip (q1 + 2 pi) are as right
    assert score_exercise(gid, {**h, "outputs": h["outputs"] + [2 * np.pi, 0]}, ref, 4).score == 4
    swapped = score_exercise(gid, {**h, "outputs": h["outputs"][:, ::-1]}, ref, 4)  # the stretched case stays right
    assert swapped.score == pytest.approx(4 * (1 + 1 / 11) / 2, abs=1e-4)
    assert "elbow order: 10 of 11 hidden cases wrong" in swapped.message
    degrees = score_exercise(gid, {**h, "outputs": np.degrees(h["outputs"])}, ref, 4)
    assert degrees.score < 2.5 and "tip of both solutions" in degrees.message and "tolerance 1e-09 m" in degrees.message


def test_ik_solutions_judged_by_the_graders_own_kinematics():
    gid, ref = "ex03_3_ik_loop_test", _course_ref("03_inverse_kinematics")
    h = dict(ref.arrays[gid])
    assert score_exercise(gid, h, ref, 4).score == 4
    home = score_exercise(gid, {**h, "outputs": np.zeros_like(h["outputs"])}, ref, 4)
    # tool on target 0, joint limits 1, the other hidden checks (the kernel's verdicts) 1
    assert home.score == pytest.approx(4 * 2 / 3, abs=1e-4) and "tool on target: 8 of 8 hidden cases wrong" in home.message
    failed = score_exercise(gid, {**h, "flags": np.array([1.0, 0.0])}, ref, 4)
    assert failed.score == pytest.approx(4 * 2.5 / 3, abs=1e-4) and "1 of 2 failed" in failed.message
    gid = "ex03_4_task1_test"
    h = dict(ref.arrays[gid])
    off = score_exercise(gid, {**h, "outputs": h["outputs"][:2]}, ref, 2)
    assert off.score == 1.0 and "results of shape (2, 5), expected (3, 5)" in off.message  # the refusal passed


def test_sampled_moves_and_violations_recomputed_by_the_grader():
    ref = _course_ref("04_trajectories")
    for gid in ("ex04_3_sample_10hz_test", "ex04_4_limit_check_test"):
        h = dict(ref.arrays[gid])
        assert score_exercise(gid, h, ref, 3).score == 3
        assert score_exercise(gid, {**h, "outputs": h["outputs"][1:]}, ref, 3).score < 3        # a row missing
        nudged = h["outputs"].copy()
        nudged[5, 2] += 1e-6
        assert score_exercise(gid, {**h, "outputs": nudged}, ref, 3).score < 3
        assert score_exercise(gid, {**h, "outputs": h["outputs"][:, :-1]}, ref, 3).score == 0  # another width
    missing_one = score_exercise("ex04_4_limit_check_test", {**ref.arrays["ex04_4_limit_check_test"],
                                 "outputs": ref.arrays["ex04_4_limit_check_test"]["outputs"][1:]}, ref, 3)
    assert "violations (time, joint, kind), you found" in missing_one.message


def test_safe_move_judged_by_its_planned_duration_and_end():
    gid, ref = "ex07_2_safe_move_test", _course_ref("07_real_robot")
    h = dict(ref.arrays[gid])
    assert score_exercise(gid, h, ref, 3).score == 3
    slow = h["outputs"].copy()
    slow[0] += 0.05                       # planned 50 ms longer than 1.875 d / v_max
    s = score_exercise(gid, {**h, "outputs": slow}, ref, 3)
    assert s.score == 2.0 and "move duration" in s.message and "tolerance 0.011 s" in s.message
    short = h["outputs"].copy()
    short[6:] = short[1:6]                # ended where it started
    assert score_exercise(gid, {**h, "outputs": short}, ref, 3).score == 2.0   # the refusals (flags) passed


def test_a_kit_installed_under_tmp_is_seen_inside_the_sandbox(tmp_path, monkeypatch):
    """A clone under /tmp (its venv and packages there) stays visible past the private /tmp."""
    need_program("unshare")
    from grader import sandbox

    kit = tmp_path / "kit"  # pytest's tmp_path lies under /tmp
    kit.mkdir()
    (kit / "marker.txt").write_text("the kit is here")
    assert str(kit).startswith("/tmp/")
    binds = sandbox.default_binds()
    monkeypatch.setattr(sandbox, "default_binds", lambda: binds + [str(kit)])
    work = tmp_path / "work"
    work.mkdir()
    script = (f"import os; print(open({str(kit / 'marker.txt')!r}).read()); "
              "open('/tmp/scratch', 'w').write('x'); print(sorted(os.listdir('/tmp')))")
    with open(tmp_path / "out.txt", "w") as out:
        outcome = sandbox.run([sys.executable, "-c", script], workdir=work, env={"PATH": "/usr/bin:/bin"},
                              limits=sandbox.Limits(wall=60), stdout=out, stderr=subprocess.STDOUT)
    text = (tmp_path / "out.txt").read_text()
    assert outcome.returncode == 0, text
    assert "the kit is here" in text
    assert not (Path("/tmp") / "scratch").exists() or (Path("/tmp") / "scratch").read_text() != "x"  # private /tmp


# --- the warm fork server ----------------------------------------------------------------------


def _probe(nb):
    """A first cell that records what the kernel had imported before the notebook's own imports."""
    import nbformat

    nb.cells.insert(0, nbformat.v4.new_code_cell(
        "import sys, os\nprint('preloaded:', 'mujoco' in sys.modules, 'pinocchio' in sys.modules, 'uid', os.getuid())"))


def _grade_in_process(course, *, warm: bool, monkeypatch):
    from grader import batch

    if not warm:
        monkeypatch.setattr(batch.Grader, "_start_fork_server", lambda self, base: None)
    used = {}
    real_execute = batch.Grader._execute

    def execute(self, work, student):
        used[student] = self.server is not None
        return real_execute(self, work, student)

    monkeypatch.setattr(batch.Grader, "_execute", execute)
    results = batch.Grader(course, ASSIGNMENT, jobs=2, timeout=60, references=REFERENCES).run()
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
    assert printed[True]["alice"] == f"preloaded: True True uid {want_uid}"
    assert printed[False]["alice"] == f"preloaded: False False uid {want_uid}"


def test_fork_server_that_cannot_start_says_why(tmp_path):
    from grader.forkserver import ForkServer

    server = ForkServer({"PATH": "/usr/bin:/bin", "PYTHONPATH": str(tmp_path / "nothing"),
                         "SNAKEKIT_FORKSERVER_PRELOAD": "no_such_module_anywhere"})
    with pytest.raises(RuntimeError, match="the grader's fork server did not start: ModuleNotFoundError: No module named 'no_such_module_anywhere'"):
        server.wait_ready()
    assert server.proc.poll() is not None  # not left running
