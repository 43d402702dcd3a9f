"""Exercise 2.1 asks for the exact Jacobian: one verdict in two places.

A Jacobian by central differences of ``tool_pose_2d`` comes within about 1e-11 m of the exact one: inside
2.1's tolerance (exact math, 1e-9 relative) where the entries are large, outside it where an entry is near 0.
The hidden cases hold such a pose (the cases module draws one), and so does the visible check, so that answer
fails both, with the same hint; a right answer in any style (loops, a vectorised sum, ``np.cumsum``, the
geometric one from the joints' positions) passes both.
Both sides run here as they run for a student: the lesson's own check cell, and the grader's scoring of the
hidden cases of several batches against the instructor's answer, at the lesson's tolerances.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grader.scoring.cases import draw
from grader.scoring.references import REFERENCES, Reference
from grader.scoring.score import DEFAULT_TOLERANCES, Expected, score_exercise
from grader.scoring.verdict import with_local_check
from snakekit.errors import CheckFailed
from tests.conftest import need

COURSE = Path(__file__).resolve().parents[2] / "course"
GID = "ex02_1_planar_jacobian_test"
HINT = "finite differences are exercise 2.2's method; 2.1 asks for the exact formula"

RIGHT = {
    "loops": "def planar_jacobian(q):\n    J = np.ones((3, 5))\n    for i in range(5):\n        sx = sy = 0.0\n"
             "        for k in range(i, 5):\n            phi = sum(q[:k + 1])\n"
             "            sx += L[k] * np.sin(phi)\n            sy += L[k] * np.cos(phi)\n"
             "        J[0, i], J[1, i] = -sx, sy\n    return J",
    "vectorised": "def planar_jacobian(q):\n    phi = np.cumsum(q)\n    M = np.tril(np.ones((5, 5)))   # M[k, i] = 1 for k >= i\n"
                  "    return np.vstack([-(L * np.sin(phi)) @ M, (L * np.cos(phi)) @ M, np.ones(5)])",
    "geometric": "def planar_jacobian(q):\n    phi = np.cumsum(q)\n"   # the tool's offset from joint i, turned 90 degrees
                 "    x = np.concatenate([[0.0], np.cumsum(L * np.cos(phi))])\n"
                 "    y = np.concatenate([[0.0], np.cumsum(L * np.sin(phi))])\n"
                 "    return np.vstack([-(y[-1] - y[:-1]), x[-1] - x[:-1], np.ones(5)])",
    "cumsum": "def planar_jacobian(q):\n    phi = np.cumsum(q)\n    down = lambda v: np.cumsum(v[::-1])[::-1]\n"
              "    return np.vstack([down(-L * np.sin(phi)), down(L * np.cos(phi)), np.ones(len(q))])",
}
FINITE = ("def planar_jacobian(q, h=1e-6):\n    q = np.asarray(q, dtype=float)\n"
          "    return np.column_stack([(snakekit.tool_pose_2d(q + h * e) - snakekit.tool_pose_2d(q - h * e)) / (2 * h)\n"
          "                            for e in np.eye(len(q))])")


@pytest.fixture(autouse=True)
def _fresh_verdicts(fresh_verdicts):
    """The kernel's verdicts as they were after each test here (tests/conftest.py)."""


def _lesson():
    nbformat = need("nbformat")
    nb = nbformat.read(COURSE / "source" / "02_jacobian" / "02_jacobian.ipynb", as_version=4)
    return {c.metadata.get("nbgrader", {}).get("grade_id", c.get("id")): c.source for c in nb.cells
            if c.cell_type == "code"}


def _function(cells, answer: str):
    namespace = {"__name__": "lesson02"}
    exec("\n".join(line for line in cells["02-code-02"].splitlines() if not line.startswith("%")), namespace)
    exec(answer, namespace)
    return namespace


def _local(cells, answer: str, gid: str = GID) -> str:
    """What the check cell ``gid`` (2.1's unless told) says of ``answer`` ("" when it passes)."""
    namespace = _function(cells, answer)
    if gid != GID:
        exec(cells[GID].split("\n\nex = ")[0], namespace)   # the shortcuts 2.1's cell names, 2.2's cell forbids too
    try:
        exec(cells[gid], namespace)
    except CheckFailed as e:
        return str(e)
    return ""


def _graded(cells, answer: str, seed: int):
    """The grader's verdict on ``answer`` at a batch's hidden cases (``seed``), against the instructor's answer."""
    cases = draw(COURSE, "02_jacobian", seed=seed).cases[GID]
    mine = _function(cells, answer)["planar_jacobian"]
    theirs = _function(cells, cells["ex02_1_planar_jacobian"].replace("### BEGIN SOLUTION", "")
                       .replace("### END SOLUTION", ""))["planar_jacobian"]
    tol = {**DEFAULT_TOLERANCES["values"], **Reference.load(REFERENCES / "02_jacobian.npz").exercises[GID]["tolerances"]}
    expected = Expected(GID, "values", cases, [{"value": theirs(*c)} for c in cases], tol, "planar_jacobian")
    return score_exercise(GID, [{"value": mine(*c)} for c in cases], expected, 4.0)


