"""Score one exercise from what the student's kernel handed in, case by case, against the
instructor solution's results at the same cases.

Runs in the grader's own process: nothing here executes student code. A hand-in is the npz of
:func:`snakekit.handin.encode_results` (read with ``allow_pickle=False``): per hidden case a dict
of arrays (the function's value, or a procedure's named arrays) or the text of what went wrong
(``"<Type>: <message>"``, ``"returned None"``). The expected results (:class:`Expected`) come
from the instructor notebook, run by the grader at the batch's cases (:mod:`grader.scoring.references`).

Kinds of exercise, recognised from the names the instructor's results carry:

* ``run``: a recorded run (``measured_times``, ``measured_positions``) and the commanded
  trajectory (``times``/``positions`` or ``commanded_times``/``commanded_positions``);
* ``trajectory``: ``times`` and ``positions``;
* ``values``: anything else (a function's value, or named arrays).
"""

from __future__ import annotations

import re
import zipfile
from dataclasses import dataclass, field

import numpy as np

from snakekit.closeness import bound, is_table, not_finite, sentence, worst
from snakekit.errors import SnakekitError
from snakekit.handin import decode_results
from snakekit.watch import forgot_return, not_an_array
from snakekit.model import SPEC
from snakekit.trajectory import Trajectory

from grader.scoring import compare
from grader.scoring.cases import describe
from grader.scoring.rules import RULES
from grader.scoring.wording import Wording

__all__ = ["ExerciseScore", "Expected", "kind_of", "read_handin", "score_exercise"]

#: Default tolerances by kind: exact math (course/README.md); a commanded trajectory 1e-6 rad.
DEFAULT_TOLERANCES = {"values": {"rtol": 1e-9, "atol": 1e-12}, "trajectory": {"max": 1e-6, "rms": 1e-6}}


@dataclass(frozen=True)
class ExerciseScore:
    """The grader's verdict on one autograded test cell.

    Attributes:
        grade_id: the test cell's nbgrader id.
        score, max_score: points.
        status: ``scored``, ``missing``, ``inconsistent`` or ``tampered``.
        message: what the student reads: the checks that failed, with numbers.
        checks: the individual checks.
        cases: per hidden case, ``(kind, fraction right)`` (:func:`case_kind`), for the class's report.
        curves: for plots: name -> (times, positions) of the student's and the reference's runs.
    """

    grade_id: str
    score: float
    max_score: float
    status: str
    message: str
    checks: tuple = ()
    curves: dict = field(default_factory=dict, repr=False)
    cases: tuple = ()


@dataclass(frozen=True)
class Expected:
    """One exercise's hidden cases in this batch and the instructor's results there.

    Attributes:
        grade_id: the test cell's nbgrader id.
        kind: ``values``, ``trajectory`` or ``run``.
        cases: each case's positional arguments.
        results: per case, the instructor's dict of arrays, or the exception it raised
            (``"<Type>: <message>"``: the student must raise the same type there).
        tolerances: ``rtol``/``atol`` (values), ``max``/``rms`` (trajectories; a run's
            measured angles), ``commanded_max``/``commanded_rms`` (a run's commanded trajectory).
        function: the name of the function the test cell hands in (see :func:`handed_in_function`).
        wording: how messages name the student's function, its arguments and each value, in the words of
            the notebook's check (:func:`grader.scoring.wording.wording`); default: the names handed in.
    """

    grade_id: str
    kind: str
    cases: list
    results: list = field(repr=False)
    tolerances: dict = field(default_factory=dict)
    function: str = ""  # what the test cell hands in; default: from the grade id
    wording: Wording | None = None

    def words(self) -> Wording:
        return self.wording or Wording(self.function or label(self.grade_id))


def kind_of(results) -> str:
    """The kind of exercise the instructor's ``results`` (per case: a dict or an error) show."""
    names = set().union(*(r for r in results if isinstance(r, dict))) if results else set()
    if {"measured_times", "measured_positions"} <= names:
        return "run"
    if {"times", "positions"} <= names or {"commanded_times", "commanded_positions"} <= names:
        return "trajectory"
    return "values"


def case_kind(args, want) -> str:
    """What kind of hidden case a case is, from the instructor's result there: one where the exercise
    asks for an error, the function at its defaults (the task itself), or a case drawn for the batch.

    >>> case_kind((3, 1.0), "LimitError: beyond"), case_kind((), {}), case_kind((3, 1.0), {})
    ('must raise LimitError', 'at its defaults', 'drawn')
    """
    if isinstance(want, str):
        return f"must raise {want.split(':', 1)[0]}"
    return "at its defaults" if len(args) == 0 else "drawn"


