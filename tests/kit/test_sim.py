"""The MuJoCo simulator behaves like five MX-28s in position mode."""

import time

import numpy as np
import pytest

import snakekit
from snakekit import SPEC, Trajectory
from snakekit.profile_planner import VELOCITY_UNIT
from snakekit.robot import Robot
from snakekit.run import JointState
from snakekit.sim import SimRobot
from snakekit.trajectory import joint_trajectory


def test_make_robot_defaults_to_the_simulator():
    with snakekit.make_robot() as robot:
        assert isinstance(robot, SimRobot) and robot.backend == "sim" and not robot.realtime
    with pytest.raises(snakekit.BackendError, match="unknown backend 'gazebo'; choose one of sim, emulator, hardware"):
        snakekit.make_robot("gazebo")


def test_a_held_goal_converges():
    goal = np.array([0.5, -0.3, 0.2, 0.1, -0.4])
    with SimRobot() as robot:
        robot.command(goal)
        robot.step(2.0)
        s = robot.read()
    assert s.time == pytest.approx(2.0)
    np.testing.assert_allclose(s.positions, goal, atol=0.01)  # friction leaves a few mrad
    np.testing.assert_allclose(s.velocities, 0, atol=1e-3)


def test_reference_follows_the_firmware_profile_timing():
    # 1 ms reference updates so the 39.7 ms acceleration phase is resolved
    pv, pa = 62, 100
    with SimRobot(profile_velocity=pv, profile_acceleration=pa) as robot:
        robot.command([1.5, 0, 0, 0, 0])
        ref_vel = []
        for _ in range(200):
            robot.step(0.001)
            ref_vel.append(robot.data.ctrl[0])  # the actuator's reference velocity
        ref_vel = np.array(ref_vel)
        vmax = pv * VELOCITY_UNIT
        # ref_vel[i] is the reference's mean velocity over [i, i+1] ms: the first interval at
        # full speed starts on the first whole millisecond after t1 = 64 * 62 / 100 = 39.68 ms
        first_full = int(np.argmax(ref_vel >= vmax * (1 - 1e-9)))
        assert first_full - 1 < 64 * pv / pa <= first_full
        assert 0 < ref_vel[first_full - 1] < vmax
        # the joint itself follows: its speed settles at the profile velocity
        robot.step(0.3)
        assert robot.read().velocities[0] == pytest.approx(vmax, rel=0.03)


def test_a_large_step_saturates_the_torque():
    with SimRobot(profile_velocity=0, any_profile=True) as robot:  # velocity 0: no profile, a step
        robot.command([1.0, 0, 0, 0, 0])
        efforts = []
        for _ in range(100):
            robot.step(0.002)
            efforts.append(robot.read().efforts[0])
    efforts = np.array(efforts)
    assert efforts.max() == pytest.approx(SPEC.servo.stall_torque)  # clamped at 2.5 N m
    assert np.abs(efforts).max() <= SPEC.servo.stall_torque + 1e-12
    assert np.sum(np.isclose(efforts, 2.5)) >= 5  # held at the limit for a while


def test_two_identical_runs_are_bit_identical():
    rng = np.random.default_rng(3)
    q = np.cumsum(rng.uniform(-0.05, 0.05, (40, 5)), axis=0)
    q[0] = 0
    tr = Trajectory(np.arange(40) * 0.1, q)
    runs = []
    for _ in range(2):
        with SimRobot() as robot:
            runs.append(robot.run(tr))
    a, b = runs
    for x, y in [(a.measured.times, b.measured.times), (a.measured.positions, b.measured.positions),
                 (a.measured.velocities, b.measured.velocities), (a.efforts, b.efforts),
                 (a.commanded.times, b.commanded.times)]:
        assert np.array_equal(x, y)


def test_the_sweep_stays_inside_the_limits_and_returns_home():
    with SimRobot() as robot:
        run = robot.run(snakekit.side_sweep())
    assert run.limits_held()
    assert np.diff(run.measured.times).max() <= 0.01 + 1e-12  # recorded at 100 Hz
    assert run.robot_time == pytest.approx(49.9 + 0.5)
    assert run.final_distance_from_home() < 0.005
    assert np.abs(run.measured.positions).max() < 0.25  # the sweep's amplitude is 0.2 rad
    assert np.all(run.tracking_error() < 0.25)
    assert "limits held:        yes" in run.summary()


def test_a_trajectory_outside_the_limits_is_refused_before_anything_moves():
    bad = joint_trajectory(np.zeros(5), [1.5, 0, 0, 0, 0], 1.0)  # 1.5 rad in 1 s: too fast
    with SimRobot() as robot:
        with pytest.raises(snakekit.LimitError, match="Nothing was sent"):
            robot.run(bad)
        assert robot.read().time == 0.0
        np.testing.assert_array_equal(robot.planner.goals, 0)
        np.testing.assert_array_equal(robot.read().positions, 0)


