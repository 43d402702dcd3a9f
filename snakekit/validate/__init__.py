"""Input checks shared by every layer: numpy only, so the light modules stay light.

Kinematics, trajectories, the robot interface and the viewer all take joint angles from
students; they check them here, with the same messages everywhere. A message quotes an input
through :func:`quote` (or :func:`excerpt`): at most a short excerpt of it. The checks of files
(a path to read or to write, an ``.npz`` archive) are in :mod:`snakekit.validate.files` and
are names of this module too.

>>> as_configuration([0, 0.1, 0, 0, 0]).tolist()
[0.0, 0.1, 0.0, 0.0, 0.0]
>>> check_limits([2.0, 0, 0, 0, 0])
Traceback (most recent call last):
...
snakekit.errors.LimitError: q is outside the joint limits [-1.57, 1.57] rad: joint 1 = 2.0000 rad. Choose angles inside the limits (see snakekit.SPEC).
"""

from __future__ import annotations

import operator
import reprlib
from functools import lru_cache
from itertools import chain
import numpy as np

from ..errors import ConfigurationError, InputTypeError, LimitError, NotFiniteError, ShapeError
from ..model import SPEC, SnakeSpec


#: How an input is quoted in a message: at most a short excerpt of it (a 150-million-character
#: string or a list of a million values is shown by its first few characters or items).
_QUOTE = reprlib.Repr()
_QUOTE.maxstring = _QUOTE.maxother = 60
_QUOTE.maxlist = _QUOTE.maxtuple = _QUOTE.maxdict = _QUOTE.maxset = 6
_QUOTE.maxlevel = 3


def quote(x) -> str:
    """``repr(x)`` for a message, cut to a short excerpt when ``x`` is long (with its length).

    >>> quote("x" * 10_000_000)
    "'xxxxxxxxxxxxxxxxxxxxxxxxxxx...xxxxxxxxxxxxxxxxxxxxxxxxxxxx' (10000000 characters)"
    >>> quote([0.5] * 1000)
    '[0.5, 0.5, 0.5, 0.5, 0.5, 0.5, ...] (1000 items)'
    """
    text = _QUOTE.repr(x)
    if isinstance(x, (str, bytes)) and len(x) > _QUOTE.maxstring:
        return f"{text} ({len(x)} characters)"
    if isinstance(x, (list, tuple, dict, set, frozenset)) and len(x) > _QUOTE.maxlist:
        return f"{text} ({len(x)} items)"
    return text


def excerpt(text: str, limit: int = 120) -> str:
    """``text`` itself, or its start and end with the length between, if longer than ``limit``
    (a file name or a line of a file, shown in a message)."""
    text = str(text)
    if len(text) <= limit:
        return text
    half = limit // 2
    return f"{text[:half]}...{text[-half:]} ({len(text)} characters)"


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


def _first_text(items):
    """The first str or bytes in the (nested) lists or tuples ``items``, or None: found before
    numpy would make an array of it (a list holding one string of 150 million characters
    would become gigabytes of text)."""
    kinds = set(map(type, items))
    if kinds & {str, bytes, np.str_, np.bytes_}:
        return next(x for x in items if isinstance(x, (str, bytes)))
    if kinds and kinds <= {list, tuple}:
        return _first_text(list(chain.from_iterable(items)))
    return None


def _reads_as_number(text) -> bool:
    """Whether ``text`` (str or bytes) is a number written as text: at most 100 characters
    (none is written longer), that ``float`` reads."""
    if len(text) > 100:
        return False
    try:
        float(text)
    except ValueError:
        return False
    return True


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
    text = _first_text(a) if isinstance(a, (list, tuple)) else None
    if text is not None and not _reads_as_number(text):  # "0.5" is a number written as text: numpy reads it
        raise InputTypeError(f"{name} holds {quote(text)}, which is not a number ({type(text).__name__}); every "
                             "value must be a real number" + (f". {hint}" if hint else ""))
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
    raise InputTypeError(f"{name} holds {quote(x)}, which is {why}; every value must be a real number"
                         + (" (use .real if the imaginary parts are only rounding noise)" if "complex" in why else "")
                         + (f". {hint}" if hint else ""))


def finite_array(a, name: str, expected: str, hint: str = "") -> np.ndarray:
    """``a`` as a float array (:func:`real_array`) of at most :data:`MAX_POINTS` rows (checked
    before it is made), every value finite.

    Raises:
        ConfigurationError: more rows than :data:`MAX_POINTS`.
        NotFiniteError: a NaN or an infinity (the message says where).
    """
    check_length(a, name)
    arr = real_array(a, name, expected, hint)
    if not np.isfinite(arr).all():
        where = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        at = f" (first at index {where[0] if len(where) == 1 else where})" if where else ""
        raise NotFiniteError(f"{name} holds NaN or infinity{at}; every value must be finite"
                             + (f". {hint}" if hint else ""))
    return arr


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
        raise InputTypeError(f"{want}, got {quote(x)} ({type(x).__name__}){tail}")
    try:
        v = operator.index(x) if integer else float(np.real(x))
    except (TypeError, ValueError) as e:
        raise InputTypeError(f"{want}, got {quote(x)} ({type(x).__name__}){tail}") from None
    if not np.isfinite(v) or (above is not None and not v > above) or (
            at_least is not None and not v >= at_least) or (at_most is not None and not v <= at_most):
        raise ConfigurationError(f"{want}, got {quote(x)}{tail}")
    return v


