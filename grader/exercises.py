"""Exercises the grader judges by a rule of its own, not by closeness to the instructor's numbers.

Most exercises hand in a function's outputs at hidden inputs, and the grader compares them with
the instructor's (:func:`grader.compare.values`). Some hidden tests judge something else: the
tip that two-link angles reach (other angles reach it as well), the tool that an IK solution
puts on target, a recorded move's end within the servo's settling. For those the kernel hands in
the hidden inputs and the student's raw results, and the rule below recomputes, in the grader's
own process, what the hidden test judges, with the hidden test's tolerance. The hidden inputs
still have to equal the reference's (:func:`grader.score.score_exercise` checks that first).

Each rule takes the hand-in (name -> array) and the exercise's tolerances and returns
:class:`grader.compare.Check` objects. ``RULES`` maps grade ids to rules.
"""

from __future__ import annotations

import numpy as np

from snakekit.model import SPEC

from .compare import Check

__all__ = ["RULES"]


def _cases(ok, what: str, first_bad: str = "", weight: float = 1.0) -> Check:
    """Credit as the share of hidden cases that pass; the message names the first that does not."""
    ok = np.asarray(ok, dtype=bool)
    n, nbad = len(ok), int((~ok).sum())
    if nbad == 0:
        return Check(what, 1.0, f"{what}: all {n} hidden cases right.", weight)
    return Check(what, 1.0 - nbad / n, f"{what}: {nbad} of {n} hidden cases wrong; first: {first_bad}", weight)


def _shape(h, name, shape, what) -> Check | None:
    a = np.asarray(h.get(name))
    if h.get(name) is None:
        return Check(what, 0.0, f"{what}: nothing was handed in ('{name}'): your function raised an error on the "
                                "hidden inputs, or called a library function the exercise asks you to write.")
    if a.shape != tuple(shape):
        return Check(what, 0.0, f"{what}: results of shape {a.shape}, expected {tuple(shape)}.")
    return None


def _first_failed(ok) -> int:
    """Index of the first failed case (0 when all passed: the message is then not shown)."""
    return int(np.argmax(~ok)) if not ok.all() else 0


def _tool_xy(q) -> np.ndarray:
    """The tool point [x, y] of each row of joint angles, by the kit's own FK (the grader's process)."""
    from snakekit.kinematics import tool_pose_2d

    return np.array([tool_pose_2d(row)[:2] for row in q])


def _within(got, expected, atol, rtol=1e-9):
    return np.abs(np.asarray(got, float) - expected) <= atol + rtol * np.abs(expected)


def _split(rows, n, width):
    """Rows tagged with their case index in column 0 -> one array per case (shape (k, width)).

    None when the rows are not ``width`` numbers plus the index (the results had another shape).
    """
    rows = np.asarray(rows, dtype=float)
    if rows.ndim != 2 or rows.shape[1] != width + 1:
        return None
    return [rows[rows[:, 0] == k, 1:] for k in range(n)]


def _wrong_width(h, what, width) -> Check:
    return Check(what, 0.0, f"{what}: results of shape {np.shape(h['outputs'])[1:]} per row, expected {width} "
                            "numbers per row.")


# --- lesson 03 ----------------------------------------------------------------------------


def _tips(q, l1, l2):
    return np.stack([l1 * np.cos(q[..., 0]) + l2 * np.cos(q[..., 0] + q[..., 1]),
                     l1 * np.sin(q[..., 0]) + l2 * np.sin(q[..., 0] + q[..., 1])], axis=-1)


