"""The course's check helpers (snakekit/checks.py) say a beginner's slips in plain words."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np
import pytest

from snakekit import checks
from snakekit.errors import CheckFailed, ShortcutError
from tests.conftest import need, notebook_client


def message(call) -> str:
    with pytest.raises(CheckFailed) as e:
        call()
    return str(e.value)


def test_a_function_without_return_is_said_to_return_none():
    ex = checks.Exercise("9.1", "double")

    def double(x):
        2 * x     # noqa: B018 - the slip: no return

    said = message(lambda: ex(double, 0.5))
    assert said == ("exercise 9.1 double: double returned None when called with 0.5: did you forget `return`? A "
                    "function gives its result with a `return` line; is it missing, or does the function stop before "
                    "it?")


def test_a_wrapper_that_stumbles_on_a_none_names_the_forgotten_return():
    """A check that runs the student's function inside its own code (a fresh arm, a loop) says
    "returned None", not the error its code met on the None."""
    import __main__

    ex = checks.Exercise("9.1", "double")

    def double(x):
        2 * x     # noqa: B018 - the slip: no return

    def graded(x):
        return {"value": double(x)[0]}     # TypeError on the None

    __main__.double = double
    try:
        said = message(lambda: ex(graded, 0.5))
    finally:
        del __main__.double
    assert said.startswith("exercise 9.1 double: double returned None when called with 0.5: did you forget `return`?")


@pytest.mark.parametrize("got, want, unit", [(-0.000252097, -0.000252, "rad"), (0.13521, 0.135214, "m"),
                                               (49.90001, 49.9, "s"), (1.0 + 1e-7, 1.0, "")])
def test_a_value_off_by_less_than_its_shown_digits_is_shown_with_the_digits_that_tell_it_apart(got, want, unit):
    said = message(lambda: checks.Exercise("9.3", "f").close(got, want, what="value", unit=unit, tol=1e-15))
    shown, wanted = said.split(" is ", 1)[1].split(": off by", 1)[0].split(", expected ")
    assert shown != wanted, said
    assert float(shown.split()[0]) != float(wanted.split()[0])
    # each is the value it stands for, to the digits shown
    for text, value in ((shown, got), (wanted, want)):
        number = text.split()[0]
        digits = len(number.lstrip("-").replace(".", "").split("e")[0].lstrip("0"))
        assert abs(float(number) - value) <= abs(value) * 10.0 ** (1 - digits), (text, value)


def test_a_list_where_an_array_is_asked_says_to_return_an_array():
    ex = checks.Exercise("9.2", "rows")
    said = message(lambda: ex.close([[0.0, 0.0], [1.0, 0.0]], [[0.0, 0.0], [1.0, 0.0]], what="rows", unit="m",
                                    array=True))
    assert "rows returned a Python list when called with" not in said
    assert "rows returned a Python list, not a numpy array: the exercise asks for an array" in said
    assert said.rstrip().endswith("return np.array(...) of it.")
    ex.close(np.array([[0.0, 0.0], [1.0, 0.0]]), [[0.0, 0.0], [1.0, 0.0]], what="rows", unit="m", array=True)
    ex.close([1.0, 2.0], [1.0, 2.0], what="a list is fine where no array is asked")


def test_raises_passes_the_asked_error_and_names_what_came_instead():
    ex = checks.Exercise("9.3", "ik")

    def refuses(x):
        raise ValueError(f"{x} is out of reach")

    ex.raises(ValueError, refuses, 0.5, why="the target is out of reach")
    assert ex.checked == 1
    said = message(lambda: ex.raises(ValueError, lambda x: x, 0.5, why="the target is out of reach"))
    assert said == ("exercise 9.3 ik: `ik` returned a result when called with 0.5, raising nothing; the target is out of reach: raise a "
                    'ValueError there (`raise ValueError("...")`, saying why).')
    said = message(lambda: ex.raises(ValueError, lambda x: 1 / 0, 0.5, why="the target is out of reach"))
    assert said.startswith("exercise 9.3 ik: `ik` raised ZeroDivisionError when called with 0.5: division by zero")

    def stub(x):
        raise NotImplementedError("exercise 9.3: ik")

    assert "is not written yet" in message(lambda: ex.raises(ValueError, stub, 0.5))


def test_a_shortcut_inside_a_checked_call_is_reported_as_the_shortcut():
    import snakekit

    ex = checks.Exercise("9.4", "fk")
    with checks.forbid("snakekit.tool_pose_2d", what="planar FK"):
        with pytest.raises(ShortcutError) as e:
            ex(lambda q: snakekit.tool_pose_2d(q), np.zeros(5))
    assert str(e.value).startswith("exercise 9.4 fk: this exercise asks you to write planar FK yourself; "
                                   "`snakekit.tool_pose_2d` was called")


def test_a_check_cell_after_a_broken_answer_cell_says_the_answer_did_not_run(tmp_path, monkeypatch):
    """A syntax error in the answer cell defines nothing: the check cell says so, not a bare NameError."""
    nbformat = need("nbformat")
    need("nbclient")
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    nb = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell("from snakekit import checks"),
        nbformat.v4.new_code_cell("def planar_fk(q)\n    return q"),           # the colon is missing
        nbformat.v4.new_code_cell('ex = checks.Exercise("1.1", "planar_fk")\nex(planar_fk, 0.0)'),
        nbformat.v4.new_code_cell("print(undefined_name)")])
    notebook_client(nb, timeout=120, kernel_name="python3", allow_errors=True,
                    resources={"metadata": {"path": str(tmp_path)}}).execute()
    assert nb.cells[1].outputs[0].ename == "SyntaxError"
    error = nb.cells[2].outputs[0]
    assert (error.ename, error.evalue) == (
        "NameError", "name 'planar_fk' is not defined: the cell that defines `planar_fk` has not run yet, or it "
        "stopped with an error (a SyntaxError in your answer, say), so nothing was defined. Run that cell, fix the "
        "error it shows, then run this cell again.")
    assert "has not run yet" in nb.cells[3].outputs[0].evalue


def test_a_demonstration_that_stops_on_a_wrong_answer_points_to_its_check():
    def distance_mm(q, target):
        pass     # the answer's slip: no return

    with pytest.raises(CheckFailed) as e:
        with checks.waiting_for("0.1"):
            print(f"{distance_mm(0, (0, 0)):.2f} mm")
    assert str(e.value).startswith("this cell uses your answer to exercise 0.1, and it stopped with TypeError: ")
    assert str(e.value).endswith("Run exercise 0.1's check cell first: it says what is wrong.")


def test_the_live_part_is_left_out_while_graded_and_in_quick_mode_and_only_then(monkeypatch):
    for switch in ("SNAKEKIT_CASES", "SNAKEKIT_QUICK", "SNAKEKIT_TEST"):
        monkeypatch.delenv(switch, raising=False)
    assert checks.live_off() is None
    monkeypatch.setenv("SNAKEKIT_QUICK", "1")
    assert checks.live_off() == "quick mode leaves the live arm out"
    monkeypatch.delenv("SNAKEKIT_QUICK")
    monkeypatch.setenv("SNAKEKIT_CASES", "/tmp/grader.sock")   # the grader's socket: the notebook is being graded
    assert checks.live_off().startswith("a graded run leaves the live arm out")


def test_a_run_loaded_where_reading_a_bag_is_forbidden_says_which_call_and_what_to_use_not_a_path(tmp_path):
    import snakekit

    bag = snakekit.side_sweep(points=20, rate=10.0, sweeps=1, amplitude=0.1)
    with snakekit.make_robot("sim") as robot:
        path = robot.run(bag).save(tmp_path / "recorded.bag")
    for names in (("snakekit.bags.read",), ("snakekit.bags.read", "snakekit.Run.load")):
        with checks.forbid(*names, what="the reading of a bag", instead="Read it with rosbags' AnyReader, as the lesson shows"):
            with pytest.raises(ShortcutError) as e:
                snakekit.Run.load(path)
        assert str(e.value) == (f"this exercise asks you to write the reading of a bag yourself; `{names[-1]}` was called. "
                                "Read it with rosbags' AnyReader, as the lesson shows (the library's version is for after "
                                "the exercise).")
    assert snakekit.Run.load(path).measured.positions.shape[1] == 5    # restored after the block


# --- a known mistake's hint: the mistake, and only it -------------------------------------------------------------

COARSE = "the lag lies between your grid's steps."
MS = "a lag in milliseconds; return seconds."


def _lag_hint(got) -> str:
    """6.4's check at Task 2 (the lag 0.159 s, tolerance 6 ms): the hint ``got`` is told."""
    said = message(lambda: checks.Exercise("6.4", "estimate_lag").close(
        got, 0.159, what="lag", unit="s", tol=0.006, why="the method of the text",
        mistakes={COARSE: 0.15, MS: checks.scaled(1000)}))
    return CheckFailed.hint_of(said)


