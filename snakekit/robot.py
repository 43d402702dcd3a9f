"""The one robot interface, shared by the simulator, the emulated bus and the real arm.

>>> import snakekit
>>> move = snakekit.joint_trajectory([0, 0, 0, 0, 0], [0.5, -0.3, 0.2, 0, 0], duration=1.0)
>>> with snakekit.make_robot("sim") as robot:
...     run = robot.run(move)
...     state = robot.read()
>>> run.limits_held(), bool(abs(state.positions - [0.5, -0.3, 0.2, 0, 0]).max() < 0.01)
(True, True)

Every backend refuses a command or trajectory outside the joint limits, or whose path folds
the arm onto itself (:mod:`snakekit.collision`), *before* anything moves, and turns torque
off (or holds) when closed, even after an exception.
"""

from __future__ import annotations

import contextlib
import importlib
import time
from abc import ABC, abstractmethod

import numpy as np

from .errors import BackendError, InputTypeError, LimitError, ShapeError, SnakekitError
from .host import realtime as _realtime
from .model import SPEC, SnakeSpec
from .progress import LONG_RUN, TextProgress
from .run import JointState, Run  # noqa: F401  (snakekit.robot.Run: where the robot interface names them)
from .trajectory import Trajectory, joint_trajectory
from .validate import (MAX_DURATION, check_flag, check_limits, check_rate, number, options_of, quote, sample_count,
                       too_long)


