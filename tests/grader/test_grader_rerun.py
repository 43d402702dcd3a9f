"""An exercise built on earlier ones: graded again with the lesson's own parts; what earns by accident earns nothing.

The second run itself (a sandbox with the instructor's answer cells) is graded end to end by the
class of lesson 06 and lesson 03 (``tests/grader/test_class_grades.py``: ray, sam, uma, liv, ned, oda).
"""

from __future__ import annotations

import nbformat
import numpy as np
import pytest

from grader.scoring import rerun
from grader.scoring.cases import draw
from grader.errors import CasesError
from grader.scoring.rules import two_link_ik
from grader.scoring.score import Expected, ExerciseScore, score_exercise
from snakekit.trajectory import side_sweep

DEPENDS = {"ex06_3_task2_test": ["ex06_1_sweep_times", "ex06_2_sweep_positions"]}


def scores(**got):
    """{'ex06_1_sweep_times_test': ExerciseScore(...)} from ex06_1=0.5 (share of 1 point)."""
    names = {"ex06_1": "ex06_1_sweep_times_test", "ex06_2": "ex06_2_sweep_positions_test",
             "ex06_3": "ex06_3_task2_test"}
    return {names[k]: ExerciseScore(names[k], v, 1.0, "scored", "") for k, v in got.items()}


WRITTEN = {"ex06_1_sweep_times": True, "ex06_2_sweep_positions": True, "ex06_3_task2": True}


def test_a_second_run_replaces_only_the_parts_that_lost_points_under_an_exercise_that_did():
    assert rerun.needed(DEPENDS, scores(ex06_1=0.0, ex06_2=1.0, ex06_3=0.2), WRITTEN) == \
        {"ex06_3_task2_test": ["ex06_1_sweep_times"]}
    assert rerun.needed(DEPENDS, scores(ex06_1=0.0, ex06_2=0.5, ex06_3=0.2), WRITTEN) == \
        {"ex06_3_task2_test": ["ex06_1_sweep_times", "ex06_2_sweep_positions"]}


def test_a_dependent_exercise_stopped_by_a_part_that_never_returns_is_run_again_with_the_lessons_part():
    """6.1 loops endlessly: 6.3's test cell, which calls it, is stopped before it hands anything in."""
    got = scores(ex06_1=0.0, ex06_2=1.0)
    got["ex06_3_task2_test"] = ExerciseScore("ex06_3_task2_test", 0.0, 1.0, "missing", "nothing was handed in")
    assert rerun.needed(DEPENDS, got, WRITTEN) == {"ex06_3_task2_test": ["ex06_1_sweep_times"]}
    # ...but not when it was never written, nor when it tampered with its test cell
    assert rerun.needed(DEPENDS, got, {**WRITTEN, "ex06_3_task2": False}) == {}
    got["ex06_3_task2_test"] = ExerciseScore("ex06_3_task2_test", 0.0, 1.0, "tampered", "")
    assert rerun.needed(DEPENDS, got, WRITTEN) == {}


def test_test_cells_the_notebooks_clock_stopped_before_are_run_again_with_every_part_that_lost_points():
    """6.1 loops endlessly: its check, the lesson's demonstration that calls it and Task 2's run each use up the
    cell limit, and the notebook's time runs out before 6.3's and 6.4's test cells. 6.4 does not build on 6.1,
    yet it lost everything: both run again, with the lesson's 6.1, and neither one's own answer replaced."""
    got = scores(ex06_1=0.0, ex06_2=1.0)
    got["ex06_4_phase_lag_test"] = ExerciseScore("ex06_4_phase_lag_test", 0.0, 6.0, "missing", "nothing was handed in")
    got["ex06_3_task2_test"] = ExerciseScore("ex06_3_task2_test", 0.0, 7.0, "missing", "nothing was handed in")
    written = {**WRITTEN, "ex06_4_phase_lag": True}
    unreached = {"ex06_3_task2_test", "ex06_4_phase_lag_test"}
    assert rerun.needed(DEPENDS, got, written) == {"ex06_3_task2_test": ["ex06_1_sweep_times"]}   # before: 6.4 lost 6
    assert rerun.needed(DEPENDS, got, written, unreached) == {"ex06_3_task2_test": ["ex06_1_sweep_times"],
                                                              "ex06_4_phase_lag_test": ["ex06_1_sweep_times"]}
    # the clock stopped the notebook in 6.2's check: 6.2 is graded again with its own answer, and 6.3 with the
    # student's 6.2 (read from the same run), the lesson's 6.1
    got["ex06_2_sweep_positions_test"] = ExerciseScore("ex06_2_sweep_positions_test", 0.0, 1.0, "missing", "")
    assert rerun.needed(DEPENDS, got, written, unreached | {"ex06_2_sweep_positions_test"}) == {
        "ex06_3_task2_test": ["ex06_1_sweep_times"], "ex06_2_sweep_positions_test": ["ex06_1_sweep_times"],
        "ex06_4_phase_lag_test": ["ex06_1_sweep_times"]}
    # nothing else lost points (a slow notebook): the cell runs again as it is; one never written does not
    assert rerun.needed({}, {"ex06_4_phase_lag_test": got["ex06_4_phase_lag_test"]}, written,
                        {"ex06_4_phase_lag_test"}) == {"ex06_4_phase_lag_test": []}
    assert rerun.needed({}, got, {**written, "ex06_4_phase_lag": False}, {"ex06_4_phase_lag_test"}) == {}


