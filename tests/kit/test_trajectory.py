"""Trajectories: validation, files, resampling, time scaling and the Task 2 sweep."""

import numpy as np
import pytest

import snakekit
from snakekit import SPEC, Trajectory
from snakekit.trajectory import (
    cubic_time_scaling, joint_trajectory, quintic_time_scaling, trapezoidal_time_scaling,
)


def small():
    t = np.array([0.0, 0.5, 1.0])
    q = np.array([[0, 0, 0, 0, 0], [0.2, 0.1, 0, 0, -0.1], [0.4, 0.2, 0, 0, -0.2]], float)
    return Trajectory(t, q)


def test_arrays_are_read_only_copies():
    q = np.zeros((2, 5))
    tr = Trajectory([0, 1], q)
    q[0, 0] = 9
    assert tr.positions[0, 0] == 0
    with pytest.raises(ValueError):
        tr.positions[0, 0] = 1


@pytest.mark.parametrize("times, positions, err, text", [
    ([0, 1, 1], np.zeros((3, 5)), snakekit.TrajectoryError, "times must increase strictly: times[1] = 1 s"),
    ([0, 2, 1], np.zeros((3, 5)), snakekit.TrajectoryError, "Sort the points"),
    ([0, 1], np.zeros((2, 4)), snakekit.ShapeError, "The arm has 5 joints: give 5 angles"),
    ([0, 1, 2, 3, 4], np.zeros((5, 2)) + 0, snakekit.ShapeError, "(5, 5)"),
    ([0, 1], np.zeros((5, 2)), snakekit.ShapeError, "did you pass the transpose?"),
    ([], np.zeros((0, 5)), snakekit.ShapeError, "N >= 1"),
    ([0, np.nan], np.zeros((2, 5)), snakekit.NotFiniteError, "times hold NaN"),
    ([0, 1], [[0] * 5, [0, 0, np.inf, 0, 0]], snakekit.NotFiniteError, "first at index (1, 2)"),
])
def test_malformed_trajectories_are_rejected(times, positions, err, text):
    with pytest.raises(err) as e:
        Trajectory(times, positions)
    assert text in str(e.value)


def test_limit_violations_name_joint_time_and_kind():
    t = np.array([0.0, 0.1, 0.2])
    q = np.zeros((3, 5))
    q[1, 2] = 0.3  # 3 rad/s on joint 3 between t=0 and 0.1, then back
    q[2, 4] = 1.6  # joint 5 past 1.57 at t=0.2
    bad = Trajectory(t, q).limit_violations()
    kinds = {(v.joint, round(v.time, 3), v.kind) for v in bad}
    assert (5, 0.2, "position") in kinds
    assert (3, 0.1, "velocity") in kinds and (3, 0.2, "velocity") in kinds
    with pytest.raises(snakekit.LimitError) as e:
        Trajectory(t, q).check_limits()
    assert "joint 5 at t=0.200 s: position +1.6000 rad (limit +1.5700)" in str(e.value)
    assert "Nothing was sent" in str(e.value)


def test_a_slow_trajectory_inside_limits_passes():
    assert small().check_limits().limit_violations() == []


@pytest.mark.parametrize("suffix", [".npz", ".csv"])
def test_save_load_round_trip(tmp_path, suffix):
    tr = joint_trajectory(np.zeros(5), [0.3, -0.2, 0.1, 0, 0.5], rate=50)
    back = Trajectory.load(tr.save(tmp_path / f"t{suffix}"))
    np.testing.assert_array_equal(back.times, tr.times)
    np.testing.assert_array_equal(back.positions, tr.positions)
    np.testing.assert_array_equal(back.velocities, tr.velocities)


def test_truncated_csv_says_which_line(tmp_path):
    p = small().save(tmp_path / "t.csv")
    text = p.read_text().splitlines()
    p.write_text("\n".join(text[:-1] + [text[-1][:9]]) + "\n")
    with pytest.raises(snakekit.FileFormatError, match=r"t.csv, line 4: 3 values, expected 6; the file may be truncated"):
        Trajectory.load(p)


