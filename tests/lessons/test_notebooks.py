"""Notebooks are code: every student lesson runs top to bottom, and is committed without outputs.

The student versions in notebooks/ are generated from course/ (tests/lessons/test_course.py). Run as
handed out, a lesson fails only in its exercises' check cells, each with a message that names
the exercise; every other cell runs, or says which exercise it waits for; every plot arrives
as a picture (image/png).
"""

import json
import os
import re
import shutil
import sys
from pathlib import Path

import pytest

from tests.conftest import need, notebook_client

ROOT = Path(__file__).resolve().parents[2]
LESSONS = sorted((ROOT / "notebooks").glob("*.ipynb"))
ANSI = re.compile(r"\x1b\[[0-9;]*m")


def test_there_are_lessons():
    names = [p.name for p in LESSONS]
    for n in ("00_meet_the_arm", "01_forward_kinematics", "02_jacobian", "03_inverse_kinematics", "04_trajectories",
              "05_simulation", "06_coded_sweep", "07_real_robot", "08_ros"):
        assert f"{n}.ipynb" in names


@pytest.mark.parametrize("path", LESSONS, ids=[p.stem for p in LESSONS])
def test_committed_without_outputs(path):
    nb = json.loads(path.read_text())
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            assert cell["outputs"] == [] and cell["execution_count"] is None, \
                f"{path.name}: clear the outputs before committing"


#: a cell that moves an arm (a robot's run or move) and what lets the student watch it in the 3D view
MOVES = re.compile(r"\b(?:robot|sim|arm)\.(?:run|move_to|home)\(")
WATCHED = re.compile(r"\.play\(|ControlPanel\(")


@pytest.mark.parametrize("path", LESSONS, ids=[p.stem for p in LESSONS])
def test_every_lesson_that_moves_the_arm_lets_the_student_watch_a_move_in_the_3d_view(path):
    sources = ["".join(c["source"]) for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code"]
    moving = [s.splitlines()[0] for s in sources if MOVES.search(s)]
    if moving:
        assert any(WATCHED.search(s) for s in sources), \
            f"{path.name} moves the arm (first in the cell starting {moving[0]!r}) but never plays a run in the 3D view"


def execute(path: Path, work: Path, monkeypatch, **env):
    """Run a notebook in a fresh kernel in ``work`` (a copy of its folder); errors are kept."""
    nbformat = need("nbformat")
    need("nbclient")
    shutil.copytree(path.parent, work, ignore=shutil.ignore_patterns(".ipynb_checkpoints", "*.html", "*.npz"))
    monkeypatch.setenv("SNAKEKIT_TEST", "1")
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    nb = nbformat.read(work / path.name, as_version=4)
    client = notebook_client(nb, timeout=180, kernel_name="python3", allow_errors=True,
                             resources={"metadata": {"path": str(work)}})
    client.execute()
    return nb


def plot_cells(nb):
    """Code cells that draw a figure (and are not waiting for an exercise)."""
    return [c for c in nb.cells if c.cell_type == "code" and ("plt.show()" in c.source or "display(plot_" in c.source)]


@pytest.mark.parametrize("path", LESSONS, ids=[p.stem for p in LESSONS])
def test_student_lesson_fails_only_in_its_checks(path, tmp_path, monkeypatch):
    nb = execute(path, tmp_path / "notebooks", monkeypatch)
    graded = {}
    for index, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        meta = cell.metadata.get("nbgrader", {})
        errors = [o for o in cell.outputs if o.output_type == "error"]
        if meta.get("grade"):
            graded[meta["grade_id"]] = errors
            continue
        assert errors == [], f"cell {index} of {path.name} failed outside an exercise check:\n" + \
            ANSI.sub("", "\n".join(errors[0].traceback))
    assert graded, f"{path.name} has no exercise"
    for grade_id, errors in graded.items():
        number = re.match(r"ex(\d+)_(\d+)_", grade_id)
        number = f"{int(number.group(1))}.{number.group(2)}"
        assert len(errors) == 1, f"{grade_id} should fail while its exercise is a stub"
        e = errors[0]
        shown = " ".join(ANSI.sub("", "\n".join(e.traceback)).split())   # wrapped to 80 columns: compare words
        assert e.ename == "CheckFailed"
        assert shown.startswith(f"Check failed: exercise {number} "), shown
        assert "is not written yet" in shown and f'NotImplementedError: exercise {number}' in shown, shown
        assert "checks.py" not in shown and "Traceback" not in shown, shown   # the message, not the stack
    # demonstrations that wait for an exercise say so; the others draw their plots as pictures
    text = "\n".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs
                     if o.output_type == "stream")
    for cell in plot_cells(nb):
        if "waiting_for" in cell.source:
            assert "This cell waits for exercise" in "".join(o.get("text", "") for o in cell.outputs), cell.source
            continue
        assert any("image/png" in o.get("data", {}) for o in cell.outputs), \
            f"{path.name}: this cell's plot did not arrive as image/png:\n{cell.source[:200]}"
    assert "Traceback" not in text
