"""The MX-28(2.0) position-mode profile generator, in SI units.

The firmware turns each Goal Position into a reference motion limited by Profile Velocity
and Profile Acceleration (control table 112 and 108):

* velocity 0: no profile, the reference jumps to the goal (a step);
* acceleration 0: rectangular velocity profile (the speed jumps to the profile velocity);
* both set: a trapezoid, or a triangle when the move is too short to reach the velocity;
  the acceleration phase lasts ``t1 = 64 * velocity / acceleration`` ms;
* a new goal while moving re-plans from the present reference position and velocity.

Both the simulator and the bus emulator use :class:`ProfilePlanner`, so the two move alike.

>>> planner = ProfilePlanner([0.0] * 5)
>>> planner.set_goal(0.0, [1.0, 0, 0, 0, 0])
>>> p, v = planner.at(0.04)                 # past the acceleration phase (t1 = 35.2 ms)
>>> round(float(v[0]), 3), planner.moving(0.5), planner.moving(1.0)
(1.319, True, False)

Register units: velocity 0.229 rev/min, acceleration 214.577 rev/min^2.
"""

from __future__ import annotations

import math
import numbers
from typing import NamedTuple

import numpy as np

from .errors import ConfigurationError
from .model import SPEC, SnakeSpec
from .validate import number

VELOCITY_UNIT = 0.229 * 2 * math.pi / 60  # rad/s per Profile Velocity unit
ACCELERATION_UNIT = 214.577 * 2 * math.pi / 3600  # rad/s^2 per Profile Acceleration unit

# The kit's defaults, for the simulator and the real arm alike: 55 units = 1.32 rad/s, 12 %
# under the 1.5 rad/s limit (62 = 1.487 rad/s is the most the limit allows, but a servo
# overshoots its profile while it catches up with the reference: a full-speed step peaks at
# 1.56 rad/s with 62), and 100 units = 37.45 rad/s^2, so t1 = 64 * 55 / 100 = 35.2 ms.
DEFAULT_PROFILE_VELOCITY = 55
DEFAULT_PROFILE_ACCELERATION = 100


def max_profile_velocity(spec: SnakeSpec = SPEC) -> int:
    """The largest Profile Velocity inside the joint speed limit [0.229 rev/min units].

    >>> max_profile_velocity()                 # 1.5 rad/s
    62
    """
    return math.floor(spec.velocity_limit / VELOCITY_UNIT + 1e-9)


#: The most a servo's Velocity Limit register (and so its Profile Velocity) can hold.
FIRMWARE_MAX_PROFILE_VELOCITY = 1023


def check_profile(profile_velocity, profile_acceleration, spec: SnakeSpec = SPEC, *,
                  firmware_range: bool = False) -> tuple[int, int]:
    """The Profile Velocity and Acceleration register values the kit lets a servo use.

    Velocity 1..:func:`max_profile_velocity` (0 would mean no profile: the servo steps to each
    goal at full speed, and a 1 rad step peaks at 5.5 rad/s on the simulated arm), acceleration
    1..32767. The simulator and the driver both check with this, so neither runs what the
    other would refuse. With
    ``firmware_range`` (the simulator's ``any_profile``, to show what such values do), every
    value the firmware takes: velocity 0..1023, acceleration 0..32767.

    Raises:
        ConfigurationError: a value outside those ranges; InputTypeError: not a whole number.

    >>> check_profile(0, 100)
    Traceback (most recent call last):
    ...
    snakekit.errors.ConfigurationError: profile_velocity 0 would let the servos move at full speed (0 = no profile), over the 1.5 rad/s joint speed limit; use 1..62 (0.229 rev/min units)
    """
    low, top = (0, FIRMWARE_MAX_PROFILE_VELOCITY) if firmware_range else (1, max_profile_velocity(spec))
    if not firmware_range and isinstance(profile_velocity, numbers.Integral) and not isinstance(
            profile_velocity, bool) and (profile_velocity == 0 or profile_velocity > top):
        fast = ("full speed (0 = no profile)" if profile_velocity == 0
                else f"{profile_velocity * VELOCITY_UNIT:.2f} rad/s")
        raise ConfigurationError(f"profile_velocity {profile_velocity} would let the servos move at {fast}, over the "
                                 f"{spec.velocity_limit} rad/s joint speed limit; use 1..{top} (0.229 rev/min units)")
    profile_velocity = number(profile_velocity, "profile_velocity", at_least=low, at_most=top, integer=True,
                              hint="It is the servos' Profile Velocity register, in 0.229 rev/min units, "
                              f"e.g. {DEFAULT_PROFILE_VELOCITY} (the kit's default)")
    profile_acceleration = number(profile_acceleration, "profile_acceleration", at_least=low, at_most=32767,
                                  integer=True, hint="It is the servos' Profile Acceleration register, in 214.577 "
                                  f"rev/min^2 units, e.g. {DEFAULT_PROFILE_ACCELERATION} (the kit's default)")
    return profile_velocity, profile_acceleration