def test_a_command_outside_the_limits_is_refused():
    with SimRobot() as robot:
        with pytest.raises(snakekit.LimitError, match="joint 2 = -1.6000 rad"):
            robot.command([0, -1.6, 0, 0, 0])
        np.testing.assert_array_equal(robot.planner.goals, 0)


def test_a_trajectory_starting_away_from_the_arm_is_refused():
    tr = joint_trajectory([0.5, 0, 0, 0, 0], [0.6, 0, 0, 0, 0])
    with SimRobot() as robot:
        with pytest.raises(snakekit.LimitError, match=r"starts 0.500 rad away.*robot.move_to"):
            robot.run(tr)
        run = robot.move_to([0.5, 0, 0, 0, 0])
        assert abs(run.measured.positions[-1, 0] - 0.5) < 0.01
        robot.run(tr)  # now it starts where the arm is


def test_a_closed_robot_says_so():
    robot = SimRobot()
    robot.close()
    robot.close()  # twice is fine
    with pytest.raises(snakekit.BackendError, match="robot is closed"):
        robot.command(np.zeros(5))


def test_real_time_mode_follows_the_wall_clock(monkeypatch):
    """Paced: the run takes at least its robot time on the wall clock. Not stalled: it never
    waits longer than the robot clock asks (how close to real time a run keeps is a figure of
    ``bench/sim.py``)."""
    import snakekit.sim as sim

    real_sleep, slept = time.sleep, []

    def sleep(seconds):
        slept.append(seconds)
        real_sleep(seconds)

    tr = joint_trajectory(np.zeros(5), [0.2, 0, 0, 0, 0], 0.5)
    with SimRobot(realtime=True) as robot:
        monkeypatch.setattr(sim.time, "sleep", sleep)
        t0 = time.perf_counter()
        run = robot.run(tr, settle=0.2)
        wall = time.perf_counter() - t0
    assert run.realtime and wall >= 0.7 - 0.02
    assert run.robot_time == pytest.approx(0.7, abs=0.011)
    assert slept and all(s > 0 for s in slept) and sum(slept) <= 0.7 + 1e-9, (len(slept), sum(slept))


class StepArm(Robot):
    """A backend of the bare interface: its runs are :meth:`Robot.run`'s own loop."""

    backend = "step"

    def __init__(self):
        super().__init__(SPEC)
        self.t, self.q = 0.0, np.zeros(5)

    def read(self):
        return JointState(self.t, self.q, self.q / 10, np.zeros(5))

    def _send(self, q):
        self.q = np.array(q)

    def _now(self):
        return self.t

    def _advance(self, t):
        self.t = max(self.t, t)


@pytest.mark.parametrize("make", [lambda: SimRobot(realtime=True), StepArm], ids=["sim-realtime", "robot-run"])
def test_on_record_sees_each_state_a_paced_run_records(make):
    seen = []
    tr = joint_trajectory(np.zeros(5), [0.2, -0.1, 0, 0, 0.1], 0.3)
    with make() as robot:
        robot.on_record = lambda t, p, v: seen.append((t, p.copy(), v.copy()))
        start = robot.read().time
        run = robot.run(tr, settle=0.1, record_rate=50.0)
    t, p, v = (np.array(x) for x in zip(*seen))
    assert len(seen) == len(run.measured) == 21  # 0.4 s at 50 Hz, both ends
    np.testing.assert_array_equal(t - start, run.measured.times)
    np.testing.assert_array_equal(p, run.measured.positions)
    np.testing.assert_array_equal(v, run.measured.velocities)
    assert np.abs(p[-1] - [0.2, -0.1, 0, 0, 0.1]).max() < 0.05  # the states of the move, not of the rest


def red_tool_tip(image):
    """Pixel (row, column) centroid of the red tool tip."""
    r, g, b = (image[..., i].astype(int) for i in range(3))
    rows, cols = np.nonzero((r > 150) & (g < 90) & (b < 90))
    assert len(rows) > 3, "the red tool tip is not in the picture"
    return rows.mean(), cols.mean()


def test_render_shows_the_pose():
    # The top camera looks down: image right is +x, image up is +y.
    with SimRobot() as robot:
        home = robot.render(np.zeros(5), width=320, height=240, camera="top")
        left = robot.render([1.2, 0, 0, 0, 0], width=320, height=240, camera="top")
        assert home.shape == (240, 320, 3) and home.dtype == np.uint8
        (hr, hc), (lr, lc) = red_tool_tip(home), red_tool_tip(left)
        assert hc > 160 + 40 and abs(hr - 120) < 20  # straight arm: tip right of centre, on the x axis
        assert lr < hr - 60 and lc < hc - 60  # turned left: the tip moves up and back
        np.testing.assert_array_equal(home, robot.render(np.zeros(5), width=320, height=240, camera="top"))
        assert robot.read().time == 0  # rendering a pose does not move the arm
        persp = robot.render(width=160, height=120)  # the present pose, default camera
        assert persp.shape == (120, 160, 3) and persp.std() > 10
    assert robot._renderer is None  # closed with the robot


