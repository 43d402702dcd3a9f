"""`snakekit progress`: a student's own state across the lessons, read from their saved notebooks."""

from __future__ import annotations

import io
import os
import shutil
import sys
from pathlib import Path

import pytest

from tests.conftest import need, notebook_client

ROOT = Path(__file__).resolve().parents[2]
L0, L1 = "00_meet_the_arm", "01_forward_kinematics"


def _meta(cell) -> dict:
    return cell.get("metadata", {}).get("nbgrader", {})


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """The student's notebooks/: lesson 0 as handed out, never run; lesson 1 run in JupyterLab's
    way (top to bottom, errors and all) and saved, with 1.1 written right, 1.2 written with the
    angles not accumulated, 1.3 not written."""
    nbformat = need("nbformat")
    need("nbclient")
    work = tmp_path_factory.mktemp("notebooks")
    shutil.copy(ROOT / "notebooks" / f"{L0}.ipynb", work)
    source = nbformat.read(ROOT / "course" / "source" / L1 / f"{L1}.ipynb", as_version=4)
    solution = {_meta(c)["grade_id"]: c.source for c in source.cells if _meta(c).get("solution")}
    nb = nbformat.read(ROOT / "notebooks" / f"{L1}.ipynb", as_version=4)
    for c in nb.cells:
        if _meta(c).get("grade_id") == "ex01_1_planar_fk":
            c.source = solution["ex01_1_planar_fk"]
        if _meta(c).get("grade_id") == "ex01_2_joint_positions":
            c.source = ("def joint_positions(q):\n    L = spec.lengths\n"
                        "    steps = L[:, None] * np.column_stack([np.cos(q), np.sin(q)])\n"
                        "    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])")
    env = {"SNAKEKIT_TEST": "1", "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        notebook_client(nb, timeout=300, kernel_name="python3", allow_errors=True,
                        resources={"metadata": {"path": str(work)}}).execute()
    finally:
        for k, v in old.items():
            os.environ.pop(k) if v is None else os.environ.__setitem__(k, v)
    nbformat.write(nb, work / f"{L1}.ipynb")
    points = {_meta(c)["grade_id"]: _meta(c)["points"] for c in nb.cells if _meta(c).get("grade")}
    points0 = {_meta(c)["grade_id"]: _meta(c)["points"]
               for c in nbformat.read(work / f"{L0}.ipynb", as_version=4).cells if _meta(c).get("grade")}
    return work, points, points0


def test_each_exercise_is_read_as_the_saved_notebook_shows_it(folder):
    from snakekit.lesson_progress import lesson_states

    work, points, _ = folder
    states = {s.number: s for s in lesson_states(work / f"{L1}.ipynb")}
    assert [(n, s.state) for n, s in states.items()] == [("1.1", "passed"), ("1.2", "failed"), ("1.3", "not written")]
    assert states["1.2"].message.startswith("exercise 1.2 joint_positions: ") and "\n" not in states["1.2"].message
    assert states["1.1"].points == points["ex01_1_planar_fk_test"]


def test_progress_shows_each_lesson_the_total_and_what_is_next(folder):
    from snakekit.lesson_progress import progress_report

    work, points, points0 = folder
    out = io.StringIO()
    assert progress_report(work, out=out) == 0
    shown = out.getvalue()
    p1, total1 = points["ex01_1_planar_fk_test"], sum(points.values())
    total = total1 + sum(points0.values())
    assert f"{L0:<{len(L1)}}  0 of {len(points0)} exercises passed, 0 of {sum(points0.values()):g} points  (not started)" in shown
    assert (f"{L1}  1 of 3 exercises passed, {p1:g} of {total1:g} points  (1.2 failed, 1.3 not written)") in shown
    assert f"total{' ' * (len(L1) - 5)}  1 of {3 + len(points0)} exercises passed, {p1:g} of {total:g} points" in shown
    worth = points0["ex00_1_tool_distance_test"]   # 1 point: "(1 point)", never "(1 points)"
    assert f"Next: exercise 0.1 in {L0} ({worth:g} point{'' if worth == 1 else 's'}): write it" in shown
    assert " 1 points)" not in shown


def test_in_a_graded_copy_the_cell_says_where_progress_shows_instead_of_not_started(folder, monkeypatch):
    from grader.sandbox import runner
    from snakekit.lesson_progress import progress_report

    assert "SNAKEKIT_HANDIN_DIR" in Path(runner.__file__).read_text()  # what the grader's sandbox sets
    work, _, _ = folder
    monkeypatch.setenv("SNAKEKIT_HANDIN_DIR", str(work / "handin"))
    out = io.StringIO()
    assert progress_report(work, out=out) == 0
    assert out.getvalue() == ("Your progress across the lessons shows when you run this cell in your own notebooks; "
                              "the graded copy holds this lesson only.\n")


def test_the_command_reads_the_folder_it_is_given_and_refuses_one_without_lessons(folder, tmp_path, capsys):
    from snakekit.cli import main

    work, *_ = folder
    assert main(["progress", str(work)]) == 0
    assert "1 of 3 exercises passed" in capsys.readouterr().out
    assert main(["progress", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("snakekit progress: no lesson notebooks") and str(tmp_path) in err[0]
