"""One mistake, one message: for a wrong value, the notebook's check and the graded feedback name the same
entry (the one furthest from its expected value; in a table of rows, the first wrong row) in the same words:
its name, its value, the expected value, how far off, and the tolerance with its reason.

Over every exercise the grader judges by closeness (a lesson's reference of kind ``values``, not one of the
rules of :mod:`grader.scoring.rules`) and every value it compares, at hidden cases drawn as a batch draws
them: expected values of many shapes and sizes, one or several entries moved beyond both sides' tolerance
by random amounts, others moved within both. The two message-making functions are compared at their
boundary: the check's :meth:`snakekit.checks.Exercise.close`, called as the exercise's check cell calls it
(its ``what``, ``unit``, ``labels``, ``tol``, ``rtol`` and ``why``, read from the cell), and the grader's
:func:`grader.scoring.score.score_exercise`, with the wording it reads from the same cell and the tolerances
of the lesson's recorded reference. Running ``snakekit grade`` per case would check the same two functions
at a few hundred times the cost (a sandboxed kernel per notebook), so only a handful of wrong answers could
be tried; tests/grader/test_hints_graded.py grades real notebooks end to end.
"""

from __future__ import annotations

import ast
import zlib
from pathlib import Path

import numpy as np
import pytest

from grader.scoring.cases import draw
from grader.scoring.references import REFERENCES, Reference
from grader.scoring.rules import RULES
from grader.scoring.score import DEFAULT_TOLERANCES, Expected, call, handed_in_function, score_exercise
from grader.scoring.wording import EXERCISE, signatures, wording
from snakekit import checks
from snakekit.closeness import ZERO, bound, per_row
from tests.conftest import need

COURSE = Path(__file__).resolve().parents[2] / "course"
LESSONS = sorted(p.name for p in (COURSE / "source").iterdir() if (p / f"{p.name}.ipynb").exists())
TRIES = 60   # wrong answers per compared value


def _exercises():
    nbformat = need("nbformat")
    out = []
    for lesson in LESSONS:
        nb = nbformat.read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4)
        ref = Reference.load(REFERENCES / f"{lesson}.npz")
        sigs = signatures(c.source for c in nb.cells if c.cell_type == "code")
        for c in nb.cells:
            gid = c.metadata.get("nbgrader", {}).get("grade_id")
            if c.metadata.get("nbgrader", {}).get("grade") and gid in ref.exercises \
                    and ref.exercises[gid]["kind"] == "values" and gid not in RULES:
                out.append((lesson, gid, c.source, sigs, ref.exercises[gid]))
    return out


EXERCISES = _exercises()


def _check_calls(source: str) -> dict:
    """The check cell's ``ex.close`` calls by what they compare (an f-string's placeholders left out): the
    arguments of the first of each, in the cell's order, as the check passes them (``**TOOL`` expanded, a
    name the cell assigns, ``labels=FIELDS``, read as its value)."""
    tree = ast.parse(source)
    names = {n.targets[0].id: n.value for n in ast.walk(tree)
             if isinstance(n, ast.Assign) and len(n.targets) == 1 and isinstance(n.targets[0], ast.Name)}

    def value(node):
        node = names.get(node.id, node) if isinstance(node, ast.Name) else node
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "per_row":   # checks.per_row("m", ...)
            return per_row(*(value(a) for a in node.args))
        if isinstance(node, ast.JoinedStr):
            return " ".join("".join(v.value if isinstance(v, ast.Constant) else " " for v in node.values).split())
        try:
            return ast.literal_eval(node)
        except ValueError:
            return None

    out = {}
    for node in sorted((n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "attr", "") == "close"),
                       key=lambda n: (n.lineno, n.col_offset)):
        kw = {}
        for k in node.keywords:
            if k.arg is None and isinstance(k.value, ast.Name):   # **TOOL: the cell's dict(...)
                kw.update({a.arg: a.value for a in names[k.value.id].keywords})
            elif k.arg is not None:
                kw[k.arg] = k.value
        if "what" in kw:
            args = {k: value(kw[k]) for k in ("what", "unit", "labels", "tol", "rtol", "why") if k in kw}
            args["templated"] = isinstance(kw["what"], ast.JoinedStr)
            out.setdefault(args["what"], args)
    return out


def _expected_value(rng, labels) -> np.ndarray:
    """A value to be right about: a number, a row or a matrix (with ``labels``, its entries named: one entry
    per label, or a table of rows), of random sizes and magnitudes, with exact zeros and whole numbers among
    its entries (what a time, a tick count or a joint number holds)."""
    kinds = ["labelled", "table"] if labels else ["number", "row", "matrix"]
    kind = kinds[rng.integers(len(kinds))]
    shape = {"number": (), "row": (int(rng.integers(1, 40)),), "matrix": tuple(int(x) for x in rng.integers(1, 9, 2)),
             "labelled": (len(labels or ()),), "table": (int(rng.integers(1, 12)), len(labels or ()))}[kind]
    value = rng.normal(size=shape) * 10.0 ** rng.uniform(-3, 3)
    special = rng.random(shape) < 0.2
    value = np.where(special, np.round(value) * (rng.random(shape) < 0.5), value)
    return np.array(value + 0.0, dtype=float)   # no -0


