"""Notebooks are code: every lesson runs top to bottom, and is committed without outputs."""

import json
import os
import shutil
import sys
from pathlib import Path

import pytest

from tests.conftest import need

ROOT = Path(__file__).resolve().parents[1]
LESSONS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_there_are_lessons():
    names = [p.name for p in LESSONS]
    for n in ("00_meet_the_arm", "01_forward_kinematics", "02_jacobian", "03_inverse_kinematics", "04_trajectories",
              "05_simulation", "06_coded_sweep", "07_real_robot"):
        assert f"{n}.ipynb" in names


@pytest.mark.parametrize("path", LESSONS, ids=[p.stem for p in LESSONS])
def test_committed_without_outputs(path):
    nb = json.loads(path.read_text())
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            assert cell["outputs"] == [] and cell["execution_count"] is None, \
                f"{path.name}: clear the outputs before committing"


@pytest.mark.parametrize("path", LESSONS, ids=[p.stem for p in LESSONS])
def test_lesson_runs(path, tmp_path, monkeypatch):
    nbformat = need("nbformat")
    nbclient = need("nbclient")
    work = tmp_path / "notebooks"
    shutil.copytree(path.parent, work)
    monkeypatch.setenv("SNAKEKIT_TEST", "1")  # lessons shorten long runs under test
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    nb = nbformat.read(work / path.name, as_version=4)
    client = nbclient.NotebookClient(nb, timeout=180, kernel_name="python3",
                                     resources={"metadata": {"path": str(work)}})
    client.execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert errors == []
    assert any(o.output_type in ("stream", "display_data", "execute_result")
               for c in nb.cells if c.cell_type == "code" for o in c.outputs)