def two_link_ik(h, tol) -> list[Check]:
    """Both elbows' angles must put the tip on the target (1e-9 m), row 0 with q2 >= 0."""
    cases = h["inputs"]
    bad = _shape(h, "outputs", (len(cases), 2, 2), "two_link_ik")
    if bad:
        return [bad]
    q = h["outputs"]
    x, y, l1, l2 = cases.T
    tips = _tips(q, l1[:, None], l2[:, None])                       # (n, 2 solutions, 2)
    target = np.stack([x, y], axis=-1)[:, None, :]
    on_target = _within(tips, target, tol["atol"], tol["rtol"]).all(axis=(1, 2))
    ordered = (q[:, 0, 1] >= -1e-9) & (q[:, 1, 1] <= 1e-9)
    k = _first_failed(on_target)
    off = np.abs(tips[k] - target[k]).max()
    m = _first_failed(ordered)
    return [_cases(on_target, "tip of both solutions",
                   f"target ({x[k]:.6g}, {y[k]:.6g}) m, links {l1[k]:.6g} and {l2[k]:.6g} m: the angles "
                   f"{np.round(q[k], 6).tolist()} put the tip {off:.3g} m away (tolerance {tol['atol']:.2g} m)."),
            _cases(ordered, "elbow order",
                   f"target ({x[m]:.6g}, {y[m]:.6g}) m: row 0 has q2 = {q[m, 0, 1]:.6g} and row 1 q2 = "
                   f"{q[m, 1, 1]:.6g} rad; row 0 is the solution with q2 >= 0, row 1 the one with q2 <= 0.")]


def ik_loop(h, tol) -> list[Check]:
    """The solution must lie inside the joint limits and put the tool on the target (1e-5 m)."""
    targets = h["inputs"]
    bad = _shape(h, "outputs", (len(targets), SPEC.n_joints), "solve_ik")
    if bad:
        return [bad]
    q = h["outputs"]
    tool = _tool_xy(q)
    on_target = _within(tool, targets, tol["atol"], 0.0).all(axis=1)
    inside = ((q >= SPEC.lower - 1e-12) & (q <= SPEC.upper + 1e-12)).all(axis=1)
    k = _first_failed(on_target)
    m = _first_failed(inside)
    return [_cases(on_target, "tool on target",
                   f"target ({targets[k, 0]:.6g}, {targets[k, 1]:.6g}) m: your angles put the tool "
                   f"{np.abs(tool[k] - targets[k]).max():.3g} m away (tolerance {tol['atol']:.2g} m)."),
            _cases(inside, "joint limits",
                   f"target ({targets[m, 0]:.6g}, {targets[m, 1]:.6g}) m: q={np.round(q[m], 4).tolist()} is outside "
                   f"the joint limits +-{SPEC.upper} rad.")]


def task1(h, tol) -> list[Check]:
    """One move per target, each ending with the tool within 3 mm of it (the servo settles)."""
    targets = h["inputs"]
    bad = _shape(h, "outputs", (len(targets), SPEC.n_joints), "task1 (the final angles of its moves)")
    if bad:
        return [bad]
    tool = _tool_xy(h["outputs"])
    ok = _within(tool, targets[:, :2], tol["atol"], 0.0).all(axis=1)
    k = _first_failed(ok)
    return [_cases(ok, "tool after each move",
                   f"move {k + 1} to ({targets[k, 0]:.4f}, {targets[k, 1]:.4f}) m ended with the tool at "
                   f"({tool[k, 0]:.4f}, {tool[k, 1]:.4f}) m, {np.abs(tool[k] - targets[k, :2]).max() * 1000:.3g} mm "
                   f"off (tolerance {tol['atol'] * 1000:.3g} mm).")]


# --- lesson 04 ----------------------------------------------------------------------------


