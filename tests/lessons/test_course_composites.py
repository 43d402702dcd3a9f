"""Exercises built on earlier ones: every one declares what it builds on, and is judged by one rule.

A composite is an exercise whose answer calls a function another exercise's answer defines (4.3's
``sample_move`` calls 4.1's ``quintic``). It is judged on what it adds, the same way locally and
graded: its cases module names the parts (``DEPENDS``), so the grader runs it again with the
lesson's own parts when a part lost points (``grader/rerun.py``); and its check cell names them
(``checks.Exercise(..., builds_on=...)``), so a failed local check says which part to fix first.
The calls are found in the instructor notebooks, so a new composite cannot go undeclared.
"""

from __future__ import annotations

import ast
import re
import runpy
from pathlib import Path

import pytest

from grader.scoring.rerun import exercise
from snakekit import checks
from tests.conftest import need, notebook_client

ROOT = Path(__file__).resolve().parents[2]
COURSE = ROOT / "course"
LESSONS = sorted(p.name for p in (COURSE / "source").iterdir() if (p / f"{p.name}.ipynb").exists())

#: Composites whose check cell runs them with the kit's own part in place of the student's, locally
#: and graded alike, so a slip in the part never reaches them (the hand-in procedure swaps it in).
INDEPENDENT = {"ex03_3_ik_loop_test": 'globals()["dls_step"] = lesson_step'}


def _cells(lesson: str):
    nbformat = need("nbformat")
    nb = nbformat.read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    return [(c.metadata["nbgrader"], c.source) for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id")]


def composites(lesson: str) -> dict[str, list[str]]:
    """Test cell grade id -> the answer cells whose functions its exercise's answer uses (found in
    the instructor notebook's code: a name an answer cell defines, used in another answer cell)."""
    answers = {meta["grade_id"]: ast.parse(src) for meta, src in _cells(lesson) if meta.get("solution")}
    defined = {node.name: gid for gid, tree in answers.items() for node in tree.body
               if isinstance(node, (ast.FunctionDef, ast.ClassDef))}
    tests = {exercise(meta["grade_id"]): meta["grade_id"] for meta, _ in _cells(lesson) if meta.get("grade")}
    out = {}
    for gid, tree in answers.items():
        used = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
        parts = sorted({defined[name] for name in used if name in defined and defined[name] != gid})
        if parts:
            out[tests[exercise(gid)]] = parts
    return out


def declared(lesson: str) -> dict[str, list[str]]:
    return {k: sorted(v) for k, v in runpy.run_path(str(COURSE / "cases" / f"{lesson}.py")).get("DEPENDS", {}).items()}


def test_the_course_has_the_composites_the_lessons_teach():
    """The scan finds what the lessons say: 2.3 on 2.1, 3.3 on 3.2, 4.3 on 4.1, 6.3 on 6.1 and 6.2 (a scan
    that found nothing would pass every test below)."""
    found = {gid: parts for lesson in LESSONS for gid, parts in composites(lesson).items()}
    assert found == {"ex02_3_manipulability_test": ["ex02_1_planar_jacobian"],
                     "ex03_3_ik_loop_test": ["ex03_2_dls_step"], "ex04_3_sample_10hz_test": ["ex04_1_quintic"],
                     "ex06_3_task2_test": ["ex06_1_sweep_times", "ex06_2_sweep_positions"]}


@pytest.mark.parametrize("lesson", LESSONS)
def test_every_call_between_graded_functions_is_declared_in_the_cases_module(lesson):
    assert declared(lesson) == composites(lesson), (
        f"course/cases/{lesson}.py: DEPENDS must name, for each exercise whose answer uses another's function, "
        f"the answer cells it uses: found {composites(lesson)}, declared {declared(lesson)}")


@pytest.mark.parametrize("lesson", LESSONS)
def test_every_composites_check_cell_names_its_parts_or_runs_with_the_kits_own(lesson):
    sources = {meta["grade_id"]: src for meta, src in _cells(lesson)}
    for gid, parts in composites(lesson).items():
        src = sources[gid]
        if gid in INDEPENDENT:
            assert INDEPENDENT[gid] in src, f"{gid}: its check no longer runs with the kit's part in place"
            continue
        m = re.search(r"checks\.Exercise\([^)]*builds_on=\(([^)]*)\)", src)
        assert m, f"{gid}: its check cell's checks.Exercise(...) does not say what it builds on (builds_on=...)"
        named = sorted(ast.literal_eval(f"({m.group(1)})"))
        assert named == sorted(exercise(p) for p in parts), f"{gid}: builds_on={named}, its answer uses {parts}"


def test_a_composites_failed_check_names_the_part_to_fix_first_and_how_it_is_graded():
    first, part = checks.Exercise("8.1", "times"), checks.Exercise("8.2", "goals")
    with pytest.raises(checks.CheckFailed):
        first.close([0.1, 0.2], [0.0, 0.1], what="times")
    part.close([1.0], [1.0], what="goals")
    part.done()
    composite = checks.Exercise("8.3", "sweep", builds_on=("8.1", "8.2"))
    with pytest.raises(checks.CheckFailed) as failed:
        composite.close([2.0], [1.0], what="sweep")
    assert str(failed.value).splitlines()[-1] == (
        "8.3 uses your 8.1, which fails its check: fix 8.1 first; graded, 8.3 is run with the lesson's own 8.1.")


def test_a_composite_whose_parts_pass_fails_on_its_own_words():
    part = checks.Exercise("8.4", "times")
    part.close([0.0], [0.0], what="times")
    part.done()
    composite = checks.Exercise("8.5", "sweep", builds_on=("8.4",))
    with pytest.raises(checks.CheckFailed) as failed:
        composite.close([2.0], [1.0], what="sweep")
    assert str(failed.value) == ("exercise 8.5 sweep: sweep[0] is 2, expected 1: off by 1 "
                                 "(tolerance 1e-09: exact math, 1e-9 relative).")


def _assigned(tree) -> set[str]:
    out = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign, ast.AugAssign)):
            for t in node.targets if isinstance(node, ast.Assign) else [node.target]:
                out |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            out |= {(a.asname or a.name).split(".")[0] for a in node.names}
    return out


