"""The arm as a ROS 1 node: ``snakekit ros``.

The node ``/snakekit_arm`` publishes ``/joint_states`` (``sensor_msgs/JointState``: joint1..joint5
as in the URDF, measured positions [rad] and velocities [rad/s]) at a steady rate, sets the
parameter ``/robot_description`` to the kit's URDF (for ``robot_state_publisher``), and takes
``trajectory_msgs/JointTrajectory`` goals on ``/arm/command``. A goal goes through the kit's
own checks (:meth:`snakekit.Robot.run`: joint limits, speed, the start pose, self-collision on
the servos' way) before anything moves; a refused goal moves nothing and the reason goes to
``/rosout`` as an error. A goal whose first point is later than 0 s starts from where the arm
is, as ROS's trajectory controllers do, so one point is a move there.

ROS 1 is Debian's (``python3-rospy``, Noetic era): it is not on PyPI, and it lives in the
system's Python. The node runs in the kit's Python, where the simulator, Pinocchio and the
servo driver are, with Debian's ``dist-packages`` appended to the module path for this command
only: the kit's own packages come first, and only what it lacks (rospy, genpy, the message
modules) comes from Debian. Both are the same CPython (3.11 on Debian 12), so Debian's few
compiled modules load too.

For a notebook (lesson 8), :func:`live_arm` starts a master and the node of its own on a free port and
points the notebook's process at that master, so the student's own node (``rospy.init_node``) joins it
and publishes the goals; :meth:`LiveArm.recording` runs ``rosbag record`` while a block runs, and
:meth:`LiveArm.send` (publish a goal and wait for the node's word) is the kit's own sender, for tests.
:func:`ros_missing` says, in one line, what to use on a machine without Debian's ROS 1.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import queue
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .bags import ros1_bytes
from .errors import BackendError, ConfigurationError, MissingDependencyError, SnakekitError, TrajectoryError
from .model import SPEC, URDF_PATH, SnakeSpec
from .robot import make_robot
from .trajectory import Trajectory

#: Where Debian keeps its Python modules (ROS 1's among them).
DEBIAN_MODULES = "/usr/lib/python3/dist-packages"
#: The Debian packages the node needs, and roscore's.
APT_PACKAGES = "python3-rospy python3-sensor-msgs python3-trajectory-msgs python3-roslaunch python3-rostopic"
NODE, JOINT_STATES, COMMAND = "snakekit_arm", "/joint_states", "/arm/command"

#: The errors of the kit's checks before a goal moves anything (a goal refused).
REFUSALS = (ConfigurationError, TrajectoryError, ValueError, TypeError)


def import_ros():
    """``(rospy, sensor_msgs.msg, trajectory_msgs.msg)``: Debian's ROS 1, appended to the path."""
    if os.path.isdir(DEBIAN_MODULES) and DEBIAN_MODULES not in sys.path:
        sys.path.append(DEBIAN_MODULES)  # last: the kit's own packages win
    try:
        import rosgraph
        import rospy
        from sensor_msgs import msg as sensor_msgs
        from trajectory_msgs import msg as trajectory_msgs
    except ImportError as e:
        raise MissingDependencyError(
            f"snakekit ros needs Debian's ROS 1 ({e}); on Debian 12: sudo apt-get install --no-install-recommends "
            f"{APT_PACKAGES}") from None
    return rosgraph, rospy, sensor_msgs, trajectory_msgs


def goal_trajectory(names, times, positions, present, spec: SnakeSpec = SPEC) -> Trajectory:
    """A :class:`Trajectory` in the arm's joint order from a JointTrajectory's ``joint_names``,
    its points' ``time_from_start`` [s] and ``positions`` [rad]; when the first point is later
    than 0 s, the arm's ``present`` position [rad] is put first, at 0 s.

    >>> goal_trajectory(["joint2", "joint1", "joint3", "joint4", "joint5"], [2.0], [[0.1, 0.2, 0, 0, 0]],
    ...                 np.zeros(5)).positions[-1].tolist()
    [0.2, 0.1, 0.0, 0.0, 0.0]
    """
    names, want = list(names), list(spec.joint_names)
    if sorted(names) != sorted(want):
        raise ConfigurationError(f"the goal's joint_names are {names}; this arm's are {want} (each once, any order)")
    if not len(times):
        raise TrajectoryError("the goal has no points: send at least one, with its time_from_start")
    bad = [i for i, p in enumerate(positions) if len(p) != len(names)]
    if bad:
        raise TrajectoryError(f"point {bad[0]} of the goal has {len(positions[bad[0]])} positions; each point "
                              f"needs one per joint name ({len(names)})")
    order = [names.index(n) for n in want]
    times, positions = np.asarray(times, float), np.asarray(positions, float)[:, order]
    if times[0] > 0:
        times, positions = np.concatenate([[0.0], times]), np.vstack([present, positions])
    return Trajectory(times, positions, n_joints=spec.n_joints)