def test_a_known_mistake_s_value_gets_its_hint_and_a_result_wrong_otherwise_does_not():
    assert _lag_hint(0.15) == COARSE                   # what lags 50 ms apart give
    assert _lag_hint(0.174) == ""                      # 15 ms late: wrong, and no grid gives it
    assert _lag_hint(0.141) == ""                      # 18 ms early, 9 ms past the grid's value: not the grid either


def test_a_unit_slip_is_recognised_within_the_tolerance_scaled_by_the_slip():
    assert _lag_hint(159.0) == MS and _lag_hint(163.0) == MS       # 0.163 s would pass: in ms it is the slip alone
    assert _lag_hint(170.0) == ""                                  # 0.170 s is wrong in seconds too
    ex = checks.Exercise("9.9", "angle")
    degrees = np.degrees(0.5 + 0.009)                              # 0.509 rad passes a 0.01 rad tolerance
    hint = CheckFailed.hint_of(message(lambda: ex.close(degrees, 0.5, what="angle", unit="rad", tol=0.01)))
    assert hint.startswith("this looks like degrees")
    hint = CheckFailed.hint_of(message(lambda: ex.close(np.degrees(0.5) + 5, 0.5, what="angle", unit="rad", tol=0.01)))
    assert hint == ""                                               # 5 degrees off beside the slip: not the slip alone


