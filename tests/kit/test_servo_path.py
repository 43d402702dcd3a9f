"""The self-collision check follows the way the servos really move, not the straight line.

With the firmware's profile every joint moves at the profile's speed and stops at its own
goal, so a joint with less to travel arrives first and the arm leaves the straight line
between two poses in joint space. Two safe poses whose straight path is clear can so fold
the arm on the way. These tests build such pairs on purpose (through a folded pose), mix
them with random pairs of safe poses, and watch the emulated servos over the bus every
10 ms: no pose read back brings two links that are not neighbours closer than the margin.
The clearance of what is read back is computed by MuJoCo's own distance of the links' hulls
(`mj_geomDistance`, placed by MuJoCo's kinematics), not by the kit's check (Pinocchio, coal),
and cross-checked with the links as polygons in the plane (tests/kit/planar_clearance.py).
"""

import time

import numpy as np
import pytest

from tests.conftest import need

need("pinocchio")
mujoco = need("mujoco")
need("dynamixel_sdk")
need("serial")

import snakekit  # noqa: E402
from snakekit import CollisionError, collision  # noqa: E402
from snakekit.model import SPEC, body_names  # noqa: E402
from snakekit.profile_planner import ProfilePlanner, ReferencePath  # noqa: E402
from snakekit.sim import SimRobot, load_model  # noqa: E402
from tests.kit.planar_clearance import planar_clearance  # noqa: E402

MARGIN = SPEC.collision_margin
LIMIT = SPEC.upper


class MujocoClearance:
    """The least distance [m] between non-neighbouring links at ``q``, by MuJoCo."""

    def __init__(self):
        self.model = load_model()
        self.data = mujoco.MjData(self.model)
        names = body_names()
        ids = [mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, f"{n}_collision") for n in names]
        self.pairs = [(ids[a], ids[b]) for a in range(len(ids)) for b in range(a + 2, len(ids))]

    def __call__(self, q) -> float:
        self.data.qpos[:] = q
        mujoco.mj_kinematics(self.model, self.data)
        return min(mujoco.mj_geomDistance(self.model, self.data, a, b, 0.1, None) for a, b in self.pairs)


def _through_a_fold(rng, low=-0.03, high=0.002):
    """Two safe goals whose straight path is clear, built so that the servos' way between
    them (each joint at the same speed, stopping at its own goal) passes a pose F whose
    clearance is between ``low`` and ``high`` [m]: folded by default."""
    while True:
        F = rng.uniform(-LIMIT, LIMIT, 5)
        F[1:4] = rng.choice([-1.0, 1.0]) * rng.uniform(0.6, LIMIT, 3)  # curled: folds are common there
        if not low < collision.clearance(F).distance < high:
            continue
        way = rng.choice([-1.0, 1.0], 5)
        A = F - way * rng.uniform(0.2, 1.2)  # every joint was moving at the same speed into F
        B = F + way * np.where(rng.random(5) < 0.5, 0.0, rng.uniform(0.2, 1.5, 5))  # some stop in F
        if np.abs(A).max() > LIMIT or np.abs(B).max() > LIMIT:
            continue
        if min(collision.clearance(A).distance, collision.clearance(B).distance) < MARGIN + 0.002:
            continue
        if collision.first_collision([0, 1], [A, B]) is None:
            return A, B


def _random_pair(rng):
    while True:
        A, B = rng.uniform(-LIMIT, LIMIT, (2, 5))
        if min(collision.clearance(A).distance, collision.clearance(B).distance) >= MARGIN + 0.002:
            return A, B


@pytest.fixture(scope="module")
def pairs():
    rng = np.random.default_rng(20261128)
    return [("through a fold", *_through_a_fold(rng)) for _ in range(6)] + \
           [("grazing", *_through_a_fold(rng, MARGIN + 0.0003, MARGIN + 0.002)) for _ in range(4)] + \
           [("random", *_random_pair(rng)) for _ in range(4)]


def test_the_straight_check_alone_lets_the_servos_fold_the_arm(pairs):
    """Before: each pair built through a fold passes the straight-line check, yet sent as one
    goal (past every check) the simulated servos overlap two links on the way."""
    clearance = MujocoClearance()
    worst = np.inf
    for kind, A, B in pairs:
        if kind != "through a fold":
            continue
        assert collision.first_collision([0.0, 1.0], [A, B]) is None
        with SimRobot(q0=A) as robot:
            robot._send(B)  # what the kit sent before it followed the servos' way
            closest = np.inf
            for _ in range(300):
                robot.step(0.01)
                closest = min(closest, clearance(robot.read().positions))
        assert closest < MARGIN, (A, B, closest)
        worst = min(worst, closest)
    print(f"the straight check alone: the servos came to {1000 * worst:.2f} mm")


def test_every_robot_refuses_the_servos_way_through_a_fold_and_names_when(pairs):
    for kind, A, B in pairs:
        if kind != "through a fold":
            continue
        with SimRobot(q0=A) as robot:
            with pytest.raises(CollisionError) as e:
                robot.command(B)
            err = e.value
            message = str(err)
            assert f"{err.time:.2f} s after the goal is sent, on the way the servos take" in message
            assert f"{err.links[0]} and {err.links[1]} come closer than the 5 mm margin" in message
            assert "robot.move_to(q) keeps the joints together" in message
            # the refusal is real: the reference at that time is within the margin
            path = ReferencePath.of_goals(ProfilePlanner(A), [0.0], [B])
            assert collision.clearance(path.positions([err.time])[0]).distance < MARGIN + 1e-3
            robot.step(0.5)
            assert robot.read().positions == pytest.approx(A, abs=2e-3)  # nothing moved


