"""How a graded message names what it judges: in the words of the exercise's own notebook check.

A test cell often hands in through a helper of its own (``graded_move``, ``graded_lag``) that calls the
student's function and returns named arrays (``goal_times``). A student never wrote those names: a
graded message names the student's function (``checks.Exercise("4.3", "sample_move")``), the arguments
it was called with, and each value as the check's ``ex.close(..., what=, unit=, labels=, why=)`` says it
("send times", in s, its tolerance for the check's reason). All of it is read from the test cell's source,
so it needs nothing of a lesson but its check; a value that only the helper makes (7.2's ``refused``) is named
by :data:`WORDS`, a yes or no as what it means ("safe_move moved the arm although ..."), never by its key.
"""

from __future__ import annotations

import ast
import dataclasses
import re
from dataclasses import dataclass, field

import numpy as np

from snakekit.closeness import entry_name, per_row, unit_of

__all__ = ["WORDS", "Part", "Wording", "wording", "title", "points", "shown", "signatures"]

#: Words that cannot end a value's name: what the compared values of a check share stops before them.
DANGLING = {"of", "at", "in", "for", "to", "the", "a", "an", "and"}

#: How a graded message names a value that a test cell's hand-in helper makes and its check names nowhere, by
#: grade id and key (a key such as ``refused`` is the helper's: the student never wrote it, and "the refused is
#: True" says nothing). A value is named by a phrase; a yes or no by three: whether it holds, what is said when
#: the student's is yes and the solution's no, and what is said the other way round, each in the words of the
#: lesson and its check. tests/grader/test_graded_keys.py walks every key of every lesson's hand-ins.
WORDS = {
    "ex03_4_task1_test": {
        "poses": "tool poses task1 returned",
        "final_q": "joint angles the arm measured at the end of each move"},
    "ex06_2_sweep_positions_test": {
        "last_row_home": ("whether the last goal is home", "the last goal is home where the solution's is not",
                          "the last goal is not home: the text asks 0 there (within 1e-12 rad: near zero is zero)")},
    "ex07_1_ticks_test": {
        "whole_numbers": ("whether to_ticks returned whole numbers",
                          "to_ticks returned whole numbers where the solution's are not",
                          "to_ticks returned values that are not whole numbers: ticks are whole numbers, "
                          "np.rint(...).astype(int)")},
    "ex07_2_safe_move_test": {
        "refused": ("whether safe_move refused the target",
                    "safe_move refused the move (it raised snakekit.LimitError), but no angle of the target is "
                    "within the margin of the limits: move there",
                    "safe_move moved the arm although the target is within the margin of the limits: raise "
                    "snakekit.LimitError before moving"),
        "arm_still": ("whether the arm stayed where it was when safe_move refused the target",
                      "the arm stayed where it was where the solution's moved",
                      "the arm moved although safe_move refused the target: check before you move"),
        "moves": "number of moves safe_move sent to the arm"},
    "ex07_3_fault_test": {
        "rebooted": "list of rebooted ids recover returned",
        "torque_on": ("whether torque is on after recover", "torque is on after recover where the solution's is off",
                      "torque is still off after recover: call robot.torque_on() after the reboots"),
        "errors_cleared": ("whether every servo's error is cleared after recover",
                           "every servo's error is cleared after recover where the solution's is not",
                           "a servo still reports an error after recover: reboot every servo whose "
                           "robot.hardware_error_status(id) is not empty")},
}

#: A test cell's ``checks.Exercise("6.3", "task2_sweep")``: the exercise's number and the student's function.
EXERCISE = re.compile(r"checks\.Exercise\(\s*[\"']([\w.]+)[\"']\s*,\s*[\"'](\w+)[\"']")


def title(grade_id: str, source: str = "") -> str:
    """An exercise as its lesson names it (its test cell's ``checks.Exercise``), never by the test cell's id.

    >>> title("ex06_3_task2_test", 'ex = checks.Exercise("6.3", "task2_sweep")'), title("ex04_4_limit_check_test")
    ('6.3 task2_sweep', '4.4 limit_check')
    """
    m = EXERCISE.search(source or "")
    if m:
        return f"{m.group(1)} {m.group(2)}"
    m = re.match(r"ex0*(\d+)_(\d+)_(\w+?)(?:_test)?$", grade_id)
    return f"{m.group(1)}.{m.group(2)} {m.group(3)}" if m else grade_id


def points(x: float) -> str:
    """A score as a student reads it: at most 2 decimals.

    >>> points(2.6666667), points(3.0), points(1.3636), points(3.9773)
    ('2.67', '3', '1.36', '3.98')
    """
    return f"{round(float(x), 2) + 0.0:g}"