def test_a_cell_run_again_on_its_own_says_so_and_names_no_part():
    first = ExerciseScore("ex06_4_phase_lag_test", 0.0, 6.0, "missing", "nothing was handed in.")
    got = rerun.better(first, ExerciseScore("ex06_4_phase_lag_test", 6.0, 6.0, "scored", ""), [])
    assert got.score == 6.0 and got.message == (
        "graded in a run of its own, as your notebook's time ran out before this cell had run: 6 of 6 "
        "(in your notebook's run: 0, the run below). nothing was handed in.")


@pytest.mark.parametrize("got, written", [
    (dict(ex06_1=0.0, ex06_2=1.0, ex06_3=1.0), WRITTEN),                  # 6.3 full: nothing to gain
    (dict(ex06_1=1.0, ex06_2=1.0, ex06_3=0.3), WRITTEN),                  # 6.3's own slip
    (dict(ex06_1=0.0, ex06_2=1.0, ex06_3=0.0), {**WRITTEN, "ex06_3_task2": False}),   # 6.3 not written
])
def test_no_second_run_where_it_cannot_change_the_grade(got, written):
    assert rerun.needed(DEPENDS, scores(**got), written) == {}


def test_the_second_run_has_the_instructors_answer_without_its_solution_markers_and_the_rest_as_handed_in():
    def cell(gid, src):
        return nbformat.v4.new_code_cell(src, metadata={"nbgrader": {"grade_id": gid, "solution": True}})
    mine = nbformat.v4.new_notebook(cells=[cell("ex06_1_sweep_times", "def sweep_times(points, rate):\n    pass\n"),
                                           cell("ex06_2_sweep_positions", "def sweep_positions(*a):\n    return 1\n")])
    theirs = nbformat.v4.new_notebook(cells=[cell("ex06_1_sweep_times", "def sweep_times(points, rate):\n"
                                                  "    ### BEGIN SOLUTION\n    return np.arange(points) / rate\n"
                                                  "    ### END SOLUTION\n")])
    out = rerun.with_answers({"a": mine}, {"a": theirs}, {"ex06_1_sweep_times"})["a"]
    assert out.cells[0].source == "def sweep_times(points, rate):\n    return np.arange(points) / rate\n"
    assert out.cells[1].source == mine.cells[1].source
    assert mine.cells[0].source.endswith("pass\n")   # the submission itself is untouched


def test_the_better_run_counts_and_its_line_names_the_parts_and_its_score_only():
    first = ExerciseScore("ex06_3_task2_test", 1.5, 7.0, "scored", "3 of 4 hidden cases gave no trajectory.",
                          checks=("mine",))
    second = ExerciseScore("ex06_3_task2_test", 6.5, 7.0, "scored", "largest error 0.0123 rad at t=4.2 s",
                           checks=("theirs",))
    got = rerun.better(first, second, ["ex06_1_sweep_times", "ex06_2_sweep_positions"])
    assert got.score == 6.5 and got.checks == ("mine",)
    assert got.message == ("graded with the lesson's own 6.1 and 6.2 in place of yours: 6.5 of 7 "
                           "(with yours: 1.5, the run below). "
                           "3 of 4 hidden cases gave no trajectory.")
    assert rerun.better(second, first, ["ex06_1_sweep_times"]) is second


def test_depends_must_name_handed_in_grade_ids(tmp_path):
    (tmp_path / "cases").mkdir()
    (tmp_path / "cases" / "a.py").write_text("def ex1_test(rng, spec):\n    return [(1,)]\n"
                                             "DEPENDS = {'ex2_test': ['ex1']}\n")
    with pytest.raises(CasesError, match="DEPENDS must map a handed-in grade id"):
        draw(tmp_path, "a", 1)
    (tmp_path / "cases" / "a.py").write_text("def ex1_test(rng, spec):\n    return [(1,)]\n"
                                             "def ex2_test(rng, spec):\n    return [()]\n"
                                             "DEPENDS = {'ex2_test': ['ex1']}\n")
    assert draw(tmp_path, "a", 1).depends == {"ex2_test": ["ex1"]}


def test_two_link_ik_gives_each_elbow_its_quarter_and_the_order_its_half():
    x, y, l1, l2 = 0.1, 0.12, 0.1, 0.08
    c = (x * x + y * y - l1 * l1 - l2 * l2) / (2 * l1 * l2)
    rows = []
    for q2 in (np.arccos(c), -np.arccos(c)):
        rows.append([np.arctan2(y, x) - np.arctan2(l2 * np.sin(q2), l1 + l2 * np.cos(q2)), q2])
    tol = {"rtol": 1e-9, "atol": 1e-7}
    assert two_link_ik((x, y, l1, l2), {"value": np.array(rows)}, tol) == (True, "")
    swapped, why = two_link_ik((x, y, l1, l2), {"value": np.array(rows[::-1])}, tol)
    assert swapped == 0.5 and "both tips are on the target" in why
    one, why = two_link_ik((x, y, l1, l2), {"value": np.array([rows[0], [0.3, 0.3]])}, tol)
    assert one == 0.25 and "(row 1)" in why
    assert two_link_ik((x, y, l1, l2), {"value": np.degrees(rows)}, tol)[0] == 0


