"""Linux, macOS and Windows, checked from Linux: MUJOCO_GL per system, what `snakekit start`
and tools/setup ask for on each, and the README's platform table against a wheel-only
resolution of environment.lock for each system (uv, PyPI's index)."""

from __future__ import annotations

import fnmatch
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from snakekit import host
from tests.conftest import IN_CI, need

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.system  # Linux, macOS and Windows: not in `make test-quick`


def as_if_on(tmp_path: Path, platform: str, machine: str, **env: str) -> dict:
    """An environment whose Pythons report ``platform`` as ``sys.platform`` and ``machine`` as
    ``platform.machine()`` (a sitecustomize), with MUJOCO_GL unset unless given."""
    site = tmp_path / f"site-{platform}-{machine}"
    site.mkdir()
    (site / "sitecustomize.py").write_text(
        f"import platform, sys\nsys.platform = {platform!r}\nplatform.machine = lambda: {machine!r}\n")
    base = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "PYTHONPATH")}
    return {**base, "PYTHONPATH": str(site), **env}


# --- MUJOCO_GL -----------------------------------------------------------------------------------

@pytest.mark.parametrize("platform, expected", [("linux", "egl"), ("darwin", None), ("win32", None)])
def test_egl_on_linux_and_mujocos_own_default_elsewhere(platform, expected):
    env = {}
    assert host.choose_mujoco_gl(env, platform=platform) == expected
    assert env == ({"MUJOCO_GL": "egl"} if expected else {})


def test_a_mujoco_gl_the_user_set_is_kept():
    env = {"MUJOCO_GL": "osmesa"}
    assert host.choose_mujoco_gl(env, platform="linux") == "osmesa" and env == {"MUJOCO_GL": "osmesa"}


def test_importing_the_kit_on_macos_does_not_force_egl(tmp_path):
    """On a system reported as macOS the kit leaves MUJOCO_GL alone (MuJoCo refuses egl there),
    and the simulator still loads and steps."""
    code = ("import os, sys, snakekit, snakekit.sim; from snakekit.sim import SimRobot\n"
            "with SimRobot() as robot:\n"
            "    robot.command([0.3, 0, 0, 0, 0]); robot.step(0.5); q = robot.read().positions[0]\n"
            "print(sys.platform, os.environ.get('MUJOCO_GL'), 'mujoco' in sys.modules, round(q, 2))")
    r = subprocess.run([sys.executable, "-c", code], env=as_if_on(tmp_path, "darwin", "arm64"),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == ["darwin", "None", "True", "0.3"]


# --- what `snakekit start` asks for -------------------------------------------------------------

def start_check(env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "snakekit.cli", "start", "--check"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=60)


def test_start_on_apple_silicon_asks_for_nothing_more(tmp_path):
    r = start_check(as_if_on(tmp_path, "darwin", "arm64"))
    assert r.returncode == 0, r.stderr
    py = ".".join(map(str, sys.version_info[:3]))
    assert r.stdout == (f"snakekit start: this system (macOS arm64, Python {py}, MUJOCO_GL=(MuJoCo default)) "
                        "has what the lessons need\n")


def test_start_on_linux_chooses_egl_and_checks_the_libraries():
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    r = start_check(env)
    assert r.returncode == 0, r.stderr
    assert "(Linux " in r.stdout and "MUJOCO_GL=egl) has what the lessons need" in r.stdout


def test_start_on_an_intel_mac_points_to_the_container(tmp_path):
    r = start_check(as_if_on(tmp_path, "darwin", "x86_64"))
    assert r.returncode == 1
    assert r.stdout == ""
    assert "(macOS x86_64, " in r.stderr
    assert "this Python is x86_64, and MuJoCo publishes macOS wheels for Apple silicon (arm64) only" in r.stderr
    assert "use the container (Docker Desktop): `docker compose -f docker/compose.yaml up lab`" in r.stderr
    assert "apt" not in r.stderr


def test_start_on_macos_refuses_mujoco_gl_egl(tmp_path):
    r = start_check(as_if_on(tmp_path, "darwin", "arm64", MUJOCO_GL="egl"))
    assert r.returncode == 1
    assert ("- MUJOCO_GL=egl is set, which MuJoCo refuses on macOS arm64 (it takes glfw, cgl)\n"
            "  -> unset MUJOCO_GL (`unset MUJOCO_GL`); the kit then uses MuJoCo's default, CGL\n") in r.stderr


def test_start_without_the_lessons_folder_says_so(tmp_path):
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "start", "--check", "--notebooks", str(tmp_path / "no")],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 1
    assert f"- the lessons' folder {tmp_path / 'no'} does not exist\n" in r.stderr