def acceleration_time_ms(profile_velocity: int, profile_acceleration: int) -> float:
    """The firmware's acceleration time t1 [ms] for the given register values.

    >>> acceleration_time_ms(55, 100)          # the kit's defaults
    35.2
    """
    return 64.0 * profile_velocity / profile_acceleration


class Segment(NamedTuple):
    """Constant acceleration ``a`` [rad/s^2] from ``t0`` [s] at position ``p0``, velocity ``v0``."""

    t0: float
    p0: float
    v0: float
    a: float


class JointProfile:
    """The reference motion of one servo: piecewise constant acceleration, ending at rest."""

    __slots__ = ("segments", "end_time", "goal")

    def __init__(self, t: float, p: float, v: float, goal: float, vmax: float, amax: float):
        self.goal = goal
        self.segments: list[Segment] = []
        if vmax <= 0 or math.isinf(vmax):  # no profile: a step to the goal
            self.segments.append(Segment(t, goal, 0.0, 0.0))
            self.end_time = t
            return
        if amax <= 0 or math.isinf(amax):  # rectangular: cruise, then stop dead
            d = goal - p
            dur = abs(d) / vmax
            self.segments.append(Segment(t, p, math.copysign(vmax, d) if d else 0.0, 0.0))
            self.segments.append(Segment(t + dur, goal, 0.0, 0.0))
            self.end_time = t + dur
            return
        self._plan(t, p, v, goal, vmax, amax)

    def _plan(self, t, p, v, goal, vmax, amax):
        d = goal - p
        stop = v * v / (2 * amax)
        # Moving away from the goal, or too fast to stop before it: brake to rest first.
        if (v != 0 and (d == 0 or v * d < 0)) or (v * d > 0 and stop > abs(d) + 1e-12):
            dt = abs(v) / amax
            a = -math.copysign(amax, v)
            self.segments.append(Segment(t, p, v, a))
            t, p, v = t + dt, p + v * dt + 0.5 * a * dt * dt, 0.0
            d = goal - p
        s = 1.0 if d >= 0 else -1.0
        D, v0 = abs(d), abs(v)
        peak = math.sqrt(amax * D + 0.5 * v0 * v0)
        vc = min(peak, vmax)
        t1 = abs(vc - v0) / amax
        a1 = amax if vc >= v0 else -amax
        d1 = (vc * vc - v0 * v0) / (2 * a1) if t1 > 0 else 0.0
        d3 = vc * vc / (2 * amax)
        t2 = max(D - d1 - d3, 0.0) / vc if vc > 0 else 0.0
        t3 = vc / amax
        for dur, acc, vel in ((t1, a1, v0), (t2, 0.0, vc), (t3, -amax, vc)):
            if dur > 0:
                self.segments.append(Segment(t, p, s * vel, s * acc))
                p += s * (vel * dur + 0.5 * acc * dur * dur)
                t += dur
        self.segments.append(Segment(t, goal, 0.0, 0.0))
        self.end_time = t

    def at(self, t: float) -> tuple[float, float]:
        """Reference ``(position [rad], velocity [rad/s])`` at time ``t`` [s]."""
        segs = self.segments
        seg = segs[0]
        for s in segs[1:]:
            if s.t0 > t:
                break
            seg = s
        dt = max(t - seg.t0, 0.0)
        return seg.p0 + seg.v0 * dt + 0.5 * seg.a * dt * dt, seg.v0 + seg.a * dt

    def sample(self, times) -> tuple[np.ndarray, np.ndarray]:
        """Reference positions and velocities at many ``times`` [s] at once."""
        pos, vel = _sample_segments([self.segments], np.asarray(times, dtype=float))
        return pos[:, 0], vel[:, 0]


