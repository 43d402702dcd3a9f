"""Binder: the repository as jupyter-repo2docker builds it, and the image it makes.

binder/test.sh builds the repository with repo2docker (`--no-run`) on the private Docker engine
of docker/engine.sh, starts the image with the command Binder starts it with and opens lesson
00 (binder/open-lesson); it needs root. Outside CI a machine without root or apt skips it;
with CI=true it runs or fails.
"""

import os
import re
from pathlib import Path

import pytest

from tests.system._engine import on_engine, run_on_engine

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.system  # the Binder image, on the private Docker engine: not in `make test-quick`


def test_binder_builds_the_containers_dockerfile():
    """repo2docker's Dockerfile route: binder/Dockerfile is docker/Dockerfile, and it reaches the build."""
    link = ROOT / "binder/Dockerfile"
    assert link.is_symlink() and os.readlink(link) == "../docker/Dockerfile"
    assert link.resolve() == (ROOT / "docker/Dockerfile").resolve()
    # the build's context is the repository, filtered by .dockerignore: the link's target is in it
    ignore = (ROOT / ".dockerignore").read_text().splitlines()
    assert "*" in ignore and "!docker/Dockerfile" in ignore
    # only the Dockerfile decides the build: no other repo2docker configuration beside it
    others = {p.name for p in (ROOT / "binder").iterdir()} & {
        "environment.yml", "requirements.txt", "apt.txt", "postBuild", "start", "runtime.txt", "install.R",
        "Project.toml", "setup.py", "default.nix", "pyproject.toml"}
    assert not others, others


@on_engine
def test_binder_image_builds_with_repo2docker_and_opens_a_lesson(capsys):
    """binder/test.sh: repo2docker --no-run, then the image as Binder runs it: /lab, the lessons, a cell run."""
    out = run_on_engine("binder/test.sh", capsys, what="the Binder test", timeout_min=30,
                        modules=("repo2docker",),  # jupyter-repo2docker, in .venv (the dev extra)
                        show=("figure:", "open-lesson:", "binder-test: restored", "binder-test: host state"))
    assert "binder-test: passed" in out
    assert re.search(r"figure: repo2docker build: [\d.]+ s \(\d+ of \d+ steps from the engine's cache; \d{4}\.\d+\.\d+\)", out), out[-3000:]
    lessons = len(list((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb")))
    assert f"opens JupyterLab; the server's folder lists the {lessons} lessons" in out, out[-3000:]
    if "jupyter-server-proxy" in (ROOT / "pyproject.toml").read_text():  # the 3D view through the server
        assert "the 3D view's page answers through the Jupyter server" in out, out[-3000:]
        assert "the control panel's 3D view, through the Jupyter server, draws the arm" in out, out[-3000:]
    assert "in headless Chromium, /lab/tree/00_meet_the_arm.ipynb opened and its first cell ran from the page" in out
    # a self-learner's lab: nbgrader's Validate, none of the teacher's tools, on the server and in the page
    assert "the server serves no formgrader, course list or assignment list (404), and Validate" in out, out[-3000:]
    assert "none of nbgrader's teacher tools in the page (no menu, no Create Assignment panel)" in out, out[-3000:]
    assert re.search(r"00_meet_the_arm\.ipynb's first code cell ran in its kernel .* it printed: <snakekit Viewer",
                     out), out[-3000:]
