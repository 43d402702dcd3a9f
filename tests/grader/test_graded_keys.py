"""A value that a test cell's hand-in helper makes is named in a graded message as a student reads it, never by
the helper's key: 7.2's ``{"refused": True, "arm_still": ...}`` once read "the refused is True, expected False",
where the student reads "safe_move refused the move ..." (grader.scoring.wording.WORDS).

Every key of every lesson's hand-ins (the names its recorded reference holds) is walked. The instructor's results
stand as the helper's own dicts (read from the test cell: each ``return {...}`` of the helper is one kind of
result, a yes or no where the helper makes one), and wrong hand-ins of every kind are scored as the grader scores
them: each value wrong on its own (a yes for a no, another number, another shape, not a number, missing), and the
helper's other kind of result in place of this one (7.2: refused where the solution moved, and the other way).
"""

from __future__ import annotations

import ast
import re
import runpy

import numpy as np
import pytest

from grader.scoring.references import REFERENCES, Reference
from grader.scoring.rules import RULES
from grader.scoring.score import Expected, handed_in_function, score_exercise
from grader.scoring.wording import WORDS, wording
from snakekit import SPEC
from tests.grader.test_graded_words import COURSE, LESSONS, SHAPES, _lesson, _want, lesson_signatures

#: every exercise whose hand-in is a dict of named values (the rest hand in the student's own value)
NAMED = [(lesson, gid) for lesson in LESSONS
         for gid, ex in Reference.load(REFERENCES / f"{lesson}.npz").exercises.items() if ex["outputs"] != ["value"]]


def _is_yes_or_no(node) -> bool:
    """Whether the helper makes this value a yes or no (``True``, ``bool(...)``, ``all(...)``, a comparison)."""
    if isinstance(node, ast.Constant):
        return isinstance(node.value, bool)
    if isinstance(node, ast.Call):
        return getattr(node.func, "id", getattr(node.func, "attr", "")) in ("bool", "all", "any")
    return isinstance(node, (ast.Compare, ast.BoolOp)) or (isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not))


def kinds_of_result(source: str, handed: str, outputs: list) -> list[dict]:
    """The helper's kinds of result: per ``return {...}`` of it, key -> the constant it returns (True, False), "yes or
    no" for a yes or no it computes, or None for a number; a ``**spread`` stands for the outputs no return names."""
    helper = next((n for n in ast.parse(source).body if isinstance(n, ast.FunctionDef) and n.name == handed), None)
    kinds = []
    for node in ast.walk(helper) if helper else ():
        if isinstance(node, ast.Return) and isinstance(node.value, (ast.Dict, ast.Call)):
            value = node.value
            if isinstance(value, ast.Call) and getattr(value.func, "id", "") == "dict":
                pairs = [(k.arg, k.value) for k in value.keywords]
            elif isinstance(value, ast.Dict):
                pairs = [(k.value if k is not None else None, v) for k, v in zip(value.keys, value.values)]
            else:
                continue
            kind = {}
            for key, v in pairs:
                if key is None:   # {**handed, ...}: what the spread holds
                    kind.update({o: None for o in outputs})
                else:
                    kind[key] = (v.value if isinstance(v, ast.Constant) else "yes or no") if _is_yes_or_no(v) else None
            kinds.append(kind)
    named = {k for kind in kinds for k in kind}
    return kinds if named >= set(outputs) else [{o: None for o in outputs}]


def _result(kind: dict, gid: str, args, n: int) -> dict:
    """A result of ``kind`` at a case: its yes or no as the helper returns it (True where it computes one), numbers
    that stand for any (of the shape the exercise's rule asks for)."""
    shapes = SHAPES.get(gid, lambda args: {})(args)
    out = {}
    for k, (key, v) in enumerate(kind.items()):
        if v is None:
            shape = shapes.get(key, (2,))
            out[key] = np.full(shape, 0.25 + 0.125 * k + n)
        else:
            out[key] = np.bool_(True if v == "yes or no" else v)
    return out


def _wrong(want: dict) -> list[tuple[str, dict]]:
    """Each value of ``want`` wrong on its own, in every way a hand-in can be: (what is wrong, the hand-in)."""
    out = []
    for key, v in want.items():
        if v.dtype.kind == "b":
            out.append((f"{key} the other way", {**want, key: ~v}))
        else:
            out += [(f"{key} another number", {**want, key: v * 1.5 + 0.1}),
                    (f"{key} another shape", {**want, key: np.zeros(3)}),
                    (f"{key} not a number", {**want, key: np.full(v.shape, np.nan)})]
        out.append((f"{key} missing", {k: x for k, x in want.items() if k != key}))
    return out


