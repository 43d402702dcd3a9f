"""A graded message speaks the student's words: for every exercise of the course, with a wrong answer, it names
the student's function and each value as the notebook's own check does (its name and unit), never a name that
only the test cell holds (a helper that hands in, a key of what it hands in, a variable of its own).

No notebook runs here: each exercise's hidden cases are drawn from its cases module, the instructor's results
stand as the kinds and names its reference records, and wrong hand-ins of every kind a student's code gives
(another value, another shape, a missing value, an error, a forgotten ``return``) are scored as the grader scores
them (:func:`grader.scoring.score.score_exercise`, with the test cell's wording as :func:`grader.scoring.references.expected`
gives it).
"""

from __future__ import annotations

import ast
import builtins
import re
import runpy
from pathlib import Path

import numpy as np
import pytest

from grader import markup
from grader.scoring.references import REFERENCES, Reference
from grader.scoring.score import Expected, handed_in_function, score_exercise
from grader.scoring.wording import signatures, wording
from snakekit import SPEC
from tests.conftest import need

ROOT = Path(__file__).resolve().parents[2]
COURSE = ROOT / "course"
LESSONS = sorted(p.name for p in (COURSE / "source").iterdir() if (p / f"{p.name}.ipynb").exists())


def _lesson(lesson: str):
    nb = need("nbformat").read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    tests = {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade")}
    # what the student reads and writes: the lesson's text, the answer cells (their solutions) and what the
    # visible checks say (their strings)
    own = [c.source for c in nb.cells if c.cell_type == "markdown" or
           (c.metadata.get("nbgrader", {}).get("solution") and not c.metadata["nbgrader"].get("grade"))]
    own += [n.value for src in tests.values() for n in ast.walk(ast.parse(markup.visible_part(src)))
            if isinstance(n, ast.Constant) and isinstance(n.value, str)]
    return tests, set(re.findall(r"[A-Za-z_]\w*", " ".join(own)))


def lesson_signatures(lesson: str) -> dict:
    """The parameters of every function the lesson's notebook defines (the grader reads them as a batch does)."""
    nb = need("nbformat").read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    return signatures(c.source for c in nb.cells if c.cell_type == "code")


EXERCISES = [(lesson, gid) for lesson in LESSONS for gid in sorted(_lesson(lesson)[0])]


def cell_identifiers(source: str) -> set[str]:
    """The names a test cell holds: its functions, their arguments, its variables and the keys of its dicts."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.FunctionDef, ast.Lambda)):
            names |= {a.arg for a in node.args.args + node.args.kwonlyargs}
            names |= {a.arg for a in (node.args.vararg, node.args.kwarg) if a}
            names |= {node.name} if isinstance(node, ast.FunctionDef) else set()
        elif isinstance(node, ast.Name):
            names.add(node.id)
        elif isinstance(node, ast.Dict):
            names |= {k.value for k in node.keys if isinstance(k, ast.Constant) and isinstance(k.value, str)}
        elif isinstance(node, ast.Call) and getattr(node.func, "id", None) == "dict":
            names |= {k.arg for k in node.keywords if k.arg}
    return {n for n in names if n.isidentifier() and n not in vars(builtins)}


def _sweep(points, rate, sweeps, amplitude):
    t = np.arange(points) / rate
    return t, np.repeat((amplitude * np.sin(2 * np.pi * sweeps * t / t[-1]))[:, None], 5, axis=1)


#: The exercises judged by a rule (grader.scoring.rules) look at their result's shape first, and a table of
#: rows (4.4's violations: time, joint, kind) is named by its row and column: per case, the shape of each value
#: a right answer has there.
SHAPES = {"ex04_4_limit_check_test": lambda args: {"value": (2, 3)},
          "ex03_1_two_link_ik_test": lambda args: {"value": (2, 2)},
          "ex03_3_ik_loop_test": lambda args: {"value": (5,)},
          "ex03_4_task1_test": lambda args: {"final_q": (len(args[0]), 5), "poses": (len(args[0]), 3)}}


def _want(gid: str, kind: str, names: list, args) -> dict:
    """A result of the instructor's kind and names at a case (numbers that stand for any)."""
    if kind == "values":
        shapes = SHAPES.get(gid, lambda args: {})(args)
        return {n: np.full(shapes.get(n, (2,)), 0.25) + np.arange(int(np.prod(shapes.get(n, (2,))))).reshape(
            shapes.get(n, (2,))) * 0.125 for n in names}
    t, p = _sweep(*(args or (500, 10.0, 50, 0.2)))
    if np.abs(p).max() > SPEC.upper:
        return "LimitError: beyond the joint limits"     # the instructor's raises there
    return {"times": t, "positions": p, "measured_times": t, "measured_positions": p}


def _wrongs(want: dict) -> list:
    """What a wrong answer hands in, of every kind (a late start only where there are times)."""
    off = {n: a * 1.5 + 0.1 for n, a in want.items()}
    late = [{n: a + 0.1 if "times" in n else a for n, a in want.items()}] if "times" in want else []
    shape = {n: np.zeros(3) for n in want}
    return [off, *late, shape, {}, "ValueError: out of reach", "returned None", "returned list",
            "NameError: name 'helper' is not defined"]


def graded_messages(lesson: str, gid: str, *, each: bool = False) -> list[str]:
    """Every message the grader gives at one draw of the exercise's hidden cases, for each kind of wrong answer
    (``each``: for each of its values wrong on its own, the others right)."""
    tests, _ = _lesson(lesson)
    source = tests[gid]
    meta = Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]
    cases = runpy.run_path(str(COURSE / "cases" / f"{lesson}.py"))[gid](np.random.default_rng(5), SPEC)
    results = [_want(gid, meta["kind"], meta["outputs"], args) for args in cases]
    handed = handed_in_function(gid, source)
    e = Expected(gid, meta["kind"], cases, results, meta["tolerances"], handed,
                 wording(gid, source, handed, lesson_signatures(lesson)))
    out = []
    if each:
        for name in results[0]:
            s = score_exercise(gid, [{**r, name: r[name] * 1.5 + 0.1} if isinstance(r, dict) else r for r in results], e, 1.0)
            out += [s.message] + [c.message for c in s.checks]
        return out
    right = next(r for r in results if isinstance(r, dict))
    for k in range(len(_wrongs(right))):
        s = score_exercise(gid, [_wrongs(r)[k] if isinstance(r, dict) else r for r in results], e, 1.0)
        assert s.score < 1.0, (gid, _wrongs(right)[k])
        out += [s.message] + [c.message for c in s.checks]
    return out