def _num(x) -> str:
    """One number, to 4 significant digits (an integer as it is)."""
    if isinstance(x, (bool, np.bool_)):
        return str(bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    return f"{float(x):.4g}"


def shown(value, most: int = 8) -> str:
    """An argument as a message shows it: numbers to 4 significant digits, a short array whole (a 5-angle ``q``),
    a long one as its first and last entries with its brackets closed and its size said.

    >>> shown(0.16485351659594227), shown(np.array([1.2664, 0.28429, -0.6266, 0.3641, 0.5])), shown((0.12, 0.2073))
    ('0.1649', '[1.266, 0.2843, -0.6266, 0.3641, 0.5]', '(0.12, 0.2073)')
    >>> shown(np.arange(23) / 10)
    '[0, 0.1, 0.2, ..., 2.2] (23 values)'
    >>> shown(np.array([[0.235, -0.18, -1.194], [0.1, 0.2, 0.3], [0.163, 0.2144, 1.461]]))
    '[[0.235, -0.18, -1.194], [0.1, 0.2, 0.3], [0.163, 0.2144, 1.461]]'
    >>> shown(np.zeros((23, 5)))
    '[[0, 0, 0, 0, 0], ..., [0, 0, 0, 0, 0]] (shape (23, 5))'
    """
    if isinstance(value, str):
        return repr(value)
    if not isinstance(value, (np.ndarray, list, tuple)):
        return _num(value) if isinstance(value, (int, float, np.number, bool, np.bool_)) else repr(value)
    arr = np.asarray(value)
    if arr.dtype.kind not in "biuf":
        return repr(value)[:60]
    open_, close = ("(", ")") if isinstance(value, tuple) else ("[", "]")
    if arr.ndim == 0:
        return _num(arr.item())
    if arr.ndim == 1:
        items = [_num(x) for x in arr.tolist()]
        if len(items) <= most:
            return open_ + ", ".join(items) + close
        return f"{open_}{', '.join(items[:3])}, ..., {items[-1]}{close} ({len(items)} values)"
    rows = [shown(r, most) for r in arr]
    if arr.size <= 2 * most:   # three targets of (x, y, heading): whole
        return open_ + ", ".join(rows) + close
    return f"{open_}{rows[0]}, ..., {rows[-1]}{close} (shape {arr.shape})"


def signatures(sources) -> dict:
    """The parameters of every function the notebook cells ``sources`` define: name -> their names (the
    student's function as the lesson writes it, ``distance_mm(q, target)``)."""
    out = {}
    for source in sources:
        for m in re.finditer(r"^def (\w+)\((.*?)\)\s*(?:->[^:\n]*)?:", source, re.M | re.S):
            try:
                fn = ast.parse(f"def f({m.group(2)}): pass").body[0]
            except SyntaxError:
                continue
            out[m.group(1)] = tuple(a.arg for a in fn.args.posonlyargs + fn.args.args)
    return out


@dataclass(frozen=True)
class Part:
    """A value as the notebook's check names it: ``what`` ("send times"), its ``unit`` (one, or one per
    entry of a 1-D value), the ``labels`` of its entries ("x", "y") and ``why`` its tolerance is what it is
    (the check's ``why=``, as its message says it; None: exact math)."""

    what: str
    unit: str | tuple = ""
    labels: tuple | None = None
    template: str = field(default="", repr=False)
    why: str | None = field(default=None, repr=False, compare=False)
    #: a yes or no, as :data:`WORDS` says it: (said when the hand-in's is yes and the solution's no, said the
    #: other way round); ``what`` is then "whether ..."
    said: tuple | None = field(default=None, repr=False, compare=False)

    def at(self, values: dict) -> "Part":
        """The part at a hidden case whose named values are ``values``: a name the check makes of a value of
        its case ("lag of joint {joint + 1}") filled in from the case ("lag of joint 3")."""
        if not self.template:
            return self
        try:
            what = re.sub(r"\{([^{}]+)\}", lambda m: _number(_evaluate(m.group(1), values)), self.template)
        except (KeyError, ValueError, SyntaxError):
            return self
        return Part(what, self.unit, self.labels, why=self.why)

    def unit_at(self, index: tuple) -> str:
        """The unit of the entry at ``index``, as the check gives it (:func:`snakekit.closeness.unit_of`: one unit,
        one per entry of the last axis, or one per row)."""
        return unit_of(self.unit, index)

    def name_at(self, index: tuple, ndim: int) -> str:
        """The entry at ``index`` as the check names it: ``move duration``, ``send times[3]``
        (:func:`snakekit.closeness.entry_name`)."""
        return entry_name(self.what, index, ndim, self.labels)


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
    args: tuple | None = None
    given: tuple = ()
    returns: str = ""
    #: :data:`WORDS` of this exercise, as (key, words) pairs: how a value that the hand-in helper makes and the
    #: check names nowhere is called (``refused``: "whether safe_move refused the target")
    says: tuple = ()

    def values(self, case) -> dict:
        """A hidden case's values by the names the test cell gives them (its hand-in helper's arguments)."""
        return dict(zip(self.params or (), case))

    def call(self, case) -> str:
        """A hidden case as the student's function takes it, each argument named as the function names it:
        ``distance_mm(q=[0.1, 0.2, 0.3, 0.4, 0.5], target=(0.12, 0.2))``. Where the test cell's helper builds
        an argument from the case's values (a run from a sweep's), the call names it, and what it was built
        of follows: ``estimate_lag(run, joint=2) on the run of points=195, rate=10, ...``."""
        if not self.params:
            names = self.args if self.args and len(self.args) >= len(case) else ()
            return f"{self.function}({', '.join(_labelled(names, case))})"
        values = self.values(case)
        if not self.given:   # the test cell calls the function in a way of its own: the case's values, named
            return f"{self.function} at the hidden case {', '.join(_labelled(self.params, case))}"
        names = self.args if self.args and len(self.args) >= len(self.given) else \
            tuple(g or "a value it builds" for g in self.given)
        inner = [f"{n}={shown(values[g])}" if g in values else n for n, g in zip(names, self.given)]
        built = [f"{p}={shown(v)}" for p, v in values.items() if p not in self.given]
        made = [n for n, g in zip(names, self.given) if g not in values]
        of = f" on the {made[0]} of " if len(made) == 1 else " at "
        return f"{self.function}({', '.join(inner)})" + (of + ", ".join(built) if built else "")

    def part(self, name: str, case=()) -> Part:
        """The check's words for the result ``name`` (``value``: the function's own value): the compared
        value whose words share one with the name (``goal_times``: "send times"), else the name in words,
        in the unit every compared value of the check has (if they have one)."""
        if name == "value":   # the words every compared value of the check shares ("Jacobian"), and its unit
            if len(self.parts) <= 1:
                return self.parts[0].at(self.values(case)) if self.parts else Part("the result")
            # a case that names what it is taken of ("g", "tool": 2.2's test functions): the value the check names so
            named = {a.lower() for a in case if isinstance(a, str)}
            mine = list(dict.fromkeys(p for p in self.parts if named & set(re.findall(r"[\w*]+", p.what.lower()))))
            if len(mine) == 1:
                return mine[0].at(self.values(case))
            words = [p.what.split() for p in self.parts]
            common = [w[0] for w in zip(*words) if len(set(w)) == 1]
            while common and common[-1] in DANGLING:   # "Jacobian of q0*q1", "Jacobian of g": the Jacobian
                common.pop()
            common = " ".join(common)
            whole = [p for p in self.parts if p.what == common]
            if whole:   # one compared value is named by just those words (2.1's "Jacobian", beside its row 3)
                return whole[0].at(self.values(case))
            units, whys = {p.unit for p in self.parts}, {p.why for p in self.parts}
            return Part(common or "the result", units.pop() if len(units) == 1 else "",
                        why=whys.pop() if len(whys) == 1 else None)
        said = dict(self.says).get(name)
        if isinstance(said, str):       # the course's name of a value only the hand-in helper makes
            return Part(said)
        if isinstance(said, tuple):     # a yes or no, said as a whole clause either way
            return Part(said[0], said=tuple(said[1:]))
        words = set(name.lower().split("_"))
        shared = [len(words & set(re.findall(r"[a-z]+", p.what.lower()))) for p in self.parts]
        if any(shared):   # the most words in common: recorded_angles is "recorded angles", not "recorded times"
            return self.parts[shared.index(max(shared))].at(self.values(case))
        units = {p.unit for p in self.parts}
        return Part(f"the {name.replace('_', ' ')}", units.pop() if len(units) == 1 else "")


def _labelled(names, case) -> list:
    return [f"{n}={shown(v)}" if n else shown(v) for n, v in zip(tuple(names) + (None,) * len(case), case)]


def _number(x) -> str:
    return str(int(x)) if float(x).is_integer() else f"{float(x):.4g}"


def _evaluate(text: str, values: dict):
    """A placeholder of a check's f-string (``joint + 1``) at a case's ``values``: names, numbers, + - * only."""
    def value(node):
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return node.value
        if isinstance(node, ast.Name):
            return float(values[node.id])
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult)):
            a, b = value(node.left), value(node.right)
            return a + b if isinstance(node.op, ast.Add) else a - b if isinstance(node.op, ast.Sub) else a * b
        raise ValueError(text)
    return value(ast.parse(text, mode="eval").body)


