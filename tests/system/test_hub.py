"""The class's JupyterHub (docker/hub/): one JupyterHub version everywhere, and the week of a
class on a real hub (docker/hub/test.sh, on the private engine of docker/engine.sh)."""

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.system._engine import on_engine, run_on_engine

ROOT = Path(__file__).resolve().parents[2]
LESSONS = len(list((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb")))  # the students' lessons, as listed
pytestmark = pytest.mark.system  # the class's JupyterHub, on the private Docker engine: not in `make test-quick`


def pins(text: str, name: str) -> set[str]:
    return set(re.findall(rf"^{name}==(\S+)", text, re.M))


def test_the_hub_and_the_image_pin_one_jupyterhub_of_the_same_major_version():
    image = pins((ROOT / "environment.lock").read_text(), "jupyterhub")
    hub = pins((ROOT / "docker/hub/requirements.txt").read_text(), "jupyterhub")
    wanted = pins((ROOT / "docker/hub/requirements.in").read_text(), "jupyterhub")
    assert len(image) == 1 and image == hub == wanted, (image, hub, wanted)
    assert next(iter(image)).startswith("5."), image  # Zero to JupyterHub 4.x's major version
    for name in ("dockerspawner", "jupyterhub-idle-culler", "jupyterhub-ltiauthenticator", "jupyterhub-nativeauthenticator"):
        assert len(pins((ROOT / "docker/hub/requirements.txt").read_text(), name)) == 1, name


@on_engine
def test_hub_week_of_a_class(capsys):
    """docker/hub/test.sh: the hub starts; 25 students log in at once, 6 fetch, submit and get feedback; refusals."""
    out = run_on_engine("docker/hub/test.sh", capsys, what="the hub test", timeout_min=45,
                        show=("figure:", "hub-test:", "hub:", "check-config:"))
    assert "hub-test: passed" in out
    # identity: accounts made by the teacher, a password each; what a student could try is refused
    assert "accounts: teacher and ta made by docker/hub/up, 25 students' by docker/hub/accounts" in out, out[-3000:]
    assert re.search(r"refused log-ins \(9\): s02 with s01's password; teacher with a student's password; "
                     r"teacher with the TA's password; teacher with no password; s01 with no password; "
                     r"a name without an account; teacher with the old shared password; s01 with the old shared "
                     r"password; mallory with the old shared password: each the form again", out), out[-3000:]
    assert "no sign-up page (404)" in out
    # the 3D view: on the container's loopback, refused to another student on the network and through the hub
    assert re.search(r"refused: s01's 3D view to s02: on the hub's network snakekit-lab-s01:70\d\d "
                     r"(ConnectionRefusedError|TimeoutError|timeout) \(its server listens on 127.0.0.1 only; "
                     r"snakekit-lab-s01:8888 open\), through the hub /user/s01/proxy/70\d\d/static/ 40[34] with s02's "
                     r"token and 403 with s02's log-in; s01's own: 200", out), out[-3000:]
    assert "all known and valid" in out and "LTI13Authenticator" in out
    assert re.search(r"6 students fetched, filled and submitted", out), out[-3000:]  # docker/hub/test.sh's SUBMITTING
    # the class logging in at once (to the servers the teacher started before): every one of the 25
    # ready, each one's time printed
    assert "25 students logged in at once, each with a ready server" in out
    again = re.search(r"figure: 25 students logging in at once to servers started before the lesson, log-in to a "
                      r"ready server: median [\d.]+ s, max [\d.]+ s \(target <= 30 s\); each: (.*)", out)
    assert again, out[-3000:]
    assert [n for n, _ in re.findall(r"(s\d\d) ([\d.]+)", again.group(1))] == [f"s{i:02d}" for i in range(1, 26)]
    # no host shell: the kit's commands in every terminal; the README's commands per role; grading from the hub
    assert ("every terminal has snakekit and nbgrader on its PATH: bash -l and sh -l, in the teacher's, the TA's "
            "and a student's server") in out, out[-3000:]
    assert "(2 commands in the teacher's terminal, in course/)" in out, out[-3000:]
    assert re.search(r"figure: grading the 6 collected submissions \(snakekit grade in the TA's terminal, the hub's "
                     r"grading service\): [\d.]+ s", out), out[-3000:]
    assert re.search(r"refused: grading for a student \(the grading service 403 to s01's token; snakekit grade in "
                     r"their server: snakekit grade: the hub's grading service refused \(403\): s01 is not an "
                     r"instructor or TA", out), out[-3000:]
    assert "ta: feedback returned" in out
    assert re.search(r"figure: memory: s01's server with lesson 00 run and its 3D view open in Chromium: usage \d+ MiB, "
                     r"peak \d+ MiB", out), out[-3000:]
    assert "every student fetched their feedback page" in out
    for refusal in ("submitting as", "collecting or reading others' submissions", "another's feedback",
                    "the hub's tokens", "over the size limit", "a full exchange",
                    "the saved file and the filled lesson are there",
                    "nbgrader's teacher tools on a student's server (formgrader, course list: 404/404); "
                    "the teacher's formgrader answers 200"):
        assert refusal in out, refusal
    # a student logged in on the hub's page reaches lesson 00 with the arm drawn, and it moves
    assert f"browser: the hub's log-in page as s01, then /user/s01/lab lists the {LESSONS} lessons" in out, out[-3000:]
    assert re.search(r"the 3D view /user/s01/proxy/\d+/static/ \(through the lab's port\) draws the arm", out), out[-3000:]
    assert "browser: the motion cell moved the arm" in out, out[-3000:]
    assert "went to the lab's port 127.0.0.1:18000" in out, out[-3000:]


# --- docker/hub/up finds a compose that works -------------------------------------------------------
# A stand-in for the Docker client: the engine answers, no image is built yet (so up builds), and
# `docker compose` is the plugin (PLUGIN=1) or, as Debian's docker.io answers, no such command.
FAKE_DOCKER = """#!/bin/bash
echo "docker $*" >> "$LOG"
case "$1" in
  version) exit 0 ;;
  image) exit 1 ;;
  compose)
    if [ -n "${PLUGIN:-}" ]; then [ "$2" = version ] && echo "Docker Compose version v2.29.7" && exit 0; exit 3; fi
    if [ "$2" = version ]; then echo "docker: 'compose' is not a docker command." >&2; else echo "unknown shorthand flag: 'f' in -f" >&2; fi
    exit 1 ;;
esac
exit 0
"""
# A stand-in docker-compose: answers `version` (or fails it: BROKEN), records the build and stops
# the start there (exit 3), so nothing further runs.
FAKE_COMPOSE = """#!/bin/bash
echo "$0 $*" >> "$LOG"
if [ "$1" = version ]; then [ -z "${BROKEN:-}" ]; exit; fi
exit 3
"""
BUILD = "-f docker/compose.yaml --profile grader build lab grader"


@pytest.mark.parametrize("plugin, on_path, in_venv, used", [
    (True, "works", True, "docker compose"),
    (False, "works", True, "PATH/docker-compose"),
    (False, None, True, "VENV/bin/docker-compose"),
    (False, "broken", True, "VENV/bin/docker-compose"),
    (False, None, False, None),
], ids=["the plugin", "docker-compose on PATH", "the kit's own", "a broken one on PATH: the kit's own", "none"])
def test_up_builds_with_the_first_compose_that_works(tmp_path, plugin, on_path, in_venv, used):
    bin_, venv, log = tmp_path / "bin", tmp_path / "venv", tmp_path / "log"
    (venv / "bin").mkdir(parents=True)
    bin_.mkdir()
    for tool in ("bash", "dirname"):
        (bin_ / tool).symlink_to(shutil.which(tool))
    (bin_ / "docker").write_text(FAKE_DOCKER)
    env = {"PATH": str(bin_), "LOG": str(log), "HOME": str(tmp_path), "SNAKEKIT_VENV": str(venv)}
    if plugin:
        env["PLUGIN"] = "1"
    if on_path:
        (bin_ / "docker-compose").write_text(FAKE_COMPOSE.replace("${BROKEN:-}", "broken" if on_path == "broken" else ""))
    if in_venv:
        (venv / "bin/docker-compose").write_text(FAKE_COMPOSE)
    for f in [*bin_.iterdir(), *(venv / "bin").iterdir()]:
        f.chmod(0o755)
    proc = subprocess.run([str(ROOT / "docker/hub/up")], env=env, capture_output=True, text=True, timeout=60)
    calls = log.read_text().splitlines()
    builds = [c for c in calls if c.endswith(BUILD)]
    if used is None:
        assert proc.returncode != 0 and builds == [], (proc.returncode, calls)
        assert proc.stderr.splitlines() == [
            f"hub: no Docker Compose works here (docker compose, docker-compose, {venv}/bin/docker-compose): run make "
            "setup (the kit's own docker-compose) or install Docker's compose plugin (docker-compose-plugin), then "
            "docker/hub/up again"], proc.stderr
        return
    who = used.replace("PATH", str(bin_)).replace("VENV", str(venv))
    assert builds == [f"{who} {BUILD}"], calls
    assert proc.returncode == 3, (proc.returncode, proc.stderr)  # the stand-in's build failing stops the start
    assert f"hub: building snakekit-lab:latest and snakekit-grader:latest ({who} {BUILD})" in proc.stdout, proc.stdout
