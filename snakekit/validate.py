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

import operator
from pathlib import Path

import numpy as np

from .errors import (ConfigurationError, FileFormatError, FileWriteError, InputTypeError, LimitError,
                     NotFiniteError, ShapeError)
from .model import SPEC, SnakeSpec


def frozen(a) -> np.ndarray:
    """A read-only float copy of ``a`` (the caller's array stays theirs)."""
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def _first_not_real(a: np.ndarray):
    """The first element of ``a`` that is not a real number, and why (for messages)."""
    for x in a.flat:
        x = x.item() if isinstance(x, np.generic) else x
        if isinstance(x, (complex, np.complexfloating)) and x.imag != 0:
            return x, "a complex number"
        try:
            float(x)
        except (TypeError, ValueError):
            return x, f"not a number ({type(x).__name__})"
    return None, ""


def real_array(a, name: str, expected: str, hint: str = "") -> np.ndarray:
    """``a`` as a float array, refusing what numpy would turn into a confusing error or
    silently change: ragged rows, text that is not a number, complex numbers.

    Raises:
        ShapeError: rows of different lengths (``expected`` says the shape wanted).
        InputTypeError: an element is not a real number (``hint`` says what to give).

    >>> real_array([[0, 1], [2]], "positions", "(N, 2)")
    Traceback (most recent call last):
    ...
    snakekit.errors.ShapeError: positions must have shape (N, 2), got rows of different lengths (2, 1). Give every row the same number of values
    """
    try:
        arr = np.asarray(a)
    except ValueError as e:  # numpy's "inhomogeneous shape": ragged rows
        try:
            lengths = ", ".join(str(len(r)) for r in a)
        except TypeError:
            raise ShapeError(name, expected, "nested lists of different depths",
                             "Give a flat list or a table") from e
        raise ShapeError(name, expected, f"rows of different lengths ({lengths})",
                         "Give every row the same number of values") from e
    kind = arr.dtype.kind
    if kind in "fiub":
        return arr.astype(float, copy=False)
    if kind == "c" and not (arr.imag != 0).any():
        return arr.real.astype(float)
    if kind != "c":
        try:
            return arr.astype(float)
        except (TypeError, ValueError):
            pass
    x, why = _first_not_real(arr)
    if not why:
        raise InputTypeError(f"{name} holds values numpy can't read as numbers ({arr.dtype}); every value must "
                             "be a real number" + (f". {hint}" if hint else ""))
    raise InputTypeError(f"{name} holds {x!r}, which is {why}; every value must be a real number"
                         + (" (use .real if the imaginary parts are only rounding noise)" if "complex" in why else "")
                         + (f". {hint}" if hint else ""))


def number(x, name: str, unit: str = "", *, above: float | None = None, at_least: float | None = None,
           at_most: float | None = None, integer: bool = False, hint: str = "") -> float:
    """``x`` as a float (or int, with ``integer``), checked to be finite and in range.

    Raises:
        InputTypeError: ``x`` is not a real number (text, a list, a complex number...).
        ConfigurationError: ``x`` is NaN, infinite or out of range.

    >>> number(0, "rate", "Hz", above=0)
    Traceback (most recent call last):
    ...
    snakekit.errors.ConfigurationError: rate must be a finite number > 0 [Hz], got 0
    """
    kind = "a whole number" if integer else "a finite number"
    limits = " and ".join(t for t in (f"> {above:g}" if above is not None else "",
                                      f">= {at_least:g}" if at_least is not None else "",
                                      f"<= {at_most:g}" if at_most is not None else "") if t)
    want = f"{name} must be {kind}" + (f" {limits}" if limits else "") + (f" [{unit}]" if unit else "")
    tail = f". {hint}" if hint else ""
    if isinstance(x, (str, bytes, bool, np.bool_)) or np.ndim(x) != 0 or (
            isinstance(x, (complex, np.complexfloating)) and x.imag != 0):
        raise InputTypeError(f"{want}, got {x!r} ({type(x).__name__}){tail}")
    try:
        v = operator.index(x) if integer else float(np.real(x))
    except (TypeError, ValueError) as e:
        raise InputTypeError(f"{want}, got {x!r} ({type(x).__name__}){tail}") from e
    if not np.isfinite(v) or (above is not None and not v > above) or (
            at_least is not None and not v >= at_least) or (at_most is not None and not v <= at_most):
        raise ConfigurationError(f"{want}, got {x!r}{tail}")
    return v


def as_configuration(q, spec: SnakeSpec = SPEC, name: str = "q") -> np.ndarray:
    """``q`` as a float array of shape (n_joints,), checked for shape and finiteness.

    Raises:
        ShapeError: ``q`` does not hold one angle per joint.
        InputTypeError: ``q`` holds something that is not a real number.
        NotFiniteError: ``q`` holds NaN or infinity.
    """
    q = real_array(q, name, f"({spec.n_joints},)", "Give one angle [rad] per joint, base to tip")
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


# --- files --------------------------------------------------------------------------------


def writable_file(path, what: str, *, probe: bool = True) -> Path:
    """``path`` as a Path, if ``what`` (e.g. "run file") can be written there.

    With ``probe``, a file is really opened there for writing (and removed again if it was
    not there before): permission bits do not tell everything (read-only mounts, /proc...),
    so this is how a long job checks its output before it starts.

    Raises:
        FileWriteError: the folder is missing, the path is a folder, or writing fails; the
            message says which and what to do.
    """
    path = Path(path)
    parent = path.absolute().parent
    if not parent.is_dir():
        state = "is a file, not a folder" if parent.exists() else "does not exist"
        raise FileWriteError(f"cannot write {what} {path}: folder {parent} {state}. Create the folder first "
                             f"(pathlib.Path('{parent}').mkdir(parents=True)) or choose another path")
    if path.is_dir():
        raise FileWriteError(f"cannot write {what} {path}: it is a folder. Give a file name inside it, "
                             f"e.g. {path / ('name' + path.suffix)}")
    if probe:
        existed = path.exists()
        try:
            with open(path, "ab"):
                pass
            if not existed:
                path.unlink()
        except OSError as e:
            raise write_failed(path, what, e) from e
    return path


def write_failed(path, what: str, e: OSError) -> FileWriteError:
    """The error for an ``OSError`` while writing ``what`` to ``path``."""
    return FileWriteError(f"cannot write {what} {path}: {e.strerror or e}. Choose a place you can write to "
                          "(e.g. a file in your home folder)")


def readable_file(path, what: str) -> Path:
    """``path`` as a Path, if it is an existing file (not a folder).

    Raises:
        FileFormatError: it does not exist, or it is a folder.
    """
    path = Path(path)
    if path.is_dir():
        raise FileFormatError(f"{what} {path} is a folder, not a file; give the path of the "
                              "file itself")
    if not path.exists():
        raise FileFormatError(f"{what} {path} does not exist")
    return path