class Robot(ABC):
    """The interface every backend implements.

    Subclasses provide the clock (:meth:`_now`), waiting (:meth:`_advance`), sending a
    checked goal (:meth:`_send`) and reading (:meth:`read`); this class does the checking,
    the timing of :meth:`run` and the recording.
    """

    #: the backend's name, as :func:`make_robot` takes it
    backend = "robot"
    #: whether :meth:`run` is paced by the wall clock (a real or emulated bus, a real-time
    #: simulator) rather than stepped as fast as possible
    realtime = True
    #: whether :meth:`run`'s loop keeps a bus's timing (goals to servos, whose Bus Watchdog stops
    #: them when the loop stalls): it then runs under ``SCHED_FIFO`` where allowed (``host.realtime``)
    keeps_bus_time = False
    #: How far [rad] a trajectory's first point may be from the present position.
    start_tolerance = 0.05
    #: How late [s] a run's goal or record may come before the rest of the run is moved later
    #: by as much. A host that stalls (a busy laptop) then never makes a joint catch up with
    #: goals that are overdue: the arm resumes the path where it was, at the planned speed,
    #: and the run ends later (:attr:`late_shifts` counts these).
    late_goal = 0.03
    late_shifts = 0
    _checked = None  # the servos' way of the goals last checked (snakekit.profile_planner.ReferencePath)
    #: how much later [s] than its check assumed a goal may leave (a later one is checked again)
    send_slack = 0.005
    _lead = 0.0  # how long a check takes on this robot's clock [s] (learnt): goals are checked as sent then
    #: The longest trajectory :meth:`run` accepts [s]; longer is refused as probably given in
    #: milliseconds. Raise it on a robot to run a longer one on purpose.
    max_duration = MAX_DURATION
    #: Called as ``on_record(time [s], positions [rad], velocities [rad/s])`` with each state a
    #: run paced by the wall clock records, as it is taken (a live view: the ROS node's
    #: ``/joint_states``); the arrays are the run's own, to copy, not keep. None: no call.
    on_record = None
    #: What the last run stopped part way (Ctrl-C, an error once goals went out) had sent and
    #: recorded, as a :class:`Run`; None when the last run finished or nothing was recorded.
    interrupted_run: Run | None = None

    def __init__(self, spec: SnakeSpec = SPEC):
        self.spec = spec
        self.closed = False
        #: the last goal sent [rad] (None before the first): a command's path starts there
        self.last_goal: np.ndarray | None = None

    # --- what a backend provides -------------------------------------------------------

    @abstractmethod
    def read(self) -> JointState:
        """The present joint state."""

    @abstractmethod
    def _send(self, q: np.ndarray) -> None:
        """Send a goal that is already checked to be inside the limits."""

    @abstractmethod
    def _now(self) -> float:
        """The robot clock [s]."""

    @abstractmethod
    def _advance(self, t: float) -> None:
        """Return when the robot clock reaches ``t`` [s] (simulate, or wait)."""

    def _record(self) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        s = self.read()
        return s.time, s.positions, s.velocities, s.efforts

    def _shutdown(self) -> None:
        """Release the backend (torque off, close ports, free the simulator)."""

    # --- the interface ------------------------------------------------------------------

    def _check_open(self):
        if self.closed:
            raise BackendError(f"this {self.backend} robot is closed; make a new one with "
                               f"snakekit.make_robot('{self.backend}')")

    def command(self, q) -> None:
        """Send a position goal ``q`` [rad].

        Raises:
            LimitError: ``q`` is outside the joint limits.
            CollisionError: the way the servos take from where they are now to ``q`` (each
                joint on its own profile, :meth:`_profiles`) brings two links that are not
                neighbours closer than ``spec.collision_margin``. Nothing is sent.
        """
        self._check_open()
        q = check_limits(q, self.spec, "commanded q")
        start = self.read().positions if self.last_goal is None else self.last_goal
        self._check_path(np.array([0.0, 1.0]), np.array([start, q]), "command")
        self._send(q)
        self.last_goal = q

    def _profiles(self):
        """The servos' profile generator as it stands now, with its clock at :meth:`_now`
        (a :class:`snakekit.profile_planner.ProfilePlanner`, left untouched by the checks), or
        None for a backend that has none: its paths are checked as straight lines."""
        return None

    def _goal_times(self, times: np.ndarray, start: float) -> np.ndarray:
        """When goals due ``times`` [s] after ``start`` (robot clock [s]) reach the servos [s]."""
        return start + times

    def _check_path(self, times: np.ndarray, positions: np.ndarray, what: str) -> None:
        """Refuse goals whose path folds the arm onto itself (:func:`snakekit.collision.check_path`):
        the path the servos' profiles make of them, when the backend has profiles; for a
        command (``times`` ``[0, 1]``: from the last goal to the new one) only the new goal is
        sent, and its way starts where the servos are then.

        On a robot whose clock runs while the kit checks (the real arm, the emulated bus), the
        goals are checked as sent :attr:`_lead` later than now, and this returns at that time:
        a goal then leaves when its check said, not later on a way that was never checked. A
        check that outlasts its lead is made again with a longer one.
        """
        from .collision import check_path  # Pinocchio only when a goal is checked: runs load without it
        from .profile_planner import ReferencePath

        planner = self._profiles()
        if planner is None:
            return check_path(times, positions, what=what, spec=self.spec)
        if what == "command":
            times, positions = times[1:] - times[1], positions[1:]
        for _ in range(8):
            begun = self._now()
            sent = self._goal_times(times - times[0], begun + self._lead)
            self._checked = ReferencePath.of_goals(planner, sent, positions)  # a backend may reuse its planning
            path = self._checked.shifted(times[0] - sent[0])
            if what == "command":  # judged from where the servos are when it leaves, not from the last goal
                check_path([0.0, path.end], [path.positions([0.0])[0], positions[-1]], what=what, spec=self.spec,
                           path=path)
            else:
                check_path(times, positions, what=what, spec=self.spec, path=path)
            took = self._now() - begun
            in_time = self._now() <= sent[0]
            if took > 0:  # a clock that runs while checking: the lead follows what checks take
                self._lead = max(1.5 * took + 0.002, 0.8 * self._lead) if in_time else min(1.5 * took + 0.002, 1.0)
            if in_time:
                self._advance(sent[0] - 0.004)
                while self._now() < sent[0]:  # the last few ms without sleep's lateness
                    pass
            # Late by more than the slack matters only while a joint moves: from rest, the way is the same whenever.
            if self._now() <= sent[0] + self.send_slack or not planner.moving(sent[0]):
                return
        raise BackendError(f"the {what} was checked 8 times, but each check took longer than the time it was "
                           "checked for, so its goals would leave later, on a way that was not checked; nothing was "
                           "sent. The computer is too busy: close other programs and try again.")

    def run(self, trajectory: Trajectory, *, record_rate: float = 100.0, settle: float = 0.5,
            progress: bool | None = None) -> Run:
        """Send each point of ``trajectory`` at its time and record the motion.

        The whole trajectory is checked against the position and velocity limits first,
        and must start within :attr:`start_tolerance` of the present position; if not,
        nothing moves.

        Args:
            trajectory: the goals to send; time 0 of the run is ``trajectory.times[0]``.
            record_rate: how often the state is recorded [Hz].
            settle: how long to keep recording after the last goal [s].
            progress: show a progress line while it runs (default: when the run is paced
                by the wall clock and longer than :data:`snakekit.progress.LONG_RUN`).
        """
        self._check_trajectory(trajectory)
        progress = None if progress is None else check_flag(progress, "progress")
        self.interrupted_run = None
        times = trajectory.times - trajectory.times[0]
        goals = trajectory.positions
        n_goals = len(times)
        record_at = self._record_times(trajectory, record_rate, settle)
        n_rec = len(record_at)
        rec_t = np.empty(n_rec)
        rec_p = np.empty((n_rec, self.spec.n_joints))
        rec_v = np.empty_like(rec_p)
        rec_e = np.empty_like(rec_p)
        sent_t = np.empty(n_goals)

        if progress is None:
            progress = self.realtime and record_at[-1] > LONG_RUN
        bar = TextProgress(record_at[-1], f"running on the {self.backend} robot") if progress else None
        wall0 = time.perf_counter()
        t0 = self._now()
        shift = 0.0  # how much later than planned the rest of the run goes (late goals)
        k = r = 0
        complete = False
        try:
            with _realtime() if self.keeps_bus_time else contextlib.nullcontext():  # the bus's timing
                while k < n_goals or r < n_rec:
                    t_goal = times[k] if k < n_goals else np.inf
                    t_rec = record_at[r] if r < n_rec else np.inf
                    due = t0 + shift + min(t_goal, t_rec)
                    self._advance(due)
                    late = self._now() - due
                    if late > self.late_goal:  # the host stalled: go on from here, never catch up
                        shift += late
                        self.late_shifts += 1
                    if k < n_goals and t_goal <= t_rec:
                        self._send(goals[k])
                        sent_t[k] = self._now() - t0  # when it really left, delays included
                        k += 1
                        if bar is not None:
                            bar.update(t_goal)
                    else:
                        t, rec_p[r], rec_v[r], rec_e[r] = self._record()
                        rec_t[r] = t - t0
                        if self.on_record is not None:
                            self.on_record(t, rec_p[r], rec_v[r])
                        r += 1
            complete = True
        finally:
            if k:  # the next command's path starts at the last goal that was sent
                self.last_goal = goals[k - 1]
            if bar is not None:
                bar.close(complete=complete)
            if not complete:
                o = trajectory.times[0]
                self._keep_partial(sent_t[:k] + o, goals[:k], rec_t[:r] + o, rec_p[:r], rec_v[:r], rec_e[:r],
                                   time.perf_counter() - wall0)
        wall = time.perf_counter() - wall0
        offset = trajectory.times[0]
        return Run(Trajectory(sent_t + offset, goals, n_joints=self.spec.n_joints),
                   Trajectory(rec_t + offset, rec_p, rec_v, n_joints=self.spec.n_joints),
                   rec_e, self.backend, wall, bool(self.realtime), self.spec)

    def _keep_partial(self, sent_t, goals, rec_t, rec_p, rec_v, rec_e, wall: float) -> None:
        """Keep what a run stopped part way had sent and recorded as :attr:`interrupted_run`
        (none if no goal was sent or no state recorded)."""
        if len(sent_t) and len(rec_t):
            n = self.spec.n_joints
            try:
                self.interrupted_run = Run(Trajectory(sent_t, goals, n_joints=n),
                                           Trajectory(rec_t, rec_p, rec_v, n_joints=n),
                                           rec_e, self.backend, wall, bool(self.realtime), self.spec)
            except SnakekitError:  # e.g. two goals stamped at one clock reading: nothing to keep
                self.interrupted_run = None

    def _check_trajectory(self, trajectory: Trajectory) -> None:
        """Refuse, before anything moves, a trajectory this arm must not run."""
        self._check_open()
        if not isinstance(trajectory, Trajectory):
            raise InputTypeError(f"run() takes a snakekit.Trajectory, got {type(trajectory).__name__}; "
                            "build one with snakekit.Trajectory(times, positions)")
        if trajectory.n_joints != self.spec.n_joints:
            raise ShapeError("trajectory positions", f"(N, {self.spec.n_joints})",
                             (len(trajectory), trajectory.n_joints),
                             f"the arm has {self.spec.n_joints} joints: give one column per joint")
        if trajectory.duration > self.max_duration:
            raise too_long(trajectory.duration, "the trajectory's duration", self.max_duration,
                           f"nothing was sent. To run one this long on purpose, set robot.max_duration = "
                           f"{np.ceil(trajectory.duration):.0f} first")
        trajectory.check_limits(self.spec)
        state = self.read()
        present = state.positions
        gap = np.abs(trajectory.positions[0] - present)
        if gap.max() > self.start_tolerance:
            j = int(gap.argmax())
            moving = np.abs(state.velocities)
            todo = (f"The arm is still moving (joint {int(moving.argmax()) + 1} at {moving.max():.2f} rad/s): wait "
                    "until it stops, then try again." if moving.max() > 0.05 else
                    "Move there first with robot.move_to(trajectory.positions[0]).")
            raise LimitError(
                f"the trajectory starts {gap[j]:.3f} rad away from the arm's present position "
                f"(joint {j + 1}: {present[j]:+.3f} -> {trajectory.positions[0, j]:+.3f} rad); nothing was sent. "
                + todo)
        self._check_path(trajectory.times, trajectory.positions, "trajectory")  # last: it returns when the run starts

    @staticmethod
    def _record_times(trajectory: Trajectory, record_rate: float, settle: float) -> np.ndarray:
        """When the state is recorded during a run, from the run's start [s]."""
        record_rate = check_rate(record_rate, "record_rate",
                                 "It is how often the state is recorded during the run (default: 100)")
        settle = number(settle, "settle", "s", at_least=0, at_most=3600,
                        hint="It is how long recording goes on after the last goal (default: 0.5)")
        end = trajectory.duration + settle
        return np.arange(sample_count(end, record_rate, "the run's recording")) / record_rate

    def move_to(self, q, duration: float | None = None, **run_options) -> Run:
        """Move smoothly (quintic, within the velocity limit) from the present position to ``q``."""
        self._check_open()
        target = check_limits(q, self.spec, "target q")
        start = np.clip(self.read().positions, self.spec.lower, self.spec.upper)
        return self.run(joint_trajectory(start, target, duration, spec=self.spec), **run_options)

    def home(self, duration: float | None = None, **run_options) -> Run:
        """Move smoothly back to the home pose (every joint at 0 rad)."""
        return self.move_to(self.spec.home, duration, **run_options)

    def close(self) -> None:
        """Stop and release the robot. Safe to call more than once."""
        if not self.closed:
            self.closed = True
            self._shutdown()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


BACKENDS = {
    "sim": ("snakekit.sim", "SimRobot"),
    "emulator": ("snakekit.emulator", "make_emulated_robot"),
    "hardware": ("snakekit.hardware", "DynamixelSnake"),
}


def make_robot(backend: str = "sim", **options) -> Robot:
    """A robot on the named backend: ``"sim"`` (default), ``"emulator"`` or ``"hardware"``.

    Options go to the backend, e.g. ``make_robot("sim", realtime=True)`` or
    ``make_robot("hardware", port="/dev/ttyUSB0")``.
    """
    if not isinstance(backend, str):
        raise InputTypeError(f"the backend is named by a string, one of {', '.join(map(repr, BACKENDS))}; got "
                             f"{backend!r} ({type(backend).__name__})")
    if backend not in BACKENDS:
        raise BackendError(f"unknown backend {quote(backend)}; choose one of {', '.join(BACKENDS)}")
    module, name = BACKENDS[backend]
    try:
        factory = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError) as e:
        raise BackendError(f"the '{backend}' backend is not available: {e}") from e
    options_of(factory, options, f"the '{backend}' backend",
               needs={"port": "the arm's serial port, e.g. port='/dev/ttyUSB0'; docs/hardware.md says how to find it"})
    return factory(**options)