def _sample_segments(plans: list[list[Segment]], times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Evaluate several segment lists at ``times``: arrays of shape (len(times), len(plans))."""
    width = max(len(p) for p in plans)
    table = np.empty((4, len(plans), width))
    table[0] = np.inf  # padding segments start never, so they are never selected
    for j, plan in enumerate(plans):
        table[:, j, : len(plan)] = np.array(plan).T
    t0, p0, v0, a = table
    idx = np.maximum((times[:, None, None] >= t0[None]).sum(-1) - 1, 0)  # (T, n)
    cols = np.arange(len(plans))[None, :]
    t0, p0, v0, a = t0[cols, idx], p0[cols, idx], v0[cols, idx], a[cols, idx]
    dt = np.maximum(times[:, None] - t0, 0.0)
    return p0 + v0 * dt + 0.5 * a * dt * dt, v0 + a * dt


class ProfilePlanner:
    """Profiles of several servos: feed goals with :meth:`set_goal`, read the reference.

    Args:
        positions: initial reference positions [rad] (the servos are at rest there).
        profile_velocity: Profile Velocity register value(s) (0 = no profile).
        profile_acceleration: Profile Acceleration register value(s) (0 = rectangular).
    """

    def __init__(self, positions, profile_velocity=DEFAULT_PROFILE_VELOCITY,
                 profile_acceleration=DEFAULT_PROFILE_ACCELERATION, t: float = 0.0):
        positions = np.asarray(positions, dtype=float)
        n = positions.size
        self.profile_velocity = np.broadcast_to(np.asarray(profile_velocity), (n,)).astype(int)
        self.profile_acceleration = np.broadcast_to(np.asarray(profile_acceleration), (n,)).astype(int)
        self.profiles = [JointProfile(t, float(p), 0.0, float(p), 0.0, 0.0) for p in positions]  # at rest

    @property
    def goals(self) -> np.ndarray:
        return np.array([p.goal for p in self.profiles])

    def set_profile(self, joint: int, velocity: int | None = None, acceleration: int | None = None):
        """Change the Profile Velocity / Acceleration registers of one joint (0-based)."""
        if velocity is not None:
            self.profile_velocity[joint] = velocity
        if acceleration is not None:
            self.profile_acceleration[joint] = acceleration

    def hold(self, t: float, joint: int, position: float) -> None:
        """From time ``t`` [s], ``joint`` (0-based) rests at ``position`` [rad], whatever it was doing.

        What a servo's reference does when torque comes on where the joint now is.
        """
        self.profiles[joint] = JointProfile(t, float(position), 0.0, float(position), 0.0, 0.0)

    def set_goal(self, t: float, goals, joints=None):
        """New goal position(s) [rad] at time ``t`` [s]; re-plans from the present reference."""
        goals = np.atleast_1d(np.asarray(goals, dtype=float))
        joints = range(len(self.profiles)) if joints is None else np.atleast_1d(joints)
        for j, g in zip(joints, goals.tolist()):
            p, v = self.profiles[j].at(t)
            vmax = int(self.profile_velocity[j]) * VELOCITY_UNIT
            amax = int(self.profile_acceleration[j]) * ACCELERATION_UNIT
            self.profiles[j] = JointProfile(t, p, v, g, vmax, amax)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Reference positions [rad] and velocities [rad/s] of every joint at ``t`` [s]."""
        pv = [p.at(t) for p in self.profiles]
        return np.array([x[0] for x in pv]), np.array([x[1] for x in pv])

    def sample(self, times) -> tuple[np.ndarray, np.ndarray]:
        """Reference positions and velocities, shape (len(times), n), at many times."""
        return _sample_segments([p.segments for p in self.profiles], np.asarray(times, dtype=float))

    def moving(self, t: float) -> bool:
        return any(p.end_time > t for p in self.profiles)

    def step_velocities(self, first: int, dt: float, goal_steps, goals, *, path=None) -> np.ndarray:
        """Apply ``goals`` at their ``goal_steps`` and return the reference's mean velocity of
        every step [rad/s] from step ``first`` until every joint is at rest again.

        Row i moves the reference from step ``first + i`` to ``first + i + 1``; the simulator
        feeds it to MuJoCo as the actuator's control. Steps are of ``dt`` [s]; goal steps
        must not decrease. With no profile (velocity 0) a goal's jump happens in one step.
        ``path``: a :meth:`ReferencePath.of_goals` of this planner for the same goals at the
        same times (the collision check's), whose planning is then used instead of done again.
        """
        n = len(self.profiles)
        goal_steps = np.asarray(goal_steps, dtype=int)
        step_list = goal_steps.tolist()
        goals = np.asarray(goals, dtype=float).reshape(len(step_list), n)
        after = getattr(path, "_after", None)
        if (after is not None and after[0] is self and np.array_equal(after[1], goal_steps * dt)
                and np.array_equal(after[2], goals)):
            self.profiles, plans, before = list(after[3]), [list(p) for p in after[4]], after[5]
        else:
            plans = [list(p.segments) for p in self.profiles]
            before = _apply_goals(self, plans, [s * dt for s in step_list], goals.tolist())
        before = np.array(before, dtype=float).reshape(len(step_list), n)
        end = max(p.end_time for p in self.profiles)
        last = max(int(np.ceil(end / dt - 1e-9)), int(goal_steps[-1]) + 1 if len(goal_steps) else first + 1)
        steps = np.arange(first, last + 1)
        pos = np.empty((len(steps), n))
        t = steps * dt
        for j, plan in enumerate(plans):
            pos[:, j] = _evaluate(np.array(plan), t)  # rows t0, p0, v0, a
        inside = (goal_steps >= first) & (goal_steps <= last)
        pos[goal_steps[inside] - first] = before[inside]
        return np.diff(pos, axis=0) / dt


def _apply_goals(planner: ProfilePlanner, plans: list[list[Segment]], times: list[float],
                 goal_rows: list[list[float]]) -> list[list[float]]:
    """Send ``goal_rows`` at ``times`` [s] (not decreasing) to ``planner``, as :meth:`ProfilePlanner.set_goal`
    does, and extend each joint's segment list in ``plans`` with what follows (the old plan's
    future replaced). Returns the reference positions at each goal time, before the goal."""
    n = len(planner.profiles)
    profiles = planner.profiles
    vmax = [int(x) * VELOCITY_UNIT for x in planner.profile_velocity]
    amax = [int(x) * ACCELERATION_UNIT for x in planner.profile_acceleration]
    before: list = [None] * len(times)
    for g, t in enumerate(times):
        same = g > 0 and t == times[g - 1]
        row = before[g - 1] if same else [0.0] * n
        for j in range(n):  # what set_goal does, with the reference read once
            p, v = profiles[j].at(t)
            if not same:
                row[j] = p
            prof = profiles[j] = JointProfile(t, p, v, goal_rows[g][j], vmax[j], amax[j])
            plan = plans[j]
            while plan and plan[-1].t0 >= t:
                plan.pop()
            plan.extend(prof.segments)
        before[g] = row
    return before


class ReferencePath:
    """The path the servos' references take when goals are sent at given times.

    Each joint follows its own profile (:class:`JointProfile`): a joint with less to travel
    arrives first, and a goal sent while moving is re-planned from the present velocity, so
    the arm does not keep to the straight line between goals in joint space. This is what the
    self-collision check follows (:func:`snakekit.collision.check_path`).

    Besides positions it gives each joint's *variation*: the distance it has travelled since
    the start, back and forth counted alike, so that ``variation(t1) - variation(t0)`` bounds
    how far a joint moved between two times, whatever it did in between.

    >>> path = ReferencePath.of_goals(ProfilePlanner([0.0] * 5), [0.0], [[1.0, 0.1, 0, 0, 0]])
    >>> q = path.positions([0.2])[0]           # joint 2 (0.1 rad) has arrived, joint 1 has not
    >>> round(float(q[0]), 3), round(float(q[1]), 3), round(path.end, 3)
    (0.241, 0.1, 0.793)
    """

    def __init__(self, plans: list[list[Segment]], checkpoints):
        self._tables = [np.array(p, dtype=float).reshape(-1, 4) for p in plans]
        self._turns = [_turning_points(t) for t in self._tables]
        #: the times [s] a check looks at first: the start, each goal, the end
        self.checkpoints = np.unique(np.asarray(checkpoints, dtype=float))
        self.start = float(self.checkpoints[0])
        #: when every joint is at rest again [s]
        self.end = float(self.checkpoints[-1])

    @classmethod
    def of_goals(cls, planner: ProfilePlanner, times, goals) -> ReferencePath:
        """The reference of ``planner`` (left untouched) from ``times[0]`` on, when the goals
        ``goals`` (N, n) [rad] are sent at ``times`` (N,) [s], not decreasing."""
        times = np.asarray(times, dtype=float).reshape(-1)
        goals = np.asarray(goals, dtype=float).reshape(len(times), len(planner.profiles))
        shadow = ProfilePlanner.__new__(ProfilePlanner)
        shadow.profile_velocity, shadow.profile_acceleration = planner.profile_velocity, planner.profile_acceleration
        shadow.profiles = list(planner.profiles)
        plans = [list(p.segments) for p in shadow.profiles]
        before = _apply_goals(shadow, plans, times.tolist(), goals.tolist())
        end = max([times[-1]] + [p.end_time for p in shadow.profiles])
        path = cls(plans, np.append(times, end))
        # what ProfilePlanner.step_velocities needs to follow the same goals without planning again
        path._after = (planner, times, goals, shadow.profiles, plans, before)
        return path

    @classmethod
    def from_rest(cls, times, goals, profile_velocity=DEFAULT_PROFILE_VELOCITY,
                  profile_acceleration=DEFAULT_PROFILE_ACCELERATION) -> ReferencePath:
        """The way servos at rest on the first goal take through ``goals`` (N, n) [rad] sent at
        ``times`` (N,) [s]: a trajectory's path on an arm with this profile (the kit's by default)."""
        goals = np.asarray(goals, dtype=float)
        return cls.of_goals(ProfilePlanner(goals[0], profile_velocity, profile_acceleration, float(times[0])),
                            times, goals)

    def positions(self, times) -> np.ndarray:
        """Reference positions (len(times), n) [rad]."""
        times = np.asarray(times, dtype=float)
        return np.column_stack([_evaluate(tab, times) for tab in self._tables])

    def variation(self, times) -> np.ndarray:
        """How far each joint has travelled since the path's first segment (len(times), n) [rad]."""
        times = np.asarray(times, dtype=float)
        out = np.empty((len(times), len(self._tables)))
        for j, (tab, (crit, at_crit, total)) in enumerate(zip(self._tables, self._turns)):
            k = np.maximum(np.searchsorted(crit, times, side="right") - 1, 0)
            out[:, j] = total[k] + np.abs(_evaluate(tab, times) - at_crit[k])
        return out

    def shifted(self, dt: float) -> ReferencePath:
        """The same path with every time moved by ``dt`` [s]."""
        out = ReferencePath.__new__(ReferencePath)
        out._tables = [t + np.array([dt, 0.0, 0.0, 0.0]) for t in self._tables]
        out._turns = [(c + dt, a, v) for c, a, v in self._turns]
        out.checkpoints, out.start, out.end = self.checkpoints + dt, self.start + dt, self.end + dt
        return out


def _evaluate(table: np.ndarray, times: np.ndarray, *, left: bool = False) -> np.ndarray:
    """Positions of one joint's segments (rows t0, p0, v0, a) at ``times``; with ``left``, the
    limit from before each time (where a step jumps, the position before the jump)."""
    i = np.maximum(np.searchsorted(table[:, 0], times, side="left" if left else "right") - 1, 0)
    dt = np.maximum(times - table[i, 0], 0.0)
    return table[i, 1] + table[i, 2] * dt + 0.5 * table[i, 3] * dt * dt


def _turning_points(table: np.ndarray):
    """The times where one joint's motion may change direction (each segment's start, and
    where its velocity crosses zero inside it), the positions there, and the distance
    travelled up to each: between two of them the joint moves one way only."""
    t0, _, v0, a = table.T
    ends = np.append(t0[1:], np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        turn = np.where(a != 0, t0 - v0 / a, np.nan)
    inside = (turn > t0) & (turn < ends)
    crit = np.unique(np.concatenate([t0, turn[inside]]))
    right, left = _evaluate(table, crit), _evaluate(table, crit, left=True)
    steps = np.abs(left[1:] - right[:-1]) + np.abs(right[1:] - left[1:])  # the way there, then any jump
    return crit, right, np.concatenate([[0.0], np.cumsum(steps)])