def test_the_emulated_servos_never_bring_two_links_within_the_margin(pairs):
    """The property over many pairs, on the emulated bus with the firmware's profile: each
    pair is tried as one command; a refused one goes by robot.move_to, as its message says,
    or stays where it is. The servos are read every 10 ms."""
    clearance = MujocoClearance()
    seen, moved, refused, again = [], 0, 0, []

    def tried(A, B):
        """(refused, the poses read back) of one pair on a new emulated arm."""
        with snakekit.make_robot("emulator", q0=A) as robot:  # the profile, then MuJoCo's servo loop
            try:
                robot.command(B)
            except CollisionError:
                try:  # checked along the servos' way too; its record is the servos read every 10 ms
                    return True, robot.move_to(B, record_rate=100.0).measured.positions
                except CollisionError:
                    return True, None
            poses, still, deadline = [], 0, time.monotonic() + 8.0
            while time.monotonic() < deadline and still < 5:
                poses.append(robot.read().positions)
                still = still + 1 if len(poses) > 1 and np.abs(poses[-1] - poses[-2]).max() < 1e-4 else 0
                time.sleep(0.01)
            return False, poses

    for kind, A, B in pairs:
        try:
            was_refused, poses = tried(A, B)
        except snakekit.CommunicationError as e:
            # the emulated servos' thread, held up by the machine for longer than the driver's 4 tries (the
            # suite's own Docker tests beside it): not the property. The pair is tried once more, from the start
            again.append(str(e)[:80])
            was_refused, poses = tried(A, B)
        refused += was_refused
        if poses is None:
            continue
        moved += 1
        seen += [(clearance(q), planar_clearance(q) if i % 10 == 0 else -np.inf, kind) for i, q in enumerate(poses)]
        assert poses[-1] == pytest.approx(B, abs=5e-3)
    d = np.array([s[0] for s in seen])
    assert moved >= 9 and refused >= 6 and len(seen) > 500
    assert len(again) <= 2, f"the emulated bus failed {len(again)} pairs (a bus that fails this often is a defect): {again}"
    print(f"{len(seen)} poses read back over {moved} moves ({refused} commands refused): "
          f"smallest clearance {1000 * d.min():.2f} mm; of the grazing pairs' moves "
          f"{1000 * min(m for m, _, k in seen if k == 'grazing'):.2f} mm")
    assert d.min() >= MARGIN, d.min()
    # the polygons in the plane never see more room than the hulls in space
    assert all(p <= m + 1e-6 for m, p, _ in seen)


def test_a_goal_leaves_when_its_check_said_however_long_the_check_takes(monkeypatch):
    """On the emulated bus the clock runs while the kit checks: a goal sent when the check ends
    would take a way nobody checked (the servos moved on meanwhile). With every check slowed by
    0.3 s, a goal sent while the arm moves is checked for the time it will leave, and leaves
    then: never before, and far less than a check's time after (a busy machine may still
    hold the program up for a few ms between the check and the packet)."""
    slow = collision.first_collision_on

    def slowed(*args, **kwargs):
        time.sleep(0.3)
        return slow(*args, **kwargs)

    monkeypatch.setattr(collision, "first_collision_on", slowed)
    with snakekit.make_robot("emulator") as robot:
        robot.command([0.6, 0.3, 0.0, 0.0, 0.0])  # from rest: its way is the same whenever it leaves
        for q in ([0.1, -0.3, 0.2, 0.0, 0.1], [-0.4, 0.0, 0.0, 0.3, 0.0]):
            time.sleep(0.05)  # the next goal comes while the arm still moves
            assert robot._profiles().moving(robot._now())
            robot.command(q)
            sent_at = robot._goals_since[-1][0]
            checked_at = robot._checked.checkpoints[0]
            assert checked_at - 1e-9 <= sent_at < checked_at + 0.3, (sent_at, checked_at)
        assert robot._lead >= 0.3  # learnt from the checks


def test_an_arm_already_inside_the_margin_may_move_out_but_not_deeper():
    start = [0.0, 0.5, 1.5, 1.5, 0.5]  # base and link 5 about 4 mm apart: started so, or bent by hand
    clearance = MujocoClearance()
    d0 = collision.clearance(start).distance
    assert 0 < d0 < MARGIN
    with SimRobot(q0=start) as robot:
        with pytest.raises(CollisionError) as e:
            robot.command([0.0, 0.5, 1.5, 1.5, 1.5])  # swings link 5 further over the base
        assert (f"the arm already stands inside the 5 mm margin (base_link and link5 are {1000 * d0:.2f} mm "
                "apart): it may move out, but not bring two links closer than that") in str(e.value)
        robot.step(0.3)
        assert robot.read().positions == pytest.approx(start, abs=2e-3)
        robot.command(np.zeros(5))  # the way out
        closest = np.inf
        for _ in range(250):
            robot.step(0.01)
            closest = min(closest, clearance(robot.read().positions))
        assert closest >= d0 - collision.FOLDED_START_ALLOWANCE
        assert robot.read().positions == pytest.approx(np.zeros(5), abs=2e-3)
    with SimRobot(q0=start) as robot:
        robot.home()  # a run out of it too
        assert robot.read().positions == pytest.approx(np.zeros(5), abs=5e-3)