def graded(lesson: str, gid: str) -> list[tuple[str, str]]:
    """(what was wrong, the graded messages) for every wrong hand-in of the exercise at one draw of its cases."""
    tests, _ = _lesson(lesson)
    source = tests[gid]
    meta = Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]
    cases = runpy.run_path(str(COURSE / "cases" / f"{lesson}.py"))[gid](np.random.default_rng(5), SPEC)
    handed = handed_in_function(gid, source)
    w = wording(gid, source, handed, lesson_signatures(lesson))
    kinds = kinds_of_result(source, handed, meta["outputs"])
    out = []
    for a, kind in enumerate(kinds):
        if meta["kind"] == "values":
            results = [_result(kind, gid, args, n) for n, args in enumerate(cases)]
        else:
            results = [_want(gid, meta["kind"], meta["outputs"], args) for args in cases]
        e = Expected(gid, meta["kind"], cases, results, meta["tolerances"], handed, w)
        right = next(r for r in results if isinstance(r, dict))
        wrongs = [(f"result {a}: {what}", lambda r, k=k: _wrong(r)[k][1]) for k, (what, _) in enumerate(_wrong(right))]
        wrongs += [(f"result {b} where the solution's is {a}", lambda r, b=b: _result(kinds[b], gid, (), 0))
                   for b in range(len(kinds)) if b != a]
        for what, make in wrongs:
            s = score_exercise(gid, [make(r) if isinstance(r, dict) else r for r in results], e, 1.0)
            assert s.score < 1.0, (gid, what)
            out.append((what, " ".join([s.message] + [c.message for c in s.checks])))
    return out


def test_every_key_of_every_lesson_s_hand_ins_is_walked():
    """The walk covers what the references record: every named value of every lesson, 7.2's and 7.3's among them."""
    walked = {(gid, key) for lesson, gid in NAMED
              for kind in kinds_of_result(_lesson(lesson)[0][gid], handed_in_function(gid, _lesson(lesson)[0][gid]),
                                          Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]["outputs"])
              for key in kind}
    assert {("ex07_2_safe_move_test", k) for k in ("refused", "arm_still", "moves", "duration", "final")} <= walked
    assert {("ex07_3_fault_test", k) for k in ("rebooted", "torque_on", "errors_cleared")} <= walked
    for lesson, gid in NAMED:
        outputs = Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]["outputs"]
        assert set(outputs) <= {k for g, k in walked if g == gid}, (gid, outputs)


@pytest.mark.parametrize("lesson, gid", NAMED, ids=[g for _, g in NAMED])
def test_a_graded_message_names_a_hand_in_s_values_as_the_student_reads_them(lesson, gid):
    tests, own = _lesson(lesson)
    source = tests[gid]
    handed = handed_in_function(gid, source)
    outputs = Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]["outputs"]
    keys = {k for kind in kinds_of_result(source, handed, outputs) for k in kind}
    for what, message in graded(lesson, gid):
        # never "the refused is True": a yes or no is said as what it means
        assert not re.search(r"\b(is|are) (True|False)\b", message), f"{gid}, {what}: {message}"
        # never a key the helper made, as it is or quoted (a name the lesson's text uses is the student's: time_from_start)
        raw = [k for k in keys if (("_" in k and re.search(rf"\b{k}\b", message)) or f"'{k}'" in message) and k not in own]
        assert not raw, f"{gid}, {what}: names {raw}: {message}"
    if Reference.load(REFERENCES / f"{lesson}.npz").exercises[gid]["kind"] == "values" and gid not in RULES:
        w = wording(gid, source, handed)
        for key in keys:   # named by the check, or by WORDS: never the key in words ("the arm still")
            assert w.part(key).what != f"the {key.replace('_', ' ')}", (gid, key, WORDS.get(gid))


def test_7_2_says_what_safe_move_did_where_it_refused_or_moved_against_the_solution():
    said = dict(graded("07_real_robot", "ex07_2_safe_move_test"))
    refused, moved = said["result 1 where the solution's is 0"], said["result 0 where the solution's is 1"]
    assert "safe_move refused the move (it raised snakekit.LimitError), but no angle of the target is within the " \
           "margin of the limits: move there." in refused, refused
    assert "safe_move moved the arm although the target is within the margin of the limits: raise " \
           "snakekit.LimitError before moving." in moved, moved
    assert "the arm moved although safe_move refused the target: check before you move." in \
        said["result 1: arm_still the other way"]
    assert "number of moves safe_move sent to the arm is" in said["result 0: moves another number"]