def _wrong(rng, want, atols) -> np.ndarray:
    """``want`` with one or several entries moved beyond every tolerance in ``atols`` (pairs of tol, rtol) by
    random amounts, and others moved by less than any of them; one time in five, every entry moved by one
    amount (a time vector one step late: equally far off everywhere, give or take rounding)."""
    widest = np.max([bound(want, atol=a, rtol=r) for a, r in atols], axis=0)
    narrowest = np.min([bound(want, atol=a, rtol=r) for a, r in atols], axis=0)
    if rng.random() < 0.2:
        return want + rng.choice([-1, 1]) * widest.max() * 10.0 ** rng.uniform(1, 9)
    got = want.copy()
    flat, far, near = got.reshape(-1), widest.reshape(-1), narrowest.reshape(-1)
    order = rng.permutation(flat.size)
    n_wrong = int(rng.integers(1, flat.size + 1))
    for k in order[:n_wrong]:
        flat[k] += rng.choice([-1, 1]) * far[k] * 10.0 ** rng.uniform(1, 9)
    for k in order[n_wrong:]:
        if rng.random() < 0.5:
            flat[k] += rng.uniform(-0.5, 0.5) * near[k]
    return got


def _local(source: str, what: str, check: dict, got, want) -> str:
    """What the check cell's ``ex.close`` says of ``got``, called as the cell calls it (``what``: at the case)."""
    number, name = EXERCISE.search(source).groups()
    ex = checks.Exercise(number, name)
    labels = tuple(check["labels"]) if check.get("labels") is not None else None
    with pytest.raises(checks.CheckFailed) as e:
        ex.close(got, want, what=what, unit=check.get("unit", ""), labels=labels, tol=check.get("tol", 0.0),
                 rtol=check.get("rtol", 1e-9), why=check.get("why"))
    said = str(e.value)
    assert said.startswith(f"{ex.prefix}: "), said
    return said[len(ex.prefix) + 2:].split(checks.CheckFailed.HINT)[0]   # its hint is the hint's test


def _graded(gid: str, w, name: str, args, got, want, tol: dict) -> str:
    e = Expected(gid, "values", [args], [{name: want}], tol, wording=w)
    verdict = score_exercise(gid, [{name: got}], e, 1.0)
    assert verdict.score == 0.0, verdict.message
    head = f"1 of 1 hidden cases wrong; the first: {call(w, args)}: "
    assert verdict.message.startswith(head), verdict.message
    return verdict.message[len(head):]


def _split(sentence: str) -> tuple[str, str]:
    """A wrong entry's sentence as (what it names with the numbers, its tolerance)."""
    at = sentence.rindex(" (tolerance ")
    return sentence[:at], sentence[at:]


def _judged(tol: float, rtol: float) -> tuple:
    """A tolerance as it judges: an absolute part at or below the floor is the floor."""
    return (tol if tol > ZERO else 0.0, rtol)


#: What the grader compares in words of its own, not a value of the exercise's check (a flag its test cell
#: makes of the result, the sum of several checks): there is no local message to match.
OWN_WORDS = {("ex06_2_sweep_positions_test", "last_row_home"),
             ("ex07_1_ticks_test", "whole_numbers"),
             ("ex07_2_safe_move_test", "arm_still"), ("ex07_2_safe_move_test", "moves"),
             ("ex07_2_safe_move_test", "refused"), ("ex07_3_fault_test", "errors_cleared"),
             ("ex07_3_fault_test", "rebooted"), ("ex07_3_fault_test", "torque_on")}


