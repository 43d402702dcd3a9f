"""environment.lock pins everything pyproject.toml declares, with hashes."""

import re
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.system  # the lock against pyproject.toml: not in `make test-quick`
# "name==version \" or, for a package only some systems need, "name==version ; marker \"
ENTRY = re.compile(r"^([A-Za-z0-9_.\-]+)==([^\s;]+)(?: ; ([^\\\n]+))? \\$", re.M)


def locked():
    text = (ROOT / "environment.lock").read_text()
    pins = {canonicalize_name(m[1]): Version(m[2]) for m in ENTRY.finditer(text)}
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


def test_the_lock_is_universal_with_each_systems_packages_under_its_marker():
    """One lock for Linux, macOS and Windows: what ipykernel needs on macOS (appnope), and
    what pytest and the terminal need on Windows (colorama, pywinpty), under their markers."""
    markers = {canonicalize_name(m[1]): m[3] for m in ENTRY.finditer((ROOT / "environment.lock").read_text())}
    assert markers["appnope"] == "sys_platform == 'darwin'"
    assert markers["colorama"] == "sys_platform == 'win32'"
    assert markers["pywinpty"] == "os_name == 'nt'"
    assert markers["numpy"] is None and markers["pin"] is None


def test_the_venv_holds_exactly_what_the_lock_selects_for_this_system():
    """The markers select, for this system and Python, the packages tools/setup installed:
    no more, no fewer, same versions (the universal lock changed nothing on Linux)."""
    import sysconfig
    from importlib import metadata

    from packaging.markers import Marker

    text = (ROOT / "environment.lock").read_text()
    selected = {canonicalize_name(m[1]): Version(m[2]) for m in ENTRY.finditer(text)
                if m[3] is None or Marker(m[3]).evaluate()}
    site = sorted({sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]})  # not setuptools' _vendor
    installed = {canonicalize_name(d.metadata["Name"]): Version(d.version) for d in metadata.distributions(path=site)}
    for own in {"snakekit", "pip", "setuptools"} - selected.keys():  # the kit; what `python -m venv` brings
        installed.pop(own, None)
    assert installed == selected


def test_setup_does_nothing_when_the_venv_is_current():
    import subprocess

    r = subprocess.run([str(ROOT / "tools" / "setup")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().endswith(".venv is current")
