"""Exercises the grader judges by a rule of its own, not by closeness to the instructor's numbers.

Most exercises are judged case by case against the instructor solution's results at the same
hidden cases (:func:`grader.scoring.score.score_exercise`). Some have more than one right answer: the
two angles that put a two-link tip on a target (either elbow), an IK solution (any angles that
put the tool on the target inside the limits), a move on the simulator (it ends where the
servo settles). For those a rule below judges each case, in the grader's own process, from the
case's arguments and the student's result, with the exercise's tolerance. A case where the
instructor's solution raises is judged before any rule: the student must raise the same type.

Each rule takes ``(args, result, tol)`` -- the case's positional arguments, the student's result
(name -> array; a plain return value is ``"value"``) and the tolerances -- and returns
``(right, why)``: whether the case is right (or the share of it that is, a number in [0, 1])
and, if not, what is wrong, with numbers.
``RULES`` maps grade ids to rules.
"""

from __future__ import annotations

import numpy as np

from snakekit.mistakes import known_mistake, pose_mistakes
from snakekit.model import SPEC

__all__ = ["RULES"]


def _value(result: dict, shape: tuple, what: str, name: str = "value", called: str = ""):
    """The result's array ``name`` of ``shape``, or (None, why not); ``called``: what the missing value is, in the
    student's words (``what`` where it is not said)."""
    if name not in result:
        if name == "value":   # the student's function returned a dict of its own: its keys are the student's
            return None, f"{what} handed in {', '.join(sorted(result))}, expected one array."
        return None, f"your result does not hold {called or what}."   # a key the test cell made: never shown
    a = np.asarray(result[name], dtype=float)
    if a.shape != shape:
        return None, f"{what} returned shape {a.shape}, expected {shape}."
    if not np.isfinite(a).all():
        return None, f"{what} returned {a.tolist()}: every value must be a finite number."
    return a, ""


def _tool_xy(q) -> np.ndarray:
    """The tool point [x, y] of joint angles ``q`` (rows), by the kit's own FK (the grader's process)."""
    from snakekit.kinematics import tool_pose_2d

    q = np.atleast_2d(q)
    return np.array([tool_pose_2d(row)[:2] for row in q])


# --- lesson 03 ----------------------------------------------------------------------------


def two_link_ik(args, result, tol):
    """``two_link_ik(x, y, l1, l2)``: both rows put the tip on the target; row 0 has q2 >= 0.

    Credit per case: each row whose tip is on the target a quarter (each elbow is judged on its
    own), the order asked (row 0 the elbow with q2 >= 0) the other half, judged once both tips
    are right (the order of wrong angles means nothing)."""
    x, y, l1, l2 = (float(a) for a in args[:4])
    q, why = _value(result, (2, 2), "two_link_ik")
    if q is None:
        return False, why
    tips = np.stack([l1 * np.cos(q[:, 0]) + l2 * np.cos(q[:, 0] + q[:, 1]),
                     l1 * np.sin(q[:, 0]) + l2 * np.sin(q[:, 0] + q[:, 1])], axis=-1)
    off = np.abs(tips - [x, y]).max(axis=1)
    on = off <= tol["atol"] + tol["rtol"] * np.hypot(x, y)
    if not on.all():
        k = int(np.argmax(~on))
        return 0.25 * int(on.sum()), (f"the angles {np.round(q[k], 6).tolist()} (row {k}) put the tip {off[k]:.3g} m "
                                      f"from the target ({x:.6g}, {y:.6g}) m (tolerance {tol['atol']:.2g} m).")
    if q[0, 1] < -1e-9 or q[1, 1] > 1e-9:
        return 0.5, (f"both tips are on the target, but row 0 has q2 = {q[0, 1]:.6g} and row 1 q2 = {q[1, 1]:.6g} "
                     "rad; row 0 is the solution with q2 >= 0 (elbow one way), row 1 the one with q2 <= 0.")
    return True, ""


def ik_loop(args, result, tol):
    """``solve_ik(target[, q0])``: angles inside the joint limits that put the tool on the target; from a
    given start ``q0`` (a zigzag pose near a solution: the cases module's ``_decided_by_start``), angles
    within :data:`START_NEAR` of it, as a loop that starts there ends."""
    target = np.asarray(args[0], dtype=float)[:2]
    q, why = _value(result, (SPEC.n_joints,), "solve_ik")
    if q is None:
        return False, why
    off = float(np.abs(_tool_xy(q)[0] - target).max())
    if ((q < SPEC.lower - 1e-12) | (q > SPEC.upper + 1e-12)).any():
        return False, (f"q={np.round(q, 4).tolist()} is outside the joint limits {SPEC.lower}..{SPEC.upper} rad. "
                       + (CLAMP_AT_LIMITS if (np.abs(q) <= np.pi / 2 + 1e-9).all() else CLAMP_EVERY_STEP))
    if len(args) > 1 and args[1] is not None:
        q0 = np.asarray(args[1], dtype=float)
        far = np.abs(q - q0)
        if far.max() > START_NEAR:
            j = int(far.argmax())
            return False, (f"q={np.round(q, 4).tolist()} is {far[j]:.3g} rad from the start q0 at joint {j + 1}; a loop "
                           f"that starts at q0 ends within {START_NEAR:g} rad of it here. " + START_HINT)
    if off > NEAR * tol["atol"] and (np.abs(q) >= SPEC.upper - 1e-12).any():   # not a loop stopped early
        return False, (f"q={np.round(q, 4).tolist()} has a joint at its limit, with the tool {off * 1000:.3g} mm from "
                       f"the target (tolerance {tol['atol']:.2g} m). " + CLAMP_INSIDE)
    if off > tol["atol"]:
        # near but not within the tolerance asked (a loop that stops too early): half the case
        near = off <= NEAR * tol["atol"]
        return 0.5 if near else False, (f"your angles put the tool {off:.3g} m from the target (tolerance "
                                        f"{tol['atol']:.2g} m){'; near, not on it: half of this case' if near else ''}.")
    return True, ""