@pytest.mark.parametrize("lesson, gid", EXERCISES, ids=[g for _, g in EXERCISES])
def test_no_graded_message_names_what_only_the_test_cell_holds(lesson, gid):
    tests, own = _lesson(lesson)
    # (the words of a wrong answer's own error are the student's: "name 'helper' is not defined")
    theirs = cell_identifiers(tests[gid]) - own - {w for x in _wrongs({}) if isinstance(x, str) for w in re.findall(r"\w+", x)}
    leaks = {(w, m) for m in graded_messages(lesson, gid) for w in re.findall(r"[A-Za-z_]\w*", m) if w in theirs}
    assert not leaks, f"{gid}: the graded messages name {sorted({w for w, _ in leaks})}, which the student never wrote: " \
                      f"{sorted(leaks)[0][1]}"


def _local_units(source: str, outputs: list) -> set[str]:
    """The units the notebook's check names (``ex.close(..., unit=...)``): for a function's value, those of the
    check that compares it whole (2.1's "Jacobian": m, and rad/rad for its heading row), else the one every value
    it compares has (none if they differ); for named values, any."""
    w = wording("", markup.visible_part(source))
    parts = w.parts
    if outputs == ["value"] and w.part("value") in parts:   # one check compares the value whole (2.1's "Jacobian")
        parts = (w.part("value"),)
    per = [set(p.unit) if isinstance(p.unit, tuple) else {p.unit} for p in parts]
    units = (set.union(*per) if outputs != ["value"] or len(parts) == 1 else set.intersection(*per)) if per else set()
    return {u for u in units if u}


