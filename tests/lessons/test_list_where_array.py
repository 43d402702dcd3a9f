"""A Python list where an exercise asks for an array: one rule across the course, the same locally and graded.

Where an exercise's text asks for an array (``np.array([x, y, theta])``, "an array of shape (6, 2)", "two numpy
arrays"), a list of the right numbers fails its visible check and its grading alike, with the same words
(:func:`snakekit.watch.not_an_array`), as lesson 1's text says. The exercise declares it once,
``checks.Exercise(..., array=True)``, and the check and the hand-in both follow it. Exercise 3.2 refused a list while
6.1 and 6.2 took one, locally and graded; each lesson's own answers are tried here, each returning ``.tolist()`` of
the instructor's answer: the notebook runs with those answers and the batch's hidden cases served, and each
exercise's check cell and the grader's comparison of what it handed in must both refuse it.
"""

from __future__ import annotations

import ast
import copy
import os
import re
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from grader.scoring.cases import CaseServer, draw, read_handins
from grader.scoring.references import REFERENCES, Reference, expected
from grader.scoring.score import score_exercise
from grader.scoring.wording import signatures
from snakekit import host
from snakekit.kernel_client import NotebookClient
from tests.conftest import need

ROOT = Path(__file__).resolve().parents[2]
COURSE = ROOT / "course"
LESSONS = sorted(p.name for p in (COURSE / "source").iterdir() if (p / f"{p.name}.ipynb").exists())

#: Every exercise whose text asks for an array, with the words that ask (in its "### Exercise" section).
ASKS_AN_ARRAY = {
    "ex01_1_planar_fk_test": "→ `np.array([x, y, theta])`",
    "ex01_2_joint_positions_test": "Return an array of shape `(6, 2)`",
    "ex02_1_planar_jacobian_test": "Return the $3 \\times 5$ Jacobian",
    "ex02_2_numerical_jacobian_test": "Return the $m \\times n$ matrix",
    "ex03_1_two_link_ik_test": "Return an array of shape `(2, 2)`",
    "ex03_2_dls_step_test": "shape `(5,)`",
    "ex03_4_task1_test": "shape `(len(targets), 3)`",
    "ex04_1_quintic_test": "for a scalar or an array `t` [s] (same shape as `t`)",
    "ex04_2_trapezoid_test": "Return `np.array([T, v_peak])`",
    "ex04_4_limit_check_test": "as an array of shape `(k, 3)`",
    "ex06_1_sweep_times_test": "as a float array of shape `(points,)`",
    "ex06_2_sweep_positions_test": "as an array of shape `(len(times), 5)`",
    "ex08_2_read_joint_states_test": "two numpy arrays",
}
#: the parts of an exercise whose answer is a pair of arrays
PARTS = {"ex08_2_read_joint_states_test": ("times", "positions")}


def _notebook(lesson: str):
    return need("nbformat").read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4)


def _gid(cell) -> str:
    return cell.metadata.get("nbgrader", {}).get("grade_id", "")


def _spec(nb, number: str) -> str:
    """The text of exercise ``number``'s section: from its "### Exercise" heading to the next heading."""
    text = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    m = re.search(rf"### Exercise {re.escape(number)} .*?(?=\n#|\Z)", text, re.S)
    return m.group(0) if m else ""


def _declared(source: str):
    """What a check cell's ``checks.Exercise(...)`` declares: (number, name, its array=, as Python)."""
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "Exercise":
            array = next((ast.literal_eval(k.value) for k in node.keywords if k.arg == "array"), False)
            return node.args[0].value, node.args[1].value, array
    return None


def test_the_exercises_whose_text_asks_for_an_array_declare_it_and_no_other_does():
    declared = {}
    for lesson in LESSONS:
        nb = _notebook(lesson)
        for c in nb.cells:
            if c.metadata.get("nbgrader", {}).get("grade") and _declared(c.source):
                number, _, array = _declared(c.source)
                if array:
                    declared[_gid(c)] = array
                    assert ASKS_AN_ARRAY.get(_gid(c), "\0") in _spec(nb, number), (_gid(c), _spec(nb, number))
                # one declaration: no check or hand-in of the cell says it again
                assert c.source.count("array=") == (1 if array else 0), _gid(c)
    assert declared == {g: PARTS.get(g, True) for g in ASKS_AN_ARRAY}
    assert "a Python list, even of the right numbers, fails its check and its grading alike" in \
        _notebook("01_forward_kinematics").cells[0].source


class _ToList(ast.NodeTransformer):
    """Every ``return X`` of an answer becomes ``return np.asarray(X).tolist()`` (a pair: each of its parts)."""

    def visit_Return(self, node):
        if node.value is None:
            return node
        parts = node.value.elts if isinstance(node.value, ast.Tuple) else [node.value]
        listed = [ast.parse(f"np.asarray({ast.unparse(p)}).tolist()", mode="eval").body for p in parts]
        node.value = ast.Tuple(listed, ast.Load()) if isinstance(node.value, ast.Tuple) else listed[0]
        return node


