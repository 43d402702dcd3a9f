"""``snakekit ros``: the arm as a ROS 1 node, on a real ``roscore`` (Debian's ROS 1) on a free
port. A small rospy client in the system's Python sends goals on ``/arm/command`` and reads
``/joint_states`` and ``/rosout`` back: the Task 2 sweep (shortened) is run and the joint states
follow the kit's own simulator run of it; an over-limit goal and a folding goal are refused in
the kit's words and nothing moves; SIGTERM stops the node, closing the robot.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import snakekit
from snakekit.ros import StateStamps, goal_trajectory
from snakekit.sim import SimRobot
from tests.conftest import need_program

HANG = 120  # [s] a bound for a hang on a busy machine (a quiet one needs a few seconds for each wait)
NAMES = [f"joint{i + 1}" for i in range(5)]
SWEEP = snakekit.side_sweep(points=40, rate=10.0, sweeps=3, amplitude=0.2)  # 3.9 s, every joint swings
# The sweep as the node gets it: ROS carries times in whole nanoseconds (rospy.Duration.from_sec
# truncates), which moves the 50 Hz record grid's last row (4.4 s is 4.39999... s).
AS_SENT = goal_trajectory(NAMES, [int(t) + int((t - int(t)) * 1e9) / 1e9 for t in SWEEP.times], SWEEP.positions,
                          np.zeros(5))
OVER_LIMIT = {"times": [3.0], "positions": [[2.0, 0.0, 0.0, 0.0, 0.0]]}
FOLD = {"times": [4.0], "positions": [[1.57, 1.57, 1.57, 1.57, 0.0]]}  # joint 5 onto joint 1

# Sends each goal of a plan in turn and waits for the node's word on /rosout about it; keeps
# every /joint_states message, and the index of the first one received after each goal left.
CLIENT = r"""
import json, sys, time
import rospy
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

plan = json.load(open(sys.argv[1]))
states, logs = [], []
rospy.init_node("sweep_client", disable_signals=True)
state_sub = rospy.Subscriber("/joint_states", JointState,
                             lambda m: states.append([list(m.position), list(m.name), m.header.stamp.to_nsec()]))
log_sub = rospy.Subscriber("/rosout", Log, lambda m: logs.append((m.name, m.level, m.msg)))
pub = rospy.Publisher("/arm/command", JointTrajectory, queue_size=10)

def wait(what, ready):
    end = time.monotonic() + plan["hang"]
    while not ready():
        if time.monotonic() > end:
            sys.exit(f"client: no {what} within {plan['hang']} s")
        time.sleep(0.01)

def from_node(sub):
    return any(c.callerid_pub == "/snakekit_arm" for c in sub.impl.connections)

wait("joint states", lambda: states)
wait("subscriber of goals", lambda: pub.get_num_connections())
wait("/rosout from the node", lambda: from_node(log_sub))
sent = []
for goal in plan["goals"]:
    said = len([m for m in logs if m[0] == "/snakekit_arm" and m[2].startswith("goal ")])
    sent.append(len(states))
    pub.publish(JointTrajectory(joint_names=plan["names"], points=[
        JointTrajectoryPoint(positions=p, time_from_start=rospy.Duration.from_sec(t))
        for t, p in zip(goal["times"], goal["positions"])]))
    wait("word on /rosout about goal %d" % len(sent),
         lambda: len([m for m in logs if m[0] == "/snakekit_arm" and m[2].startswith("goal ")]) > said)
