"""Single-slip variants of the instructor's answers: the slips students make, one at a time.

Each operator takes the instructor's answer cell (the solution of ``course/source/NN_*/NN_*.ipynb``
without its markers) and makes one change a student makes by mistake: a count or a start off by
one, degrees for radians, cos for sin, a sign, a clip or ``abs`` left out, a transposed result, a
list for an array, a forgotten ``return``, a scale of 1000, two arguments swapped, the library's
own function called where the exercise asks to write it, an exception, an endless loop. An
operator changes the first place in the answer's function where it applies; where it applies
nowhere it gives no variant (:class:`Skipped`, counted by :func:`variants`).

:mod:`grader.course.fairness` grades the variants with the real grader and checks the fairness
rules on each (grader/README.md, "Fairness, tested by mutation").
"""

from __future__ import annotations

import ast
import copy
import pkgutil
import re
from dataclasses import dataclass
from pathlib import Path

from grader.markup import without_solution_markers

#: The operators, in the order the matrix shows them: name -> what the slip is, as a TA notes it.
OPERATORS = {
    "off_by_one": "a count or a start off by one",
    "degrees": "degrees for radians",
    "cos_for_sin": "cos for sin (or sin for cos)",
    "sign": "a sign: a minus for a plus",
    "no_clip": "a clip or abs left out",
    "transpose": "the result transposed",
    "list": "a list for an array",
    "no_return": "the return forgotten",
    "scale_1000": "a scale of 1000 (millimetres for metres)",
    "swap_args": "two arguments swapped",
    "forbidden": "the library's own function called",
    "exception": "an exception (a misspelt name)",
    "endless_loop": "an endless loop",
}

TRIG = {"sin", "cos", "tan"}
INVERSE_TRIG = {"arcsin", "arccos", "arctan", "arctan2", "asin", "acos", "atan", "atan2"}
#: calls whose first two arguments commute: swapping them is no slip
SYMMETRIC = {"hypot", "maximum", "minimum", "max", "min", "add", "multiply", "zip", "isclose", "allclose"}
COUNTS = {"range", "arange", "linspace", "zeros", "ones", "eye", "integers"}


@dataclass(frozen=True)
class Mutant:
    """One slip: ``source`` is the answer cell with ``operator`` applied once, where ``where`` says."""

    lesson: str
    grade_id: str          # the answer cell's grade id
    operator: str
    where: str             # the changed line, as the variant has it
    source: str


@dataclass(frozen=True)
class Skipped:
    lesson: str
    grade_id: str
    operator: str


def _name(func: ast.expr) -> str:
    """'np.sin' -> 'sin'; 'sin' -> 'sin'; anything else -> ''."""
    return func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""


def _np(name: str, *args: ast.expr) -> ast.Call:
    return ast.Call(ast.Attribute(ast.Name("np", ast.Load()), name, ast.Load()), list(args), [])


def _nodes(fn: ast.FunctionDef, kind):
    """The nodes of ``kind`` in ``fn``'s body, in source order (its docstring and signature left out)."""
    out = [n for stmt in fn.body for n in ast.walk(stmt) if isinstance(n, kind)]
    return sorted(out, key=lambda n: (n.lineno, n.col_offset))


def _returns(fn: ast.FunctionDef) -> list[ast.Return]:
    return [r for r in _nodes(fn, ast.Return) if r.value is not None]


def _replace(fn: ast.FunctionDef, old: ast.AST, new: ast.AST) -> None:
    for parent in ast.walk(fn):
        for field, value in ast.iter_fields(parent):
            if value is old:
                setattr(parent, field, new)
            elif isinstance(value, list):
                for i, item in enumerate(value):
                    if item is old:
                        value[i] = new


def off_by_one(fn, ctx) -> ast.AST | None:
    """The first count (``range``, ``arange``, ``linspace``'s number...) one more, else the first
    constant index or slice start one further."""
    for call in _nodes(fn, ast.Call):
        name = _name(call.func)
        if name in COUNTS and call.args:
            i = 2 if name == "linspace" and len(call.args) >= 3 else 0
            call.args[i] = ast.BinOp(call.args[i], ast.Add(), ast.Constant(1))
            return call
    for sub in _nodes(fn, ast.Subscript):
        index = sub.slice.lower if isinstance(sub.slice, ast.Slice) else sub.slice
        if isinstance(index, ast.Constant) and isinstance(index.value, int):
            index.value += 1
            return sub
        if isinstance(index, ast.UnaryOp) and isinstance(index.op, ast.USub) and isinstance(index.operand, ast.Constant):
            index.operand.value += 1
            return sub
    return None