def _template(node) -> str:
    """An f-string's text with each placeholder's expression kept (``lag of joint {joint + 1}``); "" for a literal."""
    if not isinstance(node, ast.JoinedStr):
        return ""
    return "".join(v.value if isinstance(v, ast.Constant) else "{" + ast.unparse(v.value) + "}" for v in node.values)


def _text(node) -> str | None:
    """A string literal's text; an f-string's text with each placeholder left out ("lag of joint")."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return " ".join("".join(v.value if isinstance(v, ast.Constant) else " " for v in node.values).split())
    return None


def _unit(node, names: dict | None = None):
    """A check's ``unit=``: a string, a tuple of them, ``checks.per_row(...)``, or the name of one the cell assigns."""
    if isinstance(node, ast.Name):
        node = (names or {}).get(node.id, node)
    if isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == "per_row":
        units = tuple(_text(e) for e in node.args)   # checks.per_row("m", "m", "rad/rad"): one unit per row
        return per_row(*units) if all(u is not None for u in units) else ""
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


def _labels(node, names: dict) -> tuple | None:
    """A check's ``labels=``: a tuple of strings, or the name of one the cell assigns (``labels=FIELDS``)."""
    if isinstance(node, ast.Name):
        node = names.get(node.id)
    if isinstance(node, ast.Tuple):
        return tuple(_text(e) or "" for e in node.elts)
    return None


