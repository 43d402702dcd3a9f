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
from itertools import chain
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


def _first_bool(items):
    """The first boolean in the (nested) lists, tuples or arrays ``items``, or None."""
    kinds = set(map(type, items))  # the types are gathered in C: a 500 x 5 list costs ~0.1 ms
    if kinds and kinds <= {list, tuple}:  # rows of values: look at the values
        return _first_bool(list(chain.from_iterable(items)))
    if bool in kinds or np.bool_ in kinds:
        return next(x for x in items if type(x) is bool or type(x) is np.bool_)
    if kinds & {list, tuple, np.ndarray}:  # a mix of rows and arrays
        for x in items:
            if type(x) in (list, tuple) or (type(x) is np.ndarray and x.dtype.kind in "bO" and x.ndim):
                found = _first_bool(x)
                if found is not None:
                    return found
    return None


def _no_bools(a, arr: np.ndarray, name: str, hint: str) -> None:
    """Refuse booleans given as numbers: numpy reads True as 1 (1 rad, 1 s...) without a word."""
    if arr.dtype.kind == "b":
        b = arr.flat[0].item() if arr.size else None
    else:
        b = _first_bool(a) if isinstance(a, (list, tuple)) or (isinstance(a, np.ndarray) and a.ndim) else None
    if b is not None:
        raise InputTypeError(f"{name} holds {bool(b)!r}, a boolean, where a number is needed (numpy would read it as "
                             f"{int(b)}); every value must be a real number" + (f". {hint}" if hint else ""))


def real_array(a, name: str, expected: str, hint: str = "") -> np.ndarray:
    """``a`` as a float array, refusing what numpy would turn into a confusing error or
    silently change: ragged rows, text that is not a number, complex numbers, booleans
    (``True`` would be 1).

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
    if kind == "b" or not isinstance(a, np.ndarray) or kind == "O":
        _no_bools(a, arr, name, hint)
    if kind in "fiu":
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


def _num(v: float) -> str:
    """A bound as a person writes it: 100000, not 1e+05; 1e-12 stays."""
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"


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
    if at_least is not None and at_most is not None and above is None:
        limits = f"from {_num(at_least)} to {_num(at_most)}"
    else:
        limits = " and ".join(t for t in (f"> {_num(above)}" if above is not None else "",
                                          f">= {_num(at_least)}" if at_least is not None else "",
                                          f"<= {_num(at_most)}" if at_most is not None else "") if t)
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


# --- counts, rates and durations: bounded, so a typo can't ask for terabytes or a day ----------

#: The longest move or run the kit accepts [s]: ten minutes, twelve times the lessons' longest
#: task (the 50 s sweep of Task 2). Longer is almost always times in milliseconds.
MAX_DURATION = 600.0
#: The highest sample or goal rate [Hz]: ten times the simulator's 1 kHz physics.
MAX_RATE = 10_000.0
#: The most points a generated trajectory may hold (80 MB of positions and velocities).
MAX_POINTS = 1_000_000


def check_count(x, name: str, low: int, high: int, hint: str = "") -> int:
    """``x`` as an int from ``low`` to ``high``: how many points, restarts, steps...

    >>> check_count(10**9, "points", 2, 100_000)
    Traceback (most recent call last):
    ...
    snakekit.errors.ConfigurationError: points must be a whole number from 2 to 100000, got 1000000000
    """
    return number(x, name, at_least=low, at_most=high, integer=True, hint=hint)


def check_rate(x, name: str = "rate", hint: str = "", *, high: float = MAX_RATE) -> float:
    """``x`` as a rate > 0 and at most ``high`` [Hz]."""
    return number(x, name, "Hz", above=0, at_most=high, hint=hint)


def too_long(seconds: float, what: str, high: float = MAX_DURATION, fix: str = "") -> ConfigurationError:
    """The error for ``what`` (a duration) being ``seconds`` [s], over ``high``: it says the likely cause
    (milliseconds) and ``fix``, the way to run something that long on purpose."""
    return ConfigurationError(
        f"{what} is {seconds:.6g} s ({seconds / 60:.3g} min), longer than the {_num(high)} s "
        f"({high / 60:.3g} min) the kit accepts. Times are in seconds: if these are milliseconds, divide them "
        "by 1000" + (f"; {fix}" if fix else ""))


def check_duration(x, name: str = "duration", hint: str = "", *, high: float = MAX_DURATION) -> float:
    """``x`` as a duration > 0 and at most ``high`` [s] (longer: see :func:`too_long`).

    >>> check_duration(2000.0)
    Traceback (most recent call last):
    ...
    snakekit.errors.ConfigurationError: duration is 2000 s (33.3 min), longer than the 600 s (10 min) the kit accepts. Times are in seconds: if these are milliseconds, divide them by 1000
    """
    v = number(x, name, "s", above=0, hint=hint)
    if v > high:
        raise too_long(v, name, high)
    return v


def sample_count(seconds: float, hz: float, what: str) -> int:
    """How many samples ``seconds`` [s] at ``hz`` [Hz] make (both ends included), if at most
    :data:`MAX_POINTS`."""
    n = int(np.floor(seconds * hz + 1e-9)) + 1
    if n > MAX_POINTS:
        raise ConfigurationError(f"{what} would hold {n} points ({seconds:.6g} s at {hz:.6g} Hz), more than the "
                                 f"{MAX_POINTS} the kit makes; lower the rate or shorten the time")
    return n


def options_of(fn, options: dict, what: str, *, given: tuple = (), also: tuple = (),
               needs: dict | None = None) -> None:
    """Refuse keyword ``options`` that ``fn`` does not take, or a required one left out.

    Args:
        fn: the function (or class) the options go to.
        what: what takes them, for the message ("the 'sim' backend").
        given: names the caller passes itself (not the user's to give).
        also: names the caller takes itself before passing the rest to ``fn``.
        needs: what each required option is, for the message (``{"port": "the serial port..."}``).

    Raises:
        InputTypeError: an unknown option (the message lists the valid ones), or a missing one.
    """
    import inspect

    params = inspect.signature(fn).parameters
    named = [k for k, p in params.items() if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
             and k not in given]
    if not any(p.kind == p.VAR_KEYWORD for p in params.values()):
        valid = [*also, *(k for k in named if k not in also)]
        unknown = [k for k in options if k not in valid]
        if unknown:
            raise InputTypeError(f"{what} has no option {', '.join(map(repr, unknown))}; its options are "
                                 f"{', '.join(valid)}")
    missing = [k for k in named if params[k].default is params[k].empty and k not in options]
    if missing:
        raise InputTypeError(f"{what} needs " + "; ".join(
            f"{k}=..." + (f" ({(needs or {})[k]})" if k in (needs or {}) else "") for k in missing))


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
    """``path`` as a Path, if it is an existing regular file (not a folder, pipe or device).

    Raises:
        FileFormatError: it does not exist, it is a folder, or it is not a regular file (a
            named pipe would make reading wait forever).
    """
    path = Path(path)
    if path.is_dir():
        raise FileFormatError(f"{what} {path} is a folder, not a file; give the path of the "
                              "file itself")
    if not path.exists():
        raise FileFormatError(f"{what} {path} does not exist")
    if not path.is_file():  # a pipe or a device: reading it could wait forever
        raise FileFormatError(f"{what} {path} is not a regular file (a pipe, socket or device); give the "
                              "path of a file saved on disk")
    return path