@pytest.mark.parametrize("lesson, gid, source, sigs, ref", EXERCISES, ids=[e[1] for e in EXERCISES])
def test_a_wrong_value_is_named_alike_in_the_check_and_the_graded_feedback(lesson, gid, source, sigs, ref):
    tol = {**DEFAULT_TOLERANCES["values"], **ref["tolerances"]}
    w = wording(gid, source, handed_in_function(gid, source), sigs)
    calls = _check_calls(source)
    cases = draw(COURSE, lesson, seed=7).cases[gid]
    rng = np.random.default_rng(zlib.crc32(gid.encode()))
    compared = 0
    for name in ref["outputs"]:
        for t in range(TRIES):
            args = cases[t % len(cases)]
            part = w.part(name, args)
            # the part as the cell writes it (its placeholders unfilled), the one the case names (2.2's "g", "tool")
            check = calls.get(part.what) or calls.get(w.part(name).what)
            assert (check is None) == ((gid, name) in OWN_WORDS), f"{gid} {name}: {part}"
            if check is None:
                break
            what = part.what if check["templated"] else check["what"]
            want = _expected_value(rng, check.get("labels"))
            got = _wrong(rng, want, [(check.get("tol", 0.0), check.get("rtol", 1e-9)), (tol["atol"], tol["rtol"])])
            local = _local(source, what, check, got, want)
            graded = _graded(gid, w, name, args, got, want, tol)
            (said, tol_said), (graded_said, tol_graded) = _split(local), _split(graded)
            assert said == graded_said, f"{gid} {name}:\n  local:  {local}\n  graded: {graded}"
            if _judged(check.get("tol", 0.0), check.get("rtol", 1e-9)) == _judged(tol["atol"], tol["rtol"]):
                assert tol_said == tol_graded, f"{gid} {name}:\n  local:  {local}\n  graded: {graded}"
            else:   # the grader's tolerance is another (its cases module's): each says its own, for the same reason
                reason = check.get("why") or "exact math"
                assert tol_said.split(": ", 1)[1].startswith(reason) and tol_graded.split(": ", 1)[1].startswith(reason), \
                    f"{gid} {name}:\n  local:  {local}\n  graded: {graded}"
            compared += 1
    assert compared == TRIES * sum((gid, n) not in OWN_WORDS for n in ref["outputs"])


def _lesson_cell(lesson: str, gid: str) -> tuple[str, dict]:
    nbformat = need("nbformat")
    nb = nbformat.read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    source = next(c.source for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") == gid)
    return source, signatures(c.source for c in nb.cells if c.cell_type == "code")


def test_a_jacobian_row_is_named_in_its_own_unit_graded_as_in_the_check():
    """2.1: the heading row is in rad/rad, locally and graded (graded, it was "m", off by "1000 mm")."""
    gid = "ex02_1_planar_jacobian_test"
    source, sigs = _lesson_cell("02_jacobian", gid)
    ref = Reference.load(REFERENCES / "02_jacobian.npz").exercises[gid]
    tol = {**DEFAULT_TOLERANCES["values"], **ref["tolerances"]}
    w = wording(gid, source, handed_in_function(gid, source), sigs)
    check = _check_calls(source)["Jacobian"]
    q = np.zeros(5)
    want = np.vstack([np.zeros(5), [0.3315, 0.2605, 0.1895, 0.1185, 0.0475], np.ones(5)])
    got = want.copy()
    got[2, 0] = 0.0
    local = _local(source, "Jacobian", check, got, want)
    graded = _graded(gid, w, "value", (q,), got, want, tol)
    assert local.startswith("Jacobian[2, 0] is 0 rad/rad, expected 1 rad/rad: off by 1 rad/rad (tolerance "), local
    assert _split(local)[0] == _split(graded)[0] and "mm" not in graded, graded
    got = want.copy()
    got[1, 3] += 1e-3   # a position row: in m, its difference in mm
    assert "Jacobian[1, 3] is 0.1195 m, expected 0.1185 m: off by 1 mm" in _graded(gid, w, "value", (q,), got, want, tol)


@pytest.mark.parametrize("function, what", [("g", "entry [2, 2] of Jacobian of g"),
                                            ("tool", "entry [2, 2] of Jacobian of the tool pose")])
def test_a_finite_difference_is_named_with_its_test_function_and_its_reason_graded_as_in_the_check(function, what):
    """2.2: graded, the tolerance is the check's "finite differences" (it said "exact math, 1e-06"), the value is
    named by the test function the case takes ("Jacobian of g"), and the tool pose's heading row is in rad/rad."""
    gid = "ex02_2_numerical_jacobian_test"
    source, sigs = _lesson_cell("02_jacobian", gid)
    ref = Reference.load(REFERENCES / "02_jacobian.npz").exercises[gid]
    tol = {**DEFAULT_TOLERANCES["values"], **ref["tolerances"]}
    w = wording(gid, source, handed_in_function(gid, source), sigs)
    n = 3 if function == "g" else 5
    want = np.arange(3.0 * n).reshape(3, n) / 10
    got = want.copy()
    got[2, 2] += 0.5
    args = (function, np.zeros(n), 1e-3)
    graded = _graded(gid, w, "value", args, got, want, tol)
    part = w.part("value", args)
    local = _local(source, part.what, _check_calls(source)[part.what], got, want)
    unit = "" if function == "g" else " rad/rad"
    assert graded == local, f"local:  {local}\ngraded: {graded}"
    assert graded.startswith(f"{what} is {want[2, 2] + 0.5:.4g}{unit}, expected {want[2, 2]:.4g}{unit}: off by "
                             f"0.5{unit} (tolerance 1e-06{unit}: finite differences)."), graded