def read_handin(data: bytes) -> list:
    """The results of a hand-in file. Raises ValueError if it is not one."""
    try:
        out = decode_results(data)
    except (OSError, ValueError, EOFError, KeyError, SnakekitError, zipfile.BadZipFile) as e:
        raise ValueError(f"the hand-in file is not readable ({type(e).__name__})") from e
    for r in out:
        for a in r.values() if isinstance(r, dict) else ():
            if a.dtype.kind not in "biuf":
                raise ValueError("the hand-in holds something other than numbers")
    return out


def _zero(gid, max_score, status, message):
    return ExerciseScore(gid, 0.0, max_score, status, message)


def label(grade_id: str) -> str:
    """What a student calls an exercise's function: ``ex06_1_sweep_times_test`` -> ``sweep_times``.

    >>> label("ex06_1_sweep_times_test"), label("ex1_tool_xy_test"), label("odd")
    ('sweep_times', 'tool_xy', 'odd')
    """
    return re.sub(r"^ex\d+(?:_\d+)?_|_test$", "", grade_id) or grade_id


def handed_in_function(grade_id: str, source: str) -> str:
    """The name of the function a test cell's source hands in for ``grade_id`` ("" if none is named).

    >>> handed_in_function("ex1_t", 'ex.hand_in("ex1_t", graded_run, forbid=())')
    'graded_run'
    """
    m = re.search(r"hand_in\(\s*[\"']" + re.escape(grade_id) + r"[\"']\s*,\s*([A-Za-z_][\w.]*)", source)
    return m.group(1) if m else ""


def call(name: str | Wording, args) -> str:
    """The case as a call a student recognises, each argument named as their function names it:
    ``sweep_times(points=4, rate=10)`` (:meth:`grader.scoring.wording.Wording.call`)."""
    w = name if isinstance(name, Wording) else Wording(name)
    return w.call(args)


def _a(word: str) -> str:
    """The article before a type's name: "an int", "a float".

    >>> _a("int"), _a("float"), _a("dict")
    ('an', 'a', 'a')
    """
    return "an" if word[:1].lower() in "aeiou" else "a"


def explain_error(text: str, name: str = "your function", returns: str = "") -> str:
    """What went wrong in the student's function ``name`` at a case, in plain words; a forgotten
    ``return`` in the words the notebook's own check uses (:func:`snakekit.watch.forgot_return`); a result the
    test cell could not use (``"returned tuple from task2_sweep"``) as the wrong kind of result (``returns``:
    the kind the exercise asks for, as its check says).

    >>> explain_error("returned None from task1", "graded_task1")[:52]
    'task1 returned None: did you forget `return`? A func'
    >>> explain_error("NameError: name 'sweep_times' is not defined", "sweep_times")[:59]
    'sweep_times is not defined: its answer cell did not run to '
    >>> explain_error("returned tuple from task2_sweep", "graded_run", "a snakekit.Trajectory")
    'task2_sweep should return a snakekit.Trajectory, got tuple.'
    >>> explain_error("NameError: name 'helper' is not defined", "sweep_times")
    "your function raised NameError: name 'helper' is not defined"
    """
    m = re.match(r"not an array: (\w+)(?: (\w+))? from (\w+)$", text)
    if m:   # a list where the exercise asks for an array: the notebook's check's words (snakekit.watch.not_an_array)
        return not_an_array(m.group(3), m.group(1), m.group(2) or "")
    m = re.match(r"returned (\w+) from (\w+)$", text)
    if m and m.group(1) == "None":
        return forgot_return(m.group(2))
    if m:   # the test cell's code stumbled on what the function gave back: a result of the wrong kind
        what, fn = m.groups()
        return f"{fn} should return {returns}, got {what}." if returns else \
            f"{fn} returned {_a(what)} {what}, which is not the kind of result the exercise asks for (see its check)."
    m = re.match(r"returned (\w+)(?: for (\w+))?$", text)
    if m:
        what, part = m.groups()
        if what == "None":
            return forgot_return(name) if not part else \
                f"the '{part}' of the result of {name} is None: " + forgot_return(name).split(": ", 1)[1]
        where = f"the '{part}' of your result" if part else "your function"
        if what in ("list", "tuple"):   # (a hand-in's own array=True: the same words as the check's)
            return not_an_array(name, what)
        return f"{where} returned {_a(what)} {what}, not numbers or an array."
    if text.startswith("ShortcutError:"):
        return text.split(":", 1)[1].strip()
    m = re.match(r"NameError: name '(\w+)' is not defined", text)
    if m and m.group(1) == name:
        return (f"{name} is not defined: its answer cell did not run to the end (an error in that cell, such as "
                f"an IndentationError or a SyntaxError, stops it before the def): see that cell's output above.")
    etype, _, msg = text.partition(":")
    return f"your function raised {etype}: {msg.strip()}" if msg.strip() else f"your function raised {etype}."


