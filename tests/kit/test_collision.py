"""Self-collision: the links' distances, the path check, and every backend refusing a fold."""

import time

import numpy as np
import pytest

from tests.conftest import need

need("pinocchio")
need("mujoco")

import mujoco  # noqa: E402

import snakekit  # noqa: E402
from snakekit import CollisionError, collision  # noqa: E402
from snakekit.model import SPEC, body_names  # noqa: E402
from snakekit.sim import SimRobot, load_model  # noqa: E402

FOLD = [1.57, 1.57, 1.57, 1.57, 0.0]  # the issue's fold: joint 5 on joint 1
# Two goals, each with the links at least 8 mm apart, whose straight path between them
# (joint 5 swinging the tool over the base) brings link 5 onto the base.
SAFE_A = np.array([0.0, 0.5, 1.5, 1.5, -1.0])
SAFE_B = np.array([0.0, 0.5, 1.5, 1.5, 1.5])
GOAL_POSITION = 116  # Goal Position register of the MX-28 (Protocol 2.0), 4 bytes


# --- distances against an independent computation ---------------------------------------

def test_straight_arm_closest_pair_is_the_base_plate_and_link2():
    # Base plate: 90 mm long, centred 20 mm behind joint 1, so it ends 25 mm in front of it;
    # link 2's bracket starts on joint 2's axis, 71 mm out.
    c = collision.clearance(np.zeros(5))
    assert c.links == ("base_link", "link2")
    assert c.distance == pytest.approx(SPEC.link_length - (0.09 / 2 - 0.02), abs=1e-9)


def test_u_turn_distances_match_hand_computation():
    # Joints 2 and 3 at 90 deg: link 3 comes back above link 1, one pitch away, parallel.
    q = [0, np.pi / 2, np.pi / 2, 0, 0]
    d = collision.pair_distances(q)
    half_servo_width = SPEC.servo.size[1] / 2
    # link 1's servo and link 3's servo face each other across one pitch
    assert d[("link1", "link3")] == pytest.approx(SPEC.link_length - 2 * half_servo_width, abs=1e-9)
    # the base plate (70 mm wide) under link 3's servo
    assert d[("base_link", "link3")] == pytest.approx(SPEC.link_length - half_servo_width - 0.07 / 2, abs=1e-9)
    assert collision.clearance(q).links == ("base_link", "link3")