def test_a_mistake_that_spreads_says_how_far():
    near = {"near the target, not on it.": checks.within([0.22, 0.12], 1e-4)}
    ex = checks.Exercise("3.3", "solve_ik")
    said = message(lambda: ex.close([0.22005, 0.12], [0.22, 0.12], what="tool", unit="m", tol=1e-5, mistakes=near))
    assert CheckFailed.hint_of(said) == "near the target, not on it."
    said = message(lambda: ex.close([0.2205, 0.12], [0.22, 0.12], what="tool", unit="m", tol=1e-5, mistakes=near))
    assert CheckFailed.hint_of(said) == ""


def test_a_forgotten_return_names_a_long_argument_by_its_kind():
    """6.4's estimate_lag(run) without `return`: the message names the run "a Run", not its whole repr
    (arrays of efforts and all), which the graded page copied too."""
    import snakekit

    with snakekit.make_robot("sim") as robot:
        run = robot.run(snakekit.side_sweep(points=20, sweeps=2))
    ex = checks.Exercise("9.4", "estimate_lag")
    said = message(lambda: ex(lambda r, j=0: None, run, 0))
    assert said.startswith("exercise 9.4 estimate_lag: estimate_lag returned None when called with a Run, 0: did you "
                           "forget `return`?"), said


def test_a_list_argument_is_called_a_list_not_an_array():
    """3.4's task1(panel, targets) without `return`: the targets, a list of (x, y, heading), are "a list of 3
    entries of 3 numbers each", not "array of shape (3, 3)"."""
    ex = checks.Exercise("9.5", "task1")
    targets = [(0.25, 0.10, 0.3), (0.12, 0.22, 1.6), (0.28, -0.08, -0.4)]
    said = message(lambda: ex(lambda t: None, targets))
    assert said.startswith("exercise 9.5 task1: task1 returned None when called with a list of 3 entries of 3 numbers "
                           "each: did you forget `return`?"), said
    said = message(lambda: ex(lambda t: None, np.zeros((3, 3))))
    assert "when called with array of shape (3, 3):" in said, said


