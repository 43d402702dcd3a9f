"""Score one exercise from what the student's kernel handed in, against the reference.

Runs in the grader's own process: nothing here executes student code. A hand-in is a plain
``.npz`` (read with ``allow_pickle=False``); everything in it is checked before it is used.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from snakekit.errors import SnakekitError
from snakekit.trajectory import Trajectory

from . import compare
from .exercises import RULES
from .references import TASK2, Reference

__all__ = ["ExerciseScore", "read_handin", "score_exercise"]


@dataclass(frozen=True)
class ExerciseScore:
    """The grader's verdict on one autograded test cell.

    Attributes:
        grade_id: the test cell's nbgrader id.
        score, max_score: points.
        status: ``scored``, ``missing``, ``inconsistent`` or ``tampered``.
        message: what the student reads: the checks that failed, with numbers.
        checks: the individual checks (trajectory exercises).
        curves: for plots: name -> (times, positions) of the student's and the reference's runs.
    """

    grade_id: str
    score: float
    max_score: float
    status: str
    message: str
    checks: tuple = ()
    curves: dict = field(default_factory=dict, repr=False)


def read_handin(path: Path) -> dict:
    """The arrays of a hand-in file. Raises ValueError if it is not a plain ``.npz``."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise ValueError(f"the hand-in file is not a readable .npz ({type(e).__name__})") from e


def _zero(gid, max_score, status, message):
    return ExerciseScore(gid, 0.0, max_score, status, message)


def score_exercise(grade_id: str, handin: dict | None, reference: Reference, max_score: float) -> ExerciseScore:
    """Points for one test cell: the hand-in checked for consistency, then compared."""
    ex = reference.exercises[grade_id]
    ref = reference.arrays[grade_id]
    if handin is None:
        return _zero(grade_id, max_score, "missing",
                     "nothing was handed in: the test cell stopped before it reached your results "
                     "(an error in your code, a timeout, or the kernel stopped).")
    for name in ex["inputs"]:
        if name not in handin:
            return _zero(grade_id, max_score, "inconsistent", f"hand-in lacks the hidden input '{name}'.")
        got, want = np.asarray(handin[name]), ref[name]
        if got.shape != want.shape or not np.array_equal(got, want):
            diff = (f"max difference {np.nanmax(np.abs(got.astype(float) - want)):.3g}"
                    if got.shape == want.shape and got.dtype.kind in "fiu" else f"shape {got.shape}, expected {want.shape}")
            return _zero(grade_id, max_score, "inconsistent",
                         f"hand-in inconsistent: the hidden input '{name}' is not the one the test gave ({diff}).")
    for name, a in handin.items():
        if np.asarray(a).dtype.kind not in "fiub":
            return _zero(grade_id, max_score, "inconsistent", f"hand-in inconsistent: '{name}' is not numbers.")
        if np.asarray(a).dtype.kind in "fc" and not np.isfinite(a).all():
            return _zero(grade_id, max_score, "inconsistent",
                         f"'{name}' holds NaN or infinity (first at index "
                         f"{tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])}); every value must be finite.")
    if ex["kind"] == "values":
        return _score_values(grade_id, handin, ex, ref, max_score)
    return _score_motion(grade_id, handin, ex, ref, max_score)


def _score_values(gid, handin, ex, ref, max_score) -> ExerciseScore:
    tol = ex["tolerances"]
    if gid in RULES:  # the grader recomputes what the hidden test judges (grader.exercises)
        checks = RULES[gid](handin, tol)
        if "flags" in ex["outputs"]:
            checks.append(_flags(handin, ref))
        total = sum(c.weight for c in checks)
        fraction = sum(c.weight * c.fraction for c in checks) / total
        msg = " ".join(c.message for c in checks if not c.passed) or "all hidden cases within tolerance."
        return ExerciseScore(gid, round(fraction * max_score, 4), max_score, "scored", msg, tuple(checks))
    inputs = ref[ex["inputs"][0]] if len(ex["inputs"]) == 1 else None
    checks = []
    for name in ex["outputs"]:
        if name == "flags":
            checks.append(_flags(handin, ref))
            continue
        if name not in handin:
            return _zero(gid, max_score, "missing",
                         f"no '{name}' was handed in: your function raised an error (or called the library "
                         "function the exercise asks you to write) on the hidden inputs.")
        checks.append(compare.values(handin[name], ref[name], rtol=tol["rtol"], atol=tol["atol"],
                                     what=_label(gid) if name == "outputs" else name, inputs=inputs))
    fraction = float(np.mean([c.fraction for c in checks])) if checks else 1.0
    msg = " ".join(c.message for c in checks if not c.passed) or "all hidden cases within tolerance."
    return ExerciseScore(gid, round(fraction * max_score, 4), max_score, "scored", msg, tuple(checks))