def score_exercise(grade_id: str, handin: list | None, expected: Expected, max_score: float) -> ExerciseScore:
    """Points for one test cell: every case of ``handin`` against ``expected``'s."""
    if handin is None:
        return _zero(grade_id, max_score, "missing", "nothing was handed in: the test cell stopped before it "
                     "handed in your results (an error before that line, a timeout, or the kernel stopped).")
    n = len(expected.cases)
    if len(handin) != n:
        return _zero(grade_id, max_score, "inconsistent",
                     f"hand-in inconsistent: {len(handin)} results for the {n} hidden cases the grader gave.")
    if expected.kind == "values":
        return _score_values(grade_id, handin, expected, max_score)
    return _score_motion(grade_id, handin, expected, max_score)


def _raised_as_expected(w: Wording, args, got, want: str) -> tuple[bool, str]:
    """An instructor exception at a case: the student must raise the same type there."""
    etype = want.split(":", 1)[0]
    if isinstance(got, str) and got.split(":", 1)[0] == etype:
        return True, ""
    did = explain_error(got, w.function, _kind(w)) if isinstance(got, str) else "your function returned a result"
    return False, f"{call(w, args)} must raise {etype} (the exercise asks for it there); {did}"


def _kind(w: Wording) -> str:
    """The kind of result the exercise asks for, as its check names it ("a snakekit.Trajectory"); "" if it names none."""
    return f"a {w.returns}" if w.returns else ""


def _compare_case(w: Wording, got: dict, want: dict, tol: dict, case=()) -> str:
    """Why a case's results differ from the instructor's ("" when they agree), worded as the notebook's
    check words it: the entry its check would name, the value's name and unit, the numbers with the check's
    digits and the tolerance with the check's reason (:mod:`snakekit.closeness`)."""
    for name, e in want.items():
        part = w.part(name, case)
        if name not in got:
            return f"your result does not say {part.what}." if part.said else f"your result has no {part.what}."
        g, e = np.asarray(got[name]), np.asarray(e)
        if e.dtype.kind == "b" and g.shape == e.shape and not np.array_equal(g.astype(bool), e):
            if part.said:   # a yes or no, said as what it means (wording.WORDS), never "refused is True"
                return f"{part.said[0 if bool(np.all(g)) else 1]}."
            return f"{part.what} is {bool(np.all(g))}, expected {bool(np.all(e))}."
        g, e = g.astype(float), e.astype(float)
        if g.shape != e.shape:
            hint = compare.TRANSPOSE if g.ndim == 2 and g.shape == e.shape[::-1] else ""
            return f"{part.what} has shape {g.shape}, expected {e.shape}{hint}."
        if not np.isfinite(g).all():
            return not_finite(part.what, g)
        # the entry the notebook's check names, in its words (snakekit.closeness), at the grader's tolerances
        at = bound(e, atol=tol["atol"], rtol=tol["rtol"])
        idx = worst(g, e, at, table=is_table(part.labels, e.shape))
        if idx is not None:
            return sentence(part.name_at(idx, g.ndim), g[idx], e[idx], at[idx], part.unit_at(idx), atol=tol["atol"],
                            rtol=tol["rtol"], why=part.why)
    return ""


def _score_values(gid, handin, expected: Expected, max_score) -> ExerciseScore:
    tol = {**DEFAULT_TOLERANCES["values"], **expected.tolerances}
    w = expected.words()
    rule = RULES.get(gid)
    ok, why = [], []
    for args, got, want in zip(expected.cases, handin, expected.results):
        if isinstance(want, str):
            right, msg = _raised_as_expected(w, args, got, want)
        elif isinstance(got, str):
            right, msg = False, f"{call(w, args)}: {explain_error(got, w.function, _kind(w))}"
        elif rule is not None:  # judged by a property (grader.scoring.rules), not closeness
            right, msg = rule(args, got, tol)
            msg = f"{call(w, args)}: {msg}" if msg else ""
        else:
            msg = _compare_case(w, got, want, tol, args)
            right, msg = not msg, f"{call(w, args)}: {msg}" if msg else ""
        ok.append(right)
        if msg:
            why.append(msg)
    check = _cases_check(ok, why)
    kinds = tuple((case_kind(args, want), float(right)) for args, want, right in zip(expected.cases, expected.results, ok))
    return ExerciseScore(gid, round(check.fraction * max_score, 4), max_score, "scored", check.message, (check,),
                         cases=kinds)


