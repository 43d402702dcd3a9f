"""Checks that teach: the helpers the course's test cells call.

A failed check raises :class:`CheckFailed` (an ``AssertionError``) whose message says what
was wrong, where, and by how much, in this shape::

    exercise 1.1 planar_fk: tool y at q=[0.4, -0.3, 0.5, 0.2, -0.6] is 0.1178 m, expected 0.0632 m:
    off by 54.6 mm (tolerance 6.3e-08 mm: exact math, 1e-9 relative).
    Hint: a joint angle is not accumulated: use q_1 + ... + q_i, not q_i.

In a notebook the student sees the message only, never a stack of frames from this module:
the exceptions render themselves (IPython's ``_render_traceback_``), showing at most the
frames of the student's own code.

What the grader relies on (see ``course/README.md``, "For the grader"):

* :meth:`Exercise.hand_in` asks the grader's socket (``SNAKEKIT_CASES``) for an exercise's
  hidden cases when its check cell runs, and writes the student's results there to
  ``<SNAKEKIT_HANDIN_DIR>/<grade_id>.npz`` (and does nothing outside grading);
* :func:`forbid` makes library functions raise :class:`ShortcutError` while the student's
  code runs, so an exercise can't be passed by calling the function it asks to write;
* :func:`quick` is the one switch that shortens long runs under test
  (``SNAKEKIT_QUICK=1``; the test suite's ``SNAKEKIT_TEST=1`` counts too).

A check says a beginner's slip in plain words: a function that returned None (a forgotten
``return``), a list where an array is asked (``close(..., array=True)``), and, in a notebook,
a name whose answer cell has not run or stopped with a ``SyntaxError``.

>>> import numpy as np
>>> ex = Exercise("9.9", "double")
>>> ex.close(ex(lambda x: 2 * x, 0.5), 1.0, what="result", where="x=0.5", unit="m")
>>> try:
...     ex.close(500.0, 0.5, what="result", where="x=0.25", unit="m")
... except CheckFailed as e:
...     print(e)
exercise 9.9 double: result at x=0.25 is 500 m, expected 0.5 m: off by 4.995e+05 mm (tolerance 5e-07 mm: exact math, 1e-9 relative).
Hint: this looks like millimetres where metres were asked: divide by 1000.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import sys
import traceback
import warnings
from pathlib import Path

import numpy as np

from .errors import CheckFailed, ConfigurationError, ShortcutError
from .handin import NotAnArray, Returned, ReturnedNone, encode_results, fetch_cases, live_off, quick
from .mistakes import either, error_hint, known_mistake, mistake_hint, pose_mistakes, scaled, shape_hint, within
from .closeness import ZERO, bound, entry_name, is_table, not_finite, per_row, sentence, unit_of, worst
from .verdicts import BUILDS_ON, CAUSES, PASSED, composite_note, failing_parts, stopped_note
from .watch import calls_to, forgot_return, listed, not_an_array, raised_in, returns_none

__all__ = ["CheckFailed", "ShortcutError", "Exercise", "calls_to", "either", "forbid", "known_mistake", "live_off",
           "per_row", "pose_mistakes", "quick", "scaled", "waiting_for", "within"]

_HERE = os.path.abspath(__file__)


def _shorten(exc: BaseException) -> BaseException:
    """``exc`` without the frames of this module (so plain Python shows no checks frames)."""
    return exc.with_traceback(None)


def _student_frames(tb) -> str:
    """The frames of ``tb`` outside this module, formatted (the student's code, mostly)."""
    frames = [f for f in traceback.extract_tb(tb) if os.path.abspath(f.filename) != _HERE]
    return "".join(traceback.format_list(frames))


# --- numbers in messages -----------------------------------------------------------------


def _fmt_array(a) -> str:
    kind = type(a).__name__ if isinstance(a, (list, tuple)) else ""
    a = np.asarray(a, dtype=float)
    if a.ndim == 0:
        return f"{float(a):.4g}"
    if a.size <= 8:
        return "[" + ", ".join(f"{float(x):.4g}" for x in a.ravel()) + "]"
    if not kind:
        return f"array of shape {a.shape}"
    return {1: f"a {kind} of {len(a)} numbers", 2: f"a {kind} of {len(a)} entries of {a.shape[-1]} numbers each"}.get(
        a.ndim, f"a {kind} of shape {a.shape}")


def _where(where) -> str:
    if where is None or where == "":
        return ""
    if isinstance(where, str):
        return f" at {where}"
    return f" at {_fmt_array(where)}"


# --- the exercise object ---------------------------------------------------------------


class Exercise:
    """The checks of one exercise: every message starts with its number and name.

    Args:
        number: the exercise number as the lesson shows it, e.g. ``"1.1"``.
        name: the name of what the student writes, e.g. ``"planar_fk"``.
        array: the exercise's text asks for a numpy array (True), or for a tuple of them, named
            (``("times", "positions")``): a Python list or tuple the student's function returns there fails
            the check, and is graded wrong, in the same words (:func:`snakekit.watch.not_an_array`): the one
            rule of the course, declared here once for both.
    """

    def __init__(self, number: str, name: str, *, builds_on: tuple = (), array: bool | tuple = False):
        self.number, self.name = number, name
        self.array = array
        self.builds_on = tuple(builds_on)
        self.checked = 0
        PASSED.pop(number, None)      # run again: its verdict is this run's
        CAUSES.pop(number, None)
        BUILDS_ON[number] = self.builds_on

    @property
    def prefix(self) -> str:
        return f"exercise {self.number} {self.name}"

    def fail(self, message: str, hint: str = "", student_frames: str = ""):
        """Raise :class:`CheckFailed` with ``message`` (and a hint line, and, for a composite
        whose parts fail their own checks, which parts to fix first)."""
        PASSED[self.number] = False
        weak = self._weak_parts()
        if weak:   # the part's slip explains the failure: a hint of this exercise's own would name a mistake not made
            hint = ""
        CAUSES[self.number] = hint or message
        text = CheckFailed.compose(_ended(f"{self.prefix}: {message}") if hint or weak else f"{self.prefix}: {message}",
                                   hint)
        if weak:
            text = _ended(text) + "\n" + composite_note(self.number, weak)
        raise _shorten(CheckFailed(text, student_frames)) from None

    def _weak_parts(self) -> list:
        """For an exercise built on earlier ones: the parts whose own checks failed (or have not passed yet),
        since a slip there shows up here too (:func:`snakekit.verdicts.composite_note` names them)."""
        return [n for n in self.builds_on if not PASSED.get(n, False)]

    def __call__(self, fn, *args, where=None, **kwargs):
        """Run the student's ``fn(*args, **kwargs)``; turn a stub or a crash into a clear message."""
        if not callable(fn):
            self.fail(f"`{self.name}` should be a function, got {type(fn).__name__}; "
                      "run the answer cell above (it defines it), then this check")
        try:
            with returns_none(_student_function(self.name)) as none:
                result = fn(*args, **kwargs)
        except NotImplementedError as e:
            self.fail(f"`{self.name}` is not written yet (it raises NotImplementedError"
                      f"{': ' + str(e) if str(e) else ''}). Write it in the answer cell above, run that cell, "
                      "then run this check again.")
        except ShortcutError as e:   # named with the exercise it happened in
            said = str(e) if str(e).startswith("exercise ") else f"{self.prefix}: {e}"
            raise _shorten(ShortcutError(said, _student_frames(e.__traceback__))) from None
        except CheckFailed as e:
            raise _shorten(e) from None
        except Exception as e:
            if none:   # the student's function gave back None, and the check stumbled on it
                self.fail(forgot_return(self.name, self._call(args, where)))
            if none.returned and listed(none.value, self.array):   # ...or a list, where an array is asked
                self.fail(not_an_array(self.name, *listed(none.value, self.array), self._call(args, where)))
            self.fail(f"`{self.name}` raised {type(e).__name__} when called with {self._call(args, where)}: {e}",
                      error_hint(e), student_frames=_student_frames(e.__traceback__))
        if result is None or none:
            self.fail(forgot_return(self.name, self._call(args, where)))
        bad = listed(none.value, self.array) if none.returned else None
        if bad:   # a list where the exercise asks for an array: the course's one rule, graded alike (hand_in)
            self.fail(not_an_array(self.name, *bad, self._call(args, where)))
        return result

    @staticmethod
    def _call(args, where) -> str:
        """The arguments of a call, as a message shows them."""
        if where is not None:
            return str(where)
        if not args:
            return "no arguments (its defaults)"
        def shown(a):   # an object without a short readable repr (a ControlPanel, a robot, a Run) by its type
            text = repr(a)
            if (text.startswith("<") and " at 0x" in text) or len(text) > 60 or "\n" in text:
                kind = type(a).__name__
                return f"{'an' if kind[:1].lower() in 'aeiou' else 'a'} {kind}"
            return text

        return ", ".join(_fmt_array(a) if isinstance(a, (np.ndarray, list, tuple)) else
                         (getattr(a, "__name__", type(a).__name__) if callable(a) else shown(a)) for a in args)

    def raises(self, error: type, fn, *args, where=None, why: str = "") -> None:
        """Check that the student's ``fn(*args)`` raises ``error`` (a ``ValueError`` for a target
        out of reach, say); ``why``: why it must, in the lesson's words."""
        if not callable(fn):
            self(fn)
        call = self._call(args, where)
        try:
            fn(*args)
        except NotImplementedError:
            self(fn, *args, where=where)      # says it is not written yet
        except error:
            self.checked += 1
            return
        except CheckFailed as e:
            raise _shorten(e) from None
        except Exception as e:
            self.fail(f"`{self.name}` raised {type(e).__name__} when called with {call}: {e}; {why}: raise a "
                      f"{error.__name__} there.", student_frames=_student_frames(e.__traceback__))
        self.fail(f"`{self.name}` returned a result when called with {call}, raising nothing; {why}: raise a {error.__name__} there "
                  f"(`raise {error.__name__}(\"...\")`, saying why).")

    def true(self, condition, message: str, hint: str = "") -> None:
        """Fail with ``message`` unless ``condition`` holds."""
        if not bool(condition):
            self.fail(message, hint)
        self.checked += 1

    def close(self, got, expected, *, what: str, where=None, unit: str | tuple = "", tol: float = 0.0,
              rtol: float = 1e-9, why: str | None = None, labels=None, mistakes: dict | None = None,
              array: bool = False) -> None:
        """Check that ``got`` equals ``expected`` within ``tol + rtol * |expected|``.

        Args:
            got: what the student's code returned.
            expected: the right answer (computed independently).
            what: what the value is, in the lesson's words ("tool pose").
            where: the inputs, as text or an array ("q=[...]").
            unit: the unit of every entry, one per entry of a 1-D value (or per column of a table: ("m", "rad",
                "s")), or one per row of a matrix (``per_row("m", "m", "rad/rad")``: a Jacobian's rows).
            tol: absolute tolerance [unit]; rtol: relative tolerance.
            why: the reason for the tolerance; default "exact math" when ``tol`` is 0.
            labels: names of the entries of a 1-D value ("x", "y", "heading"), or of the columns of a 2-D one
                ("time", "joint", "kind": a message names ``violations[0] time``, not ``violations[0, 0]``). Such a
                table is read from the top: a message names its first wrong entry; any other value the entry
                furthest from its expected one. The grader names the same entry in the same words
                (:mod:`snakekit.closeness`).
            mistakes: ``{hint: value}``: answers a known mistake would give (a value, ``either(...)`` of
                several, ``scaled(factor)`` of ``expected``: a unit slip, or ``within(value, spread)``: answers
                near a value, a loop stopped too early); when ``got`` is one, within the check's own tolerance
                (the tolerance times the factor for ``scaled``, the spread for ``within``), its hint is shown.
            array: the exercise asks for a numpy array: a list or tuple fails (with what to do),
                since the lesson's later cells index the result as an array. (An exercise declares it once,
                ``Exercise(..., array=True)``, which judges what the student's function returns.)
        """
        exp = np.asarray(expected, dtype=float)
        if got is None:
            self.fail(forgot_return(self.name, str(where) if where is not None else ""))
        if array and isinstance(got, (list, tuple)):   # the words of the course's one rule (Exercise's array)
            self.fail(not_an_array(self.name, type(got).__name__, where="" if where is None else str(where)))
        try:
            arr = np.asarray(got, dtype=float)
        except (TypeError, ValueError):
            self.fail(f"{what}{_where(where)} should be numbers of shape {exp.shape}, got {type(got).__name__}: "
                      f"{str(got)[:80]}")
        if arr.shape != exp.shape:   # a known mistake may give another shape (one time too many)
            near = max(tol + rtol * float(np.abs(exp).max(initial=0.0)), ZERO)
            self.fail(f"{what}{_where(where)} has shape {arr.shape}, expected shape {exp.shape}.",
                      known_mistake(arr, mistakes, tol=near, expected=exp) or shape_hint(arr, exp))
        if not np.isfinite(arr).all():
            self.fail(not_finite(what, arr, _where(where)))
        # near zero is zero: what is within ZERO of an exact 0 passes, as graded (snakekit.closeness)
        tolerances = bound(exp, atol=tol, rtol=rtol)
        table = is_table(labels, arr.shape)
        i = worst(arr, exp, tolerances, table=table)   # the entry the grader names too
        if i is None:
            self.checked += 1
            return
        hint = mistake_hint(arr, exp, unit, mistakes, tol=float(tolerances.max()))   # the mistake, and only it
        self.fail(sentence(entry_name(what, i, arr.ndim, labels), arr[i], exp[i], tolerances[i], unit_of(unit, i), atol=tol,
                           rtol=rtol, why=why, where=_where(where)), hint)

    def hand_in(self, grade_id: str, fn, *, forbid: tuple = (), what: str = "", instead: str = "",
                array: bool = False) -> int:
        """Hand in ``fn``'s results at the grader's hidden cases of this exercise.

        While a notebook is graded, ``SNAKEKIT_CASES`` names the grader's socket: the grader
        sends, at this moment, the arguments of the hidden cases of ``grade_id`` (drawn anew for
        every grading batch, outside the kernel), ``fn(*args)`` runs at each, and what it returns
        (numbers, an array, or a dict of them) or the exception it raises is written to
        ``<SNAKEKIT_HANDIN_DIR>/<grade_id>.npz`` (:func:`encode_results`). The grader scores that
        file in its own process, against the instructor solution's results at the same cases.

        It prints nothing and raises nothing (a test cell calls it first, so a visible check
        that fails after it does not lose what the hidden cases earn). ``forbid``: library
        functions that raise :class:`ShortcutError` while ``fn`` runs (see :func:`forbid`, as ``instead``).
        ``array``: the exercise asks for a numpy array (its checks use ``close(..., array=True)``):
        a list or tuple returned is handed in as such, and the grader counts it wrong, as the
        visible check does.
        Outside grading it does nothing. Returns the number of cases handed in.
        """
        folder, socket_path = os.environ.get("SNAKEKIT_HANDIN_DIR"), os.environ.get("SNAKEKIT_CASES")
        if not folder or not socket_path:
            return 0
        try:
            cases = fetch_cases(socket_path, grade_id)
        except OSError:
            return 0  # no grader answered: nothing handed in, the grader says "missing"
        results = []
        with contextlib.ExitStack() as stack:
            stack.enter_context(np.errstate(all="ignore"))
            stack.enter_context(warnings.catch_warnings())
            warnings.simplefilter("ignore")  # a warning on stderr would fail the cell in nbgrader
            if forbid:
                stack.enter_context(globals()["forbid"](*forbid, what=what or self.name, instead=instead))
            student = _student_function(self.name)
            for args in cases:
                try:
                    with returns_none(student) as none:
                        results.append(fn(*args))
                except BaseException as e:  # noqa: BLE001 - a student's SystemExit is a result too
                    if isinstance(e, KeyboardInterrupt):
                        raise
                    results.append(e)
                    if none.returned and fn is not student and raised_in(e, fn):
                        # the test cell's own code stumbled on what the student's function gave back
                        results[-1] = Returned(self.name, none.returned)
                if none:   # named as the forgotten `return` it is, whatever the wrapper made of the None
                    results[-1] = ReturnedNone(self.name)
                elif none.returned and listed(none.value, self.array):   # as the visible check says it (__call__)
                    results[-1] = NotAnArray(self.name, *listed(none.value, self.array))
        path = Path(folder) / f"{grade_id}.npz"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(encode_results(results, array=array))
        return len(results)

    def done(self, note: str = "") -> None:
        """Print that the checks passed (the last line of a test cell)."""
        PASSED[self.number] = True
        print(f"exercise {self.number} {self.name}: {self.checked} check(s) passed" + (f"; {note}" if note else ""))


def _ended(text: str) -> str:
    """``text`` ending a sentence, so that what follows it (a hint, a note) starts a new one."""
    text = text.rstrip()
    return text if text.endswith((".", "!", "?", ":")) else text + "."


def _student_function(name: str):
    """The student's function ``name`` in the notebook's namespace (None outside a notebook)."""
    fn = getattr(sys.modules.get("__main__"), name, None)
    return fn if getattr(fn, "__code__", None) is not None else None


# --- the shortcut guard ---------------------------------------------------------------------


def _resolve(name: str):
    """The object named ``name`` ("snakekit.jacobian", "snakekit.Trajectory.check_limits")."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for p in parts[i:]:
            obj = getattr(obj, p)
        return obj
    raise ConfigurationError(f"nothing is called {name}: check the name the lesson passes to forbid()")


@contextlib.contextmanager
def forbid(*names: str, what: str, instead: str = ""):
    """Make the named library functions raise :class:`ShortcutError` inside the block.

    Every place a student could reach a function from is patched: the ``snakekit`` package,
    every loaded ``snakekit.*`` module that holds it, the notebook's own namespace
    (``from snakekit import forward_kinematics``) and, for methods, their class. Everything
    is restored afterwards, also after an error.

    Args:
        names: dotted names, e.g. ``"snakekit.forward_kinematics"``.
        what: what the exercise asks to write, e.g. ``"planar FK"``.
        instead: what to use in its place (default: numpy and what the lesson taught so far).
    """
    patched = []
    called = []
    for name in names:
        original = _resolve(name)

        def guard(*args, _name=name, **kwargs):
            called.append(_name)
            raise _shorten(ShortcutError(
                f"this exercise asks you to write {what} yourself; `{_name}` was called. "
                f"{instead or 'Use only numpy and what the lesson taught so far'} (the library's version is for "
                f"after the exercise)."))

        holders = [m for k, m in list(sys.modules.items()) if m is not None and
                   (k == "snakekit" or k.startswith("snakekit.") or k == "__main__")]
        for holder in holders:
            for attr, value in list(vars(holder).items()):
                if value is original:
                    patched.append((holder, attr, value))
                    setattr(holder, attr, guard)
        owner, _, attr = name.rpartition(".")
        cls = _resolve(owner) if owner else None
        if isinstance(cls, type) and cls.__dict__.get(attr) is not None:
            value = cls.__dict__[attr]
            patched.append((cls, attr, value))
            setattr(cls, attr, property(lambda self, _g=guard: _g()) if isinstance(value, property) else guard)
    try:
        yield called
    finally:
        for holder, attr, value in reversed(patched):
            setattr(holder, attr, value)


def _explain_name_error(shell, etype, value, tb, tb_offset=None):
    """IPython's handler of a ``NameError`` in a notebook: say why a name is missing.

    A check cell that names the student's function meets a ``NameError`` when the answer cell
    above it has not run, or stopped with an error (a ``SyntaxError`` defines nothing): say so,
    instead of a bare "name ... is not defined".
    """
    name = getattr(value, "name", None)
    if name and "is not defined" in str(value) and "has not run" not in str(value):
        value = NameError(f"name '{name}' is not defined: the cell that defines `{name}` has not run yet, or it "
                          "stopped with an error (a SyntaxError in your answer, say), so nothing was defined. "
                          "Run that cell, fix the error it shows, then run this cell again.", name=name)
    shell.showtraceback((etype, value, tb), tb_offset=tb_offset)


def _install_name_error_note() -> None:
    """In a notebook kernel, explain a missing name (:func:`_explain_name_error`); elsewhere nothing."""
    try:
        from IPython import get_ipython
    except ImportError:
        return
    shell = get_ipython()
    if shell is not None and getattr(shell, "kernel", None) is not None:
        shell.set_custom_exc((NameError,), _explain_name_error)


_install_name_error_note()


class waiting_for(contextlib.AbstractContextManager):
    """A demonstration that needs an exercise: until it is written, say so and skip the rest.

    When the block stops with another error (the answer returned None, say), the cell says
    which exercise it uses and points to that exercise's check, instead of a bare traceback.

    >>> def task2_sweep():
    ...     raise NotImplementedError("exercise 6.3: task2_sweep")
    >>> with waiting_for("6.3"):
    ...     sweep = task2_sweep()
    This cell waits for exercise 6.3: write it, run it, then run this cell again.
    >>> try:
    ...     with waiting_for("6.3"):
    ...         raise ValueError("nothing was sent.")
    ... except CheckFailed as e:
    ...     print(e)
    this cell uses your answer to exercise 6.3, and it stopped with ValueError: nothing was sent. Run exercise 6.3's check cell first: it says what is wrong.

    When an exercise the answer builds on (``builds_on``, or what the exercise's check names) fails its
    own check, the cell names that part instead (:func:`snakekit.verdicts.stopped_note`).
    """

    def __init__(self, exercise: str, *, builds_on: tuple = ()):
        self.exercise = exercise
        self.builds_on = tuple(builds_on)

    def __exit__(self, kind, value, tb):
        if kind is NotImplementedError or (kind is NameError and getattr(value, "name", None)):
            weak = failing_parts(self.exercise, self.builds_on)
            if kind is NameError and weak:   # made by a cell above from a part that fails its check: the cause
                roots = []   # a part that fails because of its own part (6.3 with a wrong 6.1): that one
                for n in weak:
                    roots += [m for m in (failing_parts(n) or [n]) if m not in roots]
                via = [n for n in weak if n not in roots]
                names = " and ".join(roots)
                if all("not written yet" in CAUSES.get(n, "") for n in roots):   # stubs still: write them
                    them = "it" if len(roots) == 1 else "them"
                    print(f"This cell waits for exercise {names} (`{value.name}` is not defined yet): write {them}, "
                          f"run {them}, then run this cell again.")
                    return True
                made = f"your {' and '.join(via)}, which uses your {names}" if via else f"your {names}"
                fails = "fails its check" if len(roots) == 1 else "fail their checks"
                said = "; ".join(f"{n}: {CAUSES.get(n, 'see its check cell').rstrip('.')}" for n in roots)
                print(f"This cell needs `{value.name}`, which a cell above makes with {made}, and {names} {fails} "
                      f"({said}). Fix {names} first, run its check cell and the cells above, then this cell again.")
                return True
            what = "" if kind is NotImplementedError else f" (`{value.name}` is not defined yet)"
            print(f"This cell waits for exercise {self.exercise}{what}: write it, run it, then run this cell again.")
            return True
        if kind is not None and issubclass(kind, Exception) and not issubclass(kind, CheckFailed):
            weak = failing_parts(self.exercise, self.builds_on)
            if weak:   # a part it builds on fails its check: that is the cause, whatever the error advises
                raise _shorten(CheckFailed(stopped_note(self.exercise, weak, value), _student_frames(tb))) from None
            # most often the exercise's answer is not right yet (it returned None, a list...): its
            # check cell says what is wrong, in more words than this cell's error can
            raise _shorten(CheckFailed(
                f"this cell uses your answer to exercise {self.exercise}, and it stopped with {kind.__name__}: "
                f"{str(value).rstrip('.')}. Run exercise {self.exercise}'s check cell first: it says what is wrong.",
                _student_frames(tb))) from None
        return False
