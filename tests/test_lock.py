"""environment.lock pins everything pyproject.toml declares, with hashes."""

import re
import tomllib
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]


def locked():
    text = (ROOT / "environment.lock").read_text()
    pins = {canonicalize_name(m[1]): Version(m[2]) for m in re.finditer(r"^([A-Za-z0-9_.\-]+)==(\S+) \\$", text, re.M)}
    blocks = re.split(r"\n(?=[A-Za-z0-9])", text)
    unhashed = [b.split("==")[0] for b in blocks if "==" in b and "--hash=sha256:" not in b]
    return pins, unhashed


def declared():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return [Requirement(r) for r in project["dependencies"] + project["optional-dependencies"]["dev"]]


def test_every_declared_dependency_is_pinned_inside_its_range():
    pins, _ = locked()
    for req in declared():
        name = canonicalize_name(req.name)
        assert name in pins, f"{req.name} is declared in pyproject.toml but not locked: run `make lock`"
        assert req.specifier.contains(pins[name], prereleases=True), \
            f"{req.name}=={pins[name]} in the lock does not satisfy '{req}': run `make lock`"


def test_every_pin_has_a_hash():
    pins, unhashed = locked()
    assert len(pins) > 100 and unhashed == []


def test_numpy_2_for_pinocchio_4():
    pins, _ = locked()
    assert pins["numpy"] >= Version("2") and pins["pin"] >= Version("4")


def test_setup_does_nothing_when_the_venv_is_current():
    import subprocess

    r = subprocess.run([str(ROOT / "tools" / "setup")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().endswith(".venv is current")