def test_joint_state_is_read_only():
    with SimRobot() as robot:
        s = robot.read()
    with pytest.raises(ValueError):
        s.positions[0] = 1.0


def test_a_real_time_move_after_an_idle_spell_is_still_paced():
    """The robot clock stands still between runs; the next run must not race to catch up."""
    with SimRobot(realtime=True) as robot:
        robot.move_to([0.2, 0, 0, 0, 0], 0.4, settle=0.1)
        time.sleep(0.6)  # a student looks at the result
        t0 = time.perf_counter()
        run = robot.move_to([0, 0, 0, 0, 0], 0.4, settle=0.1)
        wall = time.perf_counter() - t0
        t0 = time.perf_counter()
        robot.step(0.3)
        step_wall = time.perf_counter() - t0
    robot_time = run.measured.times[-1] - run.measured.times[0]
    assert robot_time == pytest.approx(0.5, abs=0.011)
    assert wall >= robot_time - 0.02, f"{robot_time:.2f} s of motion ran in {wall:.2f} s"
    assert step_wall >= 0.3 - 0.02


def test_an_interrupted_real_time_run_goes_on_to_the_last_goal_sent(monkeypatch):
    """Ctrl-C in a real-time run: goals after it are never sent; the arm ends at the last one sent."""
    import snakekit.sim as sim

    tr = joint_trajectory(np.zeros(5), [0.4, 0, 0, 0, 0], 1.0, rate=10)
    real_sleep, calls = time.sleep, []

    def sleep(seconds):
        calls.append(seconds)
        if len(calls) == 40:  # about 0.4 s into the run
            raise KeyboardInterrupt
        real_sleep(seconds)

    with SimRobot(realtime=True) as robot:
        monkeypatch.setattr(sim.time, "sleep", sleep)
        with pytest.raises(KeyboardInterrupt):
            robot.run(tr)
        monkeypatch.setattr(sim.time, "sleep", real_sleep)
        stopped = robot.time
        sent = tr.positions[tr.times <= stopped + 1e-9][-1]
        assert 0.2 < stopped < 0.7 and 0.0 < sent[0] < 0.4
        np.testing.assert_allclose(robot.planner.goals, sent, atol=1e-12)
        robot_fast = SimRobot()  # the same goals sent by hand, one by one, as the servos get them
        for t, q in zip(tr.times, tr.positions):
            if t > stopped + 1e-9:
                break
            robot_fast.advance_to(t)
            robot_fast.set_servo_goals(q)
        robot_fast.advance_to(stopped)
        np.testing.assert_allclose(robot.read().positions, robot_fast.read().positions, atol=1e-9)
        robot.step(1.5)
        robot_fast.step(1.5)
        np.testing.assert_allclose(robot.read().positions, robot_fast.read().positions, atol=1e-9)
        np.testing.assert_allclose(robot.read().positions, sent, atol=5e-3)
        robot_fast.close()


def test_real_time_and_fast_modes_give_the_same_motion():
    tr = joint_trajectory(np.zeros(5), [0.3, -0.2, 0.1, 0.25, -0.3], 0.6, rate=10)
    runs = []
    for realtime in (False, True):
        with SimRobot(realtime=realtime) as robot:
            runs.append(robot.run(tr, settle=0.3))
            robot.step(0.2)  # holding afterwards continues the same way
            runs.append(robot.read())
    fast, fast_after, slow, slow_after = runs
    np.testing.assert_array_equal(fast.measured.times, slow.measured.times)
    np.testing.assert_allclose(fast.measured.positions, slow.measured.positions, atol=1e-12)
    np.testing.assert_allclose(fast.efforts, slow.efforts, atol=1e-9)
    np.testing.assert_allclose(fast_after.positions, slow_after.positions, atol=1e-12)


def test_goals_without_a_profile_jump_within_one_step():
    tr = Trajectory([0.0, 0.2], [[0] * 5, [0.05, 0, 0, 0, -0.05]])  # 0.25 rad/s: inside limits
    with SimRobot(profile_velocity=0, any_profile=True) as robot:
        run = robot.run(tr, settle=1.0)
        assert robot.data.act[0] == pytest.approx(0.05, abs=1e-12)  # the servo's reference
    np.testing.assert_allclose(run.measured.positions[-1], [0.05, 0, 0, 0, -0.05], atol=5e-3)


def test_the_kit_chooses_egl_before_mujoco_is_imported():
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}
    code = ("import snakekit, os, sys; from snakekit.sim import render; "
            "img = render([0.5, 0, 0, 0, 0], width=64, height=48); "
            "print(os.environ['MUJOCO_GL'], img.shape, 'mujoco' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["egl", "(48,", "64,", "3)", "True"]
