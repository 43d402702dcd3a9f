"""`make lab` serves the lessons in JupyterLab, offline, prints the URL with its token, and enables
nbgrader's Validate button (its JupyterLab extension and the server extension it calls)."""

import json
import os
import re
import signal
import socket
import subprocess
import time
import urllib.error
import urllib.request
from pathlib import Path

from tests.conftest import free_port, need, need_program

ROOT = Path(__file__).resolve().parents[2]


def get_json(url: str):
    with urllib.request.urlopen(url, timeout=10) as r:
        return json.loads(r.read())


def test_make_lab_serves_the_lessons(tmp_path):
    need("jupyterlab")
    psutil = need("psutil")
    make = need_program("make")
    port = free_port()
    env = dict(os.environ, JUPYTERLAB_SETTINGS_DIR=str(tmp_path / "settings"),
               JUPYTERLAB_WORKSPACES_DIR=str(tmp_path / "workspaces"), JUPYTER_RUNTIME_DIR=str(tmp_path / "runtime"))
    log = open(tmp_path / "lab.log", "w+")
    proc = subprocess.Popen([make, "lab", f"LAB_PORT={port}"], cwd=ROOT, env=env, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 90
        url = None
        while url is None:
            assert proc.poll() is None, f"make lab exited with {proc.returncode}:\n{(tmp_path / 'lab.log').read_text()}"
            assert time.monotonic() < deadline, f"no URL within 90 s:\n{(tmp_path / 'lab.log').read_text()}"
            m = re.search(rf"(http://127\.0\.0\.1:{port}/lab\?token=([0-9a-f]+))", (tmp_path / "lab.log").read_text())
            url = m and m.group(1)
            time.sleep(0.2)
        token = m.group(2)
        base = f"http://127.0.0.1:{port}"

        # the lessons are at the root of the file browser, as committed
        listing = get_json(f"{base}/api/contents?token={token}")
        served = sorted(c["name"] for c in listing["content"] if c["type"] == "notebook")
        assert served == sorted(p.name for p in (ROOT / "notebooks").glob("*.ipynb"))
        with urllib.request.urlopen(url, timeout=10) as r:
            assert r.status == 200
            page = r.read().decode()
        assert "JupyterLab" in page

        # nbgrader's Validate button: its JupyterLab extension is loaded in the page and enabled,
        # and the server extension it posts to answers (same nbgrader version on both sides)
        config = json.loads(re.search(r'<script id="jupyter-config-data" type="application/json">(.*?)</script>',
                                      page, re.S).group(1))
        federated = {e["name"] for e in config["federated_extensions"]}
        assert "@jupyter/nbgrader" in federated, sorted(federated)
        disabled = set(config.get("disabledExtensions", []))
        assert "@jupyter/nbgrader:validate-assignment" not in disabled, disabled
        # the teacher's tools are not in the student's lab: not in the page, not on the server
        teacher = {"@jupyter/nbgrader:formgrader", "@jupyter/nbgrader:create-assignment",
                   "@jupyter/nbgrader:course-list", "@jupyter/nbgrader:assignment-list", "@jupyter/nbgrader:menu"}
        assert teacher <= disabled, sorted(teacher - disabled)
        for path in ("formgrader", "assignments", "courses"):
            try:
                urllib.request.urlopen(f"{base}/{path}?token={token}", timeout=10)
                raise AssertionError(f"/{path} answers in the student's lab")
            except urllib.error.HTTPError as e:
                assert e.code == 404, (path, e.code)
        nbgrader = need("nbgrader")
        assert get_json(f"{base}/nbgrader_version?version={nbgrader.__version__}&token={token}") == {"success": True}
        log_text = (tmp_path / "lab.log").read_text()
        assert "nbgrader.server_extensions.validate_assignment | extension was successfully loaded" in log_text

        # offline: no news prompt and no update check
        notes = get_json(f"{base}/lab/api/settings/@jupyterlab/apputils-extension:notification?token={token}")
        defaults = {k: v.get("default") for k, v in notes["schema"]["properties"].items()}
        assert defaults["fetchNews"] == "false" and defaults["checkForUpdates"] is False, defaults

        # it listens on the loopback interface only
        addresses = {c.laddr.ip for c in psutil.net_connections("tcp")
                     if c.status == psutil.CONN_LISTEN and c.laddr.port == port}
        assert addresses and addresses <= {"127.0.0.1", "::1"}, addresses
    finally:
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C does in the terminal
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        log.close()
    # make exits at once; JupyterLab, which got the same Ctrl-C, shuts its kernels and extensions down
    deadline = time.monotonic() + 15
    while True:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) != 0:
                break
        assert time.monotonic() < deadline, "JupyterLab still listens 15 s after Ctrl-C"
        time.sleep(0.2)
