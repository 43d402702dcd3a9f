"""Self-collision: how close the arm's links come to each other, at a pose and along a path.

With 71 mm between joint axes and +-1.57 rad per joint, many poses inside the joint limits
fold one link onto another (``[1.57, 1.57, 1.57, 1.57, 0]`` puts joint 5 on joint 1). Every
robot backend refuses, before anything moves, a goal or a path that brings two links that
are not neighbours in the chain closer than ``SPEC.collision_margin`` (5 mm).

The geometry is Pinocchio's collision model on coal (the FCL successor): each body's shape
is the convex hull of its parts, from :func:`snakekit.model.collision_points`, and the
distance of every pair of non-neighbouring bodies (10 pairs for five joints) is one
``pinocchio.computeDistances`` call. A distance is signed: negative when two hulls overlap
(how deep).

>>> import snakekit
>>> c = clearance([0, 0, 0, 0, 0])
>>> c.links, round(c.distance * 1000, 1)          # the straight arm: base and link 2, 46 mm
(('base_link', 'link2'), 46.0)
>>> clearance([1.57, 1.57, 1.57, 1.57, 0]).distance < 0     # folded: link 4 lies on the base
True

**Paths between goals.** A path is checked with a bound, not by sampling at a fixed step:
in the frame of link ``a``, a point of link ``b`` moves by at most ``sum_j R_j |dq_j|`` when
joints ``a+1..b`` change by ``dq`` (``R_j``: the farthest that link ``b`` reaches from the
axis of joint ``j``), whatever the order in which the joints move; for a joint that goes back
and forth, ``|dq_j|`` is the way it travels. So between two checkpoints of a path (its goals)
their distance stays above ``(d_k + d_k+1 - L)/2`` with ``L = sum_j R_j travel_j``. A stretch
whose bound is above the margin for every pair is safe without looking inside it; otherwise
its middle (in time) is computed and each half checked the same way. The step so shrinks
with the largest joint change and grows with the clearance: in Task 2's sweep the goals
alone prove every stretch safe; a move that grazes the margin is split until a piece is
shorter than 0.1 mm of link travel, and is then refused (the error's distance is the bound,
so the check never errs on the unsafe side).

**Which path.** A robot does not move along the straight line between goals in joint space:
the servos' firmware moves each joint on its own profile, at the profile's speed, so a joint
with less to travel arrives first, and a goal sent while moving is re-planned from the
present velocity. Two safe poses whose straight path is clear can so fold the arm on the
way. Every robot checks the way its servos take (:class:`snakekit.profile_planner.ReferencePath`,
the same arithmetic the simulator and the bus emulator move by); :func:`first_collision`
checks the straight path (a lesson's goals), :func:`first_collision_on` any path.
This is the "adaptive dynamic collision checking" of Schwarzer, Saha and Latombe (2005).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import coal
import numpy as np
import pinocchio as pin

from .errors import CollisionError
from .model import SPEC, SnakeSpec, body_names, collision_points, urdf
from .validate import as_configuration, check_spec, frozen, number

#: A path piece whose links move less than this [m] is not split further (see the module doc).
RESOLUTION = 1e-4


@dataclass(frozen=True, eq=False)
class Clearance:
    """The closest pair of non-neighbouring links at one pose.

    Attributes:
        distance: their distance [m]; negative: they overlap, by that much.
        links: the two bodies, base side first (``"base_link"``, ``"link1"``...).
        q: the joint angles [rad] of the pose.
        time: when the pose is reached on a checked path [s] (None for a single pose).
    """

    distance: float
    links: tuple[str, str]
    q: np.ndarray
    time: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "q", frozen(self.q))

    def describe(self, digits: int = 1) -> str:
        """``"link1 and link4 are 3.2 mm apart"`` (or overlap by ...), in mm with ``digits`` decimals."""
        a, b = self.links
        if self.distance < 0:
            return f"{a} and {b} overlap by {-1000 * self.distance:.{digits}f} mm"
        return f"{a} and {b} are {1000 * self.distance:.{digits}f} mm apart"


class _Checker:
    """Pinocchio's model and collision model of one spec, and the path bound's radii."""

    def __init__(self, spec: SnakeSpec):
        self.spec = spec
        self.model = pin.buildModelFromXML(urdf(spec))
        self.data = self.model.createData()
        self.geometry = pin.GeometryModel()
        names = body_names(spec)
        for i, (name, points) in enumerate(zip(names, collision_points(spec))):
            corners = coal.StdVec_Vec3s()
            for p in points:
                corners.append(p)
            joint = 0 if i == 0 else self.model.getJointId(f"joint{i}")
            self.geometry.addGeometryObject(pin.GeometryObject(
                name, joint, self.model.getFrameId(name), pin.SE3.Identity(),
                coal.Convex.convexHull(corners, False, None)))
        n_bodies = len(names)
        self.pairs = [(a, b) for a in range(n_bodies) for b in range(a + 2, n_bodies)]
        for a, b in self.pairs:
            self.geometry.addCollisionPair(pin.CollisionPair(a, b))
        self.gdata = self.geometry.createData()
        # References into the results vector: read in place after every computeDistances.
        self._results = list(self.gdata.distanceResults)
        self.pair_names = [(names[a], names[b]) for a, b in self.pairs]
        # R[p, j]: how far the points of pair p's outer body reach from joint j's axis [m]
        # (joint j+1 in the lesson's numbering), for the joints that move it against the inner one.
        reach = [float(np.hypot(p[:, 0], p[:, 1]).max()) for p in collision_points(spec)]
        self.radii = np.zeros((len(self.pairs), spec.n_joints))
        for k, (a, b) in enumerate(self.pairs):
            for j in range(a, b):
                self.radii[k, j] = (b - (j + 1)) * spec.link_length + reach[b]

    def distances(self, q: np.ndarray) -> list[float]:
        """Signed distance [m] of every pair at ``q`` (checked joint angles)."""
        pin.computeDistances(self.model, self.data, self.geometry, self.gdata, q)
        return [r.min_distance for r in self._results]

    def closest(self, q: np.ndarray) -> tuple[int, float]:
        """The closest pair at ``q`` (checked joint angles): its index and signed distance [m]."""
        k = pin.computeDistances(self.model, self.data, self.geometry, self.gdata, q)
        return k, self._results[k].min_distance


def _checker(spec: SnakeSpec) -> _Checker:
    """The checker of ``spec`` (built once per spec)."""
    return _built_checker(check_spec(spec))


@lru_cache(maxsize=4)
def _built_checker(spec: SnakeSpec) -> _Checker:
    return _Checker(spec)


def pair_distances(q, *, spec: SnakeSpec = SPEC) -> dict[tuple[str, str], float]:
    """Signed distance [m] between every pair of non-neighbouring bodies at ``q`` [rad]."""
    c = _checker(spec)
    return dict(zip(c.pair_names, c.distances(as_configuration(q, spec))))


def clearance(q, *, spec: SnakeSpec = SPEC) -> Clearance:
    """The closest pair of non-neighbouring links at joint angles ``q`` [rad], and their distance."""
    c = _checker(spec)
    q = as_configuration(q, spec)
    k, d = c.closest(q)
    return Clearance(d, c.pair_names[k], q)


def collides(q, *, spec: SnakeSpec = SPEC, margin: float | None = None) -> bool:
    """Whether two non-neighbouring links at ``q`` [rad] are closer than ``margin`` [m]
    (default: ``spec.collision_margin``)."""
    c = _checker(spec)
    margin = spec.collision_margin if margin is None else number(margin, "margin", "m", at_least=0, hint=(
        "It is how close two links may come (default: spec.collision_margin)"))
    return c.closest(as_configuration(q, spec))[1] < margin


def collision_free(qs, *, spec: SnakeSpec = SPEC) -> np.ndarray:
    """For each row of ``qs`` (N, n_joints) [rad], whether it keeps every pair of
    non-neighbouring links at least ``spec.collision_margin`` apart."""
    c = _checker(spec)
    qs = np.asarray(qs, dtype=float)
    return np.array([c.closest(q)[1] >= spec.collision_margin for q in qs], dtype=bool)


class StraightPath:
    """The straight path in joint space through ``positions`` (N, n_joints) [rad] at ``times``
    (N,) [s]: what a check follows when the servos' profile is not known (a lesson's goals,
    a trajectory checked before a robot is made). It has what a :class:`snakekit.profile_planner.ReferencePath`
    has: ``checkpoints``, ``positions(t)``, ``variation(t)``."""

    def __init__(self, times, positions):
        self._times = np.asarray(times, dtype=float)
        self._positions = np.asarray(positions, dtype=float).reshape(len(self._times), -1)
        self._travel = np.vstack([np.zeros((1, self._positions.shape[1])),
                                  np.cumsum(np.abs(np.diff(self._positions, axis=0)), axis=0)])
        self.checkpoints = self._times
        self.start, self.end = float(self._times[0]), float(self._times[-1])

    def _interp(self, values, times):
        times = np.asarray(times, dtype=float)
        if len(self._times) == 1:
            return np.repeat(values[:1], len(times), axis=0)
        return np.column_stack([np.interp(times, self._times, v) for v in values.T])

    def positions(self, times) -> np.ndarray:
        return self._interp(self._positions, times)

    def variation(self, times) -> np.ndarray:
        return self._interp(self._travel, times)


def first_collision(times, positions, *, spec: SnakeSpec = SPEC) -> Clearance | None:
    """The first pose, in time, on the straight path through ``positions`` (N, n_joints)
    [rad] at ``times`` (N,) [s] that brings two non-neighbouring links closer than
    ``spec.collision_margin``; None when the whole path keeps them apart.

    Between goals the time is interpolated linearly. See the module doc for how the path
    between goals is covered; :func:`first_collision_on` checks any other path (the one the
    servos' profile makes).
    """
    return first_collision_on(StraightPath(times, positions), spec=spec)


def first_collision_on(path, *, spec: SnakeSpec = SPEC, margin: float | None = None) -> Clearance | None:
    """The first pose, in time, on ``path`` (a :class:`StraightPath` or the servos'
    :class:`snakekit.profile_planner.ReferencePath`) that brings two non-neighbouring links
    closer than ``spec.collision_margin``; None when the whole path keeps them apart.

    The path is looked at its checkpoints (its goals), and each stretch between two is proven
    safe by the bound of the module doc, with the joints' travel along the path (back and
    forth counted alike) in place of their change, or split in time until it is. ``margin``
    [m]: the least distance allowed (default ``spec.collision_margin``).
    """
    c = _checker(spec)
    margin = spec.collision_margin if margin is None else margin
    times = path.checkpoints
    positions, travel = path.positions(times), path.variation(times)
    D = np.array([c.distances(q) for q in positions])
    L = np.diff(travel, axis=0) @ c.radii.T
    bad = D.min(axis=1) < margin
    unproven = np.append(((D[:-1] + D[1:] - L) < 2 * margin).any(axis=1), False)  # stretch k: checkpoints k, k+1
    for k in np.flatnonzero(bad | unproven).tolist():  # in time order
        if bad[k]:
            return _at(c, D[k], positions[k], times[k])
        hit = _split(c, path, (times[k], D[k], travel[k]), (times[k + 1], D[k + 1], travel[k + 1]), margin)
        if hit is not None:
            return hit
    return None


def worst_between(q0, q1, t0: float = 0.0, t1: float = 1.0, *, samples: int = 200,
                  spec: SnakeSpec = SPEC, path=None) -> Clearance:
    """The closest approach of two non-neighbouring links between ``t0`` and ``t1`` [s], among
    ``samples`` evenly spaced times (ends included): on ``path`` when given, else on the
    straight path q0 -> q1 [rad]."""
    c = _checker(spec)
    if path is None:
        path = StraightPath([t0, t1], [as_configuration(q0, spec), as_configuration(q1, spec)])
    best = None
    for t, q in zip(np.linspace(t0, t1, samples), path.positions(np.linspace(t0, t1, samples))):
        k, d = c.closest(q)
        if best is None or d < best.distance:
            best = Clearance(d, c.pair_names[k], q, float(t))
    return best


def _at(c: _Checker, d: np.ndarray, q: np.ndarray, t: float) -> Clearance:
    k = int(d.argmin())
    return Clearance(float(d[k]), c.pair_names[k], q, float(t))


def _split(c: _Checker, path, a, b, margin) -> Clearance | None:
    """The first pose closer than ``margin`` on ``path`` between the times of ``a`` and ``b``
    (each ``(time, distances, travel)``; neither too close), or None: bisects in time, earlier
    half first, until the bound proves each piece safe."""
    (t0, d0, v0), (t1, d1, v1) = a, b
    L = c.radii @ (v1 - v0)
    bound = (d0 + d1 - L) / 2
    if (bound >= margin).all():
        return None
    if L.max() < RESOLUTION or t1 - t0 < 1e-9:  # too short to split: refuse on the bound, the safe side
        k = int(bound.argmin())
        tm = (t0 + t1) / 2
        return Clearance(float(bound[k]), c.pair_names[k], path.positions([tm])[0], tm)
    tm = (t0 + t1) / 2
    qm, vm = path.positions([tm])[0], path.variation([tm])[0]
    dm = np.array(c.distances(qm))
    hit = _split(c, path, a, (tm, dm, vm), margin)
    if hit is not None:
        return hit
    if dm.min() < margin:
        return _at(c, dm, qm, tm)
    return _split(c, path, (tm, dm, vm), b, margin)


#: How much closer [m] than where it stands an arm already inside the margin may come on a
#: way out (the check's own resolution, and the servos' tracking, with room to spare).
FOLDED_START_ALLOWANCE = 0.0005


def check_path(times, positions, *, what: str = "trajectory", spec: SnakeSpec = SPEC, path=None) -> None:
    """Raise :class:`~snakekit.errors.CollisionError` if the path through the goals
    ``positions`` (N, n_joints) [rad] at ``times`` (N,) [s] brings two non-neighbouring links
    closer than ``spec.collision_margin`` (:func:`first_collision_on`).

    Args:
        path: the path the arm takes through those goals, in the same time, when it is known:
            the servos' :class:`~snakekit.profile_planner.ReferencePath` (each joint on its own
            profile; what every robot checks). Default: the straight path in joint space.

    The message names when (the time; for ``what="command"``, from when the goal is sent, or
    with times ``[0, 1]`` and no ``path``, how far along the move from the last goal), the two
    links, and the closest they come on that stretch. An arm that already stands closer than
    the margin (started folded, or bent by hand with torque off) may move out: its path is
    refused only where it brings two links closer than they are at the start (less
    :data:`FOLDED_START_ALLOWANCE`).
    """
    times, positions = np.asarray(times, dtype=float), np.asarray(positions, dtype=float)
    straight = StraightPath(times, positions)
    profiled, path = path is not None, straight if path is None else path
    margin = spec.collision_margin
    start = clearance(path.positions([path.start])[0], spec=spec)
    allowed = min(margin, start.distance - FOLDED_START_ALLOWANCE)
    hit = first_collision_on(path, spec=spec, margin=allowed)
    if hit is None:
        return
    cps = path.checkpoints
    k = min(max(int(np.searchsorted(cps, hit.time, side="right")), 1), len(cps) - 1)  # the checkpoint after the hit
    worst = worst_between(None, None, cps[k - 1], cps[k], spec=spec, path=path)
    at_goal = hit.time == path.end
    if what == "command" and not profiled:
        where = "at the goal" if at_goal else f"{100 * hit.time:.0f} % of the way from the last goal, on the straight path"
        deepest = "at the goal" if worst.time == 1.0 else f"{100 * worst.time:.0f} % of the way"
        when = None
    elif what == "command":
        where = ("at the goal" if at_goal else f"{hit.time - times[0]:.2f} s after the goal is sent, on the way the "
                 "servos take (each joint at its profile's speed: one with less to travel arrives first)")
        deepest = "at the goal" if worst.time == path.end else f"{worst.time - times[0]:.2f} s after it is sent"
        when = hit.time - times[0]
    else:
        where, when = f"at t = {hit.time:.3f} s", hit.time
        if profiled:
            where += " on the way the servos take between the goals (each joint at its profile's speed)"
        deepest = f"at t = {worst.time:.3f} s"
    if allowed < margin:
        rule = (f"the arm already stands inside the {1000 * margin:.0f} mm margin ({start.describe(digits=2)}): it "
                f"may move out, but not bring two links closer than that. Here, {where}, {hit.links[0]} and "
                f"{hit.links[1]} would come closer")
    else:
        rule = (f"{where}, {hit.links[0]} and {hit.links[1]} come closer than the {1000 * margin:.0f} mm margin")
    advice = ("Choose goals that keep the links apart (snakekit.clearance(q) says how far apart they are), "
              "or go around through a more open pose.")
    if profiled and not at_goal and first_collision_on(straight, spec=spec, margin=allowed) is None:
        advice = ("The straight path between the goals is clear: " + (
            "robot.move_to(q) keeps the joints together along it." if what == "command" else
            "send goals closer together in time (snakekit.joint_trajectory samples a move at 100 Hz) so "
            "the joints keep together along it.") + " " + advice)
    raise CollisionError(
        f"the {what} would fold the arm onto itself: {rule}, and {deepest} {worst.describe(digits=2)} "
        f"(q = {np.round(worst.q, 3).tolist()} rad). Nothing was sent. " + advice,
        when, hit.links, hit.distance, hit.q, margin)
