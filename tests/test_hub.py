"""The class's JupyterHub (docker/hub/): one JupyterHub version everywhere, and the week of a
class on a real hub (docker/hub/test.sh, on the private engine of docker/engine.sh)."""

import re
from pathlib import Path

from tests._engine import run_on_engine

ROOT = Path(__file__).resolve().parents[1]


def pins(text: str, name: str) -> set[str]:
    return set(re.findall(rf"^{name}==(\S+)", text, re.M))


def test_the_hub_and_the_image_pin_one_jupyterhub_of_the_same_major_version():
    image = pins((ROOT / "environment.lock").read_text(), "jupyterhub")
    hub = pins((ROOT / "docker/hub/requirements.txt").read_text(), "jupyterhub")
    wanted = pins((ROOT / "docker/hub/requirements.in").read_text(), "jupyterhub")
    assert len(image) == 1 and image == hub == wanted, (image, hub, wanted)
    assert next(iter(image)).startswith("5."), image  # Zero to JupyterHub 4.x's major version
    for name in ("dockerspawner", "jupyterhub-idle-culler", "jupyterhub-ltiauthenticator"):
        assert len(pins((ROOT / "docker/hub/requirements.txt").read_text(), name)) == 1, name


def test_hub_week_of_a_class(capsys):
    """docker/hub/test.sh: the hub starts; 20 students fetch, submit and get feedback; refusals."""
    out = run_on_engine("docker/hub/test.sh", capsys, what="the hub test", timeout_min=30,
                        show=("figure:", "hub-test:", "hub:", "check-config:"))
    assert "hub-test: passed" in out
    assert "all known and valid" in out and "LTI13Authenticator" in out
    assert re.search(r"20 students fetched, filled and submitted", out), out[-3000:]
    assert "every student fetched their feedback page" in out
    for refusal in ("submitting as", "collecting or reading others' submissions", "another's feedback",
                    "the hub's tokens", "over the size limit", "a full exchange",
                    "the saved file and the filled lesson are there",
                    "nbgrader's teacher tools on a student's server (formgrader, course list: 404/404); "
                    "the teacher's formgrader answers 200"):
        assert refusal in out, refusal
    # a student logged in on the hub's page reaches lesson 00 with the arm drawn, and it moves
    assert "browser: the hub's log-in page as s01, then /user/s01/lab lists the 8 lessons" in out, out[-3000:]
    assert re.search(r"the 3D view /user/s01/proxy/\d+/static/ \(through the lab's port\) draws the arm", out), out[-3000:]
    assert "browser: the motion cell moved the arm" in out, out[-3000:]
    assert "went to the lab's port 127.0.0.1:18000" in out, out[-3000:]
