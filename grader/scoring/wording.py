"""How a graded message names what it judges: in the words of the exercise's own notebook check.

A test cell often hands in through a helper of its own (``graded_move``, ``graded_lag``) that calls the
student's function and returns named arrays (``goal_times``). A student never wrote those names: a
graded message names the student's function (``checks.Exercise("4.3", "sample_move")``), the arguments
it was called with, and each value as the check's ``ex.close(..., what=, unit=, labels=)`` says it
("send times", in s). All of it is read from the test cell's source, so it needs nothing of a lesson
but its check.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass, field

__all__ = ["Part", "Wording", "wording"]


@dataclass(frozen=True)
class Part:
    """A value as the notebook's check names it: ``what`` ("send times"), its ``unit`` (one, or one per
    entry of a 1-D value) and the ``labels`` of its entries ("x", "y")."""

    what: str
    unit: str | tuple = ""
    labels: tuple | None = None

    def unit_at(self, index: tuple) -> str:
        """The unit of the entry at ``index`` (the last axis picks a unit of a per-entry tuple)."""
        if isinstance(self.unit, tuple):
            return self.unit[index[-1]] if index and index[-1] < len(self.unit) else ""
        return self.unit

    def name_at(self, index: tuple, ndim: int) -> str:
        """The entry at ``index`` as the check names it: ``move duration``, ``send times[3]``."""
        if not index:
            return self.what
        if self.labels is not None and ndim == 1 and index[0] < len(self.labels):
            return f"{self.what} {self.labels[index[0]]}"
        return f"{self.what}[{', '.join(str(int(k)) for k in index)}]"


@dataclass(frozen=True)
class Wording:
    """How the messages of one exercise name things.

    Attributes:
        function: the student's function (the check's ``checks.Exercise`` name).
        params: the names of the hand-in's arguments, when they are not the student function's own (a
            helper that builds a run from them): a case is then shown as the hidden case's values, not a call.
        parts: the values the check compares, each a :class:`Part`.
    """

    function: str
    params: tuple | None = None
    parts: tuple = field(default=())

    def part(self, name: str) -> Part:
        """The check's words for the result ``name`` (``value``: the function's own value): the compared
        value whose words share one with the name (``goal_times``: "send times"), else the name in words,
        in the unit every compared value of the check has (if they have one)."""
        if name == "value":   # the words every compared value of the check shares ("Jacobian"), and its unit
            if len(self.parts) <= 1:
                return self.parts[0] if self.parts else Part("the result")
            words = [p.what.split() for p in self.parts]
            common = [w[0] for w in zip(*words) if len(set(w)) == 1]
            units = {p.unit for p in self.parts}
            return Part(" ".join(common) or "the result", units.pop() if len(units) == 1 else "")
        words = set(name.lower().split("_"))
        for p in self.parts:
            if words & set(re.findall(r"[a-z]+", p.what.lower())):
                return p
        units = {p.unit for p in self.parts}
        return Part(f"the {name.replace('_', ' ')}", units.pop() if len(units) == 1 else "")


def _text(node) -> str | None:
    """A string literal's text; an f-string's text with each placeholder left out ("lag of joint")."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return " ".join("".join(v.value if isinstance(v, ast.Constant) else " " for v in node.values).split())
    return None


def _unit(node):
    if isinstance(node, ast.Tuple):
        units = tuple(_text(e) for e in node.elts)
        return units if all(u is not None for u in units) else ""
    return _text(node) or ""


def _keywords(call: ast.Call, shared: dict) -> dict:
    """A call's keyword arguments, ``**NAME`` of a ``NAME = dict(...)`` of the cell expanded."""
    out = {}
    for k in call.keywords:
        if k.arg is None and isinstance(k.value, ast.Name):
            out.update(shared.get(k.value.id, {}))
        elif k.arg is not None:
            out[k.arg] = k.value
    return out


def _parts(tree: ast.Module) -> tuple:
    shared = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name) \
                and isinstance(node.value, ast.Call) and getattr(node.value.func, "id", None) == "dict":
            shared[node.targets[0].id] = {k.arg: k.value for k in node.value.keywords if k.arg}
    parts = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "close":
            kw = _keywords(node, shared)
            what = _text(kw["what"]) if "what" in kw else None
            if not what:
                continue
            labels = None
            if isinstance(kw.get("labels"), ast.Tuple):
                labels = tuple(_text(e) or "" for e in kw["labels"].elts)
            part = Part(what, _unit(kw["unit"]) if "unit" in kw else "", labels)
            if part not in parts:
                parts.append(part)
    return tuple(parts)


def _params(tree: ast.Module, handed: str, student: str) -> tuple | None:
    """The hand-in helper's argument names, or None when it passes the case on to the student's function as
    it is (``sample_move(q_start, q_end, duration, rate)``, ``task2_sweep(*case)``)."""
    helper = next((n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == handed), None)
    if helper is None or handed == student:
        return None
    names = [a.arg for a in helper.args.args]
    for node in ast.walk(helper):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == student:
            given = [a.id if isinstance(a, ast.Name) else ("*" + a.value.id if isinstance(a, ast.Starred)
                     and isinstance(a.value, ast.Name) else None) for a in node.args]
            if given == names or (helper.args.vararg and given == ["*" + helper.args.vararg.arg]):
                return None
    return tuple(names) if names else None


def wording(grade_id: str, source: str, handed: str = "") -> Wording:
    """How the messages of the exercise whose test cell is ``source`` name things (``handed``: the function
    its ``hand_in`` names). A cell that cannot be read keeps the names it hands in.

    >>> w = wording("ex9_1_f_test", 'def graded_f(a, b):\\n    return {"goal_times": f(run(a), b)}\\n'
    ...             'ex = checks.Exercise("9.1", "f")\\nex.hand_in("ex9_1_f_test", graded_f)\\n'
    ...             'ex.close(ex(f, 1, 2), 0.5, what="send times", unit="s")\\n', "graded_f")
    >>> w.function, w.params, w.part("goal_times")
    ('f', ('a', 'b'), Part(what='send times', unit='s', labels=None))
    """
    m = re.search(r"checks\.Exercise\(\s*[\"'][\w.]+[\"']\s*,\s*[\"'](\w+)[\"']", source)
    student = m.group(1) if m else handed
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return Wording(student or handed)
    return Wording(student or handed, _params(tree, handed, student), _parts(tree))