def degrees(fn, ctx) -> ast.AST | None:
    """The first angle taken as degrees: a sine's argument converted, an arc-function's result in
    degrees, or a turn of 2 pi written 360."""
    for call in _nodes(fn, ast.Call):
        if _name(call.func) in TRIG and call.args:
            call.args[0] = _np("deg2rad", call.args[0])
            return call
    for call in _nodes(fn, ast.Call):
        if _name(call.func) in INVERSE_TRIG:
            new = _np("rad2deg", copy.copy(call))
            _replace(fn, call, new)
            return new
    for op in _nodes(fn, ast.BinOp):
        if isinstance(op.op, ast.Mult) and isinstance(op.right, ast.Attribute) and op.right.attr == "pi":
            new = ast.Constant(360)
            _replace(fn, op, new)
            return new
    return None


def cos_for_sin(fn, ctx) -> ast.AST | None:
    for call in _nodes(fn, ast.Call):
        name = _name(call.func)
        if name in ("sin", "cos") and isinstance(call.func, (ast.Attribute, ast.Name)):
            swapped = "cos" if name == "sin" else "sin"
            if isinstance(call.func, ast.Attribute):
                call.func.attr = swapped
            else:
                call.func.id = swapped
            return call
    return None


def sign(fn, ctx) -> ast.AST | None:
    """The first subtraction an addition, else the first minus sign dropped."""
    for op in _nodes(fn, ast.BinOp):
        if isinstance(op.op, ast.Sub):
            op.op = ast.Add()
            return op
    for op in _nodes(fn, ast.UnaryOp):
        if isinstance(op.op, ast.USub):
            _replace(fn, op, op.operand)
            return op.operand
    return None


def no_clip(fn, ctx) -> ast.AST | None:
    """The first ``clip``, ``abs`` or ``max(0, x)`` left out: its argument in its place."""
    for call in _nodes(fn, ast.Call):
        name = _name(call.func)
        if name in ("clip", "abs", "fabs", "absolute") and call.args:
            _replace(fn, call, call.args[0])
            return call.args[0]
        if name in ("max", "maximum") and len(call.args) == 2:
            kept = call.args[1] if isinstance(call.args[0], ast.Constant) else call.args[0]
            _replace(fn, call, kept)
            return kept
    return None


def _wrap_returns(fn, wrap) -> ast.AST | None:
    """Every ``return`` of a value in ``fn`` gives ``wrap(value)`` instead (the first one changed is where)."""
    returns = _returns(fn)
    for r in returns:
        r.value = wrap(r.value)
    return returns[0] if returns else None


def transpose(fn, ctx) -> ast.AST | None:
    return _wrap_returns(fn, lambda v: ast.Attribute(_np("asarray", v), "T", ast.Load()))


def as_list(fn, ctx) -> ast.AST | None:
    return _wrap_returns(fn, lambda v: ast.Call(ast.Attribute(_np("asarray", v), "tolist", ast.Load()), [], []))


def no_return(fn, ctx) -> ast.AST | None:
    """The last ``return`` of the function's body written without ``return``: the value is computed, then lost."""
    last = fn.body[-1]
    if isinstance(last, ast.Return) and last.value is not None:
        new = ast.Expr(last.value)
        fn.body[-1] = new
        return new
    return None


def scale_1000(fn, ctx) -> ast.AST | None:
    """A factor of 1000 dropped where the answer has one, else the results 1000 times too large."""
    for c in _nodes(fn, ast.Constant):
        if c.value == 1000:
            c.value = 1
            return c
    return _wrap_returns(fn, lambda v: ast.BinOp(ast.Constant(1000), ast.Mult(), v))


def swap_args(fn, ctx) -> ast.AST | None:
    """The first call with two positional arguments that do not commute gets them the other way round."""
    for call in _nodes(fn, ast.Call):
        if len(call.args) >= 2 and _name(call.func) not in SYMMETRIC and not any(
                isinstance(a, ast.Starred) for a in call.args[:2]) and ast.dump(call.args[0]) != ast.dump(call.args[1]):
            call.args[0], call.args[1] = call.args[1], call.args[0]
            return call
    return None


def forbidden(fn, ctx) -> ast.AST | None:
    """The library's own function, which the exercise's check forbids, called first thing (its
    result used as the student's), when the check forbids one."""
    name = next(iter(ctx.get("forbidden") or ()), None)
    if name is None:
        return None
    owner, _, attr = name.rpartition(".")
    value = pkgutil.resolve_name(owner)   # the longest module, then attributes, as the kit's forbid() finds it
    if isinstance(value, type):   # a method or property of the robot's spec: reached through the lesson's spec
        import snakekit

        if not isinstance(snakekit.SPEC, value):
            return None
        target = ast.parse(f"snakekit.SPEC.{attr}", mode="eval").body
        used = target if isinstance(vars(value).get(attr), property) else ast.Call(target, _arguments(fn), [])
    else:
        used = ast.Call(ast.parse(name, mode="eval").body, _arguments(fn), [])
    new = ast.Assign([ast.Name("_library", ast.Store())], used)
    new = ast.Try([new], [ast.ExceptHandler(ast.Name("TypeError", ast.Load()), None, [ast.Pass()])], [], [])
    fn.body.insert(_first_statement(fn), new)
    return new