@pytest.mark.parametrize("what, got, want, said", [
    ("Jacobian of q0*q1", [[3.0, 4.0]], [[3.0, 2.0]], "entry [0, 1] of Jacobian of q0*q1 at q=[2, 3] is 4, expected 2"),
    ("Jacobian of g", np.eye(3) * 2, np.eye(3), "entry [0, 0] of Jacobian of g at q=[2, 3] is 2, expected 1"),
    ("Jacobian row 3 (the heading)", np.zeros(5), np.ones(5),
     "entry [0] of Jacobian row 3 (the heading) at q=[2, 3] is 0, expected 1"),
    ("send times", [0.0, 0.5], [0.0, 0.1], "send times[1] at q=[2, 3] is 0.5, expected 0.1")])
def test_an_entry_of_a_value_named_by_a_phrase_is_named_before_the_phrase_not_as_indexing_its_last_word(
        what, got, want, said):
    ex = checks.Exercise("2.2", "numerical_jacobian")
    assert message(lambda: ex.close(np.array(got), want, what=what, where="q=[2, 3]")).startswith(
        f"exercise 2.2 numerical_jacobian: {said}")


def test_a_single_number_that_is_nan_is_said_to_be_nan_locally_and_graded():
    from grader.scoring.score import Expected, score_exercise
    from grader.scoring.wording import Part, Wording

    ex = checks.Exercise("2.3", "manipulability")
    assert message(lambda: ex.close(float("nan"), 0.0, what="manipulability", where="q=[0, 0, 0, 0, 0]")) == \
        "exercise 2.3 manipulability: manipulability at q=[0, 0, 0, 0, 0] is nan: every value must be a finite number."
    w = Wording("manipulability", parts=(Part("manipulability", "m^2/rad^2"),))
    graded = score_exercise("ex02_3_manipulability_test", [{"value": np.array(np.nan)}],
                            Expected("ex02_3_manipulability_test", "values", [(np.zeros(5),)],
                                     [{"value": np.array(0.0)}], wording=w), 2.0).message
    assert graded.endswith("manipulability(q=[0, 0, 0, 0, 0]): manipulability is nan: every value must be a finite "
                           "number.") or graded.endswith("manipulability is nan: every value must be a finite number."), \
        graded
    assert "index" not in graded


def test_a_composites_note_starts_a_sentence_of_its_own_after_an_error_that_has_no_full_stop():
    from snakekit.verdicts import PASSED

    ex = checks.Exercise("2.3", "manipulability", builds_on=("2.1",))
    PASSED["2.1"] = False
    rows = [[0.0]]   # a list, indexed as an array (a name, not the literal: Python warns of a literal's [:, 0])
    try:
        said = message(lambda: ex(lambda q: rows[:, 0], np.zeros(5)))
    finally:
        PASSED.pop("2.1", None)
    assert "list indices must be integers or slices, not tuple.\n2.3 uses your 2.1, which fails its check" in said, said


def test_an_exercise_that_asks_for_an_array_refuses_a_list_its_function_returns_whoever_calls_it(monkeypatch):
    """``Exercise(..., array=True)``: what the student's function returns is judged, even where the check calls it through
    a helper of its own that makes an array of it (6.2's np.asarray(sweep_positions(...)))."""
    import __main__

    def rows(n):
        return [[0.0, 0.0]] * n

    monkeypatch.setattr(__main__, "rows", rows, raising=False)
    ex = checks.Exercise("9.4", "rows", array=True)
    said = message(lambda: ex(lambda n: np.asarray(rows(n)), 2, where="n=2"))
    assert said.startswith("exercise 9.4 rows: rows returned a Python list when called with n=2, not a numpy array"), said
    monkeypatch.setattr(__main__, "rows", lambda n: np.zeros((n, 2)), raising=False)
    assert ex(__main__.rows, 2).shape == (2, 2)                      # an array passes
    assert checks.Exercise("9.4", "rows")(rows, 2) == [[0.0, 0.0]] * 2   # and a list, where no array is asked