def _parts(tree: ast.Module) -> tuple:
    shared, names = {}, {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            names[node.targets[0].id] = node.value
            if isinstance(node.value, ast.Call) and getattr(node.value.func, "id", None) == "dict":
                shared[node.targets[0].id] = {k.arg: k.value for k in node.value.keywords if k.arg}
    parts, whys = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "close":
            kw = _keywords(node, shared)
            what = _text(kw["what"]) if "what" in kw else None
            if not what:
                continue
            part = Part(what, _unit(kw["unit"], names) if "unit" in kw else "", _labels(kw.get("labels"), names),
                        _template(kw["what"]))
            # the reason of the first check of it in the cell's order (its visible case's, as the lesson reads)
            whys.setdefault(part, []).append((node.lineno, node.col_offset, _text(kw["why"]) if "why" in kw else None))
            if part not in parts:
                parts.append(part)
    return tuple(dataclasses.replace(p, why=min(whys[p])[2]) for p in parts)


def _params(tree: ast.Module, handed: str, student: str) -> tuple:
    """The hand-in helper's argument names, or None when it passes the case on to the student's function as
    it is (``sample_move(q_start, q_end, duration, rate)``, ``task2_sweep(*case)``); and how the helper calls
    the student's function: per argument, the helper's argument it passes (None: a value the helper builds)."""
    helper = next((n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == handed), None)
    if helper is None or handed == student:
        return None, ()
    names = [a.arg for a in helper.args.args]
    given = ()
    for node in ast.walk(helper):
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == student:
            given = [a.id if isinstance(a, ast.Name) else ("*" + a.value.id if isinstance(a, ast.Starred)
                     and isinstance(a.value, ast.Name) else None) for a in node.args]
            if given == names or (helper.args.vararg and given == ["*" + helper.args.vararg.arg]):
                return None, ()
            given = tuple(g if g in names else None for g in given)
    return (tuple(names) if names else None), given


def wording(grade_id: str, source: str, handed: str = "", signatures: dict | None = None) -> Wording:
    """How the messages of the exercise whose test cell is ``source`` name things (``handed``: the function
    its ``hand_in`` names; ``signatures``: the parameters of the notebook's functions, :func:`signatures`;
    the values its hand-in helper makes are named by :data:`WORDS`).
    A cell that cannot be read keeps the names it hands in.

    >>> w = wording("ex9_1_f_test", 'def graded_f(a, b):\\n    return {"goal_times": f(run(a), b)}\\n'
    ...             'ex = checks.Exercise("9.1", "f")\\nex.hand_in("ex9_1_f_test", graded_f)\\n'
    ...             'ex.close(ex(f, 1, 2), 0.5, what="send times", unit="s")\\n', "graded_f")
    >>> w.function, w.params, w.part("goal_times")
    ('f', ('a', 'b'), Part(what='send times', unit='s', labels=None))
    """
    m = EXERCISE.search(source)
    student = m.group(2) if m else handed
    says = tuple(WORDS.get(grade_id, {}).items())
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return Wording(student or handed, says=says)
    params, given = _params(tree, handed, student)
    m = re.search(r"isinstance\(\s*\w+\s*,\s*([\w.]+)\s*\)", source)
    return Wording(student or handed, params, _parts(tree), (signatures or {}).get(student), given,
                   m.group(1) if m else "", says)