def _flags(handin, ref) -> compare.Check:
    """The verdicts (1 passed, 0 failed) of the hidden checks that come after the results: a
    refusal, an error that must be raised, an edge case. The kernel reports them."""
    want = np.asarray(ref["flags"], dtype=float)
    got = np.asarray(handin.get("flags", np.zeros_like(want)), dtype=float)
    if got.shape != want.shape:
        return compare.Check("other hidden checks", 0.0, f"other hidden checks: {got.size} verdicts handed in, "
                                                          f"expected {want.size}.")
    failed = int((got != want).sum())
    return compare.Check("other hidden checks", 1.0 - failed / want.size,
                         f"other hidden checks (a refusal, an error to raise, an edge case): {failed} of {want.size} "
                         "failed." if failed else f"other hidden checks: all {want.size} passed.")


def _label(grade_id: str) -> str:
    """What a student calls an exercise's results: ``ex06_1_sweep_times_test`` -> ``sweep_times``.

    >>> _label("ex06_1_sweep_times_test"), _label("ex1_tool_xy_test"), _label("odd")
    ('sweep_times', 'tool_xy', 'odd')
    """
    import re

    return re.sub(r"^ex\d+(?:_\d+)?_|_test$", "", grade_id) or grade_id


def _trajectory(handin, times, positions, what) -> Trajectory:
    if times not in handin or positions not in handin:
        raise ValueError(f"no {what} was handed in ('{times}' and '{positions}')")
    try:
        return Trajectory(handin[times], handin[positions])
    except (SnakekitError, ValueError) as e:
        raise ValueError(f"the {what} is not a valid trajectory: {e}") from e


def _score_motion(gid, handin, ex, ref, max_score) -> ExerciseScore:
    tol = ex["tolerances"]
    names = ("times", "positions") if "times" in ref else ("commanded_times", "commanded_positions")
    try:
        cmd = _trajectory(handin, *names, "commanded trajectory")
    except ValueError as e:
        return _zero(gid, max_score, "inconsistent" if "valid" in str(e) else "missing", str(e).rstrip(".") + ".")
    ref_cmd = Trajectory(ref[names[0]], ref[names[1]])
    points = tol.get("points", len(ref_cmd))
    hz = tol.get("rate", 1.0 / float(np.median(np.diff(ref_cmd.times))))
    sweeps = tol.get("sweeps", TASK2["sweeps"])
    checks = [
        compare.point_count(cmd, points),
        compare.rate(cmd, hz),
        compare.limits(cmd),
        compare.sweep_count(cmd, sweeps),
        compare.home(cmd),
        compare.smoothness(cmd, ref_cmd),
        compare.tracking(cmd, ref_cmd, max_tol=tol.get("commanded_max", tol.get("max")),
                         rms_tol=tol.get("commanded_rms", tol.get("rms")), name="commanded vs reference",
                         weight=2.0),
    ]
    curves = {"commanded": (cmd.times, cmd.positions), "reference commanded": (ref_cmd.times, ref_cmd.positions)}
    if ex["kind"] == "run":
        try:
            meas = _trajectory(handin, "measured_times", "measured_positions", "recorded run")
        except ValueError as e:
            checks.append(compare.Check("run vs reference", 0.0, str(e).rstrip(".") + ".", 2.0))
        else:
            ref_meas = Trajectory(ref["measured_times"], ref["measured_positions"])
            checks.append(compare.tracking(meas, ref_meas, max_tol=tol["max"], rms_tol=tol["rms"],
                                           what="measured angle", name="run vs reference", weight=2.0))
            curves["measured"] = (meas.times, meas.positions)
            curves["reference measured"] = (ref_meas.times, ref_meas.positions)
    total = sum(c.weight for c in checks)
    fraction = sum(c.weight * c.fraction for c in checks) / total
    failed = [c for c in checks if not c.passed]
    msg = " ".join(c.message for c in failed) if failed else "every check passed."
    return ExerciseScore(gid, round(fraction * max_score, 4), max_score, "scored", msg, tuple(checks), curves)