def test_distances_agree_with_mujocos_own_collision_of_the_same_hulls():
    m, rng = load_model(), np.random.default_rng(3)
    d = mujoco.MjData(m)
    names = body_names()
    geom = {n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{n}_collision") for n in names}
    compared = 0
    for q in rng.uniform(-1.57, 1.57, (30, 5)):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        for (a, b), ours in collision.pair_distances(q).items():
            if ours <= 0:  # overlap depths are measured differently; distances are not
                continue
            theirs = mujoco.mj_geomDistance(m, d, geom[a], geom[b], 1.0, None)
            assert ours == pytest.approx(theirs, abs=1e-6), (q, a, b)
            compared += 1
    assert compared > 250


def test_the_issues_fold_overlaps_the_base():
    c = collision.clearance(FOLD)
    assert c.distance < -0.02 and c.links[0] == "base_link"
    assert collision.collides(FOLD) and not collision.collides(np.zeros(5))


# --- the path check ------------------------------------------------------------------------

def test_goals_each_safe_but_the_path_between_them_is_not():
    assert collision.clearance(SAFE_A).distance > 0.008 and collision.clearance(SAFE_B).distance > 0.008
    hit = collision.first_collision([0.0, 2.0], [SAFE_A, SAFE_B])
    assert hit is not None and 0 < hit.time < 2.0
    assert hit.links == ("base_link", "link5")
    # the reported pose is on the straight path, at the reported time, and really that close
    assert hit.q == pytest.approx(SAFE_A + hit.time / 2.0 * (SAFE_B - SAFE_A))
    assert hit.distance < SPEC.collision_margin
    # fine sampling finds the same first crossing (within one sample)
    s = np.linspace(0, 1, 2001)
    close = [collision.clearance(SAFE_A + x * (SAFE_B - SAFE_A)).distance < SPEC.collision_margin for x in s]
    assert hit.time / 2.0 == pytest.approx(s[int(np.argmax(close))], abs=1e-3)


def test_task2_sweep_and_home_moves_pass_the_check():
    sweep = snakekit.side_sweep()
    assert collision.first_collision(sweep.times, sweep.positions) is None
    move = snakekit.joint_trajectory(np.zeros(5), [0.5, -0.3, 0.2, 0, 0], 1.0)
    assert collision.first_collision(move.times, move.positions) is None


def test_no_sampled_pose_of_an_accepted_path_is_closer_than_the_margin():
    rng = np.random.default_rng(7)
    accepted = 0
    for _ in range(60):
        a, b = rng.uniform(-1.57, 1.57, (2, 5))
        if collision.first_collision([0, 1], [a, b]) is None:
            accepted += 1
            d = [collision.clearance(a + s * (b - a)).distance for s in np.linspace(0, 1, 101)]
            assert min(d) >= SPEC.collision_margin - 1e-9
    assert accepted > 20


# --- every backend refuses, before anything moves ----------------------------------------------

def test_sim_refuses_a_folding_command_and_sends_nothing():
    with SimRobot() as robot:
        with pytest.raises(CollisionError) as e:
            robot.command(FOLD)
        msg = str(e.value)
        assert "the command would fold the arm onto itself" in msg
        assert "base_link and link4 come closer than the 5 mm margin" in msg
        assert "s after the goal is sent, on the way the servos take" in msg and "Nothing was sent" in msg
        assert 0 < e.value.time and f"{e.value.time:.2f} s after the goal is sent" in msg
        assert e.value.links == ("base_link", "link4") and e.value.distance < SPEC.collision_margin
        robot.step(1.0)
        assert np.abs(robot.read().positions).max() < 1e-3 and robot.last_goal is None


def test_sim_refuses_a_trajectory_whose_path_folds_and_names_time_links_distance():
    with SimRobot(q0=SAFE_A) as robot:
        tr = snakekit.Trajectory([0.0, 2.0], [SAFE_A, SAFE_B])
        with pytest.raises(CollisionError) as e:
            robot.run(tr)
        err = e.value
        # the second goal is sent at t = 2 s; the servos swing joint 5 over the base after it
        assert 2.0 < err.time < 4.0 and err.links == ("base_link", "link5")
        assert (f"at t = {err.time:.3f} s on the way the servos take between the goals (each joint at its "
                "profile's speed), base_link and link5 come closer than the 5 mm margin") in str(err)
        assert robot.read().positions == pytest.approx(SAFE_A, abs=1e-3)
        # the same goal as a command: its path from the last goal (the start) is refused too
        with pytest.raises(CollisionError, match="base_link and link5"):
            robot.command(SAFE_B)


def test_sim_runs_task2_and_goes_home():
    with SimRobot() as robot:
        sweep = snakekit.side_sweep()
        run = robot.run(sweep)
        assert run.limits_held() and robot.last_goal == pytest.approx(sweep.positions[-1])
        robot.move_to([0.4, 0.3, -0.2, 0.1, 0])
        robot.home()
        robot.command([0.2, 0.2, 0.2, 0.2, 0.2])


def test_emulator_refuses_a_fold_with_nothing_on_the_bus():
    need("serial")
    with snakekit.make_robot("emulator", q0=SAFE_A) as robot:
        bus = robot.emulator
        before = len(bus.writes(GOAL_POSITION, 4))
        with pytest.raises(CollisionError, match="the command would fold the arm onto itself"):
            robot.command(FOLD)
        with pytest.raises(CollisionError, match=r"the trajectory would fold the arm onto itself: at t = "):
            robot.run(snakekit.Trajectory([0.0, 2.0], [SAFE_A, SAFE_B]))
        assert len(bus.writes(GOAL_POSITION, 4)) == before
        assert robot.goals_sent == 0
        robot.move_to([0.0, 0.5, 1.5, 1.5, -0.9], duration=0.5)  # the driver's run: its last goal is remembered
        assert robot.last_goal == pytest.approx([0.0, 0.5, 1.5, 1.5, -0.9])
        with pytest.raises(CollisionError, match="s after the goal is sent, on the way the servos take"):
            robot.command(SAFE_B)  # safe itself, but the way there from the last goal swings over the base
        before = len(bus.writes(GOAL_POSITION, 4))
        robot.command(SAFE_A)  # a safe goal still goes through (the bus thread records it soon after)
        deadline = time.monotonic() + 10.0  # a bound for a hang
        while len(bus.writes(GOAL_POSITION, 4)) == before and time.monotonic() < deadline:
            time.sleep(0.01)
        assert len(bus.writes(GOAL_POSITION, 4)) == before + 5


def test_sweep_command_checks_its_trajectory_before_making_a_robot(monkeypatch, capsys):
    from snakekit import cli

    made = []
    monkeypatch.setattr("snakekit.robot.make_robot", lambda *a, **k: made.append(a))
    folded = snakekit.Trajectory([0.0, 2.0], [SAFE_A, SAFE_B])
    monkeypatch.setattr("snakekit.trajectory.side_sweep", lambda: folded)
    assert cli.main(["sweep"]) == 1
    assert made == []
    assert "snakekit sweep: the trajectory would fold the arm onto itself" in capsys.readouterr().err


# --- the simulator shows a forced fold ---------------------------------------------------------

def test_the_simulator_computes_contacts_between_non_neighbouring_links_only():
    m = load_model()
    pairs = {tuple(sorted((int(m.geom_bodyid[a]), int(m.geom_bodyid[b])))) for a, b in zip(m.pair_geom1, m.pair_geom2)}
    assert pairs == {(a, b) for a in range(6) for b in range(a + 2, 6)}  # body 0 is the world (the base)
    with SimRobot() as robot:
        robot.set_servo_goals(FOLD)  # the servos' side: no check, as a fold forced on the arm
        robot.step(3.0)
        touching = robot.contacts()
        assert touching and all(int(b[4:]) - (0 if a == "base_link" else int(a[4:])) >= 2 for a, b, _ in touching)
        # the links stop each other: the arm does not reach the folded goal
        assert np.abs(robot.read().positions - FOLD).max() > 0.05


# --- IK and the workspace --------------------------------------------------------------------

def test_ik_never_returns_a_folded_pose_over_1000_random_targets():
    rng = np.random.default_rng(11)
    # tool points of random poses, folded ones included, and points near the base
    targets = [snakekit.tool_pose_2d(q)[:2] for q in rng.uniform(-1.57, 1.57, (800, 5))]
    targets += list(rng.uniform(-0.08, 0.08, (200, 2)))
    solved = refused = 0
    for t in targets:
        try:
            q = snakekit.inverse_kinematics(t)
        except snakekit.UnreachableTargetError:
            refused += 1
            continue
        solved += 1
        assert collision.clearance(q).distance >= SPEC.collision_margin, t
        assert snakekit.tool_pose_2d(q)[:2] == pytest.approx(t, abs=1e-5)
    assert solved > 700 and refused > 0


def test_ik_says_when_a_target_is_reached_only_folded():
    with pytest.raises(snakekit.UnreachableTargetError, match="reached only with the arm folded onto itself"):
        snakekit.inverse_kinematics([0.0, 0.0])


def test_workspace_points_leave_out_folded_poses():
    pts = snakekit.workspace_points(3000)
    # a tool point on the base (90 x 70 mm, from 65 mm behind joint 1 to 25 mm in front) needs a fold
    on_base = (pts[:, 0] > -0.065) & (pts[:, 0] < 0.025) & (np.abs(pts[:, 1]) < 0.035)
    assert not on_base.any()
    rng = np.random.default_rng(0)  # the same draw without the check lands some there
    raw = np.array([snakekit.tool_pose_2d(q)[:2] for q in rng.uniform(-1.57, 1.57, (3000, 5))])
    assert ((raw[:, 0] > -0.065) & (raw[:, 0] < 0.025) & (np.abs(raw[:, 1]) < 0.035)).any()
