"""An independent measure of the arm's self-clearance, for the tests: the links as convex
polygons in the plane, placed by the arm's planar forward kinematics written out with
trigonometry, and their distance by elementary geometry. It shares with the kit only the
spec's numbers and each body's corner points (the shape), not Pinocchio, coal or the kit's
frames.
"""

from __future__ import annotations

import numpy as np

from snakekit.model import SPEC, collision_points


def _hull(points: np.ndarray) -> np.ndarray:
    """The convex hull of 2D ``points``, counter-clockwise (Andrew's monotone chain)."""
    pts = sorted(set(map(tuple, np.round(points, 12))))

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


SHAPES = [_hull(p[:, :2]) for p in collision_points(SPEC)]  # body frames, base to tip


def body_polygons(q, spec=SPEC) -> list[np.ndarray]:
    """Each body's polygon in the world plane at joint angles ``q`` [rad]."""
    out = [SHAPES[0]]
    origin, theta = np.zeros(2), 0.0
    for k, qk in enumerate(np.asarray(q, dtype=float)):
        if k:
            origin = origin + spec.link_length * np.array([np.cos(theta), np.sin(theta)])
        theta += qk
        c, s = np.cos(theta), np.sin(theta)
        out.append(SHAPES[k + 1] @ np.array([[c, s], [-s, c]]) + origin)
    return out


def _point_segment(p, a, b) -> float:
    ab = b - a
    t = np.clip(np.dot(p - a, ab) / np.dot(ab, ab), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + t * ab)))


def _separated(A, B) -> bool:
    """Separating-axis test of two convex polygons."""
    for P in (A, B):
        edges = np.roll(P, -1, axis=0) - P
        for n in np.column_stack([-edges[:, 1], edges[:, 0]]):
            a, b = A @ n, B @ n
            if a.max() < b.min() or b.max() < a.min():
                return True
    return False


def polygon_distance(A, B) -> float:
    """Distance [m] between two convex polygons; -1.0 when they overlap."""
    if not _separated(A, B):
        return -1.0
    best = np.inf
    for P, Q in ((A, B), (B, A)):
        for p in P:
            for a, b in zip(Q, np.roll(Q, -1, axis=0)):
                best = min(best, _point_segment(p, a, b))
    return best


def planar_clearance(q, spec=SPEC) -> float:
    """The least distance [m] between bodies that are not neighbours in the chain (-1: overlap)."""
    polys = body_polygons(q, spec)
    return min(polygon_distance(polys[a], polys[b])
               for a in range(len(polys)) for b in range(a + 2, len(polys)))
