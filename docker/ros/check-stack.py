"""The `ros` profile's stack, checked from inside it (docker/ros/test.sh runs this in the arm's
container, with the kit's Python and Debian's rospy, as a user's node would run there).

A small node sends goals on /arm/command and reads /joint_states and /rosout back:
1. a folding goal (joint 5 onto joint 1): refused in the kit's own words, and nothing moves;
2. the Task 2 sweep, shortened, as a JointTrajectory: the joint states follow the kit's own
   simulator run of it;
3. `rosbag play` of a .bag written by the kit's Run.save: its /joint_states are published, as
   the run recorded them;
4. a last goal leaves the arm in a pose other than home, for the second screenshot.
Prints one line per result, starting "ros-check:"; exits 1 (with the reason) on the first failure.

    python check-stack.py WORK_FOLDER HANG_SECONDS
"""

import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import snakekit
from snakekit.errors import CollisionError
from snakekit.ros import COMMAND, JOINT_STATES, NODE, goal_trajectory, import_ros
from snakekit.sim import SimRobot

WORK, HANG = Path(sys.argv[1]), float(sys.argv[2])
NAMES = [f"joint{i + 1}" for i in range(5)]
SWEEP = snakekit.side_sweep(points=40, rate=10.0, sweeps=3, amplitude=0.2)  # 3.9 s, every joint swings
FOLD = ([4.0], [[1.57, 1.57, 1.57, 1.57, 0.0]])  # joint 5 onto joint 1
POSE = ([4.0], [[0.8, -0.6, 0.6, 0.4, 0.0]])  # 0.2 rad/s at most: a pose RViz shows unlike home
TOLERANCE = 1e-6  # [rad]; why: at the sweep's comparison

rosgraph, rospy, sensor_msgs, trajectory_msgs = import_ros()
from rosgraph_msgs.msg import Log  # noqa: E402  (Debian's, on the path import_ros appended)


def say(line: str) -> None:
    print(f"ros-check: {line}", flush=True)


def fail(why: str) -> None:
    sys.exit(f"ros-check: FAILED: {why}")


def wait(what: str, ready) -> None:
    end = time.monotonic() + HANG
    while not ready():
        if time.monotonic() > end:
            fail(f"no {what} within {HANG:g} s")
        time.sleep(0.01)


def as_sent(times) -> list[float]:
    """Times as ROS carries them: whole nanoseconds, truncated (rospy.Duration.from_sec)."""
    return [int(t) + int((t - int(t)) * 1e9) / 1e9 for t in times]


states, players, logs = [], [], []


def on_state(m) -> None:
    caller = m._connection_header["callerid"]
    (states if caller == f"/{NODE}" else players).append((caller, list(m.position), list(m.name)))


rospy.init_node("stack_check", disable_signals=True)
rospy.Subscriber(JOINT_STATES, sensor_msgs.JointState, on_state, queue_size=None)
log_sub = rospy.Subscriber("/rosout", Log, lambda m: logs.append((m.name, m.level, m.msg)), queue_size=None)
goals = rospy.Publisher(COMMAND, trajectory_msgs.JointTrajectory, queue_size=10)
wait("joint states from the arm", lambda: states)
wait("subscriber of goals", goals.get_num_connections)
wait("/rosout from the node", lambda: any(c.callerid_pub == f"/{NODE}" for c in log_sub.impl.connections))


def words() -> list[tuple[int, str]]:
    return [(level, msg) for name, level, msg in logs if name == f"/{NODE}" and msg.startswith("goal ")]


def send(times, positions) -> tuple[int, str, int]:
    """Send one goal; wait for the node's word about it. (level, words, index of the first state after sending)"""
    said, first = len(words()), len(states)
    goals.publish(trajectory_msgs.JointTrajectory(joint_names=NAMES, points=[
        trajectory_msgs.JointTrajectoryPoint(positions=p, time_from_start=rospy.Duration.from_sec(t))
        for t, p in zip(times, positions)]))
    wait("word on /rosout about the goal", lambda: len(words()) > said)
    return (*words()[said], first)


# 1. the folding goal: refused in the kit's words (an error on /rosout), nothing moves
level, msg, first = send(*FOLD)
with SimRobot() as robot:
    try:
        robot.run(goal_trajectory(NAMES, *FOLD, robot.read().positions))
        fail("the kit ran the folding goal: no refusal to compare with")
    except CollisionError as e:
        expected = f"goal refused: {e}"