def test_csv_with_wrong_header(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("t,a,b\n0,1,2\n")
    with pytest.raises(snakekit.FileFormatError, match="expected time,q1,q2,q3,q4,q5"):
        Trajectory.load(p)


def test_csv_with_a_word_instead_of_a_number(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("time,q1,q2,q3,q4,q5\n0,0,0,zero,0,0\n")
    with pytest.raises(snakekit.FileFormatError, match="line 2: not a number"):
        Trajectory.load(p)


def test_truncated_npz(tmp_path):
    p = small().save(tmp_path / "t.npz")
    p.write_bytes(p.read_bytes()[:100])
    with pytest.raises(snakekit.FileFormatError, match="may be truncated"):
        Trajectory.load(p)


def test_npz_without_positions(tmp_path):
    p = tmp_path / "t.npz"
    np.savez(p, times=np.arange(3.0))
    with pytest.raises(snakekit.FileFormatError, match=r"lacks the array\(s\) \['positions'\]"):
        Trajectory.load(p)


def test_npz_holding_unsorted_times(tmp_path):
    p = tmp_path / "t.npz"
    np.savez(p, times=np.array([0.0, 2.0, 1.0]), positions=np.zeros((3, 5)))
    with pytest.raises(snakekit.FileFormatError, match="does not hold a valid trajectory: trajectory times"):
        Trajectory.load(p)


def test_missing_file_and_unknown_suffix(tmp_path):
    with pytest.raises(snakekit.FileFormatError, match="does not exist"):
        Trajectory.load(tmp_path / "nope.npz")
    (tmp_path / "t.json").write_text("{}")
    with pytest.raises(snakekit.FileFormatError, match="use .npz or .csv"):
        Trajectory.load(tmp_path / "t.json")
    with pytest.raises(snakekit.FileFormatError, match="use .npz or .csv"):
        small().save(tmp_path / "t.txt")


def test_resample_interpolates_linearly():
    r = small().resample(10)
    assert len(r) == 11
    np.testing.assert_allclose(r.times, np.arange(11) / 10)
    np.testing.assert_allclose(r.positions[:, 0], 0.4 * np.arange(11) / 10, atol=1e-15)
    with pytest.raises(snakekit.ConfigurationError, match=r"rate must be a finite number > 0 and <= 10000 \[Hz\], got 0"):
        small().resample(0)
    with pytest.raises(snakekit.TrajectoryError, match="resample needs a rate > 0 \\[Hz\\] or times, got neither"):
        small().resample()


@pytest.mark.parametrize("scaling", [cubic_time_scaling, quintic_time_scaling, trapezoidal_time_scaling])
def test_time_scalings_start_and_end_at_rest(scaling):
    T = 2.0
    t = np.linspace(0, T, 2001)
    s = scaling(T, t)
    assert s[0] == 0 and s[-1] == pytest.approx(1, abs=1e-12)
    assert np.all(np.diff(s) >= -1e-15)
    v = np.gradient(s, t)
    assert abs(v[0]) < 1e-2 and abs(v[-1]) < 1e-2


def test_quintic_peak_speed_is_15_over_8():
    t = np.linspace(0, 1, 100001)
    assert np.gradient(quintic_time_scaling(1.0, t), t).max() == pytest.approx(1.875, rel=1e-6)


def test_joint_trajectory_respects_the_velocity_limit():
    for method in ("cubic", "quintic", "trapezoidal"):
        tr = joint_trajectory(np.zeros(5), [1.5, -1.5, 0.7, 0, 0], method=method)
        assert tr.limit_violations() == []
        assert np.abs(tr.velocities).max() == pytest.approx(0.8 * SPEC.velocity_limit, rel=0.02)
        np.testing.assert_allclose(tr.positions[-1], [1.5, -1.5, 0.7, 0, 0])
    with pytest.raises(snakekit.LimitError, match="q_end is outside the joint limits"):
        joint_trajectory(np.zeros(5), [2, 0, 0, 0, 0])
    with pytest.raises(snakekit.TrajectoryError, match="unknown time scaling 'linear'"):
        joint_trajectory(np.zeros(5), np.zeros(5), 1.0, method="linear")


def test_side_sweep_is_the_studys_task_2():
    tr = snakekit.side_sweep()
    assert len(tr) == 500
    np.testing.assert_allclose(np.diff(tr.times), 0.1)
    assert np.all(tr.positions[0] == 0) and np.all(tr.positions[-1] == 0)
    # 50 full sweeps: each one left, right and back ends crossing zero upwards
    q = tr.sample(np.linspace(0, tr.duration, 100001))[:, 0]
    assert np.sum((q[:-1] < 0) & (q[1:] >= 0)) == 50
    assert tr.limit_violations() == []
    assert tr.positions.max() > 0.19 and tr.positions.min() < -0.19


def test_a_too_fast_move_is_reported_as_one_stretch_per_joint_and_kind():
    """Not one entry per sample: 51 points moving 5 joints too fast make 10 stretches."""
    fast = joint_trajectory(np.zeros(5), np.full(5, 1.5), 0.5, rate=100)  # peaks at 5.6 rad/s
    bad = fast.limit_violations()
    assert len(fast) == 51
    assert sorted({(v.joint, v.kind) for v in bad}) == [(j, k) for j in range(1, 6)
                                                         for k in ("stored velocity", "velocity")]
    assert len(bad) == 10
    between = np.diff(fast.positions[:, 0]) / np.diff(fast.times)
    v1 = next(v for v in bad if v.joint == 1 and v.kind == "velocity")
    assert v1.value == pytest.approx(between.max())  # the worst of the stretch
    assert v1.points == int((between > 1.5).sum())
    assert v1.start == pytest.approx(fast.times[1:][between > 1.5][0])
    with pytest.raises(snakekit.LimitError) as e:
        fast.check_limits()
    text = str(e.value)
    assert "in 10 stretch(es)" in text and "... and 5 more" in text
    assert "stored velocity +5.6" in text


def test_the_study_sweep_made_too_big_names_each_stretch_once():
    """One time is never listed twice for the same joint and kind."""
    t = np.arange(500) / 10.0
    q = np.repeat((0.4 * np.sin(2 * np.pi * t / (49.9 / 50)))[:, None], 5, 1)
    bad = Trajectory(t, q).limit_violations()
    keys = [(v.joint, v.kind, v.time) for v in bad]
    assert len(keys) == len(set(keys))
    assert all(v.kind == "velocity" for v in bad)
    assert all(abs(v.value) > 1.5 and v.bound == pytest.approx(np.copysign(1.5, v.value)) for v in bad)
