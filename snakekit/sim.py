"""The simulated arm: MuJoCo physics with each joint driven like an MX-28 in position mode.

Per joint, the simulator runs the servo firmware's profile generator
(:class:`snakekit.profile_planner.ProfilePlanner`), and MuJoCo runs the position loop at 1 kHz:
``tau = clip(kp (q_ref - q) - kv qdot, -2.5, 2.5) N m``, with back-EMF damping, friction
and rotor inertia on the joint (numbers in :class:`snakekit.model.ServoSpec`).
"""

from __future__ import annotations

import copy
import time

# MUJOCO_GL is chosen for this system by snakekit/__init__.py, which runs before this module
import mujoco
import numpy as np
from mujoco import rollout

from .errors import ConfigurationError
from .model import MJCF_PATH, SPEC, SnakeSpec, mjcf
from .progress import LONG_RUN, TextProgress
from .robot import JointState, Robot, Run
from .trajectory import Trajectory
from .validate import MAX_DURATION, as_configuration, check_flag, check_limits, check_spec, number, quote
from .profile_planner import DEFAULT_PROFILE_ACCELERATION, DEFAULT_PROFILE_VELOCITY, ProfilePlanner, check_profile


# qpos, qvel and act first, in that order (rows of rollout's state: time, qpos, qvel, act, ...)
_STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS


def load_model(spec: SnakeSpec = SPEC) -> mujoco.MjModel:
    """The MuJoCo model of ``spec`` (the committed MJCF for the default spec)."""
    if spec == SPEC:
        return mujoco.MjModel.from_xml_path(str(MJCF_PATH))
    return mujoco.MjModel.from_xml_string(mjcf(spec))


