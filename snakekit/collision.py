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
axis of joint ``j``), whatever the order in which the joints move. So along any path whose
joints move monotonically from goal ``q_k`` to goal ``q_k+1`` (the straight line included),
their distance stays above ``(d_k + d_k+1 - L)/2`` with ``L = sum_j R_j |q_k+1,j - q_k,j|``.
A segment whose bound is above the margin for every pair is safe without looking inside it;
otherwise its midpoint (on the straight line) is computed and each half checked the same way.
The step so shrinks with the largest joint change and grows with the clearance: in Task 2's
sweep (0.13 rad a goal at most) the goals alone prove every segment safe; a move that
grazes the margin is split until a piece is shorter than 0.1 mm of link travel, and is then
refused (the error's distance is the bound, so the check never errs on the unsafe side).
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

    def describe(self) -> str:
        """``"link1 and link4 are 3.2 mm apart"`` (or overlap by ...)."""
        a, b = self.links
        if self.distance < 0:
            return f"{a} and {b} overlap by {-1000 * self.distance:.1f} mm"
        return f"{a} and {b} are {1000 * self.distance:.1f} mm apart"


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


def first_collision(times, positions, *, spec: SnakeSpec = SPEC) -> Clearance | None:
    """The first pose, in time, on the straight path through ``positions`` (N, n_joints)
    [rad] at ``times`` (N,) [s] that brings two non-neighbouring links closer than
    ``spec.collision_margin``; None when the whole path keeps them apart.

    Between goals the time is interpolated linearly. See the module doc for how the path
    between goals is covered.
    """
    c = _checker(spec)
    margin = spec.collision_margin
    positions = np.asarray(positions, dtype=float)
    times = np.asarray(times, dtype=float)
    D = np.array([c.distances(q) for q in positions])
    L = np.abs(np.diff(positions, axis=0)) @ c.radii.T
    bad = D.min(axis=1) < margin
    unproven = np.append(((D[:-1] + D[1:] - L) < 2 * margin).any(axis=1), False)  # segment k: goals k, k+1
    for k in np.flatnonzero(bad | unproven).tolist():  # in time order
        if bad[k]:
            return _at(c, D[k], positions[k], times[k])
        hit = _split(c, positions[k], positions[k + 1], D[k], D[k + 1], times[k], times[k + 1], margin)
        if hit is not None:
            return hit
    return None


def worst_between(q0, q1, t0: float = 0.0, t1: float = 1.0, *, samples: int = 200,
                  spec: SnakeSpec = SPEC) -> Clearance:
    """The closest approach of two non-neighbouring links on the straight path q0 -> q1 [rad],
    among ``samples`` evenly spaced poses (ends included); times from ``t0`` to ``t1`` [s]."""
    c = _checker(spec)
    q0, q1 = as_configuration(q0, spec), as_configuration(q1, spec)
    best = None
    for s in np.linspace(0.0, 1.0, samples):
        q = q0 + s * (q1 - q0)
        k, d = c.closest(q)
        if best is None or d < best.distance:
            best = Clearance(d, c.pair_names[k], q, t0 + s * (t1 - t0))
    return best


def _at(c: _Checker, d: np.ndarray, q: np.ndarray, t: float) -> Clearance:
    k = int(d.argmin())
    return Clearance(float(d[k]), c.pair_names[k], q, float(t))


def _split(c: _Checker, q0, q1, d0, d1, t0, t1, margin) -> Clearance | None:
    """The first pose closer than ``margin`` on the straight segment q0 -> q1 (whose ends are
    not), or None: bisects, earlier half first, until the bound proves each piece safe."""
    L = c.radii @ np.abs(q1 - q0)
    bound = (d0 + d1 - L) / 2
    if (bound >= margin).all():
        return None
    if L.max() < RESOLUTION:  # too short to split: refuse on the bound, the safe side
        k = int(bound.argmin())
        return Clearance(float(bound[k]), c.pair_names[k], (q0 + q1) / 2, (t0 + t1) / 2)
    qm, tm = (q0 + q1) / 2, (t0 + t1) / 2
    dm = np.array(c.distances(qm))
    hit = _split(c, q0, qm, d0, dm, t0, tm, margin)
    if hit is not None:
        return hit
    if dm.min() < margin:
        return _at(c, dm, qm, tm)
    return _split(c, qm, q1, dm, d1, tm, t1, margin)


def check_path(times, positions, *, what: str = "trajectory", spec: SnakeSpec = SPEC) -> None:
    """Raise :class:`~snakekit.errors.CollisionError` if the straight path through
    ``positions`` (N, n_joints) [rad] at ``times`` (N,) [s] brings two non-neighbouring links
    closer than ``spec.collision_margin`` (:func:`first_collision`).

    The message names when (the time, or for ``what="command"``, with times ``[0, 1]``, how
    far along the move from the last goal), the two links, and the closest they come on that
    stretch. For a command whose start is already too close (a robot started folded), only
    the goal is judged, so the arm can move out.
    """
    times, positions = np.asarray(times, dtype=float), np.asarray(positions, dtype=float)
    hit = first_collision(times, positions, spec=spec)
    if hit is not None and what == "command" and hit.time == 0.0:
        hit = first_collision(times[1:], positions[1:], spec=spec)
    if hit is None:
        return
    margin = spec.collision_margin
    k = min(int(np.searchsorted(times, hit.time, side="right")), len(times) - 1)  # the goal after the hit
    worst = worst_between(positions[max(k - 1, 0)], positions[k], times[max(k - 1, 0)], times[k], spec=spec)
    if what == "command":
        where = ("at the goal" if hit.time == 1.0 else
                 f"{100 * hit.time:.0f} % of the way from the last goal, on the straight path")
        deepest = "at the goal" if worst.time == 1.0 else f"{100 * worst.time:.0f} % of the way"
        when = None
    else:
        where, when = f"at t = {hit.time:.3f} s", hit.time
        deepest = f"at t = {worst.time:.3f} s"
    raise CollisionError(
        f"the {what} would fold the arm onto itself: {where}, {hit.links[0]} and {hit.links[1]} come "
        f"closer than the {1000 * margin:.0f} mm margin, and {deepest} {worst.describe()} "
        f"(q = {np.round(worst.q, 3).tolist()} rad). Nothing was sent. Choose goals that keep the links "
        "apart (snakekit.clearance(q) says how far apart they are), or go around through a more open pose.",
        when, hit.links, hit.distance, hit.q, margin)