def _arguments(fn) -> list[ast.expr]:
    return [ast.Name(a.arg, ast.Load()) for a in fn.args.args]


def exception(fn, ctx) -> ast.AST | None:
    """The first use of an argument misspelt (a ``NameError`` when the function runs)."""
    names = {a.arg for a in fn.args.args}
    for n in _nodes(fn, ast.Name):
        if n.id in names and isinstance(n.ctx, ast.Load):
            n.id = n.id + "_"
            return n
    return None


def endless_loop(fn, ctx) -> ast.AST | None:
    new = ast.While(ast.Constant(True), [ast.Pass()], [])
    fn.body.insert(_first_statement(fn), new)
    return new


def _first_statement(fn) -> int:
    """Where the body's code starts: after its docstring."""
    first = fn.body[0]
    return 1 if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(
        first.value.value, str) else 0


APPLY = {"off_by_one": off_by_one, "degrees": degrees, "cos_for_sin": cos_for_sin, "sign": sign, "no_clip": no_clip,
         "transpose": transpose, "list": as_list, "no_return": no_return, "scale_1000": scale_1000,
         "swap_args": swap_args, "forbidden": forbidden, "exception": exception, "endless_loop": endless_loop}
assert list(APPLY) == list(OPERATORS)


def mutate(source: str, operator: str, *, forbidden_names: tuple = ()) -> tuple[str, str] | None:
    """``source`` (an answer cell) with ``operator`` applied to its first function, and the changed
    line as the variant has it; None where the operator does not apply."""
    tree = ast.parse(source)
    fn = next((n for n in tree.body if isinstance(n, ast.FunctionDef)), None)
    if fn is None:
        return None
    changed = APPLY[operator](fn, {"forbidden": forbidden_names})
    if changed is None:
        return None
    ast.fix_missing_locations(tree)
    text = ast.unparse(tree) + "\n"
    if ast.dump(ast.parse(text)) == ast.dump(ast.parse(source)):
        return None
    before = ast.unparse(ast.parse(source)).splitlines()
    where = next((line.strip() for line in text.splitlines() if line not in before
                  and line.strip() not in ("try:", "except TypeError:", "pass")), "")
    return text, where


def forbidden_names(test_source: str) -> tuple[str, ...]:
    """The library functions a test cell's hand-in forbids (``forbid=`` of ``ex.hand_in``), in order."""
    tree = ast.parse(test_source)
    tuples = {t.id: node.value for node in tree.body if isinstance(node, ast.Assign)
              for t in node.targets if isinstance(t, ast.Name)}
    for call in (n for n in ast.walk(tree) if isinstance(n, ast.Call) and _name(n.func) == "hand_in"):
        for kw in call.keywords:
            if kw.arg == "forbid":
                value = tuples.get(kw.value.id) if isinstance(kw.value, ast.Name) else kw.value
                if isinstance(value, ast.Constant):
                    return (value.value,)
                if isinstance(value, (ast.Tuple, ast.List)):
                    return tuple(e.value for e in value.elts if isinstance(e, ast.Constant))
    return ()


def exercises(source_notebook: Path) -> list[tuple[str, str, str]]:
    """(answer grade id, the instructor's answer without markers, its test cell's source) for every
    exercise of an instructor notebook, in the notebook's order."""
    import nbformat

    nb = nbformat.read(source_notebook, as_version=4)
    cells = [(c.metadata.get("nbgrader", {}), c.source) for c in nb.cells if c.cell_type == "code"]
    answers = [(m["grade_id"], without_solution_markers(s)) for m, s in cells if m.get("solution")]
    tests = {m["grade_id"]: s for m, s in cells if m.get("grade") and not m.get("solution")}
    out = []
    for gid, answer in answers:
        prefix = re.match(r"(ex\d+_\d+)_", gid).group(1)
        test = next((s for t, s in tests.items() if t.startswith(prefix + "_")), "")
        out.append((gid, answer, test))
    return out


def variants(course: Path, lesson: str, operators=None) -> tuple[list[Mutant], list[Skipped]]:
    """Every single-slip variant of ``lesson``'s answers (``operators``: a name list, or per answer
    grade id a name list), and the (answer, operator) pairs where an operator does not apply."""
    made, skipped = [], []
    for gid, answer, test in exercises(course / "source" / lesson / f"{lesson}.ipynb"):
        chosen = operators.get(gid, ()) if isinstance(operators, dict) else operators or list(OPERATORS)
        for op in chosen:
            result = mutate(answer, op, forbidden_names=forbidden_names(test))
            if result is None:
                skipped.append(Skipped(lesson, gid, op))
            else:
                made.append(Mutant(lesson, gid, op, result[1], result[0]))
    return made, skipped
