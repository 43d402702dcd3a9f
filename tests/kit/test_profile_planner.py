"""The MX-28 profile generator against the firmware's rules."""

import numpy as np
import pytest

from snakekit.profile_planner import (
    ACCELERATION_UNIT, VELOCITY_UNIT, JointProfile, ProfilePlanner, acceleration_time_ms,
)


def dense(profile, t0, t1, n=20001):
    t = np.linspace(t0, t1, n)
    p, v = profile.sample(t)
    return t, p, v


@pytest.mark.parametrize("pv, pa", [(62, 100), (62, 20), (100, 50), (30, 300)])
def test_acceleration_time_is_64_velocity_over_acceleration_ms(pv, pa):
    vmax, amax = pv * VELOCITY_UNIT, pa * ACCELERATION_UNIT
    prof = JointProfile(0.0, 0.0, 0.0, 1.5, vmax, amax)
    t1 = prof.segments[1].t0  # end of the acceleration phase
    assert t1 * 1000 == pytest.approx(64 * pv / pa, rel=2e-3)  # 2e-3: 0.229 and 214.577 are rounded
    assert acceleration_time_ms(pv, pa) == 64 * pv / pa
    assert prof.at(t1)[1] == pytest.approx(vmax)


def test_trapezoid_ends_at_rest_on_the_goal_within_bounds():
    vmax, amax = 62 * VELOCITY_UNIT, 100 * ACCELERATION_UNIT
    prof = JointProfile(0.0, 0.2, 0.0, 1.2, vmax, amax)
    t, p, v = dense(prof, 0, prof.end_time + 0.1)
    assert p[0] == pytest.approx(0.2) and p[-1] == 1.2 and v[-1] == 0
    assert np.abs(v).max() <= vmax * (1 + 1e-12)
    assert np.abs(np.diff(v) / np.diff(t)).max() <= amax * (1 + 1e-6)
    # area under the trapezoid: distance = vmax * (T - t1)
    t1 = vmax / amax
    assert prof.end_time == pytest.approx(1.0 / vmax + t1, rel=1e-9)


def test_short_move_is_a_triangle():
    vmax, amax = 62 * VELOCITY_UNIT, 100 * ACCELERATION_UNIT
    d = 0.01
    prof = JointProfile(0.0, 0.0, 0.0, d, vmax, amax)
    assert prof.end_time == pytest.approx(2 * np.sqrt(d / amax), rel=1e-9)
    assert max(abs(s.v0) for s in prof.segments) < vmax
    assert prof.at(prof.end_time / 2)[1] == pytest.approx(np.sqrt(d * amax), rel=1e-9)


def test_new_goal_while_moving_replans_from_present_velocity():
    planner = ProfilePlanner(np.zeros(1))
    planner.set_goal(0.0, [1.0])
    p_before, v_before = planner.at(0.3)
    assert v_before[0] > 0
    planner.set_goal(0.3, [-0.5])  # reverse while moving
    p_after, v_after = planner.at(0.3)
    assert p_after[0] == pytest.approx(p_before[0]) and v_after[0] == pytest.approx(v_before[0])
    prof = planner.profiles[0]
    assert prof.segments[0].a == pytest.approx(-100 * ACCELERATION_UNIT)  # brakes first
    t, p, v = dense(prof, 0.3, prof.end_time + 0.05)
    assert np.all(np.isfinite(p)) and p[-1] == -0.5 and v[-1] == 0
    assert np.abs(np.diff(p)).max() < 1e-3  # continuous


def test_velocity_zero_means_a_step():
    planner = ProfilePlanner(np.zeros(2), profile_velocity=0)
    planner.set_goal(1.0, [0.7, -0.2])
    p, v = planner.at(1.0)
    np.testing.assert_array_equal(p, [0.7, -0.2])
    np.testing.assert_array_equal(v, 0)


def test_acceleration_zero_means_rectangular():
    planner = ProfilePlanner(np.zeros(1), profile_velocity=62, profile_acceleration=0)
    planner.set_goal(0.0, [0.5])
    vmax = 62 * VELOCITY_UNIT
    assert planner.at(0.001)[1][0] == pytest.approx(vmax)
    assert planner.at(0.5 / vmax + 1e-6)[0][0] == 0.5


def test_sample_agrees_with_pointwise_evaluation():
    planner = ProfilePlanner(np.zeros(5))
    planner.set_goal(0.0, [0.5, -0.3, 0.01, 1.2, -1.5])
    times = np.linspace(0, 1.5, 301)
    pos, vel = planner.sample(times)
    for i in (0, 7, 150, 300):
        p, v = planner.at(times[i])
        np.testing.assert_allclose(pos[i], p, atol=1e-15)
        np.testing.assert_allclose(vel[i], v, atol=1e-15)