def no_library_lookup(name):
    raise AssertionError(f"looked for {name} on a system that does not need it")


def test_windows_is_pointed_to_the_container_and_the_bridge():
    needs = host.missing(platform="win32", machine_name="AMD64", python=(3, 11), environ={},
                         load_library=no_library_lookup, find_spec=lambda name: object())
    assert [n.what for n in needs] == ["Pinocchio publishes no Windows wheels, so the kit does not run natively "
                                       "on Windows"]
    assert needs[0].fix == ("use the container (Docker Desktop): `docker compose -f docker/compose.yaml up lab`; "
                            "for the real arm, run `snakekit bridge PORT` on Windows (docs/hardware.md)")


def test_macos_needs_no_system_libraries():
    assert host.missing(platform="darwin", machine_name="arm64", python=(3, 11), environ={},
                        load_library=no_library_lookup, find_spec=lambda name: object()) == []


@pytest.mark.parametrize("machine, libraries, packages", [
    ("x86_64", "libEGL.so.1, libgomp.so.1, libquadmath.so.0", "libegl1 libgomp1 libquadmath0"),
    ("aarch64", "libEGL.so.1, libgomp.so.1", "libegl1 libgomp1"),  # no quad-precision library on arm64
])
def test_linux_names_the_debian_packages_of_missing_libraries(machine, libraries, packages):
    absent = {"libEGL.so.1", "libgomp.so.1", "libquadmath.so.0"}
    needs = host.missing(platform="linux", machine_name=machine, python=(3, 11), environ={"MUJOCO_GL": "egl"},
                         find_spec=lambda name: object(), load_library=lambda name: name not in absent)
    assert [n.what for n in needs] == [f"these system libraries are missing: {libraries}"]
    assert needs[0].fix.startswith(f"on Debian or Ubuntu: `sudo apt-get install {packages}`")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the Linux loader")
def test_this_linux_has_the_libraries_it_needs():
    """The real loader on this machine (tools/setup installed the packages): nothing missing."""
    assert host.missing(platform="linux", environ={"MUJOCO_GL": "egl"}) == []


def test_linux_without_egl_does_not_ask_for_the_egl_libraries():
    needs = host.missing(platform="linux", machine_name="x86_64", python=(3, 11), environ={"MUJOCO_GL": "osmesa"},
                         find_spec=lambda name: object(), load_library=lambda name: not name.startswith(("libEGL", "libGLES")))
    assert needs == []


@pytest.mark.parametrize("platform, advice", [
    ("darwin", "install Python 3.11 or newer (the installer from python.org, or `brew install python@3.12`)"),
    ("linux", "`sudo apt-get install python3 python3-venv`"),
])
def test_an_old_python_gets_install_advice_for_its_system(platform, advice):
    needs = host.missing(platform=platform, machine_name="arm64", python=(3, 9), environ={},
                         find_spec=lambda name: object(), load_library=lambda name: True)
    assert [n.what for n in needs] == ["this is Python 3.9; the kit needs 3.11 or newer"]
    assert advice in needs[0].fix


def test_missing_packages_point_to_make_setup():
    needs = host.missing(platform="darwin", machine_name="arm64", python=(3, 11), environ={},
                         find_spec=lambda name: None if name in ("mujoco", "pinocchio") else object())
    assert [n.what for n in needs] == ["the kit's Python packages are not installed here: pin, mujoco"]
    assert needs[0].fix.startswith("run `make setup` (tools/setup) in the kit's folder")


# --- tools/setup on macOS ---------------------------------------------------------------------

def fake_macos_bin(tmp_path: Path) -> Path:
    """A folder for PATH where `uname -s` says Darwin and apt, dpkg leave a trace if called."""
    bin_ = tmp_path / "bin"
    bin_.mkdir()
    (bin_ / "uname").write_text("#!/bin/sh\necho Darwin\n")
    for tool in ("apt-get", "dpkg-query", "dpkg"):
        (bin_ / tool).write_text(f"#!/bin/sh\necho {tool} >> {tmp_path / 'called'}\nexit 1\n")
    for f in bin_.iterdir():
        f.chmod(0o755)
    return bin_