class SimRobot(Robot):
    """The arm in MuJoCo.

    Args:
        realtime: pace the simulation to the wall clock (for the viewer and demos);
            otherwise run as fast as possible (tests and grading).
        q0: initial joint angles [rad] (default: home).
        profile_velocity: Profile Velocity register value (0.229 rev/min units), 1..62: the
            driver's range (:func:`snakekit.profile_planner.check_profile`).
        profile_acceleration: Profile Acceleration register value (214.577 rev/min^2 units),
            1..32767.
        any_profile: take every value the servos' firmware does instead (velocity 0..1023,
            where 0 means no profile, and acceleration 0..32767), to see what they do: the
            simulator only; the real arm's driver refuses them, as they break the speed limit.

    Each physics step (1 ms) the actuator's control is the profile's mean velocity over the
    step, and MuJoCo integrates it into the reference position (the actuator's state). In
    fast mode, :meth:`run` knows every goal in advance, so it computes the controls for the
    whole trajectory and lets ``mujoco.rollout`` step them in C; real-time mode and
    :meth:`step` step from Python. Both do the same arithmetic, so they give the same motion.
    """

    backend = "sim"

    def __init__(self, *, realtime: bool = False, q0=None, spec: SnakeSpec = SPEC,
                 profile_velocity: int = DEFAULT_PROFILE_VELOCITY,
                 profile_acceleration: int = DEFAULT_PROFILE_ACCELERATION, any_profile: bool = False):
        super().__init__(check_spec(spec))
        realtime = check_flag(realtime, "realtime", "It paces the simulation to the wall clock (default: False)")
        any_profile = check_flag(any_profile, "any_profile")
        try:
            profile_velocity, profile_acceleration = check_profile(profile_velocity, profile_acceleration, spec,
                                                                   firmware_range=bool(any_profile))
        except ConfigurationError as e:
            raise ConfigurationError(f"{e}. To see what such a profile does, the simulator runs it with "
                                     "any_profile=True (the real arm never does)") from None
        self.realtime = bool(realtime)
        self.model = load_model(spec)
        self.data = mujoco.MjData(self.model)
        self.dt = float(self.model.opt.timestep)
        q0 = spec.home if q0 is None else check_limits(q0, spec, "q0")
        self.data.qpos[:] = q0
        self.data.act[:] = q0
        mujoco.mj_forward(self.model, self.data)
        self._steps = 0
        self.planner = ProfilePlanner(q0, profile_velocity, profile_acceleration)
        self._ref = (0, np.zeros((0, spec.n_joints)))  # (first step, controls from it)
        self._wall_origin = None  # (wall clock, robot clock) pair for real-time pacing
        self._renderer = None
        self._scratch = None

    # --- the interface ----------------------------------------------------------------------

    def _now(self) -> float:
        return self._steps * self.dt

    def read(self) -> JointState:
        self._check_open()
        d = self.data
        return JointState(self._now(), d.qpos.copy(), d.qvel.copy(), d.actuator_force.copy())

    def _record(self):
        d = self.data
        return self._now(), d.qpos, d.qvel, d.actuator_force

    def _profiles(self) -> ProfilePlanner:
        return self.planner

    def _goal_times(self, times: np.ndarray, start: float) -> np.ndarray:
        # the simulated clock stands still while the kit checks: start is now, and goals go on the step a run sends them
        return (self._steps + np.ceil(times / self.dt - 1e-6)) * self.dt

    def _send(self, q: np.ndarray) -> None:
        self._ref = (self._steps, self.planner.step_velocities(self._steps, self.dt, [self._steps], [q]))

    def _pace_from_now(self) -> None:
        """Real time counts from now: a run or step after an idle spell is paced from its own
        start, instead of racing through the robot time that passed while nothing ran."""
        self._wall_origin = (time.perf_counter(), self._now())

    def _advance(self, t: float) -> None:
        target = int(np.ceil(t / self.dt - 1e-6))
        m, d = self.model, self.data
        k0, ctrl = self._ref
        if self.realtime and self._wall_origin is None:
            self._pace_from_now()
        while self._steps < target:
            i = self._steps - k0
            if i < len(ctrl):
                d.ctrl[:] = ctrl[i]
                mujoco.mj_step(m, d)
                self._steps += 1
            else:  # the profile has ended: the reference holds still
                d.ctrl[:] = 0.0
                mujoco.mj_step(m, d, nstep=target - self._steps)
                self._steps = target
        if self.realtime:
            wall0, sim0 = self._wall_origin
            delay = wall0 + (self._now() - sim0) - time.perf_counter()
            if delay > 0:
                time.sleep(delay)

    def run(self, trajectory: Trajectory, *, record_rate: float = 100.0, settle: float = 0.5,
            progress: bool | None = None) -> Run:
        """Send each point of ``trajectory`` at its time and record the motion.

        The controls of the whole run are computed first, from every goal at once (the
        profile generator's arithmetic, as :meth:`Robot.run` would do goal by goal). As fast
        as possible, ``mujoco.rollout`` steps them; in real time, they are stepped in pace with
        the wall clock, from the run's start, and the state recorded as the robot clock
        passes each record time. Both give the same motion, with the same checks before
        anything moves. Interrupted (Ctrl-C), a real-time run stops sending: the arm goes on
        to the last goal sent, as the servos would.
        """
        self._check_trajectory(trajectory)
        progress = None if progress is None else check_flag(progress, "progress")
        self.interrupted_run = None
        wall0 = time.perf_counter()
        dt, n = self.dt, self.spec.n_joints
        k0 = self._steps
        record_at = self._record_times(trajectory, record_rate, settle)
        goal_steps = np.ceil((trajectory.times - trajectory.times[0]) / dt - 1e-6).astype(int)
        rec_steps = np.ceil(record_at / dt - 1e-6).astype(int)
        before = copy.deepcopy(self.planner) if self.realtime else None  # to replay, if interrupted
        # The controls of the whole run, in one pass (and what follows, for later steps).
        ctrl = self.planner.step_velocities(k0, dt, k0 + goal_steps, trajectory.positions,
                                            path=self._checked)  # planned by the check
        if self.realtime:
            rec = self._step_paced(k0, ctrl, goal_steps, rec_steps, record_at, trajectory, before, progress)
        else:
            rec = self._step_rollout(k0, ctrl, rec_steps)
        self.last_goal = trajectory.positions[-1]
        offset = trajectory.times[0]
        return Run(Trajectory(goal_steps * dt + offset, trajectory.positions, n_joints=n),
                   Trajectory(rec_steps * dt + offset, rec[0], rec[1], n_joints=n),
                   rec[2], self.backend, time.perf_counter() - wall0, self.realtime, self.spec)

    def _step_rollout(self, k0: int, ctrl: np.ndarray, rec_steps: np.ndarray):
        """Step the whole run in one ``mujoco.rollout`` call; (positions, velocities, efforts)
        at the record steps."""
        m, d, n = self.model, self.data, self.spec.n_joints
        total = int(rec_steps[-1])
        if len(ctrl) < total:
            ctrl = np.vstack([ctrl, np.zeros((total - len(ctrl), n))])
        self._ref = (k0 + total, ctrl[total:])
        ctrl = ctrl[:total]

        size = mujoco.mj_stateSize(m, _STATE)
        state0 = np.empty(size)
        mujoco.mj_getState(m, d, state0, _STATE)
        first = (d.qpos.copy(), d.qvel.copy(), d.actuator_force.copy())
        if total > 0:
            state, sensors = rollout.rollout(m, d, state0, ctrl[None], initial_warmstart=d.qacc_warmstart.copy())
            state, sensors = state[0], sensors[0]
        self._steps = k0 + total  # rollout leaves ``d`` in the final state

        rec_p = np.empty((len(rec_steps), n))
        rec_v, rec_e = np.empty_like(rec_p), np.empty_like(rec_p)
        at_start = rec_steps == 0
        rec_p[at_start], rec_v[at_start], rec_e[at_start] = first
        later = rec_steps[~at_start] - 1  # row i of the rollout is the state after step i+1
        if len(later):
            rec_p[~at_start] = state[later, 1: 1 + n]
            rec_v[~at_start] = state[later, 1 + n: 1 + 2 * n]
            rec_e[~at_start] = sensors[later]
        return rec_p, rec_v, rec_e

    def _step_paced(self, k0, ctrl, goal_steps, rec_steps, record_at, trajectory, before, progress):
        """Step the run in pace with the wall clock, recording as the robot clock passes each
        record time; (positions, velocities, efforts). Interrupted, only the goals whose time
        has come stay sent (the planner is replayed from ``before`` with them)."""
        d, dt = self.data, self.dt
        self._ref = (k0, ctrl)
        rec_p = np.empty((len(rec_steps), self.spec.n_joints))
        rec_v, rec_e = np.empty_like(rec_p), np.empty_like(rec_p)
        if progress is None:
            progress = record_at[-1] > LONG_RUN
        bar = TextProgress(record_at[-1], f"running on the {self.backend} robot") if progress else None
        self._pace_from_now()
        complete = False
        done = 0  # records taken
        wall0 = time.perf_counter()
        try:
            for r, step in enumerate(rec_steps.tolist()):
                self._advance((k0 + step) * dt)
                rec_p[r], rec_v[r], rec_e[r] = d.qpos, d.qvel, d.actuator_force
                done = r + 1
                if self.on_record is not None:
                    self.on_record(self._now(), rec_p[r], rec_v[r])
                if bar is not None:
                    bar.update(record_at[r])
            complete = True
        finally:
            if bar is not None:
                bar.close(complete=complete)
            if not complete:
                sent = int(np.searchsorted(k0 + goal_steps, self._steps, side="right"))
                if sent:
                    self.last_goal = trajectory.positions[sent - 1]
                self.planner = before
                self._ref = (k0, self.planner.step_velocities(k0, dt, k0 + goal_steps[:sent],
                                                              trajectory.positions[:sent]))
                o = trajectory.times[0]
                self._keep_partial(goal_steps[:sent] * dt + o, trajectory.positions[:sent], rec_steps[:done] * dt + o,
                                   rec_p[:done], rec_v[:done], rec_e[:done], time.perf_counter() - wall0)
        return rec_p, rec_v, rec_e

    def step(self, duration: float) -> None:
        """Let the simulation run for ``duration`` [s] holding the present goals."""
        duration = number(duration, "duration", "s", at_least=0, at_most=MAX_DURATION,
                          hint="It is how long the simulation runs holding the present goals")
        self._check_open()
        if self.realtime:
            self._pace_from_now()
        self._advance(self._now() + duration)

    def contacts(self) -> list[tuple[str, str, float]]:
        """The pairs of links touching now: ``(body, body, distance [m])``, base side first,
        the deepest contact of each pair (negative: they overlap by that much).

        The checks of :meth:`command` and :meth:`run` keep the arm from folding onto
        itself; the servos' own side (:meth:`set_servo_goals`, the emulated bus) does not,
        and a fold forced that way shows here: MuJoCo computes contacts between the collision
        hulls of links that are not neighbours, and they stop each other.
        """
        self._check_open()
        m, d = self.model, self.data
        deepest: dict[tuple[str, str], float] = {}
        for c in d.contact[: d.ncon]:
            a, b = sorted((int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])))
            names = tuple("base_link" if i == 0 else mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, i) for i in (a, b))
            deepest[names] = min(deepest.get(names, np.inf), float(c.dist))
        return [(a, b, dist) for (a, b), dist in sorted(deepest.items())]

    # --- the servos' side, for the bus emulator ------------------------------------------------

    @property
    def time(self) -> float:
        """The robot clock [s]: simulated time since the simulator was made."""
        return self._now()

    def advance_to(self, t: float) -> None:
        """Step the simulation until the robot clock reaches ``t`` [s] (nothing if it has)."""
        if t > self._now():
            self._advance(t)

    def set_servo_goals(self, q) -> None:
        """Goal positions [rad] as the servos' firmware receives them, from now on.

        Unlike :meth:`command`, the joint limits are not checked here: this is the firmware's
        side of the bus, and the bus emulator's servos apply their own Min/Max Position
        Limit registers before a goal gets here.
        """
        self._send(as_configuration(q, self.spec, "servo goals"))

    def hold_joint(self, joint: int, position: float) -> None:
        """From now on, the servo of ``joint`` (0-based) holds ``position`` [rad] at rest.

        Its profile restarts there, and so does the position loop's reference (the actuator
        state), as when a servo's torque comes on where the joint is.
        """
        self.planner.hold(self._now(), joint, position)
        self.data.act[joint] = position

    # --- rendering ----------------------------------------------------------------------------

    def render(self, q=None, *, width: int = 640, height: int = 480, camera: str = "perspective") -> np.ndarray:
        """An RGB image (height, width, 3) of the arm at ``q`` [rad] (default: its present pose).

        Rendered offscreen through EGL; the renderer is freed by :meth:`close`. The image can
        be at most as large as the model's offscreen buffer (``<visual><global offwidth
        offheight>``, 1280 x 960 for the kit's arm).

        Raises:
            ConfigurationError: a size that is not a whole number from 1 to the buffer's size.
        """
        self._check_open()
        cameras = [self.model.camera(i).name for i in range(self.model.ncam)]
        if not isinstance(camera, str) or camera not in cameras:
            raise ConfigurationError(f"camera {quote(camera)} does not exist; the cameras are {', '.join(cameras)}")
        vis = self.model.vis.global_
        width = number(width, "width", "pixels", at_least=1, at_most=vis.offwidth, integer=True,
                       hint=f"The offscreen buffer is {vis.offwidth} x {vis.offheight} pixels; render smaller "
                       "(and scale the image up if needed)")
        height = number(height, "height", "pixels", at_least=1, at_most=vis.offheight, integer=True,
                        hint=f"The offscreen buffer is {vis.offwidth} x {vis.offheight} pixels; render smaller "
                        "(and scale the image up if needed)")
        if self._renderer is None or (self._renderer.height, self._renderer.width) != (height, width):
            if self._renderer is not None:
                self._renderer.close()
            self._renderer = mujoco.Renderer(self.model, height=height, width=width)
            self._scratch = mujoco.MjData(self.model)
        if q is None:
            data = self.data
        else:
            data = self._scratch
            data.qpos[:] = as_configuration(q, self.spec)
            mujoco.mj_forward(self.model, data)  # kinematics alone leaves the cameras unplaced
        self._renderer.update_scene(data, camera=camera)
        return self._renderer.render()

    def _shutdown(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


def render(q, *, width: int = 640, height: int = 480, camera: str = "perspective",
           spec: SnakeSpec = SPEC) -> np.ndarray:
    """An RGB image of the arm at ``q`` [rad], without keeping a simulator around."""
    with SimRobot(spec=spec) as robot:
        return robot.render(q, width=width, height=height, camera=camera)