def _cases_check(ok, why, name: str = "hidden cases", weight: float = 1.0) -> compare.Check:
    """``ok``: per case whether it is right, or the share of it that is (a rule's partial credit)."""
    n, nbad = len(ok), sum(float(x) < 1.0 for x in ok)
    if not nbad:
        return compare.Check(name, 1.0, f"all {n} hidden cases right.", weight)
    part = "" if all(float(x) in (0.0, 1.0) for x in ok) else " (some in part)"
    return compare.Check(name, float(np.mean([float(x) for x in ok])),
                         f"{nbad} of {n} hidden cases wrong{part}; the first: {why[0]}", weight)


# --- trajectories and runs ------------------------------------------------------------------------


def _trajectory(d: dict, times: str, positions: str, what: str) -> Trajectory:
    if times not in d or positions not in d:
        raise ValueError(f"your result holds no {what}")
    try:
        return Trajectory(d[times], d[positions])
    except (SnakekitError, ValueError) as e:
        raise ValueError(f"the {what} is not a valid trajectory: {e}") from e


#: How far from where the arm stands a trajectory may start [rad] (the robot interface's ``start_tolerance``).
START_TOLERANCE = 0.05


def refused(cmd: Trajectory) -> str:
    """Why the arm made no run of the commanded trajectory ``cmd``: the reason the robot interface refuses
    one (it breaks the limits; it does not start where the arm stands, at home), in a student's words.

    >>> print(refused(Trajectory([0.0, 0.1], [[0.09, 0, 0, 0, 0], [0.0, 0, 0, 0, 0]])))
    the arm made no run of it: it starts with joint 1 at +0.0900 rad, away from home where the arm stands, and the arm refuses a trajectory that does not start where it is (nothing was sent).
    """
    if cmd.limit_violations():
        why = "it breaks the joint limits, and the arm refuses such a trajectory (nothing was sent)"
    else:
        gap = np.abs(cmd.positions[0] - np.asarray(SPEC.home))
        j = int(gap.argmax())
        why = (f"it starts with joint {j + 1} at {cmd.positions[0, j]:+.4f} rad, away from home where the arm "
               "stands, and the arm refuses a trajectory that does not start where it is (nothing was sent)") if gap[j] > START_TOLERANCE else "the arm refused it"
    return f"the arm made no run of it: {why}."


def _motion_checks(got: dict, want: dict, kind: str, tol: dict):
    """The weighted checks of one case: counts and limits of its own, shape against the reference."""
    names = ("times", "positions") if "times" in want else ("commanded_times", "commanded_positions")
    ref_cmd = Trajectory(want[names[0]], want[names[1]])
    cmd = _trajectory(got, *names, "trajectory")
    ref_hz = 1.0 / float(np.median(np.diff(ref_cmd.times))) if len(ref_cmd) > 1 else 1.0
    # the properties the instructor's result has, the student's must have: a count, a rate, and
    # (where the reference has them) limits held, whole sweeps, home at both ends
    checks = [compare.point_count(cmd, len(ref_cmd)), compare.rate(cmd, ref_hz)]
    safe = []  # properties any quiet trajectory has: they earn only on a sweep of the case's size
    if not ref_cmd.limit_violations():
        safe.append(compare.limits(cmd))
    sweeps = compare.count_sweeps(ref_cmd.positions)
    if sweeps >= 1:
        checks.append(compare.sweep_count(cmd, max(1, round(sweeps))))
    if compare.home(ref_cmd).passed:
        safe.append(compare.home(cmd))
    safe.append(compare.smoothness(cmd, ref_cmd))
    checks += safe + [compare.tracking(cmd, ref_cmd, max_tol=tol.get("commanded_max", tol["max"]),
                                rms_tol=tol.get("commanded_rms", tol["rms"]), name="commanded vs reference",
                                weight=2.0)]
    curves = {"commanded": (cmd.times, cmd.positions), "reference commanded": (ref_cmd.times, ref_cmd.positions)}
    if kind == "run":
        ref_meas = Trajectory(want["measured_times"], want["measured_positions"])
        try:
            meas = _trajectory(got, "measured_times", "measured_positions", "recorded run") \
                if {"measured_times", "measured_positions"} <= set(got) else None
        except ValueError as e:
            checks.append(compare.Check("run vs reference", 0.0, str(e).rstrip(".") + ".", 2.0))
        else:
            if meas is None:
                checks.append(compare.Check("run vs reference", 0.0, refused(cmd), 2.0))
            else:
                checks.append(compare.tracking(meas, ref_meas, max_tol=tol["max"], rms_tol=tol["rms"],
                                               what="measured angle", name="run vs reference", weight=2.0))
                curves["measured"] = (meas.times, meas.positions)
                curves["reference measured"] = (ref_meas.times, ref_meas.positions)
    if len(cmd) != len(ref_cmd) and abs(cmd.duration - ref_cmd.duration) > 0.01 * ref_cmd.duration:
        # another number of points over another time: not the sweep this case asks for (a stored
        # one returned whatever the arguments); only its count is judged, nothing earns for being
        # safe, smooth or at home by accident
        asked = f"{len(cmd)} points over {cmd.duration:.4g} s where {len(ref_cmd)} over {ref_cmd.duration:.4g} s " \
                "were asked"
        checks = [c if c.name == "points" else compare.Check(c.name, 0.0, f"not judged: {asked}.", c.weight)
                  for c in checks]
    return checks, curves


