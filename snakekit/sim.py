"""The simulated arm: MuJoCo physics with each joint driven like an MX-28 in position mode.

Per joint, the simulator runs the servo firmware's profile generator
(:class:`snakekit.servo.ProfilePlanner`), and MuJoCo runs the position loop at 1 kHz:
``tau = clip(kp (q_ref - q) - kv qdot, -2.5, 2.5) N m``, with back-EMF damping, friction
and rotor inertia on the joint (numbers in :class:`snakekit.model.ServoSpec`).

The profile is evaluated every :attr:`SimRobot.reference_period` seconds; in between, the
actuator's integrator state moves the reference linearly, inside MuJoCo's step.
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from .kinematics import as_configuration, check_limits  # noqa: E402
from .model import MJCF_PATH, SPEC, SnakeSpec, mjcf  # noqa: E402
from .robot import JointState, Robot  # noqa: E402
from .servo import DEFAULT_PROFILE_ACCELERATION, DEFAULT_PROFILE_VELOCITY, ProfilePlanner  # noqa: E402


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
        profile_velocity: Profile Velocity register value (0.229 rev/min units; 0 = step).
        profile_acceleration: Profile Acceleration register value (214.577 rev/min^2 units;
            0 = rectangular).
        reference_period: how often the profile is evaluated [s] (a multiple of 1 ms).
    """

    backend = "sim"

    def __init__(self, *, realtime: bool = False, q0=None, spec: SnakeSpec = SPEC,
                 profile_velocity: int = DEFAULT_PROFILE_VELOCITY,
                 profile_acceleration: int = DEFAULT_PROFILE_ACCELERATION,
                 reference_period: float = 0.01):
        super().__init__(spec)
        self.realtime = bool(realtime)
        self.model = load_model(spec)
        self.data = mujoco.MjData(self.model)
        self.dt = float(self.model.opt.timestep)
        self._knot = max(int(round(reference_period / self.dt)), 1)
        q0 = spec.home if q0 is None else check_limits(q0, spec, "q0")
        self.data.qpos[:] = q0
        self.data.act[:] = q0
        mujoco.mj_forward(self.model, self.data)
        self._steps = 0
        self.planner = ProfilePlanner(q0, profile_velocity, profile_acceleration)
        self._plan_reference()
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

    def _send(self, q: np.ndarray) -> None:
        self.planner.set_goal(self._now(), q)
        self._plan_reference()

    def _plan_reference(self) -> None:
        """Sample the profile at every knot from now until all joints are at rest.

        Knots start at the present step, so a goal takes effect at once. Each knot holds
        the reference position and the velocity that ramps it linearly to the next knot.
        """
        k0, knot, dt = self._steps, self._knot, self.dt
        end = max(p.end_time for p in self.planner.profiles)
        count = max(int(np.ceil((end - k0 * dt) / (knot * dt) - 1e-9)), 0) + 2
        pos, _ = self.planner.sample((k0 + knot * np.arange(count)) * dt)
        vel = np.zeros_like(pos)
        vel[:-1] = np.diff(pos, axis=0) / (knot * dt)
        self._ref = (k0, pos, vel)

    def _advance(self, t: float) -> None:
        target = int(np.ceil(t / self.dt - 1e-6))
        m, d, knot = self.model, self.data, self._knot
        k0, pos, vel = self._ref
        last = len(pos) - 1
        if self.realtime and self._wall_origin is None:
            self._wall_origin = (time.perf_counter(), self._now())
        while self._steps < target:
            offset = (self._steps - k0) % knot
            if offset == 0:
                i = min((self._steps - k0) // knot, last)
                d.act[:] = pos[i]
                d.ctrl[:] = vel[i]
            n = min(knot - offset, target - self._steps)
            mujoco.mj_step(m, d, nstep=n)
            self._steps += n
        if self.realtime:
            wall0, sim0 = self._wall_origin
            delay = wall0 + (self._now() - sim0) - time.perf_counter()
            if delay > 0:
                time.sleep(delay)

    def step(self, duration: float) -> None:
        """Let the simulation run for ``duration`` [s] holding the present goals."""
        if duration < 0:
            raise ValueError(f"duration must be >= 0 s, got {duration}")
        self._check_open()
        self._advance(self._now() + duration)

    # --- rendering ----------------------------------------------------------------------------

    def render(self, q=None, *, width: int = 640, height: int = 480, camera: str = "perspective") -> np.ndarray:
        """An RGB image (height, width, 3) of the arm at ``q`` [rad] (default: its present pose).

        Rendered offscreen through EGL; the renderer is freed by :meth:`close`.
        """
        self._check_open()
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
            mujoco.mj_kinematics(self.model, data)
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
