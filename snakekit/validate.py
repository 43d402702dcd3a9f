"""Input checks shared by every layer: numpy only, so the light modules stay light.

Kinematics, trajectories, the robot interface and the viewer all take joint angles from
students; they check them here, with the same messages everywhere.

>>> as_configuration([0, 0.1, 0, 0, 0]).tolist()
[0.0, 0.1, 0.0, 0.0, 0.0]
>>> check_limits([2.0, 0, 0, 0, 0])
Traceback (most recent call last):
...
snakekit.errors.LimitError: q is outside the joint limits [-1.57, 1.57] rad: joint 1 = 2.0000 rad. Choose angles inside the limits (see snakekit.SPEC).
"""

from __future__ import annotations

import numpy as np

from .errors import LimitError, NotFiniteError, ShapeError
from .model import SPEC, SnakeSpec


def frozen(a) -> np.ndarray:
    """A read-only float copy of ``a`` (the caller's array stays theirs)."""
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def as_configuration(q, spec: SnakeSpec = SPEC, name: str = "q") -> np.ndarray:
    """``q`` as a float array of shape (n_joints,), checked for shape and finiteness.

    Raises:
        ShapeError: ``q`` does not hold one angle per joint.
        NotFiniteError: ``q`` holds NaN or infinity.
    """
    q = np.asarray(q, dtype=float)
    if q.shape != (spec.n_joints,):
        raise ShapeError(name, f"({spec.n_joints},)", q.shape,
                         "Give one angle [rad] per joint, base to tip")
    total = sum(q.tolist())  # NaN or inf anywhere makes the sum NaN or inf (and is cheap)
    if not (total - total == 0) and not np.isfinite(q).all():
        raise NotFiniteError(f"{name} holds NaN or infinity: {q.tolist()}; give finite angles [rad]")
    return q


def check_limits(q, spec: SnakeSpec = SPEC, name: str = "q") -> np.ndarray:
    """Return ``q`` (as :func:`as_configuration`) if every joint is inside its limits.

    Raises:
        LimitError: a joint is outside ``[spec.lower, spec.upper]``; its ``violations`` are
            ``(joint, value, lower, upper)`` tuples, joints counted from 1.
    """
    q = as_configuration(q, spec, name)
    bad = [(i + 1, float(v), spec.lower, spec.upper) for i, v in enumerate(q)
           if not spec.lower <= v <= spec.upper]
    if bad:
        text = ", ".join(f"joint {j} = {v:.4f} rad" for j, v, _, _ in bad)
        raise LimitError(f"{name} is outside the joint limits [{spec.lower}, {spec.upper}] rad: {text}. "
                         "Choose angles inside the limits (see snakekit.SPEC).", bad)
    return q