@pytest.mark.parametrize("style", sorted(RIGHT))
def test_a_right_jacobian_in_any_style_passes_the_check_and_scores_full_marks_graded(style):
    cells = _lesson()
    assert _local(cells, RIGHT[style]) == ""
    for seed in (1, 2, 3):
        verdict = _graded(cells, RIGHT[style], seed)
        assert verdict.score == verdict.max_score, verdict.message


def test_a_jacobian_by_finite_differences_fails_the_check_and_loses_points_graded_with_the_same_hint():
    cells = _lesson()
    said = _local(cells, FINITE)
    assert HINT in CheckFailed.hint_of(said), said
    assert "q=[0.3, -0.2, -0.099, 0, 0]" in said, said
    from nbformat.v4 import new_code_cell, new_output

    cell = new_code_cell(cells[GID])
    cell.outputs = [new_output("error", ename="CheckFailed", evalue=said, traceback=[])]
    for seed in (1, 2, 3):
        verdict = _graded(cells, FINITE, seed)
        assert verdict.score < verdict.max_score, verdict.message
        assert HINT in with_local_check(verdict, cell).message


def test_the_hidden_cases_hold_a_pose_where_finite_differences_miss():
    """Every batch draws a pose where the exact Jacobian has entries near 1e-4 m and a finite difference is
    outside 2.1's tolerance (it is the last case the cases module draws)."""
    cells = _lesson()
    finite = _function(cells, FINITE)["planar_jacobian"]
    from snakekit.closeness import bound, worst
    from snakekit.kinematics import planar_jacobian

    for seed in range(10):
        q = draw(COURSE, "02_jacobian", seed=seed).cases[GID][-1][0]
        exact = planar_jacobian(q)
        assert np.abs(exact[0, 2:]).min() < 5e-4
        assert worst(finite(q), exact, bound(exact, atol=1e-12, rtol=1e-9)) is not None


# 2.2: a nudge made in place and undone (q[i] += h, then -= 2h, then += h) leaves q as it was to rounding: the
# check passes it, as the grader does; one not undone changes q, and both refuse it (the check names the copy).
IN_PLACE = ("def numerical_jacobian(f, q, h=1e-6):\n    qp = q\n    columns = []\n    for i in range(len(q)):\n"
            "        qp[i] += h\n        fp = np.asarray(f(qp))\n        qp[i] -= 2 * h\n        fm = np.asarray(f(qp))\n"
            "{undo}        columns.append((fp - fm) / (2 * h))\n    return np.column_stack(columns)")
FD_GID = "ex02_2_numerical_jacobian_test"


def _graded_fd(cells, answer: str, seed: int):
    cases = draw(COURSE, "02_jacobian", seed=seed).cases[FD_GID]
    mine = _function(cells, answer)
    theirs = _function(cells, cells["ex02_2_numerical_jacobian"].replace("### BEGIN SOLUTION", "")
                       .replace("### END SOLUTION", ""))
    for ns in (mine, theirs):
        exec(cells[FD_GID].split("\nex = ")[0], ns)   # the test functions the hidden cases name, and graded_fd
    tol = {**DEFAULT_TOLERANCES["values"], **Reference.load(REFERENCES / "02_jacobian.npz").exercises[FD_GID]["tolerances"]}
    expected = Expected(FD_GID, "values", cases, [{"value": theirs["graded_fd"](*c)} for c in cases], tol, "numerical_jacobian")
    return score_exercise(FD_GID, [{"value": mine["graded_fd"](*c)} for c in cases], expected, 3.0)


def test_a_nudge_made_in_place_and_undone_passes_2_2_both_ways():
    cells = _lesson()
    answer = IN_PLACE.format(undo="        qp[i] += h\n")
    assert _local(cells, answer, FD_GID) == ""
    for seed in (1, 2):
        verdict = _graded_fd(cells, answer, seed)
        assert verdict.score == verdict.max_score, verdict.message


def test_a_nudge_made_in_place_and_not_undone_fails_2_2_both_ways():
    cells = _lesson()
    answer = IN_PLACE.format(undo="")
    said = _local(cells, answer, FD_GID)
    assert "changed the q it was given" in said and "does not copy an array" in said, said
    for seed in (1, 2):
        verdict = _graded_fd(cells, answer, seed)
        assert verdict.score < verdict.max_score, verdict.message
