"""What a wrong result most likely is: the hints of the course's checks (:mod:`snakekit.checks`)
for a result of another shape, a known mistake's value, a transpose or a unit slip."""

from __future__ import annotations

import numpy as np


def shape_hint(arr: np.ndarray, exp: np.ndarray) -> str:
    """What to return when a result ``arr`` has another shape than the expected ``exp``."""
    if exp.ndim == 0:
        return "return one number, not a list or an array of them: float(...) makes one."
    if arr.ndim == 2 and arr.T.shape == exp.shape:
        return "this is the transpose of the expected shape: swap rows and columns (or build it the other way)."
    if arr.size == exp.size and arr.ndim != exp.ndim:
        return (f"the right number of values, arranged wrongly (a flattened or reshaped array): "
                f"return shape {exp.shape}.")
    return f"return an array of shape {exp.shape}."


class either(tuple):
    """The answers one known mistake may give (a value of ``Exercise.close``'s ``mistakes``):
    its hint is shown when the result is one of them.

    >>> mistake_hint(np.array(2.0), np.array(0.5), "", {"this is doubled or quadrupled.": either(1.0, 2.0)}, tol=1e-9)
    'this is doubled or quadrupled.'
    """

    def __new__(cls, *values):
        return super().__new__(cls, values)


class scaled(float):
    """A known mistake that multiplies the right answer by a factor (a value of ``Exercise.close``'s
    ``mistakes``): a unit slip, 1000 for milliseconds where seconds were asked. A result that is right
    but for the slip lies within the factor times the tolerance of the factor times the expected value,
    so that is where its hint is shown.

    >>> ms = {"this is in milliseconds; give seconds.": scaled(1000)}
    >>> mistake_hint(np.array(161.0), np.array(0.159), "s", ms, tol=0.005)
    'this is in milliseconds; give seconds.'
    >>> mistake_hint(np.array(0.17), np.array(0.159), "s", ms, tol=0.005)
    ''
    """


class within:
    """A known mistake whose answers spread around a value by more than the exercise's tolerance (a value of
    ``Exercise.close``'s ``mistakes``): a loop that stops too early ends near the target, not on it. Its hint
    is shown for a result within ``spread`` of ``value`` (and outside the tolerance, where it passes).

    >>> near = {"near the target, not on it.": within([0.2, 0.1], 1e-3)}
    >>> mistake_hint(np.array([0.2004, 0.1]), np.array([0.2, 0.1]), "m", near, tol=1e-5)
    'near the target, not on it.'
    >>> mistake_hint(np.array([0.21, 0.1]), np.array([0.2, 0.1]), "m", near, tol=1e-5)
    ''
    """

    def __init__(self, value, spread: float):
        self.value, self.spread = np.asarray(value, dtype=float), float(spread)

    def __repr__(self) -> str:
        return f"within({self.value.tolist()}, {self.spread:g})"


def _near(a, b, tol: float) -> bool:
    """Whether ``a`` is the value ``b`` a mistake gives: within ``tol``, the exercise's own tolerance (and
    1e-9 of ``b`` relative: the rounding of a worked number, as exact math allows)."""
    b = np.asarray(b, dtype=float)
    return b.shape == a.shape and bool(np.allclose(a, b, rtol=1e-9, atol=tol))


def known_mistake(arr, mistakes, *, tol: float, expected=None) -> str:
    """The hint of the known mistake (``mistakes``: hint -> the value, or :class:`either` of the
    values, it gives; :class:`scaled` a factor of the ``expected`` value; :class:`within` a spread of values)
    whose value ``arr`` is
    within ``tol`` (the exercise's tolerance: a result that only this mistake makes wrong lies there),
    even where its shape is not the expected one (a forgotten ``abs`` leaves rows out), "" when none is.
    A result wrong for another reason, a few tolerances from the mistake's value, gets no hint.

    >>> known_mistake(np.zeros((0, 3)), {"the lower limit counts too: compare abs(q).": np.zeros((0, 3))}, tol=1e-9)
    'the lower limit counts too: compare abs(q).'
    >>> known_mistake(np.array(0.17), {"the grid is too coarse.": 0.15}, tol=0.005)
    ''
    """
    for hint, value in (mistakes or {}).items():
        if isinstance(value, scaled):
            if expected is not None and _near(arr, float(value) * np.asarray(expected, dtype=float),
                                              abs(float(value)) * tol):
                return hint
        elif isinstance(value, within):
            if _near(arr, value.value, max(value.spread, tol)):
                return hint
        elif any(_near(arr, v, tol) for v in (value if isinstance(value, either) else (value,))):
            return hint
    return ""


