"""How the emulated servos move: the firmware profile alone, or the MuJoCo arm.

A motion source turns goals and torque switches, stamped with the emulator's clock [s],
into present joint positions [rad], velocities [rad/s] and torques [N m]:

* :class:`ProfileMotion`: each servo follows :class:`snakekit.servo.ProfilePlanner`
  exactly (a perfect position loop); the load is zero.
* :class:`MujocoMotion`: a :class:`snakekit.sim.SimRobot` advanced to the emulator's clock,
  so the emulated servos move (and lag, and load) like the simulated arm.

With torque off a joint is limp: it stays where it is (profile) or coasts (MuJoCo).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from ..model import SPEC, SnakeSpec
from ..profile_planner import ACCELERATION_UNIT, VELOCITY_UNIT, ProfilePlanner


def velocity_plan(planner: ProfilePlanner, t: float, joint: int, velocity: float, acceleration: int,
                  far: float) -> float:
    """Set ``planner`` up so ``joint`` turns at ``velocity`` [rad/s] from ``t`` [s] (velocity and
    PWM modes): the profile velocity is the speed, the goal ``far`` [rad] away; speed 0 stops
    with ``acceleration`` (register units; 0 = at once). Returns the goal [rad]."""
    p, v = planner.profiles[joint].at(t)
    if velocity == 0:
        amax = acceleration * ACCELERATION_UNIT
        if amax <= 0 or v == 0:
            planner.hold(t, joint, p)
            return p
        planner.set_profile(joint, max(int(math.ceil(abs(v) / VELOCITY_UNIT)), 1), acceleration)
        return p + v * abs(v) / (2 * amax)
    planner.set_profile(joint, max(int(round(abs(velocity) / VELOCITY_UNIT)), 1), acceleration)
    return p + math.copysign(far, velocity)


class MotionSource(ABC):
    """What the bus emulator needs from a physical model of the arm."""

    name = "motion"

    @abstractmethod
    def set_goal(self, t: float, joint: int, goal: float) -> None:
        """A new goal [rad] for ``joint`` (0-based) at time ``t`` [s]."""

    @abstractmethod
    def set_profile(self, t: float, joint: int, velocity: int, acceleration: int) -> None:
        """Profile Velocity / Acceleration register values of ``joint``."""

    @abstractmethod
    def set_torque(self, t: float, joint: int, on: bool, goal: float) -> None:
        """Torque on or off; on, the joint moves from where it is towards ``goal`` [rad]."""

    @abstractmethod
    def set_velocity(self, t: float, joint: int, velocity: float, acceleration: int) -> None:
        """Turn ``joint`` at ``velocity`` [rad/s] (velocity and PWM modes), reaching it with the
        Profile Acceleration register value ``acceleration`` (0: at once)."""

    @abstractmethod
    def stop(self, t: float, joint: int) -> float:
        """Stop ``joint`` where it is at ``t`` [s], at once (a watchdog stop); returns where [rad]."""

    @abstractmethod
    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions [rad], velocities [rad/s] and torques [N m] of every joint at ``t`` [s]."""

    def close(self) -> None:
        """Free the model."""


class ProfileMotion(MotionSource):
    """The servos reach the firmware's reference motion exactly."""

    name = "profile"

    def __init__(self, q0, *, profile_velocity: int = 0, profile_acceleration: int = 0):
        q0 = np.asarray(q0, dtype=float)
        self.planner = ProfilePlanner(q0, profile_velocity, profile_acceleration)
        self.torque = np.zeros(q0.size, dtype=bool)
        self.limp = q0.copy()  # where torque-off joints rest

    def set_goal(self, t, joint, goal):
        if self.torque[joint]:
            self.planner.set_goal(t, [goal], [joint])

    def set_profile(self, t, joint, velocity, acceleration):
        self.planner.set_profile(joint, velocity, acceleration)

    def set_velocity(self, t, joint, velocity, acceleration):
        if self.torque[joint]:
            goal = velocity_plan(self.planner, t, joint, velocity, acceleration, far=1e4)
            self.planner.set_goal(t, [goal], [joint])

    def stop(self, t, joint):
        q = float(self.planner.at(t)[0][joint])
        if self.torque[joint]:
            self.planner.hold(t, joint, q)
        return q

    def set_torque(self, t, joint, on, goal):
        if on == self.torque[joint]:
            return
        if on:
            self.planner.hold(t, joint, float(self.limp[joint]))
            self.torque[joint] = True
            self.planner.set_goal(t, [goal], [joint])
        else:
            self.limp[joint] = self.planner.at(t)[0][joint]
            self.torque[joint] = False

    def state(self, t):
        pos, vel = self.planner.at(t)
        off = ~self.torque
        pos[off] = self.limp[off]
        vel[off] = 0.0
        return pos, vel, np.zeros_like(pos)