def test_setup_on_macos_installs_no_system_packages(tmp_path):
    env = {**os.environ, "PATH": f"{fake_macos_bin(tmp_path)}:{os.environ['PATH']}"}
    r = subprocess.run([str(ROOT / "tools" / "setup"), "--debian-only"], env=env, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout == "setup: macOS: no system packages needed (no apt); the kit needs only a Python 3.11 or newer\n"
    assert not (tmp_path / "called").exists(), (tmp_path / "called").read_text()


def test_setup_on_macos_with_its_own_python_3_9_says_what_to_install(tmp_path):
    old = tmp_path / "python3.9"  # what macOS's /usr/bin/python3 answers
    old.write_text("#!/bin/sh\necho 3.9\nexit 1\n")
    old.chmod(0o755)
    env = {**os.environ, "PATH": f"{fake_macos_bin(tmp_path)}:{os.environ['PATH']}", "PYTHON": str(old),
           "SNAKEKIT_VENV": str(tmp_path / "venv")}
    r = subprocess.run([str(ROOT / "tools" / "setup")], env=env, capture_output=True, text=True, timeout=60)
    assert r.returncode == 1
    assert r.stderr == (f"setup: the kit needs Python 3.11 or newer; '{old}' is 3.9\n"
                        "setup: install one from python.org (the macOS installer) or with Homebrew "
                        "(brew install python@3.12); then run again with it, e.g.  make lab PYTHON=python3.12\n")
    assert not (tmp_path / "venv").exists() and not (tmp_path / "called").exists()


@pytest.mark.parametrize("arch, quadmath", [("amd64", True), ("arm64", False)])
def test_setup_asks_for_the_quad_precision_library_only_where_debian_has_it(tmp_path, arch, quadmath):
    """libquadmath0 exists for x86 (Pinocchio's x86_64 wheels load it), not for arm64, where the
    container on an Apple-silicon Mac is built: asking apt for it there would fail the build."""
    bin_ = tmp_path / "bin"
    bin_.mkdir()
    (bin_ / "dpkg").write_text(f"#!/bin/sh\necho {arch}\n")
    (bin_ / "dpkg-query").write_text(f"#!/bin/sh\necho \"$3\" >> {tmp_path / 'asked'}\nprintf 'install ok installed'\n")
    for f in bin_.iterdir():
        f.chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_}:{os.environ['PATH']}"}
    r = subprocess.run([str(ROOT / "tools" / "setup"), "--runtime", "--debian-only"], env=env, capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    asked = (tmp_path / "asked").read_text().split()
    assert {"libegl1", "libgomp1", "iproute2"} <= set(asked)
    assert ("libquadmath0" in asked) == quadmath


# --- the README's platform table against the lock ---------------------------------------------

#: README column -> the uv platforms it stands for (macOS from 11, the oldest the wheels ask for)
COLUMNS = {
    "Linux": ["x86_64-manylinux_2_28", "aarch64-manylinux_2_28"],
    "macOS arm64": ["aarch64-apple-darwin"],
    "macOS x86_64": ["x86_64-apple-darwin"],
    "Windows": ["x86_64-pc-windows-msvc"],
    "the container": ["x86_64-manylinux_2_36", "aarch64-manylinux_2_36"],  # Debian bookworm
}
WHEEL_ROW = "locked packages with a wheel"
ENTRY = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)==(\S+)")
NO_WHEEL = re.compile(r"Because (\S+)==\S+ has no (?:usable wheels|wheels with a matching platform tag)")
OFFLINE = re.compile(r"Failed to fetch|error sending request|dns error|failed to lookup|Connection refused|"
                     r"timed out|Could not connect|network", re.I)


def readme_claims() -> dict[str, list[str]]:
    """README column -> the package patterns its wheel row says have no wheel (empty: all do)."""
    lines = (ROOT / "README.md").read_text().split("## Platforms", 1)[1].splitlines()
    rows = [[c.strip() for c in line.strip().strip("|").split("|")] for line in lines if line.startswith("|")]
    header, row = rows[0], next(r for r in rows if r[0].startswith(WHEEL_ROW))
    assert [h.split(" (")[0] for h in header[1:]] == list(COLUMNS), header
    claims = {}
    for column, cell in zip(COLUMNS, row[1:]):
        assert cell.startswith("all"), cell
        claims[column] = re.findall(r"`([^`]+)`", cell.split("(")[0] if cell.startswith("all (") else cell)
    return claims