#: 3.3: a tool within NEAR times the tolerance (1 mm at 1e-5 m) is near the target: half a case.
NEAR = 100.0
#: 3.3: from a start q0 near a solution the lesson's loop ends within 0.25 rad of q0 (the cases are drawn so);
#: ignoring q0 it ends 1 rad away or more. 0.5 rad [each joint] lies between the two.
START_NEAR = 0.5
#: 3.3: what to do when q leaves the limits, in the words of the notebook's check: a clamp at +-pi/2 (1.5708 rad)
#: lets a joint 0.8 mrad past them; none lets it anywhere.
CLAMP_AT_LIMITS = "Clamp at the arm's limits, spec.lower and spec.upper (+-1.57 rad), not at +-pi/2."
CLAMP_EVERY_STEP = "Clamp q after every step: np.clip(q, spec.lower, spec.upper)."
CLAMP_INSIDE = ("Clamp inside the loop, after every step: a clamp once at the end moves a joint the loop needed past "
                "its limit back, and the tool off the target.")
#: 3.3: what to do, in the words of the notebook's check.
START_HINT = "Start from q0 when it is given: q = np.zeros(5) if q0 is None else np.asarray(q0, dtype=float)."


def task1(args, result, tol):
    """Task 1 on the simulator: one move per target, each ending with the tool within 3 mm of it.

    Where each move ended is the recorded run's last angles (``final_q``: the grader computes
    the tool from them); the poses the function returned (``poses``, one (x, y, heading) per
    move) must be the poses the arm measured there, within :data:`POSE_TOL` (the targets
    themselves are a few tenths of a millimetre off: they are not what the exercise asks)."""
    from snakekit.kinematics import tool_pose_2d

    targets = np.atleast_2d(np.asarray(args[0], dtype=float))
    name = "final_q" if {"final_q", "poses"} & set(result) else "value"
    q, why = _value(result, (len(targets), SPEC.n_joints), "the moves (their final angles)", name,
                    "the joint angles the arm measured at the end of each move")
    if q is None:
        return False, why
    tool = _tool_xy(q)
    off = np.abs(tool - targets[:, :2]).max(axis=1)
    bad = np.nonzero(off > tol["atol"])[0]
    if len(bad):
        k = int(bad[0])
        return False, (f"move {k + 1} to ({targets[k, 0]:.4f}, {targets[k, 1]:.4f}) m ended with the tool at "
                       f"({tool[k, 0]:.4f}, {tool[k, 1]:.4f}) m, {off[k] * 1000:.3g} mm off (tolerance "
                       f"{tol['atol'] * 1000:.3g} mm).")
    measured = np.array([tool_pose_2d(row) for row in q])   # the poses the arm measured at each move's end
    turned = measured[:, 2]
    off = np.angle(np.exp(1j * (turned - targets[:, 2])))
    bad = np.nonzero(np.abs(off) > HEADING_TOL)[0]
    if len(bad):
        k = int(bad[0])
        target = tuple(round(float(v), 4) for v in targets[k])
        return False, (f"move {k + 1} to target {target} ended with the tool's heading at {turned[k]:.4f} rad, "
                       f"{off[k]:+.3g} rad from the target's (tolerance {HEADING_TOL:g} rad: the servos settle within "
                       f"a few mrad). {HEADING_HINT[0].upper()}{HEADING_HINT[1:]}")
    if "poses" in result:
        poses, why = _value(result, (len(targets), 3), "task1", "poses", "the tool poses task1 returned")
        if poses is None:   # what it looks like, in the words of the notebook's check
            kind = known_mistake(np.asarray(result["poses"], dtype=float), pose_mistakes(q, list(measured)), tol=1e-9)
            return False, why + " " + (kind[0].upper() + kind[1:] if kind else "One tool pose (x, y, heading) per move.")
        off = np.abs(poses - measured).max(axis=1)
        if (off > POSE_TOL).any():
            k = int(np.argmax(off > POSE_TOL))
            said = (f"task1 returned the pose ({poses[k, 0]:.4f} m, {poses[k, 1]:.4f} m, {poses[k, 2]:.4f} rad) for "
                    f"move {k + 1}, but the arm measured ({measured[k, 0]:.4f} m, {measured[k, 1]:.4f} m, "
                    f"{measured[k, 2]:.4f} rad) at its end (tolerance {POSE_TOL:g}).")
            if np.allclose(poses, targets[:, :3], rtol=0.0, atol=1e-9):
                said += (" These are the targets you set, not where the arm ended: return the pose it measured, "
                         "snakekit.tool_pose_2d(run.measured.positions[-1]), for each move.")
            return False, said
    return True, ""


#: 3.4: a returned pose is the measured one within 1e-6 (m, rad): the same numbers, computed as the exercise says.
POSE_TOL = 1e-6
#: 3.4: each move ends turned to its target's heading: the five joints' settling adds up to a few mrad (at most
#: 5.2 mrad in 15 moves), and a heading left out or given in degrees is off by tenths of a radian or more.
HEADING_TOL = 0.05
#: 3.4: what to do, in the words of the notebook's check.
HEADING_HINT = "each target is (x, y, heading), the heading in radians: pass all three, panel.set_target(x, y, heading)."


#: grade id -> rule. The tolerances come from the reference (the cases module's TOLERANCES, else references.OVERRIDES).
RULES = {
    "ex03_1_two_link_ik_test": two_link_ik,
    "ex03_3_ik_loop_test": ik_loop,
    "ex03_4_task1_test": task1,
}
