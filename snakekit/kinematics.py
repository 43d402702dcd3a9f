"""Forward kinematics, Jacobians and inverse kinematics, on Pinocchio.

Pinocchio reads the URDF generated from :data:`snakekit.model.SPEC`. Poses are 4x4
homogeneous transforms ``T_world_<frame>`` in metres; angles in radians. IK, the closest
reachable point and the workspace leave out poses that fold the arm onto itself
(:mod:`snakekit.collision`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pinocchio as pin

from .collision import clearance, collides, collision_free
from .errors import NotFiniteError, ShapeError, UnreachableTargetError
from .model import SPEC, SnakeSpec, urdf
from .validate import (as_configuration, check_count, check_limits, check_seed, check_spec, number,  # noqa: F401
                       real_array)  # (lessons use them)


@dataclass(frozen=True)
class _Kin:
    spec: SnakeSpec
    model: pin.Model
    data: pin.Data
    tool: int
    joint_frames: tuple[int, ...]


def _kin(spec: SnakeSpec = SPEC) -> _Kin:
    """The Pinocchio model of ``spec`` (built once; the default spec skips the cache lookup)."""
    global _DEFAULT
    check_spec(spec)
    if spec is SPEC:
        if _DEFAULT is None:
            _DEFAULT = _build(SPEC)
        return _DEFAULT
    return _build(spec)


_DEFAULT: _Kin | None = None


@lru_cache(maxsize=4)
def _build(spec: SnakeSpec) -> _Kin:
    model = pin.buildModelFromXML(urdf(spec))
    tool = model.getFrameId("tool")
    frames = tuple(model.getFrameId(f"link{i + 1}") for i in range(spec.n_joints))
    return _Kin(spec, model, model.createData(), tool, frames)


def pinocchio_model(spec: SnakeSpec = SPEC) -> tuple[pin.Model, pin.Data, int]:
    """The Pinocchio model, its data and the tool frame id (for lessons and benchmarks)."""
    k = _kin(spec)
    return k.model, k.data, k.tool


def forward_kinematics(q, *, spec: SnakeSpec = SPEC) -> np.ndarray:
    """Tool pose ``T_world_tool`` (4x4) for joint angles ``q`` [rad].

    >>> import numpy as np, snakekit
    >>> T = snakekit.forward_kinematics(np.zeros(5))
    >>> np.round(T[:3, 3], 4).tolist()        # straight arm: 4 x 71 mm + 47.5 mm along x
    [0.3315, 0.0, 0.0]
    """
    k = _kin(spec)
    q = as_configuration(q, spec)
    pin.framesForwardKinematics(k.model, k.data, q)
    return k.data.oMf[k.tool].homogeneous


def joint_frames(q, *, spec: SnakeSpec = SPEC) -> np.ndarray:
    """Poses ``T_world_link<i>`` of every joint frame, then the tool: shape (n_joints+1, 4, 4)."""
    k = _kin(spec)
    q = as_configuration(q, spec)
    pin.framesForwardKinematics(k.model, k.data, q)
    return np.stack([k.data.oMf[f].homogeneous for f in (*k.joint_frames, k.tool)])


def tool_pose_2d(q, *, spec: SnakeSpec = SPEC) -> np.ndarray:
    """Planar tool pose ``(x [m], y [m], heading [rad])``.

    >>> import numpy as np, snakekit
    >>> np.round(snakekit.tool_pose_2d([np.pi / 2, 0, 0, 0, 0]), 4).tolist()
    [0.0, 0.3315, 1.5708]
    """
    T = forward_kinematics(q, spec=spec)
    return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


def jacobian(q, *, spec: SnakeSpec = SPEC) -> np.ndarray:
    """Tool Jacobian (6 x n_joints) in the world-aligned frame at the tool point.

    Rows are (vx, vy, vz, wx, wy, wz): ``[v; w] = J(q) @ qdot``.
    """
    k = _kin(spec)
    q = as_configuration(q, spec)
    return pin.computeFrameJacobian(k.model, k.data, q, k.tool, pin.LOCAL_WORLD_ALIGNED)


_PLANAR_ROWS = [0, 1, 5]


def planar_jacobian(q, *, spec: SnakeSpec = SPEC) -> np.ndarray:
    """Planar tool Jacobian (3 x n_joints): rows (x, y, heading) rates."""
    return jacobian(q, spec=spec)[_PLANAR_ROWS]


def dls_step(q, target_xy, damping: float = 1e-3, *, spec: SnakeSpec = SPEC) -> np.ndarray:
    """One damped least-squares step of the tool point toward ``target_xy`` (lesson 3's step).

    Args:
        q: joint angles [rad].
        target_xy: the tool target (x, y) [m].
        damping: lambda [m]: the step is q + J^T (J J^T + lambda^2 I)^-1 e, with e the tool
            error (x, y) [m] and J the first two rows of :func:`planar_jacobian`.

    Returns:
        The new joint angles [rad], not clamped to the limits.

    >>> np.round(dls_step(np.zeros(5), (0.25, 0.1)), 4).tolist()
    [0.1442, 0.1133, 0.0824, 0.0515, 0.0207]
    """
    q = as_configuration(q, spec)
    target = real_array(target_xy, "target_xy", "(2,)")
    if target.shape != (2,):
        raise ShapeError("target_xy", "(2,): the tool point (x, y) [m]", target.shape)
    if not np.isfinite(target).all():
        raise NotFiniteError(f"target_xy holds NaN or infinity: {target.tolist()}; give finite (x, y) [m]")
    damping = number(damping, "damping", "m", at_least=0, hint="It is lambda, how much the step is damped "
                     "(default: 1e-3)")
    e = target - tool_pose_2d(q, spec=spec)[:2]
    J = planar_jacobian(q, spec=spec)[:2]
    return q + J.T @ np.linalg.solve(J @ J.T + damping ** 2 * np.eye(2), e)


def _wrap(a: float) -> float:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _dls(k: _Kin, target: np.ndarray, use_heading: bool, q: np.ndarray, *, tol: float,
         max_iter: int, damping: float) -> tuple[np.ndarray, np.ndarray]:
    """Damped least squares from ``q``, projected onto the joint limits. Returns (q, error)."""
    lo, hi = k.spec.lower, k.spec.upper
    rows = _PLANAR_ROWS if use_heading else _PLANAR_ROWS[:2]
    model, data, tool = k.model, k.data, k.tool
    lam2 = damping * damping
    eye = np.eye(len(rows))
    err = np.full(len(rows), np.inf)  # no iteration yet: nothing is solved
    for _ in range(max_iter):
        J = pin.computeFrameJacobian(model, data, q, tool, pin.LOCAL_WORLD_ALIGNED)[rows]
        # computeFrameJacobian ran forward kinematics; oMf needs only this frame update.
        M = pin.updateFramePlacement(model, data, tool)
        err[0] = target[0] - M.translation[0]
        err[1] = target[1] - M.translation[1]
        if use_heading:
            err[2] = _wrap(target[2] - np.arctan2(M.rotation[1, 0], M.rotation[0, 0]))
        if abs(err[0]) < tol and abs(err[1]) < tol and (not use_heading or abs(err[2]) < tol):
            return q, err
        q = np.clip(q + J.T @ np.linalg.solve(J @ J.T + lam2 * eye, err), lo, hi)
    return q, err


def _residual(k: _Kin, target: np.ndarray, use_heading: bool, q: np.ndarray) -> np.ndarray:
    """Tool error towards ``target``; heading errors weighted by one link length [m/rad]."""
    pin.framesForwardKinematics(k.model, k.data, q)
    M = k.data.oMf[k.tool]
    e = target[:2] - M.translation[:2]
    if not use_heading:
        return e
    h = _wrap(target[2] - np.arctan2(M.rotation[1, 0], M.rotation[0, 0]))
    return np.array([e[0], e[1], k.spec.link_length * h])


def _closest(k: _Kin, target: np.ndarray, use_heading: bool, starts, *, max_iter: int = 40) -> np.ndarray:
    """The configuration, inside the limits and with the links apart, whose tool comes closest
    to an unreachable target.

    Projected Levenberg-Marquardt from each start: a step is kept only if it brings the tool
    closer, so every run descends to a local minimum of the distance, even with joints
    pressed against their limits. The best of the runs that end with the links apart is
    returned. If every run ends folded (a target inside the arm's own body), the runs are
    made again from the starts that are not folded, keeping only steps that leave the links
    apart, so the answer is never a folded pose.
    """
    best_q, best_f = None, np.inf
    for safe, tries in ((False, starts), (True, [*starts, np.zeros(k.spec.n_joints)])):  # the straight arm: 46 mm apart
        for q in tries:
            q = np.clip(np.asarray(q, dtype=float), k.spec.lower, k.spec.upper)
            if safe and collides(q, spec=k.spec):
                continue
            q, f = _descend(k, target, use_heading, q, max_iter, safe)
            if f < best_f and (safe or not collides(q, spec=k.spec)):
                best_q, best_f = q, f
        if best_q is not None:
            break
    return best_q


def _descend(k: _Kin, target: np.ndarray, use_heading: bool, q: np.ndarray, max_iter: int,
             safe: bool) -> tuple[np.ndarray, float]:
    """One run of :func:`_closest` from ``q``: the configuration it ends at and its squared
    distance; with ``safe``, a step that folds the arm is refused like one that goes farther."""
    lo, hi = k.spec.lower, k.spec.upper
    rows = _PLANAR_ROWS if use_heading else _PLANAR_ROWS[:2]
    scale = np.array([1.0, 1.0, k.spec.link_length])[: len(rows)]
    eye = np.eye(len(rows))
    e = _residual(k, target, use_heading, q)
    f, lam = e @ e, 1e-2
    for _ in range(max_iter):
        J = pin.computeFrameJacobian(k.model, k.data, q, k.tool, pin.LOCAL_WORLD_ALIGNED)[rows]
        J *= scale[:, None]
        while lam < 1e6:
            qn = np.clip(q + J.T @ np.linalg.solve(J @ J.T + lam * eye, e), lo, hi)
            en = _residual(k, target, use_heading, qn)
            fn = en @ en
            if fn < f and not (safe and collides(qn, spec=k.spec)):
                lam = max(lam / 3, 1e-9)
                break
            lam *= 4
        else:
            break  # no step brings the tool closer: a local minimum
        done = f - fn < 1e-9
        q, e, f = qn, en, fn
        if done:
            break
    return q, f


def _closest_configuration(k: _Kin, target: np.ndarray, use_heading: bool, starts, rng) -> np.ndarray:
    """The configuration inside the limits whose tool comes closest to ``target``.

    Projected Levenberg-Marquardt (:func:`_closest`) from the given starts, from the arm
    stretched towards the target, from the arm curled either way, from the three
    workspace-boundary configurations nearest the target, and from a few random poses.
    """
    spec = k.spec
    toward = float(np.clip(np.arctan2(target[1], target[0]), spec.lower, spec.upper))
    curls = []
    for sign in (1.0, -1.0):
        for m in range(1, spec.n_joints):
            c = np.zeros(spec.n_joints)
            c[0], c[1:1 + m] = toward, sign
            curls.append(c)
    stretched = np.zeros(spec.n_joints)
    stretched[0] = toward
    points, configurations = boundary_configurations(spec=spec)
    near = configurations[np.argsort(np.linalg.norm(points - target[:2], axis=1))[:3]]
    randoms = rng.uniform(spec.lower, spec.upper, (4, spec.n_joints))
    starts = [q for q in starts if q is not None]
    return _closest(k, target, use_heading, [*starts, stretched, *curls, *near, *randoms])


def closest_reachable_point(target_xy, heading: float | None = None, q0=None, *,
                            spec: SnakeSpec = SPEC, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The reachable tool pose closest to a target, and the joint angles that reach it.

    The distance is the tool's distance to ``target_xy`` [m], plus, when ``heading`` [rad] is
    given, the heading error weighted by one link length. For a reachable target this is
    the target itself (up to the solver's tolerance).

    Returns:
        ``(x [m], y [m], heading [rad])`` of the closest tool pose, and its joint angles [rad].

    >>> import numpy as np
    >>> pose, q = closest_reachable_point([0.5, 0.0])     # beyond the 0.3315 m reach
    >>> np.round(pose[:2], 4).tolist()
    [0.3315, 0.0]
    """
    k = _kin(spec)
    target_xy, heading = _target(target_xy, heading)
    seed = check_seed(seed)
    target = np.array([*_solver_xy(target_xy, spec), 0.0 if heading is None else heading])
    start = None if q0 is None else np.clip(as_configuration(q0, spec, "q0"), spec.lower, spec.upper)
    q = _closest_configuration(k, target, heading is not None, [start], np.random.default_rng(seed))
    return tool_pose_2d(q, spec=spec), q


def _target(target_xy, heading) -> tuple[np.ndarray, float | None]:
    """The checked target ``(x, y)`` [m] and heading [rad] (or None)."""
    target_xy = real_array(target_xy, "target_xy", "(2,)", "Give the tool target as (x, y) in metres")
    if target_xy.shape != (2,):
        raise ShapeError("target_xy", "(2,)", target_xy.shape, "Give the tool target as (x, y) in metres")
    if not np.isfinite(target_xy).all():
        raise NotFiniteError(f"IK target holds NaN or infinity: {target_xy.tolist()}; give finite (x, y) [m]")
    if heading is not None:
        heading = number(heading, "heading", "rad", hint="Give the tool's heading as an angle from the x axis, "
                         "e.g. heading=numpy.pi / 2 for 'north' (+y); or leave it out")
    return target_xy, heading


#: Targets farther than this many reaches are solved for along their direction, at this
#: distance: the arithmetic stays finite (a target at 1e300 m would overflow), and the
#: closest reachable pose changes by under a millimetre (0.4 mm measured, for targets
#: behind the arm at 1e5 m against 1e9 m; none in front of it).
_FAR = 100.0


def _solver_xy(target_xy: np.ndarray, spec: SnakeSpec) -> np.ndarray:
    dist = float(np.hypot(*target_xy))
    far = _FAR * spec.reach
    return target_xy * (far / dist) if dist > far else target_xy


def _fmt(v: float) -> str:
    return f"{v:.4f}" if abs(v) < 1e4 else f"{v:.4g}"


def inverse_kinematics(target_xy, heading: float | None = None, q0=None, *, spec: SnakeSpec = SPEC,
                       tol: float = 1e-6, max_iter: int = 100, restarts: int = 20,
                       seed: int = 0) -> np.ndarray:
    """Joint angles [rad] that put the tool on ``target_xy`` [m] (and ``heading`` [rad]).

    Damped least squares on the planar Jacobian, clamped to the joint limits, started from
    ``q0`` (default: home) and then from up to ``restarts`` random configurations.

    Raises:
        UnreachableTargetError: no solution within ``tol``; the error carries the closest
            tool point found and its joint angles.
        ConfigurationError: ``tol`` below 1e-12 m or not finite, ``max_iter`` not from 1 to
            10,000, ``restarts`` not from 0 to 1000.
        InputTypeError: a target or heading that is not a real number.

    >>> import numpy as np, snakekit
    >>> q = snakekit.inverse_kinematics([0.25, 0.10])
    >>> np.round(snakekit.tool_pose_2d(q)[:2], 6).tolist()
    [0.25, 0.1]
    """
    k = _kin(spec)
    target_xy, heading = _target(target_xy, heading)
    tol = number(tol, "tol", "m", at_least=1e-12, hint="It is how close the tool must come to the target; "
                 "floating point resolves about 1e-12 m at the arm's scale (default: 1e-6)")
    max_iter = check_count(max_iter, "max_iter", 1, 10_000,
                           hint="It is how many solver steps each start may take (default: 100)")
    restarts = check_count(restarts, "restarts", 0, 1000, hint="It is how many random starts follow q0 (default: 20)")
    seed = check_seed(seed)
    use_heading = heading is not None
    target = np.array([*_solver_xy(target_xy, spec), heading if use_heading else 0.0])
    if q0 is None:
        q0 = spec.home
    else:
        q0 = np.clip(as_configuration(q0, spec, "q0"), spec.lower, spec.upper)

    best_q, best_err = None, np.inf
    rng = np.random.default_rng(seed)
    starts = [q0] + [rng.uniform(spec.lower, spec.upper, spec.n_joints) for _ in range(restarts)]
    dist = float(np.hypot(*target_xy))
    if dist > spec.reach + tol:
        starts = starts[:3]  # certainly out of reach: a few tries find the closest point
    folded = None  # a solution that folds the arm onto itself: searched past, never returned
    for start in starts:
        q, err = _dls(k, target, use_heading, start.copy(), tol=tol, max_iter=max_iter, damping=1e-3)
        n = float(np.abs(err).max())
        if n < tol:
            c = clearance(q, spec=spec)
            if c.distance >= spec.collision_margin:
                return q
            folded = c
            continue
        if n < best_err:
            best_q, best_err = q, n
    what = f"({_fmt(target_xy[0])}, {_fmt(target_xy[1])}) m" + (
        f" with heading {heading:.4f} rad" if use_heading else "")
    if folded is not None:
        safe_q = _closest_configuration(k, target, use_heading, [None], np.random.default_rng(seed))  # as closest_reachable_point
        closest = tool_pose_2d(safe_q, spec=spec)
        raise UnreachableTargetError(
            f"target {what} is reached only with the arm folded onto itself: in the solutions found "
            f"from {len(starts)} starts, {folded.describe()} (they must stay "
            f"{1000 * spec.collision_margin:.0f} mm apart). The closest tool point found with the links apart "
            f"is ({closest[0]:.4f}, {closest[1]:.4f}) m (snakekit.closest_reachable_point). Pick a target the arm "
            "reaches more openly, or try another q0 or more restarts.",
            target=(*target_xy.tolist(), *([heading] if use_heading else [])),
            closest=tuple(closest[:2]), q_closest=safe_q)
    best_q = _closest_configuration(k, target, use_heading, [best_q], rng)
    closest = tool_pose_2d(best_q, spec=spec)
    why = (f"it is {_fmt(dist)} m from joint 1 and the arm reaches {spec.reach:.4f} m"
           if dist > spec.reach else "the joint limits keep the tool from it")
    raise UnreachableTargetError(
        f"target {what} is out of reach: {why}. The closest tool point found is "
        f"({closest[0]:.4f}, {closest[1]:.4f}) m, heading {closest[2]:.4f} rad; "
        f"pick a target inside the workspace (see snakekit.workspace_points).",
        target=(*target_xy.tolist(), *([heading] if use_heading else [])), closest=tuple(closest[:2]), q_closest=best_q)


def workspace_points(n: int = 5000, *, seed: int = 0, spec: SnakeSpec = SPEC) -> np.ndarray:
    """Tool points (n, 2) [m] of uniformly random configurations inside the limits that keep
    the links apart (:func:`snakekit.collision.collides`: folded poses are left out).

    Raises:
        ConfigurationError: ``n`` is not a whole number from 1 to 1,000,000.
    """
    n = check_count(n, "n", 1, 1_000_000, hint="It is how many random poses are drawn (default: 5000)")
    seed = check_seed(seed)
    k = _kin(spec)
    rng = np.random.default_rng(seed)
    out = np.empty((n, 2))
    i = 0
    while i < n:
        for q in rng.uniform(spec.lower, spec.upper, (n - i, spec.n_joints)):
            if collides(q, spec=spec):
                continue
            pin.framesForwardKinematics(k.model, k.data, q)
            out[i] = k.data.oMf[k.tool].translation[:2]
            i += 1
    return out


# --- the workspace ---------------------------------------------------------------------


def workspace_boundary(*, bins: int = 120, samples: int = 20000, refine: int = 60, seed: int = 0,
                       spec: SnakeSpec = SPEC) -> np.ndarray:
    """Outer boundary of the tool's reachable points, as a closed polygon (bins, 2) [m].

    See :func:`boundary_configurations` for how it is found.
    """
    return boundary_configurations(bins=bins, samples=samples, refine=refine, seed=seed, spec=spec)[0].copy()


def boundary_configurations(*, bins: int = 120, samples: int = 20000, refine: int = 60, seed: int = 0,
                            spec: SnakeSpec = SPEC) -> tuple[np.ndarray, np.ndarray]:
    """Outer boundary of the tool's reachable points, and the joint angles reaching them:
    :func:`_boundary_configurations`, with its options checked.

    Raises:
        ConfigurationError: ``bins`` not from 3 to 10,000, ``samples`` not from 1 to
            1,000,000, ``refine`` not from 0 to 1000, or a ``seed`` that is not a whole number >= 0.
    """
    return _boundary_configurations(
        bins=check_count(bins, "bins", 3, 10_000, hint="It is how many directions the boundary has (default: 120)"),
        samples=check_count(samples, "samples", 1, 1_000_000, hint="It is how many random poses are drawn "
                            "(default: 20000)"),
        refine=check_count(refine, "refine", 0, 1000, hint="It is how many rounds of small steps push the boundary "
                           "out (default: 60)"),
        seed=check_seed(seed), spec=check_spec(spec))


@lru_cache(maxsize=8)
def _boundary_configurations(*, bins: int, samples: int, refine: int, seed: int,
                             spec: SnakeSpec) -> tuple[np.ndarray, np.ndarray]:
    """Outer boundary of the tool's reachable points, as a closed polygon (bins, 2) [m].

    For each of ``bins`` directions around joint 1 it keeps the farthest tool point found
    among ``samples`` random configurations and the evenly curled ones (joints 2..n bent
    alike), leaving out those that fold the arm onto itself, then pushes each direction's best configuration outwards with ``refine`` small
    random steps (a step that lands in another direction improves that one). Every vertex
    is a reachable tool point.

    Returns:
        the boundary points (M, 2) [m] and the joint angles (M, n_joints) [rad] reaching
        them (cached; read-only arrays).
    """
    rng = np.random.default_rng(seed)
    n = spec.n_joints
    grid = np.linspace(spec.lower, spec.upper, 61)
    qs = np.empty((samples + grid.size ** 2, n))
    qs[:samples] = rng.uniform(spec.lower, spec.upper, (samples, n))
    qs[samples:, 0] = np.repeat(grid, grid.size)  # curled: joint 1 at a, joints 2..n all at b
    qs[samples:, 1:] = np.tile(grid, grid.size)[:, None]
    # filled in place: a list of ~24,000 poses would hold as many small arrays at once
    qs = qs[collision_free(qs, spec=spec)]  # folded poses are not part of the workspace
    pts = np.empty((len(qs), 2))
    k = _kin(spec)
    for i, q in enumerate(qs):
        pin.framesForwardKinematics(k.model, k.data, q)
        pts[i] = k.data.oMf[k.tool].translation[:2]

    def bin_of(p):
        a = np.arctan2(p[..., 1], p[..., 0])
        return np.minimum(((a + np.pi) / (2 * np.pi) * bins).astype(int), bins - 1)

    idx, rad = bin_of(pts), np.hypot(pts[:, 0], pts[:, 1])
    best_r = np.full(bins, -1.0)
    best_q = np.zeros((bins, n))
    best_p = np.zeros((bins, 2))
    for i in np.argsort(rad):  # ascending: the farthest point of each bin is written last
        best_r[idx[i]], best_q[idx[i]], best_p[idx[i]] = rad[i], qs[i], pts[i]
    for step in np.geomspace(0.3, 0.01, refine):
        for b in np.flatnonzero(best_r > 0):
            q = np.clip(best_q[b] + rng.normal(0, step, n), spec.lower, spec.upper)
            p = forward_kinematics(q, spec=spec)[:2, 3]
            r, k = float(np.hypot(*p)), int(bin_of(p))
            if r > best_r[k] and not collides(q, spec=spec):  # farther, for whichever direction it lands in
                best_r[k], best_q[k], best_p[k] = r, q, p
    keep = best_r > 0
    points, configurations = best_p[keep], best_q[keep]
    points.setflags(write=False)
    configurations.setflags(write=False)
    return points, configurations
