"""The tests that run a script on the private Docker engine of docker/engine.sh: the container
(docker/test.sh), Binder (binder/test.sh) and the hub (docker/hub/test.sh).

Each script needs root and apt-get (it installs Debian's docker.io and runs its own dockerd):
outside CI a machine without them skips the test; with CI=true it fails.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

from tests.conftest import ENGINE_GROUP, IN_CI, need, need_program

ROOT = Path(__file__).resolve().parents[2]
#: A test that runs a script here: one such test at a time in a parallel run (the scripts also
#: take the engine's lock, so two runs of the suite on one machine wait for each other).
on_engine = pytest.mark.xdist_group(ENGINE_GROUP)


def run_on_engine(script: str, capsys, *, what: str, show: tuple[str, ...], timeout_min: int,
                  modules: tuple[str, ...] = (), browser: bool = True) -> str:
    """Runs ``script`` (from the repository root) and returns its output.

    Args:
        script: the script's path in the repository, e.g. ``docker/test.sh``.
        capsys: the test's capsys, to print the script's figures and steps as it ends.
        what: what runs, for the skip or failure message ("the container test").
        show: the prefixes of the output lines printed ("figure:", ...).
        timeout_min: the script's time limit [min].
        modules: Python modules the script needs besides playwright (``need``).
        browser: whether it opens pages in headless Chromium (Chromium and playwright needed).
    """
    if os.geteuid() != 0 or not shutil.which("apt-get"):
        why = f"{what} needs root and apt-get (it installs docker.io and runs dockerd)"
        if IN_CI:
            pytest.fail(f"{why}; under CI=true it must run")
        pytest.skip(why)
    for module in modules:
        need(module)
    need_program("ip")
    if browser:
        need_program("chromium")
        need("playwright.sync_api")
    env = dict(os.environ, PATH=f"{ROOT / '.venv/bin'}:{os.environ['PATH']}")
    proc = subprocess.Popen(["bash", str(ROOT / script)], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=timeout_min * 60)
        late = ""
    except subprocess.TimeoutExpired:
        # a bound for a hang: stop the script's process group (dockerd has its own session), so its
        # exit trap removes what ran and stops the engine; then the lines it printed so far
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            out, _ = proc.communicate(timeout=300)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, _ = proc.communicate()
        late = f"{what}: stopped after its limit of {timeout_min} min"
    shown = [line for line in out.splitlines() if line.startswith(show) or "FAILED" in line]
    with capsys.disabled():
        print()
        for line in shown:
            print(line)
    # the script's own lines first: under xdist the lines printed above stay in the worker, and the
    # output's end is mostly dockerd's log
    assert not late, late + "; its lines until then:\n" + "\n".join(shown)[-6000:] + "\n--- the output's end:\n" + out[-3000:]
    assert proc.returncode == 0, "\n".join(shown)[-6000:] + "\n--- the output's end:\n" + out[-3000:]
    assert "host state checked" in out, out[-3000:]  # the engine stopped, the host as it was
    return out