@pytest.mark.parametrize("lesson", LESSONS)
def test_a_composites_check_cell_needs_nothing_another_check_or_demonstration_defines(lesson):
    """Graded with the lesson's own parts, the second run runs the cells before the first exercise,
    the answers and the composite's own check cell only (grader.sandbox.inside.worker.runs_cell): a
    name the check takes from another cell would be undefined there, and the second run worth nothing."""
    nbformat = need("nbformat")
    nb = nbformat.read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    first = next(i for i, c in enumerate(code) if c.metadata.get("nbgrader", {}).get("grade_id"))
    runs = set().union(*(_assigned(ast.parse(c.source.replace("%matplotlib inline", ""))) for c in code[:first]))
    runs |= {name for c in code if c.metadata.get("nbgrader", {}).get("solution") for name in _assigned(ast.parse(c.source))}
    for gid in composites(lesson):
        cell = next(c for c in code if c.metadata.get("nbgrader", {}).get("grade_id") == gid)
        others = set().union(*(_assigned(ast.parse(c.source.replace("%matplotlib inline", ""))) for c in code
                               if c is not cell)) - runs - _assigned(ast.parse(cell.source))
        tree = ast.parse(cell.source)
        bound = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and not isinstance(n.ctx, ast.Load)}
        bound |= {n.arg for n in ast.walk(tree) if isinstance(n, ast.arg)}
        bound |= {n.name for n in ast.walk(tree) if isinstance(n, ast.ExceptHandler) and n.name}
        used = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load)} - bound
        assert not used & others, f"{gid} uses {sorted(used & others)}, defined in another check or demonstration cell"


def test_a_demonstration_after_a_composite_names_the_part_that_fails_not_the_fix_its_error_advises(tmp_path, monkeypatch):
    """Lesson 06 with 6.1's times starting at 1/rate: the cell that runs Task 2 stops because the sweep's first goal
    is not home. It says so, and names the cause, 6.1 and its check's hint, not the robot's advice to move the arm
    to the first goal first (the wrong fix); the cells after it that need its run name 6.1 too."""
    nbformat = need("nbformat")
    import os
    import sys

    monkeypatch.setenv("SNAKEKIT_TEST", "1")
    monkeypatch.delenv("SNAKEKIT_HANDIN_DIR", raising=False)
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    nb = nbformat.read(COURSE / "source" / "06_coded_sweep" / "06_coded_sweep.ipynb", as_version=4)
    ids = [c.get("id") for c in nb.cells]
    answer = next(c for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") == "ex06_1_sweep_times")
    answer.source = "def sweep_times(points, rate):\n    return np.arange(1, points + 1) / rate"
    nb.cells = nb.cells[:ids.index("06-code-22") + 1]
    notebook_client(nb, timeout=300, kernel_name="python3", allow_errors=True,
                    resources={"metadata": {"path": str(tmp_path)}}).execute()

    def said(cell_id):
        cell = nb.cells[ids.index(cell_id)]
        return " ".join(" ".join(o.get("evalue", "") + o.get("text", "") for o in cell.outputs).split())

    assert "the times start at 1/rate" in said("ex06_1_sweep_times_test")
    assert said("06-code-14") == (
        "this cell uses your answer to exercise 6.3, which uses your 6.1, and 6.1 fails its check: the times start at "
        "1/rate: the first goal goes out at t = 0. That is why this cell stopped (LimitError: the trajectory starts "
        "0.118 rad away from the arm's present position (joint 1: +0.000 -> +0.118 rad); nothing was sent). Fix 6.1 "
        "first, run its check cell, then this cell again.")
    assert said("06-code-14b") == ("This cell needs `run`, which a cell above makes with your 6.1, and 6.1 fails its "
                                   "check (6.1: the times start at 1/rate: the first goal goes out at t = 0). Fix 6.1 "
                                   "first, run its check cell and the cells above, then this cell again.")
    # the lag table needs the same run, made with 6.3 (which uses the 6.1): not "write 6.4", which is right
    assert said("06-code-22") == ("This cell needs `run`, which a cell above makes with your 6.3, which uses your 6.1, "
                                  "and 6.1 fails its check (6.1: the times start at 1/rate: the first goal goes out at "
                                  "t = 0). Fix 6.1 first, run its check cell and the cells above, then this cell again.")