class MujocoMotion(MotionSource):
    """The simulated arm, advanced to the emulator's clock (1 ms steps).

    The simulator is driven through its servo-side methods (:meth:`~snakekit.sim.SimRobot.advance_to`,
    :meth:`~snakekit.sim.SimRobot.set_servo_goals`, :meth:`~snakekit.sim.SimRobot.hold_joint`):
    goals for all joints go in together, a joint's unchanged goal re-plans to the same
    motion. Torque off sets the joint's actuator gains to zero in the MuJoCo model, so the
    joint coasts.
    """

    name = "mujoco"

    def __init__(self, q0, *, spec: SnakeSpec = SPEC, profile_velocity: int = 0,
                 profile_acceleration: int = 0):
        from ..sim import SimRobot  # MuJoCo only when this source is used

        # the registers as the servos hold them: 0 (no profile) is the firmware's power-on value
        self.sim = SimRobot(q0=q0, spec=spec, profile_velocity=profile_velocity,
                            profile_acceleration=profile_acceleration, any_profile=True)
        m = self.sim.model
        self._gain = m.actuator_gainprm[:, 0].copy()
        self._bias = m.actuator_biasprm[:, :3].copy()
        self.goals = np.array(q0, dtype=float)
        self.torque = np.ones(spec.n_joints, dtype=bool)
        for j in range(spec.n_joints):
            self._actuator(j, False)

    def _actuator(self, joint: int, on: bool) -> None:
        m = self.sim.model
        m.actuator_gainprm[joint, 0] = self._gain[joint] if on else 0.0
        m.actuator_biasprm[joint, :3] = self._bias[joint] if on else 0.0
        self.torque[joint] = on

    def advance(self, t: float) -> None:
        """Step the simulation up to the emulator's time ``t`` [s]."""
        self.sim.advance_to(t)

    def _push(self) -> None:
        """Send every goal to the simulated servos. A servo with no profile (Profile Velocity 0)
        jumps its reference to the goal now; the others re-plan from where their reference is."""
        sim = self.sim
        for j in np.flatnonzero(self.torque & (sim.planner.profile_velocity == 0)):
            sim.hold_joint(int(j), float(self.goals[j]))
        sim.set_servo_goals(self.goals)

    def set_goal(self, t, joint, goal):
        self.advance(t)
        self.goals[joint] = goal
        if self.torque[joint]:
            self._push()

    def set_profile(self, t, joint, velocity, acceleration):
        self.sim.planner.set_profile(joint, velocity, acceleration)

    def set_velocity(self, t, joint, velocity, acceleration):
        self.advance(t)
        if self.torque[joint]:
            spec = self.sim.spec
            goal = velocity_plan(self.sim.planner, self.sim.time, joint, velocity, acceleration, far=4.0)
            self.goals[joint] = float(np.clip(goal, spec.lower, spec.upper))  # the joint's range ends there
            self._push()

    def stop(self, t, joint):
        self.advance(t)
        q = float(self.sim.data.qpos[joint])
        if self.torque[joint]:
            planner = self.sim.planner
            velocity = int(planner.profile_velocity[joint])
            planner.set_profile(joint, 0)  # the firmware stops with no profile
            self.goals[joint] = q
            self._push()
            planner.set_profile(joint, velocity)
        return q

    def set_torque(self, t, joint, on, goal):
        self.advance(t)
        if on == self.torque[joint]:
            return
        if on:
            self.sim.hold_joint(joint, float(self.sim.data.qpos[joint]))
            self._actuator(joint, True)
            self.goals[joint] = goal
            self._push()
        else:
            self._actuator(joint, False)

    def state(self, t):
        self.advance(t)
        d = self.sim.data
        return d.qpos.copy(), d.qvel.copy(), d.actuator_force.copy()

    def close(self):
        self.sim.close()


MOTION_SOURCES = {"profile": ProfileMotion, "mujoco": MujocoMotion}