def mistake_hint(arr, exp, unit, mistakes, *, tol: float) -> str:
    """The hint for a result ``arr`` that misses ``exp`` (tolerance ``tol``): a known mistake's
    (:func:`known_mistake`), a transposed square array, or a unit slip (degrees, millimetres), "" when
    none fits. A slip that scales the answer scales its tolerance too: degrees are recognised within
    57.3 times the tolerance of the expected angles in degrees."""
    def near(a, b, factor=1.0):
        return _near(a, b, tol * factor)

    hint = known_mistake(arr, mistakes, tol=tol, expected=exp)
    if hint:
        return hint
    if arr.ndim == 2 and exp.ndim == 2 and near(arr, exp.T):   # a square array, built the other way round
        return "rows and columns are swapped: this is the transpose of the expected array."
    units = set(unit) if isinstance(unit, (tuple, list)) else {unit}
    if np.abs(exp).max() > 1e-6:
        if "rad" in units and near(arr, np.degrees(exp), np.degrees(1.0)):
            return "this looks like degrees where radians were asked: use radians (np.radians / np.deg2rad)."
        if "rad" in units and near(arr, np.radians(exp), np.radians(1.0)):
            return "these numbers are the right ones converted to radians once too often: they are radians already."
        if "m" in units and near(arr, 1000 * exp, 1000.0):
            return "this looks like millimetres where metres were asked: divide by 1000."
        if "m" in units and near(arr, exp / 1000, 1e-3):
            return "this looks like metres divided by 1000 again: the link lengths are already in metres."
    return ""


#: A result that should hold one tool pose (x, y, θ) per move, of another kind: what it looks like, and what to do.
JOINT_ANGLES_FOR_POSES = ("this looks like joint angles (5 numbers a move), and the exercise asks for tool poses "
                          "(x, y, θ), 3 numbers a move: turn the arm's last angles into its tool pose with "
                          "snakekit.tool_pose_2d(run.measured.positions[-1]).")
POINTS_FOR_POSES = ("this looks like tool points (x, y) without the heading, and the exercise asks for tool poses "
                    "(x, y, θ): keep the heading too, all three numbers of snakekit.tool_pose_2d(...).")


def pose_mistakes(final_q, poses) -> dict:
    """The known mistakes (:func:`known_mistake`) of a result asked as one tool pose (x, y, θ) per move: the
    moves' last joint angles ``final_q`` (n, 5) returned as they are, or their tool ``poses`` (n, 3) without
    the heading.

    >>> q = np.zeros((1, 5)); known_mistake(q, pose_mistakes(q, [[0.3315, 0.0, 0.0]]), tol=1e-9)[:33]
    'this looks like joint angles (5 n'
    """
    return {JOINT_ANGLES_FOR_POSES: np.asarray(final_q, dtype=float),
            POINTS_FOR_POSES: np.asarray(poses, dtype=float)[..., :2]}


def error_hint(error: BaseException) -> str:
    """A hint for an error a beginner's answer raises where the error's own words do not say the fix.

    >>> import numpy as np
    >>> try:
    ...     np.linalg.solve(np.zeros((2, 2)), np.ones(2))
    ... except np.linalg.LinAlgError as e:
    ...     print(error_hint(e)[:62])
    the matrix solved has no inverse here: J J^T is singular where
    """
    if type(error).__name__ == "LinAlgError" and "singular" in str(error).lower():
        return ("the matrix solved has no inverse here: J J^T is singular where the arm is stretched out or folded "
                "(a row of J is all zeros), and the damping term + damping**2 * I is what keeps it invertible.")
    return ""