def _outputs(lesson, gid):
    return Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]["outputs"]


NUMERIC = [(lesson, gid) for lesson, gid in EXERCISES if _local_units(_lesson(lesson)[0][gid], _outputs(lesson, gid))]


@pytest.mark.parametrize("lesson, gid", NUMERIC, ids=[g for _, g in NUMERIC])
def test_a_wrong_value_graded_names_the_unit_its_notebook_check_names(lesson, gid):
    units = _local_units(_lesson(lesson)[0][gid], _outputs(lesson, gid))
    said = " ".join(graded_messages(lesson, gid, each=True))
    shown = {w for u in units for w in ((u, "mm") if u == "m" else (u,))}   # metres are also shown as mm
    # a value with a unit per entry (x, y in m, the heading in rad) shows the unit of the entry that is wrong
    assert any(re.search(rf"\d {re.escape(w)}(?!\w)", said) for w in shown), f"{gid}: its check names {units}; graded: {said}"


def _named_outputs():
    """Every handed-in value whose name is, word for word, what a compared value of its check is called."""
    out = []
    for lesson, gid in EXERCISES:
        parts = wording("", markup.visible_part(_lesson(lesson)[0][gid])).parts
        for name in _outputs(lesson, gid):
            whats = [p.what for p in parts if set(name.lower().split("_")) == set(re.findall(r"[a-z]+", p.what.lower()))]
            out += [(lesson, gid, name, whats[0])] if whats else []
    return out


NAMED = _named_outputs()


@pytest.mark.parametrize("lesson, gid, name, what", NAMED, ids=[f"{g}-{n}" for _, g, n, _ in NAMED])
def test_a_wrong_value_graded_is_called_what_its_own_check_calls_it(lesson, gid, name, what):
    said = graded_messages(lesson, gid, each=True)
    names = list(Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]["outputs"])
    mine = said[names.index(name) * len(said) // len(names)]   # the message with this value alone wrong
    assert re.search(rf": {re.escape(what)}(\[| is | has )", mine), (name, mine)


@pytest.mark.parametrize("ename, evalue, says, hint", [
    # the kit's note (snakekit.checks) already says why the name is missing: said once, not guessed at again
    ("NameError", "name 'planar_fk' is not defined: the cell that defines `planar_fk` has not run yet, or it stopped "
                  "with an error (a SyntaxError in your answer, say), so nothing was defined. Run that cell, fix the "
                  "error it shows, then run this cell again.", "then run this cell again.", False),
    # a bare NameError (a kernel without the kit's note): the grader says why, without guessing the error's kind
    ("NameError", "name 'planar_fk' is not defined", "is not defined.", True),
    ("AttributeError", "module 'numpy' has no attribute 'cumsun'.", "has no attribute 'cumsun'.", False),
])
def test_a_test_cell_that_handed_nothing_in_says_why_once_in_whole_sentences(ename, evalue, says, hint):
    from nbformat.v4 import new_code_cell, new_output

    from grader.scoring.verdict import why_missing

    cell = new_code_cell("ex.hand_in('ex01_1_planar_fk_test', planar_fk)", execution_count=3)
    cell.outputs = [new_output("error", ename=ename, evalue=evalue, traceback=["Cell In[3], line 1", "..."])]
    message = why_missing(cell, "unused")
    assert message.startswith(f"nothing was handed in: the test cell stopped before it handed in your results, with "
                              f"{ename}: {evalue}")
    assert says in message and ".." not in message and message.count("not run") <= 1
    assert ("The function is not defined: the answer cell above stopped with an error (see its output), or it was "
            "not run." in message) == hint
    assert "syntax error?" not in message