n = len(states)
wait("joint states after the last goal", lambda: len(states) > n + 10)
json.dump({"states": states, "logs": logs, "sent": sent}, open(sys.argv[2], "w"))
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(process: subprocess.Popen) -> None:
    """Stop a process group we started: SIGINT (roscore's way out), then SIGKILL."""
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGINT)
        try:
            process.wait(HANG)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    """A roscore on a free port, and the environment that points ROS clients to it."""
    roscore = need_program("roscore")
    need_program("rostopic")
    home = tmp_path_factory.mktemp("ros")
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOSTNAME="127.0.0.1",
               ROS_HOME=str(home), ROS_LOG_DIR=str(home / "log"))
    core = subprocess.Popen([roscore, "-p", str(port)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.STDOUT, start_new_session=True)
    try:
        end = time.monotonic() + HANG
        while subprocess.run(["/usr/bin/python3", "-c", "import rosgraph, sys; sys.exit(not rosgraph.is_master_online())"],
                             env=env).returncode:
            assert core.poll() is None and time.monotonic() < end, "roscore did not start"
            time.sleep(0.2)
        yield env, home
    finally:
        stop(core)


@pytest.fixture(scope="module")
def session(ros_env):
    """The node on the simulator, the client's plan run against it, then SIGTERM to the node."""
    env, home = ros_env
    plan = {"names": NAMES, "hang": HANG, "goals": [
        OVER_LIMIT, FOLD, {"times": SWEEP.times.tolist(), "positions": SWEEP.positions.tolist()}]}
    (home / "plan.json").write_text(json.dumps(plan))
    (home / "client.py").write_text(CLIENT)
    node = subprocess.Popen([sys.executable, "-m", "snakekit.cli", "ros"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    client = subprocess.Popen(["/usr/bin/python3", str(home / "client.py"), str(home / "plan.json"),
                               str(home / "seen.json")], env=env, stderr=subprocess.PIPE, text=True,
                              start_new_session=True)
    try:
        while client.poll() is None and node.poll() is None:  # a node that stops early fails at once
            time.sleep(0.1)
        node.send_signal(signal.SIGTERM)
        out, err = node.communicate(timeout=HANG)
        stop(client)  # when the node stopped first, the client would wait for it in vain
        assert client.returncode == 0, client.stderr.read()[-2000:] + "\nthe node said:\n" + err[-2000:]
    finally:
        stop(client)
        stop(node)
    seen = json.loads((home / "seen.json").read_text())
    return seen, node.returncode, out, err


def refusal(goal, error) -> str:
    """What the kit itself says (raising ``error``) about ``goal`` sent to an arm at home: the
    node's words must be these."""
    with SimRobot() as robot:
        trajectory = goal_trajectory(NAMES, goal["times"], goal["positions"], robot.read().positions)
        with pytest.raises(error) as e:
            robot.run(trajectory)
    return f"goal refused: {e.value}"


def node_words(seen) -> list[str]:
    return [msg for name, level, msg in seen["logs"] if name == "/snakekit_arm" and msg.startswith("goal ")]


def test_refused_goals_say_why_in_the_kits_words(session):
    seen, *_ = session
    words = node_words(seen)
    assert words[:2] == [refusal(OVER_LIMIT, snakekit.errors.LimitError), refusal(FOLD, snakekit.errors.CollisionError)]
    assert "position +2.0000 rad (limit +1.5700)" in words[0]
    errors = {msg for name, level, msg in seen["logs"] if level == 8}  # rosgraph_msgs/Log.ERROR
    assert set(words[:2]) <= errors


def test_refused_goals_move_nothing(session):
    seen, *_ = session
    before_sweep = np.array([p for p, *_ in seen["states"][:seen["sent"][2]]])
    assert len(before_sweep) > seen["sent"][1] > 0  # states were published while the refusals came in
    # the arm rests at home from the start; refused goals leave it there to the last bit
    assert np.abs(before_sweep).max() < 1e-9


def test_joint_states_follow_the_sweep_as_the_kit_runs_it(session):
    seen, *_ = session
    with SimRobot() as robot:  # the run as the node makes it: recorded at 50 Hz, settling 0.5 s
        took = robot.run(AS_SENT, record_rate=50.0).robot_time
    assert node_words(seen)[2] == (f"goal done: {len(SWEEP)} points, {took:.2f} s (the last goal at {AS_SENT.times[-1]:.2f} "
                                   f"s, then {took - AS_SENT.times[-1]:.2f} s to settle)")
    assert all(names == NAMES for _, names, _ in seen["states"])
    received = np.array([p for p, *_ in seen["states"][seen["sent"][2]:]])
    # The kit's own run of the same sweep on a fresh simulator, recorded at the node's rate and
    # on past the run (the node goes on holding the last goal, as the run's settling does).
    with SimRobot() as robot:
        reference = robot.run(AS_SENT, record_rate=50.0, settle=3.0).measured.positions
    # Both step the same model with the same controls from the same rest at home; only the
    # solver's warm start differs (the node's run is paced, the reference one rollout), which
    # left 1.4e-15 rad (measured). 1e-6 rad is far above that and far below what the arm moves between
    # two samples (up to 0.2 rad * 2 pi / 1.3 s * 0.02 s = 0.02 rad).
    distance = np.linalg.norm(received[:, None, :] - reference[None, :, :], axis=2)
    assert distance.min(axis=1).max() < 1e-6
    rows, row = [], 0  # each state matched to the first reference row from the last one's on: in order
    for d in distance:
        later = np.flatnonzero(d[row:] < 1e-6)
        assert len(later), f"the state after reference row {row} is none of the rows that follow"
        row += int(later[0])
        rows.append(row)
    run_rows = int(round(AS_SENT.duration * 50))
    assert len(set(rows) & set(range(run_rows))) > 0.8 * run_rows  # followed, not jumped to the end
    swing = reference[:, 0]
    assert received[:, 0].max() == pytest.approx(swing.max(), abs=1e-6) and swing.max() > 0.15


def test_a_goals_joint_states_are_stamped_when_the_arm_was_there_not_when_sent(session):
    """While the sweep runs, each stamp is the wall clock at the goal's first state plus the robot's time since: the
    stamps of the run step by the record period (20 ms at 50 Hz) to the nanosecond, however late a busy host
    sent each message; the states before and after are stamped by the wall clock as they go out (never before the
    goal's last: test_stamps_keep_a_goals_clock_and_never_go_back_whatever_the_host_stalls)."""
    seen, *_ = session
    stamps = np.array([ns for *_, ns in seen["states"][seen["sent"][2]:]], dtype=np.int64)
    on_the_robots_clock = np.abs(np.diff(stamps) - 20_000_000) <= 2       # Duration.from_sec cuts to the ns
    longest = max(len(r) for r in "".join("1" if k else "0" for k in on_the_robots_clock).split("0"))
    assert longest >= int(round(AS_SENT.duration * 50)), (longest, np.diff(stamps)[:50].tolist())
    assert (np.diff(stamps) > 0).all()                                # and never back in time


def node_states(rng, wall0):
    """One generated life of the node: idle spells and goals in turn, a state every 20 ms of robot time, the wall
    clock as the node's paced robot keeps it: the robot's time plus a lag that a stall grows (0 to 300 ms, anywhere,
    a goal's first state among them) and a goal's pace then works off (idle, the robot waits out each period of its
    own). (robot time [s], wall [ns], running, spell, lag [ns]) per state."""
    t, lag, wall, states = float(rng.uniform(0, 100)), 0, wall0, []
    for spell in range(int(rng.integers(1, 8))):
        running = bool(spell % 2) if rng.random() < 0.8 else bool(rng.integers(2))  # now and then goals in a row
        for k in range(int(rng.integers(1, 60))):
            t += 0.02
            if rng.random() < 0.15 or (running and k == 0 and rng.random() < 0.5):
                lag += int(rng.integers(1, 300_000_000))               # a stall
            elif running:
                lag = max(0, lag - int(rng.integers(0, 40_000_000)))  # a goal's paced robot catches up (idle, not)
            wall = max(wall, wall0 + round(t * 1e9) + lag)              # the wall clock never goes back
            states.append((t, wall, running, spell, lag))
    return states


def test_stamps_keep_a_goals_clock_and_never_go_back_whatever_the_host_stalls():
    """Over 2,000 generated lives of the node (node_states), the stamps StateStamps gives: strictly increasing
    and never closer than the robot's time between two states; each goal's stamps its first one plus the robot's
    time, to the nanosecond; a state outside a goal stamped by the wall clock when that allows it; and no stamp
    ahead of the wall clock by more than the wall's largest lag behind the robot's pace. The rule before (the wall
    clock outside a goal) broke the first in half of them (994): a goal whose first state came late ran its clock
    ahead of the wall's, and the home pose after it was stamped within the goal (a live recording of lesson 8 then
    differed from the reference run by 2.6e-4 rad)."""
    rng, wall0, before_broke = np.random.default_rng(20261130), 1_700_000_000_000_000_000, 0
    for life in range(2000):
        states = node_states(rng, wall0)
        wall = iter([w for _, w, *_ in states])
        clock = StateStamps(lambda: next(wall))
        stamps, running, spell = [], None, None
        for t, _, run, sp, _ in states:
            if (run, sp) != (running, spell):
                clock.running, running, spell = run, run, sp
            stamps.append(clock(t))
        stamps = np.array(stamps, dtype=np.int64)
        t = np.array([s[0] for s in states])
        walls = np.array([s[1] for s in states], dtype=np.int64)
        where = f"life {life}: {[(round(a, 2), w - wall0, r) for a, w, r, *_ in states[:8]]}..."
        steps = np.diff(stamps)
        assert (steps > 0).all() and (steps >= np.round(np.diff(t) * 1e9) - 1).all(), where
        for sp in {s[3] for s in states if s[2]}:                       # each goal on the robot's clock
            rows = [i for i, s in enumerate(states) if s[2] and s[3] == sp]
            assert np.abs(stamps[rows] - stamps[rows[0]] - np.round((t[rows] - t[rows[0]]) * 1e9)).max() <= 1, where
        for i in (i for i, s in enumerate(states) if not s[2]):         # outside goals, the wall clock if it can
            floor = stamps[i - 1] + max(1, round((t[i] - t[i - 1]) * 1e9)) if i else walls[i]
            assert stamps[i] == max(walls[i], floor), (i, where)
        assert (stamps - walls).max() <= max(s[4] for s in states), where   # ahead by no more than a stall
        before = [w if not r else None for _, w, r, *_ in states]       # the old rule, for the figure above
        origin = {}
        for i, (a, w, r, sp, _) in enumerate(states):
            if r:
                o = origin.setdefault(sp, (w, a))
                before[i] = o[0] + round((a - o[1]) * 1e9)
        before_broke += bool((np.diff(before) <= 0).any())
    assert 0.3 < before_broke / 2000 < 0.7, before_broke    # the generated lives do reach the case


class _Clock:
    """A monotonic clock the test moves: what the node's idle loop reads and waits by."""

    def __init__(self):
        self.now = 1000.0

    def monotonic(self):
        return self.now


class _PacedSim:
    """A simulator as the idle loop meets it: a step of ``d`` s advances the robot by ``d`` rounded up to its 2 ms
    time step; in real time (``realtime``) it takes that long on the clock, paced from the call."""

    backend, realtime = "sim", True

    def __init__(self, clock):
        self.clock, self.time = clock, 0.0

    def step(self, d):
        d = np.ceil(d / 0.002 - 1e-6) * 0.002
        self.time += d
        if self.realtime:
            self.clock.now += d


@pytest.mark.parametrize("work_ms", [0.0, 1.1, 7.0])
def test_idle_states_go_out_at_the_rate_asked_however_long_each_publish_takes(monkeypatch, work_ms):
    """Between two idle states the node reads and publishes (``work_ms`` of the clock each time: a walk-through saw
    47.3 Hz where 50 were asked, 1.1 ms a state). The idle loop (snakekit.ros._idle) keeps the ticks: a state every
    20 ms of the clock and of the robot's time, before and after a stall of 0.5 s, which is not caught up with a
    burst (one state goes out at once after it, the next at its tick). The robot is left paced as it was."""
    from snakekit import ros

    clock = _Clock()
    monkeypatch.setattr(ros.time, "monotonic", clock.monotonic)
    monkeypatch.setattr(ros.time, "sleep", lambda d: setattr(clock, "now", clock.now + max(0.0, d)))
    robot, period = _PacedSim(clock), 0.02
    tick, seen = clock.now, []
    for k in range(500):
        tick = ros._idle(robot, period, tick)
        seen.append((clock.now, robot.time))    # a state goes out
        clock.now += work_ms / 1000              # robot.read() and the publish
        if k == 249:
            clock.now += 0.5                     # a stall of the host
    wall, robot_time = np.array(seen).T
    for a, b in ((0, 249), (252, 499)):          # before the stall, and after it: a state every 20 ms
        assert abs((wall[b] - wall[a]) - (b - a) * period) <= 0.002, (a, b, wall[b] - wall[a])
        assert abs((robot_time[b] - robot_time[a]) - (b - a) * period) <= 0.002, (a, b, robot_time[b] - robot_time[a])
    assert robot_time[250] - robot_time[249] <= period + 0.002    # the stall is not simulated in a burst
    assert (np.diff(robot_time) >= 0).all() and (np.diff(wall) >= 0).all() and robot.realtime   # as it was


def test_sigterm_stops_the_node_closing_the_robot(session):
    _, returncode, out, err = session
    assert "goals (trajectory_msgs/JointTrajectory) on /arm/command" in out
    assert returncode == 143
    assert err.strip().splitlines()[-1] == "snakekit ros: terminated (SIGTERM); the robot was closed"


def test_without_a_master_it_says_how_to_start_one(tmp_path):
    need_program("roscore")
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{free_port()}", ROS_HOME=str(tmp_path))
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "ros"], env=env, capture_output=True, text=True,
                       timeout=HANG)
    assert r.returncode == 1 and r.stderr == (
        f"snakekit ros: no ROS master answers at {env['ROS_MASTER_URI']} (ROS_MASTER_URI): start one with roscore "
        "(roscore -p PORT for another port), or set ROS_MASTER_URI to the one that runs\n")


def compose_config(*args: str, cwd) -> dict:
    """What compose v2 makes of the files (``config``: no engine needed), as JSON."""
    compose = Path(sys.executable).parent / "docker-compose"
    if not compose.exists():
        compose = Path(need_program("docker-compose"))
    env = {k: v for k, v in os.environ.items() if not k.startswith(("COMPOSE_", "SNAKEKIT_"))}   # the defaults
    r = subprocess.run([str(compose), *args, "config", "--format", "json"], cwd=cwd, capture_output=True, text=True,
                       timeout=HANG, env=env)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_the_ros_profile_starts_from_the_repository_root_as_from_docker_compose_yaml():
    """``docker compose --profile ros up`` typed at the repository root (the issue's command, docs/ros.md)
    finds the services, with their build context and course folder where ``-f docker/compose.yaml`` puts them."""
    root = Path(__file__).resolve().parents[2]
    from_root = compose_config("--profile", "ros", cwd=root)
    named = compose_config("-f", "docker/compose.yaml", "--profile", "ros", cwd=root)
    assert from_root["name"] == named["name"] == "snakekit"
    assert sorted(from_root["services"]) == ["arm", "lab", "roscore", "rviz", "state-publisher"]
    assert from_root["services"] == named["services"]
    assert {s["build"]["context"] for s in from_root["services"].values()} == {str(root)}
    grader = compose_config("--profile", "grader", cwd=root)["services"]["grader"]
    assert {v["source"] for v in grader["volumes"]} == {str(root / "course" / d)
                                                       for d in ("submitted", "gradebook", "autograded", "feedback")}