def as_lists(source: str) -> str:
    """The instructor's answer, returning ``.tolist()`` of what it returns (the numbers right, in a list)."""
    return ast.unparse(ast.fix_missing_locations(_ToList().visit(ast.parse(source))))


def _run(nb, batch, folder: Path, tmp: Path):
    """The notebook run (errors allowed) with the batch's cases served: the executed notebook and its hand-ins."""
    from traitlets.config import Config

    work, handin = tmp / "work", tmp / "handin"
    shutil.copytree(folder, work, ignore=shutil.ignore_patterns(".ipynb_checkpoints", "*.ipynb"))
    handin.mkdir()
    sockets = Path(tempfile.mkdtemp(prefix="sk-"))   # a socket's path is short (MAX_SOCKET_PATH)
    with CaseServer(batch) as server:
        env = {"SNAKEKIT_HANDIN_DIR": str(handin), "SNAKEKIT_CASES": server.listen(sockets / "cases.sock"),
               "MPLBACKEND": "Agg", "SNAKEKIT_TEST": "1"}
        with pytest.MonkeyPatch.context() as mp:
            for k, v in env.items():
                mp.setenv(k, v)
            mp.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
            NotebookClient(nb, timeout=600, kernel_name="python3", allow_errors=True,
                           resources={"metadata": {"path": str(work)}},
                           extra_arguments=["--IPKernelApp.log_level=ERROR"],
                           config=Config(host.kernel_sockets(str(sockets)))).execute()
    shutil.rmtree(sockets, ignore_errors=True)
    return nb, read_handins(handin)


ARRAY_LESSONS = sorted({lesson for lesson in LESSONS for c in _notebook(lesson).cells if _gid(c) in ASKS_AN_ARRAY})


@pytest.mark.parametrize("lesson", ARRAY_LESSONS)
def test_a_list_of_the_right_numbers_is_refused_in_the_same_words_locally_and_graded(lesson, tmp_path):
    nb = _notebook(lesson)
    batch = draw(COURSE, lesson, seed=3)
    right, right_handins = _run(copy.deepcopy(nb), batch, COURSE / "source" / lesson, tmp_path / "right")
    wrong = copy.deepcopy(nb)
    tried = [g for g in ASKS_AN_ARRAY if any(_gid(c) == g for c in nb.cells)]
    for c in wrong.cells:
        if _gid(c) + "_test" in tried and c.metadata["nbgrader"].get("solution"):
            c.source = as_lists(c.source)
    wrong, handins = _run(wrong, batch, COURSE / "source" / lesson, tmp_path / "wrong")
    sources = {_gid(c): c.source for c in nb.cells if _gid(c)}
    want = expected(Reference.load(REFERENCES / f"{lesson}.npz"), batch, right_handins, sources=sources,
                    signatures=signatures(c.source for c in nb.cells if c.cell_type == "code"))
    for gid in tried:
        name = _declared(sources[gid])[1]
        cell = next(c for c in wrong.cells if _gid(c) == gid)
        local = " ".join(str(o.get("evalue", "")) for o in cell.outputs if o.output_type == "error")
        graded = score_exercise(gid, handins.get(gid), want[gid], 1.0)
        said = " ".join([graded.message] + [c.message for c in graded.checks])
        # the same words, locally and graded: which function, what it returned, and what to do
        who = f"{name} returned {PARTS[gid][0] + ' as ' if gid in PARTS else ''}a Python list"
        advice = ("not a numpy array: the exercise asks for an array, and the cells after it use it as one; "
                  "return np.array(...) of it.")
        assert who in local and advice in local, f"{gid}: the notebook's check said {local!r}"
        # wrong at every hidden case whose answer is an array (a ValueError asked for, or a number for a number, stays right)
        arrays = [frac for (_, frac), r in zip(graded.cases, right_handins[gid])
                  if isinstance(r, dict) and any(np.ndim(v) >= 1 for v in r.values())]
        assert arrays and not any(arrays), f"{gid}: a list of the right numbers scored {graded.cases} graded: {said}"
        assert who in said and advice in said, f"{gid}: graded {said!r}"
        # and the right answers pass both: the refusal is the list's, not the numbers'
        ok = next(c for c in right.cells if _gid(c) == gid)
        assert not [o for o in ok.outputs if o.output_type == "error"], (gid, ok.outputs)
        assert score_exercise(gid, right_handins[gid], want[gid], 1.0).score == 1.0
    assert np.all([gid in handins for gid in tried])


def test_no_list_variant_of_an_exercise_that_asks_an_array_is_called_equivalent():
    """The fairness matrix's EQUIVALENT (variants neither side can refuse) lists no list variant of an exercise whose
    task asks an array: those fail both ways alike."""
    from grader.course.fairness import EQUIVALENT

    answers = {gid.removesuffix("_test") for gid in ASKS_AN_ARRAY}
    assert not [key for key in EQUIVALENT if key[1] == "list" and key[0] in answers]