def sample_move(h, tol) -> list[Check]:
    """The quintic move sampled at the rate: every goal time and angle, recomputed here."""
    cases = h["in_cases"]                                   # rows: q_start (5), q_end (5), duration, rate
    if h.get("outputs") is None:
        return [_shape(h, "outputs", (), "sample_move")]
    got = _split(h["outputs"], len(cases), 1 + SPEC.n_joints)
    if got is None:
        return [_wrong_width(h, "sample_move (time and 5 angles per goal)", 1 + SPEC.n_joints)]
    ok, first = [], ""
    for k, (c, g) in enumerate(zip(cases, got)):
        a, b, T, rate = c[:5], c[5:10], c[10], c[11]
        times = np.arange(int(round(T * rate)) + 1) / rate
        r = np.clip(times / T, 0, 1)
        positions = a + np.outer(10 * r ** 3 - 15 * r ** 4 + 6 * r ** 5, b - a)
        where = f"a {T:.4g} s move at {rate:g} Hz"
        if len(g) != len(times):
            ok.append(False)
            first = first or f"{where} has {len(times)} goals, yours {len(g)}."
            continue
        dt, dq = np.abs(g[:, 0] - times).max(), np.abs(g[:, 1:] - positions).max()
        good = bool(_within(g[:, 0], times, 0.0, tol["rtol"]).all() and
                    _within(g[:, 1:], positions, tol["atol"], tol["rtol"]).all())
        ok.append(good)
        if not good and not first:
            first = f"{where}: times off by up to {dt:.3g} s, angles by up to {dq:.3g} rad (tolerance {tol['atol']:.2g} rad)."
    return [_cases(ok, "sample_move", first)]


def limit_violations(h, tol) -> list[Check]:
    """Every (time, joint, kind) limit violation of the hidden trajectories, recomputed here."""
    points = np.asarray(h["in_points"], dtype=float)        # rows: case, t, q1..q5
    n = int(points[:, 0].max()) + 1
    if h.get("outputs") is None:
        return [_shape(h, "outputs", (), "limit_violations")]
    got = _split(h["outputs"], n, 3)
    if got is None:
        return [_wrong_width(h, "limit_violations (time, joint, kind)", 3)]
    ok, first = [], ""
    for k, (pts, g) in enumerate(zip(_split(points, n, 1 + SPEC.n_joints), got)):
        t, p = pts[:, 0], pts[:, 1:]
        want = [[t[i], j + 1, 0] for i, j in zip(*np.nonzero(np.abs(p) > SPEC.upper))]
        speed = np.abs(np.diff(p, axis=0)) / np.diff(t)[:, None]
        want += [[t[i + 1], j + 1, 1] for i, j in zip(*np.nonzero(speed > SPEC.velocity_limit))]
        want = np.array(sorted(want), dtype=float).reshape(-1, 3)
        good = g.shape == want.shape and bool(_within(g, want, tol["atol"], tol["rtol"]).all())
        ok.append(good)
        if not good and not first:
            first = (f"random trajectory {k + 1} ({len(t)} points) has {len(want)} violations (time, joint, kind), "
                     f"you found {len(g)}." if g.shape != want.shape else
                     f"random trajectory {k + 1}: the rows differ from the violations (time, joint, kind), "
                     "sorted by time, then joint, then kind.")
    return [_cases(ok, "limit_violations", first)]


# --- lesson 07 ----------------------------------------------------------------------------


def safe_move(h, tol) -> list[Check]:
    """The planned duration 1.875 d / v_max (at least 0.2 s) and the end within servo settling."""
    target = h["inputs"]
    bad = _shape(h, "outputs", (1 + 2 * SPEC.n_joints,), "safe_move")
    if bad:
        return [bad]
    out = h["outputs"]
    planned, start, final = out[0], out[1:6], out[6:11]
    d = float(np.abs(target - start).max())
    want = max(1.875 * d / SPEC.velocity_limit, 0.2)
    off = float(np.abs(final - target).max())
    return [Check("move duration", float(abs(planned - want) <= tol["duration"]),
                  f"move duration: a move of {d:.3f} rad was planned to take {planned:.3f} s, expected {want:.3f} s "
                  f"(tolerance {tol['duration']:g} s).", 1.0),
            Check("final angles", float(off <= tol["atol"]),
                  f"final angles: up to {off:.3g} rad from the target (tolerance {tol['atol']:g} rad, servo settling).",
                  1.0)]


#: grade id -> rule. The tolerances come from the reference (references.OVERRIDES).
RULES = {
    "ex03_1_two_link_ik_test": two_link_ik,
    "ex03_3_ik_loop_test": ik_loop,
    "ex03_4_task1_test": task1,
    "ex04_3_sample_10hz_test": sample_move,
    "ex04_4_limit_check_test": limit_violations,
    "ex07_2_safe_move_test": safe_move,
}
