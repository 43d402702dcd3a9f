"""The visible check holds a case of each kind the hidden cases hold (more of tests/lessons/test_course_fairness.py):
for each slip below, every draw of the hidden cases holds a case where it gives a wrong answer, and so does the
visible check, so the slip fails locally as it loses points graded.

* 4.2: ``T = 2 d / v_peak`` in the triangle, nan for a move of no length;
* 4.4: every step divided by the first step's ``dt``, wrong on a trajectory at uneven times;
* 8.3: ``when`` taken among all the recorded times, wrong for a recording that starts before the reference; the
  largest error sought on the joint of the largest rms, wrong where the largest error is on another joint.

The visible cases are the arguments the test cell calls the student's function with, the cell run with a right
answer in the student's place.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import snakekit
from snakekit import SPEC, checks
from tests.lessons.test_course_fairness import CELLS, _cases


def _visible_calls(grade_id: str, name: str, fn, **names) -> list[tuple]:
    """The arguments the visible check of ``grade_id`` calls the student's ``name`` with (``fn`` answering)."""
    calls = []

    def kept(*args):
        calls.append(args)
        return fn(*args)

    kept.__name__ = name
    exec(dict((gid, src) for _, gid, src in CELLS)[grade_id], {"np": np, "checks": checks, name: kept, **names})
    return calls


def _trapezoid_nan_at(d, v, a) -> bool:
    """4.2's slip T = 2 d / v_peak in the triangle: nan where the move has no length."""
    with np.errstate(all="ignore"):
        return abs(d) < v * v / a and not np.isfinite(2 * abs(d) / np.sqrt(a * abs(d)))


@pytest.mark.parametrize("seed", range(50))
def test_every_draw_of_4_2_holds_a_move_of_no_length_where_2_d_over_v_peak_is_nan(seed):
    assert any(_trapezoid_nan_at(*c) for c in _cases("04_trajectories", "ex04_2_trapezoid_test", seed))


def test_4_2s_visible_check_holds_a_move_of_no_length_where_2_d_over_v_peak_is_nan():
    source = dict((gid, src) for _, gid, src in CELLS)["ex04_2_trapezoid_test"]
    visible = [tuple(map(float, m)) for m in re.findall(r"ex\(trapezoid, (-?[\d.]+), ([\d.]+), ([\d.]+)\)", source)]
    assert any(_trapezoid_nan_at(*c) for c in visible), visible


def _violations(times, positions, even=False):
    """4.4 as the lesson asks, or (``even``) with every step divided by the first one's dt: rows [time, joint, kind]."""
    t, p = np.asarray(times, dtype=float), np.asarray(positions, dtype=float)
    dt = np.full(len(t) - 1, t[1] - t[0]) if even else np.diff(t)
    rows = [[t[k], j + 1, 0] for k, j in zip(*np.nonzero(np.abs(p) > SPEC.upper))]
    speed = np.abs(np.diff(p, axis=0)) / dt[:, None]
    rows += [[t[k + 1], j + 1, 1] for k, j in zip(*np.nonzero(speed > SPEC.velocity_limit))]
    return np.array(sorted(rows), dtype=float).reshape(-1, 3)


def _even_spacing_is_wrong(times, positions) -> bool:
    right, even = _violations(times, positions), _violations(times, positions, even=True)
    return right.shape != even.shape or not np.allclose(right, even)


@pytest.mark.parametrize("seed", range(50))
def test_every_draw_of_4_4_holds_a_trajectory_at_uneven_times_where_one_dt_for_all_steps_is_wrong(seed):
    cases = _cases("04_trajectories", "ex04_4_limit_check_test", seed)
    assert any(_even_spacing_is_wrong(*c) for c in cases), cases


def test_4_4s_visible_check_holds_a_trajectory_at_uneven_times_where_one_dt_for_all_steps_is_wrong():
    calls = _visible_calls("ex04_4_limit_check_test", "limit_violations",
                           lambda tr: _violations(tr.times, tr.positions), snakekit=snakekit, spec=SPEC)
    assert len(calls) >= 5, calls
    assert any(_even_spacing_is_wrong(tr.times, tr.positions) for (tr,) in calls), calls


def _errors(times, positions, ref_times, ref_positions):
    """8.3's compared times and errors e[k, j] (None, None where nothing overlaps)."""
    times, positions = np.asarray(times, dtype=float), np.asarray(positions, dtype=float)
    ref_times, ref_positions = np.asarray(ref_times, dtype=float), np.asarray(ref_positions, dtype=float)
    inside = (times >= ref_times[0]) & (times <= ref_times[-1])
    if not inside.any():
        return None, None
    t = times[inside]
    return t, positions[inside] - np.column_stack([np.interp(t, ref_times, ref_positions[:, j]) for j in range(5)])


def _compare(times, positions, ref_times, ref_positions, slip=""):
    """8.3 as the lesson asks, or with a slip: the time taken among all the recorded times ("when"), or the largest
    error sought on the joint of the largest rms ("rms")."""
    t, error = _errors(times, positions, ref_times, ref_positions)
    if t is None:
        raise ValueError("no recorded time falls within the reference's")
    rms = np.sqrt(np.mean(error ** 2, axis=0))
    k, j = np.unravel_index(np.argmax(np.abs(error)), error.shape)
    if slip == "rms":
        j = int(np.argmax(rms))
        k = int(np.argmax(np.abs(error[:, j])))
    when = float((np.asarray(times, dtype=float) if slip == "when" else t)[k])
    return {"rms": rms, "largest": float(abs(error[k, j])), "joint": int(j) + 1, "when": when}


def _slip_is_wrong(case, slip) -> bool:
    if _errors(*case)[0] is None:
        return False
    right, wrong = _compare(*case), _compare(*case, slip=slip)
    return any(not np.isclose(right[key], wrong[key], rtol=0, atol=1e-9) for key in ("largest", "joint", "when"))


def _starts_before(case) -> bool:
    return np.asarray(case[0])[0] < np.asarray(case[2])[0]


@pytest.mark.parametrize("seed", range(50))
def test_every_draw_of_8_3_holds_a_recording_that_starts_before_the_reference_and_largest_rms_on_another_joint(seed):
    cases = _cases("08_ros", "ex08_3_compare_runs_test", seed)
    assert any(_starts_before(c) and _slip_is_wrong(c, "when") for c in cases)
    assert any(_slip_is_wrong(c, "rms") for c in cases)


def test_8_3s_visible_check_holds_a_recording_that_starts_before_the_reference_and_largest_rms_on_another_joint():
    calls = _visible_calls("ex08_3_compare_runs_test", "compare_runs", _compare)
    assert len(calls) >= 4, calls
    assert any(_starts_before(c) and _slip_is_wrong(c, "when") for c in calls)
    assert any(_slip_is_wrong(c, "rms") for c in calls)