def _score_motion(gid, handin, expected: Expected, max_score) -> ExerciseScore:
    """Each check's credit is its mean over the cases (a case that failed to run: 0 for all)."""
    tol = {**DEFAULT_TOLERANCES["trajectory"], **expected.tolerances}
    w = expected.words()
    rows, raised, curves, per_case = [], [], {}, []
    for args, got, want in zip(expected.cases, handin, expected.results):
        where = call(w, args)
        if isinstance(want, str):
            raised.append(_raised_as_expected(w, args, got, want))
            per_case.append((case_kind(args, want), raised[-1]))
            continue
        per_case.append((case_kind(args, want), len(rows)))
        try:
            if isinstance(got, str):
                raise ValueError(explain_error(got, w.function, _kind(w)))
            checks, c = _motion_checks(got, want, expected.kind, tol)
        except ValueError as e:
            rows.append((where, f"{where}: {e}"))
            continue
        rows.append((where, {ck.name: ck for ck in checks}))
        curves = curves or c
    good = [r for _, r in rows if isinstance(r, dict)]
    errors = [r for _, r in rows if isinstance(r, str)]
    # the case without arguments is the task itself (6.3: task2_sweep(), Task 2): it weighs as much
    # as the other cases together, which show the function follows its arguments
    motion = [args for args, want in zip(expected.cases, expected.results) if not isinstance(want, str)]
    weights = [max(1, len(motion) - 1) if len(args) == 0 else 1 for args in motion]
    checks = []
    for name, first in (good[0].items() if good else ()):
        fractions = [r[name].fraction if isinstance(r, dict) else 0.0 for _, r in rows]
        bad = next((f"{w}: {r[name].message}" for w, r in rows if isinstance(r, dict) and not r[name].passed), "")
        checks.append(compare.Check(name, float(np.average(fractions, weights=weights)),
                                    bad or f"{name}: right in every hidden case.", first.weight))
    if rows and not good:
        checks.append(compare.Check("results", 0.0, errors[0], 10.0))
    if raised:
        checks.append(_cases_check([ok for ok, _ in raised], [m for ok, m in raised if not ok], "raises as asked"))
    total = sum(c.weight for c in checks)
    fraction = sum(c.weight * c.fraction for c in checks) / total if total else 0.0
    failed = list(dict.fromkeys(c.message for c in checks if not c.passed))   # each said once
    if good and errors:
        failed.insert(0, f"{len(errors)} of {len(rows)} hidden cases gave no trajectory; the first: {errors[0]}")
    msg = " ".join(failed) if failed else "every check passed in every hidden case."
    kinds = tuple((kind, float(at[0]) if isinstance(at, tuple) else _case_fraction(rows[at][1]))
                  for kind, at in per_case)
    return ExerciseScore(gid, round(fraction * max_score, 4), max_score, "scored", msg, tuple(checks), curves, kinds)


def _case_fraction(row) -> float:
    """One motion case's share right: its checks weighted as the exercise weighs them (0 if it gave no trajectory)."""
    if not isinstance(row, dict):
        return 0.0
    total = sum(c.weight for c in row.values())
    return float(sum(c.weight * c.fraction for c in row.values()) / total) if total else 0.0