def serve(backend: str = "sim", *, rate: float = 50.0, topic: str = COMMAND, out=None, **options) -> None:
    """Run the node until Ctrl-C or SIGTERM (the robot is closed on the way out, as its
    :meth:`~snakekit.Robot.close` does: torque off or hold). ``rate``: how often
    ``/joint_states`` is published [Hz]; ``options`` go to :func:`snakekit.make_robot`."""
    out = out or sys.stdout
    rosgraph, rospy, sensor_msgs, trajectory_msgs = import_ros()
    master = rosgraph.get_master_uri()
    if not rosgraph.is_master_online():
        raise ConfigurationError(f"no ROS master answers at {master} (ROS_MASTER_URI): start one with roscore "
                                 "(roscore -p PORT for another port), or set ROS_MASTER_URI to the one that runs")
    if backend == "sim":
        options.setdefault("realtime", True)  # the joint states follow the wall clock
    goals: queue.Queue = queue.Queue()
    with make_robot(backend, **options) as robot:
        rospy.init_node(NODE, disable_signals=True)  # our own SIGINT/SIGTERM: the robot is closed first
        try:
            rospy.set_param("/robot_description", URDF_PATH.read_text())
            states = rospy.Publisher(JOINT_STATES, sensor_msgs.JointState, queue_size=50)  # 1 s of a slow reader
            rospy.Subscriber(topic, trajectory_msgs.JointTrajectory, goals.put, queue_size=10)
            names = list(robot.spec.joint_names)
            stamps = StateStamps(lambda: rospy.Time.now().to_nsec())

            def publish(t, positions, velocities):
                ns = stamps(t)
                states.publish(sensor_msgs.JointState(
                    header=rospy.Header(stamp=rospy.Time(ns // 1_000_000_000, ns % 1_000_000_000)), name=names,
                    position=[float(v) for v in positions], velocity=[float(v) for v in velocities]))

            robot.on_record = publish
            print(f"snakekit ros: the {backend} arm is node /{NODE} at {master}: {JOINT_STATES} at {rate:g} Hz, "
                  f"goals (trajectory_msgs/JointTrajectory) on {topic}; Ctrl-C stops it", file=out, flush=True)
            rospy.loginfo(f"ready: {JOINT_STATES} at {rate:g} Hz, goals on {topic}")
            period, tick = 1.0 / rate, time.monotonic()
            while not rospy.is_shutdown():
                try:
                    goal = goals.get_nowait()
                except queue.Empty:
                    tick = _idle(robot, period, tick)
                    s = robot.read()
                    publish(s.time, s.positions, s.velocities)
                    continue
                stamps.running = True
                try:
                    _run_goal(robot, goal, rate, rospy)
                finally:
                    stamps.running = False
                tick = time.monotonic()
        finally:
            rospy.signal_shutdown("snakekit ros stopped")


class StateStamps:
    """The stamps of ``/joint_states`` [ns of ROS time], one per state, given the robot's time ``t`` [s] of each.

    While a goal runs (:attr:`running`), a state is stamped when the arm was there: the wall clock at the
    goal's first state plus the robot's time since. A busy host that holds the node up delays the message,
    not its stamp (the run keeps its own pace, catching up after a stall). Otherwise a state is stamped by
    the wall clock as it goes out. Never back in time, and never closer to the last stamp than the robot's
    time between the two states: a host stalled as a goal began made that goal's clock run ahead of the
    wall's, and the states just after it would otherwise be stamped before the goal's last ones (a
    recording would then hold the home pose at a time within the goal).

    >>> wall = iter([100_000_000_000, 100_010_000_000, 100_020_000_000])
    >>> stamps = StateStamps(lambda: next(wall))
    >>> stamps.running = True
    >>> stamps(2.0), stamps(2.02)   # the goal's first state, then 20 ms of robot time later
    (100000000000, 100020000000)
    >>> stamps.running = False
    >>> stamps(2.04)                # the wall clock says 100.02 s, as the goal's last stamp: 20 ms after that
    100040000000
    """

    def __init__(self, now_ns):
        self._now = now_ns
        self._running = False
        self._origin = None  # (stamp, robot time) of the running goal's first state
        self._last = None    # (stamp, robot time) of the last state

    @property
    def running(self) -> bool:
        """Whether a goal runs; set at each goal's start and end (a goal's clock starts at its first state)."""
        return self._running

    @running.setter
    def running(self, value: bool) -> None:
        self._running, self._origin = bool(value), None

    def __call__(self, t: float) -> int:
        now = int(self._now())
        if self._last is not None:  # no earlier than the last stamp plus the robot time since (1 ns at least)
            now = max(now, self._last[0] + max(1, round((t - self._last[1]) * 1e9)))
        if not self._running:
            stamp = now
        else:
            if self._origin is None:
                self._origin = (now, t)
            stamp = self._origin[0] + round((t - self._origin[1]) * 1e9)
        self._last = (stamp, t)
        return stamp


def _idle(robot, period: float, tick: float) -> float:
    """Wait one publishing period, to the tick [s, monotonic]; a simulator simulates the period
    first (holding its goals), at once rather than paced by the wall clock: a paced step waits a
    whole period from when it is called, and with the time the node spends on each state the
    states went out a little under the rate asked (47 Hz of 50). The next tick."""
    tick += period
    if robot.backend == "sim":
        paced, robot.realtime = robot.realtime, False
        try:
            robot.step(period)
        finally:
            robot.realtime = paced
    time.sleep(max(0.0, tick - time.monotonic()))
    return max(tick, time.monotonic() - period)  # a stall is not caught up with a burst


def _run_goal(robot, goal, rate: float, rospy) -> None:
    """Run one JointTrajectory goal, or refuse it (nothing moves) and say why on /rosout."""
    try:
        trajectory = goal_trajectory(goal.joint_names, [p.time_from_start.to_sec() for p in goal.points],
                                     [list(p.positions) for p in goal.points], robot.read().positions, robot.spec)
        run = robot.run(trajectory, record_rate=rate)
    except REFUSALS as e:
        if not isinstance(e, SnakekitError):
            raise
        rospy.logerr(f"goal refused: {e}")
        return
    rospy.loginfo(f"goal done: {len(trajectory)} points, {run.robot_time:.2f} s (the last goal at "
                  f"{trajectory.times[-1]:.2f} s, then {run.robot_time - trajectory.times[-1]:.2f} s to settle)")


#: What a machine without Debian's ROS 1 uses for the live parts (one line).
NO_ROS = ("no ROS 1 here (Debian's roscore and python3-rospy): run the live part in compose's ros profile "
          "(docs/ros.md: docker compose -f docker/compose.yaml --profile ros up); the rest runs here")
#: ROS 1 lets a process be one node, on one master: the live arm whose master this process joined, once it has.
_JOINED: list = []


def ros_missing() -> str | None:
    """None where Debian's ROS 1 (``roscore``, ``rosbag``, rospy and the messages) is here; else
    :data:`NO_ROS`, what to use instead."""
    if not (shutil.which("roscore") and shutil.which("rosbag")):
        return NO_ROS
    try:
        import_ros()
    except MissingDependencyError:
        return NO_ROS
    return None


class LiveArm:
    """The arm's node (``snakekit ros``) on a ``roscore`` of its own (:func:`live_arm` starts them): a
    notebook's own node (``rospy.init_node``) sends it goals on :data:`COMMAND` and hears its
    ``/joint_states``; :meth:`recording` runs ``rosbag record``, :meth:`stop` stops both."""

    def __init__(self, master: str, env: dict, hang: float, started: list[subprocess.Popen]):
        self.master, self.env, self.hang, self._started = master, env, hang, started
        self._node, self._goals, self._words = started[1], None, []
        self._wait("the arm's node on the master", lambda: "/" + NODE in self._publishers(JOINT_STATES)
                   and "/" + NODE in self._subscribers(COMMAND))

    def __enter__(self) -> LiveArm:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        """Whether the master and the arm's node still run."""
        return bool(self._started) and all(p.poll() is None for p in self._started)

    def stop(self) -> None:
        """Stop the arm's node (it closes the robot on SIGTERM) and the master; this process's ROS node, if it
        joined, leaves with them (ROS 1 lets a process join one master: restart the kernel to start another)."""
        started, self._started = self._started, []
        rospy = import_ros()[1]
        if rospy.core.is_initialized() and not rospy.is_shutdown():
            rospy.signal_shutdown("the live arm stopped")
        if len(started) > 1:
            _stop(started[1], signal.SIGTERM, self.hang)  # the node closes the robot on SIGTERM
        if started:
            _stop(started[0], signal.SIGINT, self.hang)   # roscore's way out
        shutil.rmtree(self.env["ROS_HOME"], ignore_errors=True)

    def _heard(self, log) -> None:
        if log.name == "/" + NODE and log.msg.startswith("goal "):
            self._words.append(log.msg)

    def _state(self) -> list:
        import rosgraph

        return rosgraph.Master("/snakekit_lesson", master_uri=self.master).getSystemState()

    def _publishers(self, topic: str) -> list[str]:
        return next((nodes for name, nodes in self._state()[0] if name == topic), [])

    def _subscribers(self, topic: str) -> list[str]:
        return next((nodes for name, nodes in self._state()[1] if name == topic), [])

    def _wait(self, what: str, ready) -> None:
        end = time.monotonic() + self.hang
        while not ready():
            if self._node.poll() is not None:
                raise BackendError(f"the arm's node (snakekit ros) stopped (exit status {self._node.returncode}) "
                                   f"while waiting for {what}; run it in a terminal to see why")
            if time.monotonic() > end:
                raise BackendError(f"no {what} within {self.hang:g} s: the machine may be very busy; run the cell again")
            time.sleep(0.05)

    def send(self, message) -> str:
        """Publish a ``trajectory_msgs/JointTrajectory`` (:func:`snakekit.bags.ros1_messages`' or rospy's)
        on :data:`COMMAND` and wait for the node's word on ``/rosout``: ``goal done: ...`` is returned,
        ``goal refused: <why>`` raises :class:`~snakekit.TrajectoryError` (nothing moved). This process
        joins the master as a node (``/snakekit_lesson_...``) first, unless it already has."""
        if not self.running:
            raise ConfigurationError("this live arm was stopped: start another with snakekit.ros.live_arm() "
                                     "(in a notebook, after restarting the kernel)")
        _, rospy, _, trajectory_msgs = import_ros()
        if self._goals is None:
            from rosgraph_msgs.msg import Log

            if not rospy.core.is_initialized():
                rospy.init_node("snakekit_lesson", anonymous=True, disable_signals=True)
            rospy.Subscriber("/rosout", Log, self._heard, queue_size=100)
            self._goals = rospy.Publisher(COMMAND, trajectory_msgs.JointTrajectory, queue_size=10)
            self._wait("the arm's node on /arm/command", lambda: self._goals.get_num_connections() > 0)
        if not isinstance(message, trajectory_msgs.JointTrajectory):
            message = trajectory_msgs.JointTrajectory().deserialize(ros1_bytes(message))
        said = len(self._words)
        self._goals.publish(message)
        duration = message.points[-1].time_from_start.to_sec() if message.points else 0.0
        self.hang += duration
        try:
            self._wait("word from the arm about the goal on /rosout", lambda: len(self._words) > said)
        finally:
            self.hang -= duration
        word = self._words[said]
        if word.startswith("goal refused"):
            raise TrajectoryError(f"the arm's node refused the goal; nothing moved: {word}")
        return word

    @contextlib.contextmanager
    def recording(self, path, topics=(JOINT_STATES,)):
        """``rosbag record -O path topics`` while the block runs (stopped with Ctrl-C's signal, as from a
        terminal); the bag's path."""
        path = Path(path).resolve()
        path.unlink(missing_ok=True)   # rosbag would replace it: an old bag must not pass for this recording
        rosbag = subprocess.Popen(["rosbag", "record", "-O", str(path), *topics], env=self.env, cwd=path.parent,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            self._wait("rosbag record on the master", lambda: any(
                n.startswith("/record") for n in self._subscribers(topics[0])))
            yield path
        finally:
            _close_bag(rosbag, path, self.hang)
        if not path.exists():
            raise BackendError(f"rosbag record wrote no {path.name}: nothing was published on {', '.join(topics)}")


def _close_bag(rosbag: subprocess.Popen, path: Path, hang: float) -> None:
    """Stop ``rosbag record`` as Ctrl-C does and wait (up to ``hang`` s) until its bag is closed: its
    Python front exits at once, while the recorder it started (same process group) still writes
    ``NAME.active`` and renames it to ``NAME`` when it closes. Raises when the bag stayed unclosed."""
    _stop(rosbag, signal.SIGINT, hang)
    active = path.with_name(path.name + ".active")
    end = time.monotonic() + hang
    while _group_alive(rosbag.pid) and (active.exists() or not path.exists()):
        if time.monotonic() > end:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(rosbag.pid, signal.SIGKILL)
            break
        time.sleep(0.05)
    if active.exists() and not path.exists():
        raise BackendError(f"rosbag record did not close {path.name} within {hang:g} s (the machine may be very "
                           f"busy); what it recorded is in {active.name}: `rosbag reindex` it, or run the cell again")


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _stop(process: subprocess.Popen, sig: int, hang: float) -> None:
    """Stop a process group this module started: ``sig``, then SIGKILL after ``hang`` s."""
    if process.poll() is None:
        os.killpg(process.pid, sig)
        try:
            process.wait(hang)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()


def live_arm(backend: str = "sim", *, hang: float = 60.0) -> LiveArm:
    """A ``roscore`` on a free port and the arm's node on it (``snakekit ros --backend backend``), running
    until :meth:`LiveArm.stop` (or the end of a ``with`` block, or of the process). This process's
    ``ROS_MASTER_URI`` names that master, so ``rospy.init_node`` joins it. ``hang``: how long a start or a
    word may take on a busy machine [s]. Called again while the arm runs, it returns that arm; ROS 1 makes a
    process one node on one master, so once this process joined a master that stopped, it raises
    :class:`~snakekit.ConfigurationError` (restart the kernel)."""
    missing = ros_missing()
    if missing:
        raise MissingDependencyError(missing)
    if _JOINED and _JOINED[-1].running:
        return _JOINED[-1]
    if _JOINED and import_ros()[1].core.is_initialized():
        raise ConfigurationError(f"this process already joined the ROS master at {_JOINED[-1].master}, which stopped; "
                                 "ROS 1 lets a process be one node: restart the kernel to start another live arm")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    home = tempfile.mkdtemp(prefix="snakekit-ros-")
    master = f"http://127.0.0.1:{port}"
    env = dict(os.environ, ROS_MASTER_URI=master, ROS_HOSTNAME="127.0.0.1", ROS_HOME=home,
               ROS_LOG_DIR=os.path.join(home, "log"))
    started: list[subprocess.Popen] = []
    try:
        started.append(subprocess.Popen(["roscore", "-p", str(port)], env=env, stdout=subprocess.DEVNULL,
                                        stderr=subprocess.STDOUT, start_new_session=True))
        rosgraph = import_ros()[0]
        end = time.monotonic() + hang
        while not rosgraph.is_master_online(master):
            if started[0].poll() is not None or time.monotonic() > end:
                raise BackendError(f"roscore did not start on port {port} within {hang:g} s")
            time.sleep(0.2)
        started.append(subprocess.Popen([sys.executable, "-m", "snakekit.cli", "ros", "--backend", backend], env=env,
                                        stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, start_new_session=True))
        arm = LiveArm(master, env, hang, started)
    except BaseException:
        if len(started) > 1:
            _stop(started[1], signal.SIGTERM, hang)
        if started:
            _stop(started[0], signal.SIGINT, hang)
        shutil.rmtree(home, ignore_errors=True)
        raise
    os.environ.update({k: env[k] for k in ("ROS_MASTER_URI", "ROS_HOSTNAME", "ROS_HOME", "ROS_LOG_DIR")})
    _JOINED.append(arm)
    atexit.register(arm.stop)   # a kernel that ends leaves no master or node behind
    return arm