if (level, msg) != (8, expected):  # 8: rosgraph_msgs/Log.ERROR
    fail(f"the folding goal: /rosout said {msg!r} (level {level}), expected {expected!r} (an error)")
n = len(states)
wait("joint states after the refusal", lambda: len(states) > n + 25)
held = np.abs([p for _, p, _ in states]).max()
if held > 0:
    fail(f"a refused goal moved the arm: {held:.3g} rad from home")
say(f"the folding goal is refused on /rosout ({msg}); the arm stays at home "
    f"({len(states)} joint states, all 0 rad)")

# 2. the sweep: the joint states follow the kit's own simulator run of it
level, msg, first = send(SWEEP.times.tolist(), SWEEP.positions.tolist())
n = len(states)
wait("joint states after the sweep", lambda: len(states) > n + 25)
trajectory = goal_trajectory(NAMES, as_sent(SWEEP.times), SWEEP.positions, np.zeros(5))
with SimRobot() as robot:  # the run as the node makes it, recorded at its 50 Hz, on past the end
    reference = robot.run(trajectory, record_rate=50.0, settle=3.0)
with SimRobot() as robot:
    expected = f"goal done: {len(SWEEP)} points, {robot.run(trajectory, record_rate=50.0).robot_time:.2f} s"
if msg != expected and not msg.startswith(expected + " ("):   # the node may say why after the time
    fail(f"the sweep: /rosout said {msg!r}, expected {expected!r}")
if any(names != NAMES for _, _, names in states):
    fail("joint states name other joints than joint1..joint5")
received = np.array([p for _, p, _ in states[first:]])
# The node's simulator and the fresh one here step the same model with the same controls from the
# same rest at home; only the solver's warm start can differ (the node's run is paced, this one a
# rollout), which left 1.4e-15 rad on the host (tests/kit/test_ros_node.py). 1e-6 rad is far
# above that and far below what the arm moves between two samples (up to 0.02 rad).
ref = reference.measured.positions
distance = np.linalg.norm(received[:, None, :] - ref[None, :, :], axis=2).min(axis=1)
if distance.max() >= TOLERANCE:
    fail(f"the sweep: a joint state is {distance.max():.3g} rad from the kit's own run (tolerance {TOLERANCE:g})")
swing = received[:, 0].max()
if abs(swing - ref[:, 0].max()) > TOLERANCE or swing < 0.15:
    fail(f"the sweep: joint 1 swung to {swing:.4f} rad, the kit's run to {ref[:, 0].max():.4f} rad")
say(f"the sweep ({len(SWEEP)} points, {SWEEP.duration:.1f} s) moved the arm: {len(received)} joint states, joint 1 "
    f"up to {swing:.4f} rad, each within {distance.max():.2g} rad of the kit's own simulator run "
    f"(tolerance {TOLERANCE:g} rad); {msg}")

# 3. rosbag play of a kit .bag: its /joint_states are published as the run recorded them
with SimRobot() as robot:
    run = robot.run(snakekit.side_sweep(points=30, rate=10.0, sweeps=2, amplitude=0.2))
bag = run.save(WORK / "sweep.bag")
played = subprocess.run(["rosbag", "play", "--delay", "2", str(bag)], capture_output=True, text=True,
                        timeout=HANG)
if played.returncode:
    fail(f"rosbag play {bag} failed: {played.stderr[-500:]}")
# The bag's times are the robot's clock from 1 s after the epoch (snakekit.bags.ORIGIN_NS): Debian's
# rosbag loads no message stamped 0 ("Index entry ... contains invalid time"), and plays every one
# of these, the run's first sample (t = 0 s) included.
recorded = run.measured.positions
end = time.monotonic() + HANG
while len(players) < len(recorded) and time.monotonic() < end:
    time.sleep(0.01)
time.sleep(1.0)  # none more comes
got = np.array([p for _, p, _ in players])
if got.shape != recorded.shape or not np.array_equal(got, recorded):
    fail(f"rosbag play: {len(got)} joint states received; the run recorded {len(recorded)}, "
         f"and they {'differ' if got.shape == recorded.shape else 'are not as many'}")
say(f"rosbag play of {bag.name} (written by Run.save) published its joint states: {len(got)} received, equal to "
    f"the run's measured positions (float64, exactly), its first sample at t = 0 s included, from {players[0][0]}")

# 4. a pose other than home, held for the second screenshot
level, msg, first = send(*POSE)
if not msg.startswith("goal done"):
    fail(f"the pose for the screenshot: {msg}")
say(f"the arm holds {POSE[1][0]} rad: {msg}")
