"""Every draw of the hidden cases tells each known mistake from the right answer.

A known mistake (tests/lessons/test_no_solution.py's ``MISTAKES``: a wrong answer as a student writes it,
which the visible check names) must lose points graded at every draw, not only at most: a draw that
happens to hold no case where the slip shows gives it full points, where the notebook's own check failed
it (5.2's overshoot taken at max(y) passed 2 draws in 50 that held no step down). Here each mistake's
function and the instructor's are called at the hidden cases of 50 draws, outside any notebook, and
compared within the exercise's tolerance (the cases module's ``TOLERANCES``, else the grader's default):
every draw must hold a case where they differ, or where one raises and the other does not.

Lessons 01 to 05 and 08, whose graded functions are plain functions of their arguments (lessons 06 and 07
hand in what the simulator and the arm measured; their draws are held to their slips by
tests/lessons/test_course_fairness.py). The graded path itself is tests/grader/test_hints_graded.py's.
"""

from __future__ import annotations

import ast
import re
import runpy
import warnings
from pathlib import Path

import numpy as np
import pytest

from grader.scoring.score import DEFAULT_TOLERANCES
from snakekit import SPEC
from tests.conftest import need
from tests.lessons.test_no_solution import MISTAKES

ROOT = Path(__file__).resolve().parents[2]
LESSONS = ["01_forward_kinematics", "02_jacobian", "03_inverse_kinematics", "04_trajectories", "05_simulation", "08_ros"]
DRAWS = 50


def _lesson(lesson: str) -> tuple[dict, dict, dict, str]:
    """The instructor's namespace (the cells before the first exercise and every answer cell, run in order),
    the cases module, each graded id's handed-in function name, and the check cells' own functions (the
    wrappers some hand in, e.g. ``graded_ik``), to define again beside a mistake."""
    nbformat = need("nbformat")
    nb = nbformat.read(ROOT / "course" / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    first = min(i for i, c in enumerate(nb.cells) if c.metadata.get("nbgrader", {}).get("grade_id"))
    ns: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for i, c in enumerate(nb.cells):
            if c.cell_type == "code" and (i < first or c.metadata.get("nbgrader", {}).get("solution")):
                code = "\n".join(line for line in c.source.splitlines() if not line.lstrip().startswith(("%", "!")))
                try:
                    exec(compile(code, f"{lesson} cell {i}", "exec"), ns)  # noqa: S102 - the course's own code
                except Exception:  # noqa: BLE001 - a cell that needs the robot or a file: its functions are defined
                    pass
    names = {gid: f for c in nb.cells for gid, f in re.findall(r'hand_in\(\s*"(\w+)",\s*(\w+)', c.source)}
    # the other cells' definitions (the check cells' wrappers, the helpers between the exercises): their
    # functions, classes, imports and names, each statement on its own (one that needs the robot is left out)
    defs = [ast.unparse(node) for c in nb.cells[first:] if c.cell_type == "code"
            and not c.metadata.get("nbgrader", {}).get("solution")
            for node in ast.parse("\n".join(line for line in c.source.splitlines()
                                             if not line.lstrip().startswith(("%", "!")))).body
            if isinstance(node, (ast.FunctionDef, ast.ClassDef, ast.Import, ast.ImportFrom, ast.Assign))]
    kept = []
    for statement in defs:
        try:
            exec(compile(statement, f"{lesson} definitions", "exec"), ns)  # noqa: S102
            kept.append(statement)
        except Exception:  # noqa: BLE001
            pass
    wrappers = "\n".join(s for s in kept if s.startswith("def "))
    return ns, runpy.run_path(str(ROOT / "course" / "cases" / f"{lesson}.py")), names, wrappers


def _call(f, case):
    try:
        return f(*case)
    except Exception as e:  # noqa: BLE001 - what it raised is its result
        return type(e)


def _differ(a, b, tol: dict) -> bool:
    if isinstance(a, type) or isinstance(b, type):
        return a is not b
    if isinstance(a, list) != isinstance(b, list) or isinstance(a, dict) != isinstance(b, dict):
        return True
    if isinstance(a, dict):
        return set(a) != set(b) or any(_differ(a[k], b[k], tol) for k in a)
    try:
        x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    except (TypeError, ValueError):
        return a != b
    return x.shape != y.shape or not np.allclose(x, y, rtol=tol["rtol"], atol=tol["atol"], equal_nan=True)


#: a mistake that calls the kit's own function (its words: "`snakekit.joint_frames` was called") gives the right
#: numbers: the check and the grader refuse it by the call (``forbid=``), not by its results
SHORTCUT = re.compile(r"`snakekit\.[\w.]+` was called")
CASES = [(lesson, k) for lesson in LESSONS for k, m in enumerate(MISTAKES[lesson]) if not SHORTCUT.search(m[2])]


@pytest.fixture(scope="module")
def lessons():
    return {lesson: _lesson(lesson) for lesson in LESSONS}


#: (lesson, grade id, seed) -> the draw's cases and the instructor's results at them, computed once
_ANSWERS: dict = {}


def _answers(lesson, gid, seed, cases, right):
    key = (lesson, gid, seed)
    if key not in _ANSWERS:
        drawn = cases[gid](np.random.default_rng(seed), SPEC)
        _ANSWERS[key] = drawn, [_call(right, c) for c in drawn]
    return _ANSWERS[key]


@pytest.mark.parametrize("lesson, k", CASES, ids=[f"{lesson[:2]}-{k}" for lesson, k in CASES])
def test_every_draw_holds_a_case_where_the_mistake_differs_from_the_answer(lessons, lesson, k):
    ns, cases, names, wrappers = lessons[lesson]
    gid, source = MISTAKES[lesson][k][0], MISTAKES[lesson][k][1]
    name = names[gid]
    wrong_ns = dict(ns)
    exec(compile(source, f"{lesson} mistake {k}", "exec"), wrong_ns)  # noqa: S102
    exec(compile(wrappers, f"{lesson} check cells' functions", "exec"), wrong_ns)  # noqa: S102 - calling the mistake
    right, wrong = ns[name], wrong_ns[name]
    assert right is not wrong
    tol = {**DEFAULT_TOLERANCES["values"], **cases.get("TOLERANCES", {}).get(gid, {})}
    passed = []
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        for seed in range(DRAWS):
            drawn, answers = _answers(lesson, gid, seed, cases, right)
            assert not any(a is NameError for a in answers), f"{name} needs a name this test did not define"
            if not any(_differ(a, _call(wrong, c), tol) for a, c in zip(answers, drawn)):
                passed.append(seed)
    assert not passed, (f"{gid}'s known mistake ({MISTAKES[lesson][k][2]!r}) gives the right results at every hidden "
                        f"case of the draws of seeds {passed}: it would earn full points graded there")
