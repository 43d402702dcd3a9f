"""Watching a student's function while other code calls it, without replacing it.

The course's checks and demonstrations call the student's functions through wrappers of their
own (a loop that calls the student's step, a check that runs the student's task on a fresh
arm). Two things are seen from outside through :func:`sys.settrace` (on that function's frames
only), leaving every name in place: the arguments of each call (:func:`calls_to`, to draw the steps a loop took) and a call
that returned None (:func:`returns_none`: a forgotten ``return``, named as such wherever the
wrapper then stumbles). :func:`forgot_return` is the one message for it, locally and graded; so is
:func:`not_an_array` for a Python list or tuple returned where the exercise asks for a numpy array
(:func:`listed` tells one, from the value the student's function returned).
"""

from __future__ import annotations

import contextlib
import dis
import sys

import numpy as np

__all__ = ["calls_to", "forgot_return", "listed", "not_an_array", "raised_in", "returns_none"]

_RETURNS = {dis.opmap[name] for name in ("RETURN_VALUE", "RETURN_CONST") if name in dis.opmap}


def forgot_return(name: str, where: str = "") -> str:
    """What a student reads when their function gave back None (locally and graded alike).

    >>> forgot_return("task1", "targets [(0.25, 0.1, 0.3)]")
    'task1 returned None when called with targets [(0.25, 0.1, 0.3)]: did you forget `return`? A function gives its result with a `return` line; is it missing, or does the function stop before it?'
    """
    at = f" when called with {where}" if where else ""
    return (f"{name} returned None{at}: did you forget `return`? A function gives its result with a `return` line; "
            "is it missing, or does the function stop before it?")


@contextlib.contextmanager
def _trace(code, on_call=None, on_return=None):
    """While the block runs, call ``on_call(frame)`` when a frame of ``code`` starts and
    ``on_return(frame, value)`` when it returns (a trace function for that code's frames only:
    every other call costs one cheap check, and a tracer already set keeps tracing them)."""
    before = sys.gettrace()

    def local(frame, event, arg):
        if event == "return" and on_return is not None:
            on_return(frame, arg)
        return local

    def starts(frame, event, arg):
        if frame.f_code is code:
            if on_call is not None:
                on_call(frame)
            return local if on_return is not None else None
        return before(frame, event, arg) if before is not None else None

    sys.settrace(starts)
    try:
        yield
    finally:
        sys.settrace(before)


@contextlib.contextmanager
def calls_to(fn):
    """Note the arguments of every call to ``fn`` while the block runs, leaving ``fn`` and every
    name in place: a demonstration can show the steps a student's loop took without swapping the
    student's function for another.

    Yields a list that receives, per call, a tuple of its positional parameters' values (copies).

    >>> def half(x, by=2.0): return x / by
    >>> with calls_to(half) as calls:
    ...     end = half(half(8.0))
    >>> calls, end
    ([(8.0, 2.0), (4.0, 2.0)], 2.0)
    """
    code, calls = fn.__code__, []

    def note(frame):
        args = (frame.f_locals[n] for n in code.co_varnames[:code.co_argcount])
        calls.append(tuple(np.array(v) if isinstance(v, np.ndarray) else v for v in args))

    with _trace(code, on_call=note):
        yield calls


def raised_in(error: BaseException, fn) -> bool:
    """Whether ``error`` was raised by a line of ``fn`` itself (its innermost frame is ``fn``'s), not by a
    function it called."""
    tb = error.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    return tb is not None and tb.tb_frame.f_code is getattr(fn, "__code__", None)


class _Returns(list):
    """The calls that returned None (:func:`returns_none`); ``returned``: the type of the last value returned
    that was not None ("" if none was), and ``value`` that value."""

    returned = ""
    value = None


def not_an_array(name: str, kind: str, part: str = "", where: str = "") -> str:
    """What a student reads when their function returned a Python list or tuple (``kind``) where the exercise
    asks for a numpy array (``part``: which of a pair of results), locally and graded alike: the same rule in
    every exercise whose text asks for an array (:class:`snakekit.checks.Exercise`'s ``array``).

    >>> not_an_array("two_link_ik", "list")
    'two_link_ik returned a Python list, not a numpy array: the exercise asks for an array, and the cells after it use it as one; return np.array(...) of it.'
    >>> not_an_array("read_joint_states", "list", "times", "the bag a.mcap")[:74]
    'read_joint_states returned times as a Python list when called with the bag'
    """
    at = f" when called with {where}" if where else ""
    return (f"{name} returned {part + ' as ' if part else ''}a Python {kind}{at}, not a numpy array: the exercise asks "
            f"for an array, and the cells after it use it as one; return np.array(...) of it.")


def listed(value, array) -> tuple[str, str] | None:
    """Whether ``value``, what a student's function returned, is a list or tuple where ``array`` asks for numpy
    arrays (True: the value itself; a tuple of names: a tuple of that many arrays, ``("times", "positions")``):
    ``(kind, part)`` of the first one that is not, else None. A number stays a number (a scalar input's result).

    >>> listed([1.0, 2.0], True), listed(np.zeros(2), True), listed(0.5, True)
    (('list', ''), None, None)
    >>> listed((np.zeros(2), [[0.0] * 5]), ("times", "positions")), listed((1.0, 2.0), True)
    (('list', 'positions'), ('tuple', ''))
    """
    if not array:
        return None
    if array is True:
        return (type(value).__name__, "") if isinstance(value, (list, tuple)) else None
    if isinstance(value, (list, tuple)) and len(value) == len(array):
        return next(((type(v).__name__, name) for name, v in zip(array, value) if isinstance(v, (list, tuple))), None)
    return None


@contextlib.contextmanager
def returns_none(fn):
    """Count the calls of ``fn`` that returned None (a ``return`` forgotten, or not reached) while
    the block runs; a call that ends by raising is not counted. ``fn`` that is not a Python
    function (None, a builtin) is not watched.

    >>> def area(w, h):
    ...     w * h
    >>> def wrapper(w):
    ...     return [area(w, 2.0)][0] is None
    >>> with returns_none(area) as seen:
    ...     _ = wrapper(3.0)
    >>> len(seen), seen.returned
    (1, '')
    """
    code, seen = getattr(fn, "__code__", None), _Returns()

    def note(frame, value):   # a return while an exception unwinds the frame is at another opcode
        if frame.f_code.co_code[frame.f_lasti] not in _RETURNS:
            return
        if value is None:
            seen.append(frame.f_code.co_name)
        else:
            seen.returned, seen.value = type(value).__name__, value

    if code is None:
        yield seen
        return
    with _trace(code, on_return=note):
        yield seen