def uv(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    uv_bin = need("uv").find_uv_bin()
    return subprocess.run([uv_bin, *args], capture_output=True, text=True, timeout=300, env=env)


def unreachable(r: subprocess.CompletedProcess) -> None:
    if OFFLINE.search(r.stderr):
        if IN_CI:
            pytest.fail(f"PyPI's index is not reachable under CI=true:\n{r.stderr}")
        pytest.skip(f"PyPI's index is not reachable: {r.stderr.strip().splitlines()[-1]}")


def resolve(platform: str, tmp_path: Path, exclude=frozenset(), *, deps: bool,
            python: str = "3.11") -> subprocess.CompletedProcess:
    """uv's wheel-only dry-run install of environment.lock (less ``exclude``) for ``platform``,
    hashes required (so a dependency the lock lacks for that system fails it)."""
    blocks = re.split(r"\n(?=[A-Za-z0-9])", (ROOT / "environment.lock").read_text())
    kept = [b for b in blocks if not (ENTRY.match(b) and ENTRY.match(b)[1].lower() in exclude)]
    req = tmp_path / f"{platform}.txt"
    req.write_text("\n".join(kept))
    env = {**os.environ, "MACOSX_DEPLOYMENT_TARGET": "11.0"}
    return uv("pip", "install", "--dry-run", "--require-hashes", "--only-binary", ":all:", *([] if deps else ["--no-deps"]),
              "--python-platform", platform, "--python-version", python, "--python", sys.executable,
              "--target", str(tmp_path / "target"), "-r", str(req), env=env)


def without_wheels(platform: str, tmp_path: Path) -> set[str]:
    """The locked packages (for ``platform``'s markers) with no wheel for ``platform``: uv
    names one at a time, so each is set aside and the rest resolved again."""
    missing: set[str] = set()
    while True:
        r = resolve(platform, tmp_path, missing, deps=False)
        if r.returncode == 0:
            return missing
        m = NO_WHEEL.search(" ".join(r.stderr.split()))  # uv wraps its message at its own width
        if m is None:
            unreachable(r)
            pytest.fail(f"uv failed for {platform}:\n{r.stderr}")
        assert m[1].lower() not in missing, r.stderr
        missing.add(m[1].lower())


@pytest.mark.parametrize("column", list(COLUMNS))
def test_the_lock_has_wheels_where_the_platform_table_says(column, tmp_path):
    patterns = readme_claims()[column]
    for platform in COLUMNS[column]:
        missing = without_wheels(platform, tmp_path)
        print(f"{column} ({platform}): no wheel for {', '.join(sorted(missing)) or 'none'}")
        unmatched = sorted(p for p in missing if not any(fnmatch.fnmatch(p, pat) for pat in patterns))
        unused = sorted(pat for pat in patterns if not any(fnmatch.fnmatch(p, pat) for p in missing))
        assert unmatched == [] and unused == [], (
            f"README's platform table, {column}: {platform} has no wheel for {sorted(missing)}; "
            f"the table does not name {unmatched}, and names {unused} which have wheels")
        if not missing:  # the whole lock, with its dependencies, installs from wheels alone
            r = resolve(platform, tmp_path, deps=True)
            unreachable(r)
            assert r.returncode == 0, r.stderr
            assert re.search(r"Would install \d+ packages", r.stderr), r.stderr


def test_the_python_setup_advises_on_a_mac_installs_the_whole_lock_from_wheels(tmp_path):
    """tools/setup and `snakekit start` tell a Mac user to install Python 3.12 (3.11's security
    releases come as source only, without python.org installers): the lock must install there
    from wheels too."""
    advice = host.missing(platform="darwin", machine_name="arm64", python=(3, 9), environ={},
                          find_spec=lambda name: object())[0].fix
    assert "python@3.12" in advice and "python@3.12" in (ROOT / "tools" / "setup").read_text()
    r = resolve("aarch64-apple-darwin", tmp_path, deps=True, python="3.12")
    unreachable(r)
    assert r.returncode == 0, r.stderr