# --- counts, rates and durations: bounded, so a typo can't ask for terabytes or a day ----------

#: The longest move or run the kit accepts [s]: ten minutes, twelve times the lessons' longest
#: task (the 50 s sweep of Task 2). Longer is almost always times in milliseconds.
MAX_DURATION = 600.0
#: The highest sample or goal rate [Hz]: ten times the simulator's 1 kHz physics.
MAX_RATE = 10_000.0
#: The most points a generated trajectory may hold (80 MB of positions and velocities).
MAX_POINTS = 1_000_000


def length_of(a) -> int | None:
    """How many rows ``a`` has, read without converting it (None if it has no length): what
    :func:`check_length` compares before an array is made."""
    if isinstance(a, np.ndarray):
        return a.shape[0] if a.ndim else None
    try:
        return len(a)
    except Exception:  # a number, or an object without a length
        return None


def check_length(a, name: str, high: int = MAX_POINTS, hint: str = "") -> None:
    """Refuse ``a`` if it holds more than ``high`` rows, before any memory is taken for it.

    >>> check_length(range(2_000_000), "times")
    Traceback (most recent call last):
    ...
    snakekit.errors.ConfigurationError: times holds 2000000 points, more than the 1000000 the kit handles; use fewer points (a lower rate, or shorter moves)
    """
    n = length_of(a)
    if n is not None and n > high:
        raise ConfigurationError(f"{name} holds {n} points, more than the {high} the kit handles; "
                                 + (hint or "use fewer points (a lower rate, or shorter moves)"))


def check_count(x, name: str, low: int, high: int, hint: str = "") -> int:
    """``x`` as an int from ``low`` to ``high``: how many points, restarts, steps...

    >>> check_count(10**9, "points", 2, 100_000)
    Traceback (most recent call last):
    ...
    snakekit.errors.ConfigurationError: points must be a whole number from 2 to 100000, got 1000000000
    """
    return number(x, name, at_least=low, at_most=high, integer=True, hint=hint)


def check_seed(x, name: str = "seed") -> int:
    """``x`` as a seed for numpy's random generator: a whole number >= 0."""
    return number(x, name, at_least=0, integer=True, hint="It picks the random draws: the same seed, the same "
                  "result (default: 0)")


def check_flag(x, name: str, hint: str = "") -> bool:
    """``x`` as a bool, if it is one: a switch given as text (``"no"``) or a number would
    otherwise be read as on."""
    if not isinstance(x, (bool, np.bool_)):
        raise InputTypeError(f"{name} is a switch, True or False, got {quote(x)} ({type(x).__name__})"
                             + (f". {hint}" if hint else ""))
    return bool(x)


def check_spec(spec) -> SnakeSpec:
    """``spec`` if it is a :class:`~snakekit.model.SnakeSpec` (the arm's description) whose
    numbers are usable: checked once per spec (:func:`_check_spec_fields`), the kit's own at once."""
    if spec is SPEC:
        return spec
    if not isinstance(spec, SnakeSpec):
        raise InputTypeError(f"spec must be a snakekit.SnakeSpec (the arm's description, e.g. snakekit.SPEC), got "
                             f"{quote(spec)} ({type(spec).__name__}); leave it out for the kit's arm")
    try:
        hash(spec)
    except TypeError:  # a field holds a list...: checked each time
        _check_spec_fields.__wrapped__(spec)
    else:
        _check_spec_fields(spec)
    return spec


@lru_cache(maxsize=16)
def _check_spec_fields(spec: SnakeSpec) -> None:
    """Refuse a spec whose numbers the kinematics, simulator or driver can't use (NaN, a negative
    length, limits the wrong way round, servo ids that are not one per joint...)."""
    hint = "It is a field of the SnakeSpec"
    n = check_count(spec.n_joints, "spec.n_joints", 1, 100, hint)
    for name in ("link_length", "tool_offset", "velocity_limit"):
        number(getattr(spec, name), f"spec.{name}", above=0, at_most=1e3, hint=hint)
    for name in ("link_mass", "tool_mass", "collision_margin"):
        number(getattr(spec, name), f"spec.{name}", at_least=0, at_most=1e3, hint=hint)
    lower = number(spec.lower, "spec.lower", "rad", at_least=-np.pi, at_most=np.pi, hint=hint)
    number(spec.upper, "spec.upper", "rad", above=lower, at_most=np.pi, hint=hint + "; upper > lower")
    ids = spec.servo_ids
    if not isinstance(ids, tuple) or len(ids) != n or len(set(ids)) != n or not all(
            isinstance(i, int) and not isinstance(i, bool) and 0 <= i <= 252 for i in ids):
        raise ConfigurationError(f"spec.servo_ids must be a tuple of {n} distinct servo ids in 0..252, one a joint, "
                                 f"got {quote(ids)}")


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
    check_spec(spec)
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


# The file checks use quote() and MAX_POINTS from above: imported once those exist.
from .files import as_path, read_npz, readable_file, writable_file, write_failed  # noqa: E402,F401