def test_a_sweep_of_another_size_earns_nothing_for_being_safe():
    asked = side_sweep(points=100, rate=10.0, sweeps=5, amplitude=0.2)
    e = Expected("ex06_3_task2_test", "trajectory", [(100, 10.0, 5, 0.2)],
                 [{"times": asked.times, "positions": asked.positions}])
    stored = side_sweep()    # 500 points over 49.9 s, whatever was asked
    got = score_exercise("ex06_3_task2_test", [{"times": stored.times, "positions": stored.positions}], e, 1.0)
    checks = {c.name: c for c in got.checks}
    for name in ("rate", "limits", "home", "smoothness"):   # rate: 10 Hz as asked, but not the sweep asked
        assert checks[name].fraction == 0.0 and "not judged: 500 points over 49.9 s" in checks[name].message
    # the same sweep resampled to the count asked is judged on them
    same_size = side_sweep(points=100, rate=10.0, sweeps=7, amplitude=0.2)
    got = score_exercise("ex06_3_task2_test", [{"times": same_size.times, "positions": same_size.positions}], e, 1.0)
    assert {c.name: c.fraction for c in got.checks}["limits"] == 1.0


def test_the_task_itself_called_without_arguments_weighs_as_much_as_the_other_cases_together():
    cases = [(100, 10.0, 5, 0.2), (60, 5.0, 3, 0.1), (80, 20.0, 4, 0.15), ()]
    sweeps = [side_sweep(points=p, rate=r, sweeps=k, amplitude=a) for p, r, k, a in cases[:3]] + [side_sweep()]
    e = Expected("ex06_3_task2_test", "trajectory", cases, [{"times": t.times, "positions": t.positions} for t in sweeps])
    right = [{"times": t.times, "positions": t.positions} for t in sweeps]
    only_task = ["TypeError: task2_sweep() takes 0 positional arguments"] * 3 + right[3:]
    only_others = right[:3] + ["LimitError: beyond the limits"]
    assert score_exercise("ex06_3_task2_test", right, e, 1.0).score == 1.0
    assert score_exercise("ex06_3_task2_test", only_task, e, 1.0).score == pytest.approx(0.5)
    assert score_exercise("ex06_3_task2_test", only_others, e, 1.0).score == pytest.approx(0.5)


def test_an_ik_solution_near_the_target_earns_half_a_case_and_one_outside_the_limits_nothing():
    from grader.scoring.rules import ik_loop
    from snakekit.kinematics import tool_pose_2d

    q = np.array([0.3, -0.2, 0.4, 0.1, -0.3])
    target = tool_pose_2d(q)[:2]
    tol = {"rtol": 0.0, "atol": 1e-5}
    assert ik_loop((target,), {"value": q}, tol) == (True, "")
    near, why = ik_loop((target + [3e-4, 0.0],), {"value": q}, tol)
    assert near == 0.5 and "0.0003 m from the target" in why and "half of this case" in why
    assert ik_loop((target + [3e-2, 0.0],), {"value": q}, tol)[0] is False
    outside = q.copy()
    outside[0] = 1.6
    assert ik_loop((tool_pose_2d(outside)[:2],), {"value": outside}, tol)[0] is False


@pytest.mark.parametrize("lesson, tests, run", [
    ("06_coded_sweep", {"ex06_3_task2_test"},
     ["imports", "ex06_1_sweep_times", "ex06_2_sweep_positions", "ex06_3_task2", "ex06_3_task2_test"]),
    ("03_inverse_kinematics", {"ex03_3_ik_loop_test"},
     ["imports", "before the exercises", "ex03_1_two_link_ik", "ex03_2_dls_step", "ex03_3_ik_loop",
      "ex03_3_ik_loop_test"]),   # lesson 03 draws its triangle before the first exercise
])
def test_the_second_run_runs_the_imports_the_answers_and_the_test_read_from_it_and_nothing_after(lesson, tests, run):
    """Of the lesson's code cells, the second run skips the other test cells, the demonstrations between
    the exercises (lesson 06's full Task 2 run and its plots) and everything after the last test it reads."""
    from pathlib import Path

    from grader.sandbox.inside.worker import runs_cell

    nb = nbformat.read(Path(__file__).resolve().parents[2] / "course" / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    first = min(i for i, c in enumerate(nb.cells) if c.metadata.get("nbgrader", {}).get("grade_id"))
    ran = [c.metadata.get("nbgrader", {}).get("grade_id") or ("imports" if "import numpy" in c.source else
                                                              "before the exercises" if i < first else c.source)
           for i, c in enumerate(nb.cells) if c.cell_type == "code" and runs_cell(nb.cells, i, tests)]
    assert ran == run
