"""The computer the kit runs on: what it supports, and what it lacks for the lessons.

One place decides what differs between Linux, macOS and Windows:

- :func:`choose_mujoco_gl`: MuJoCo's OpenGL back-end. On Linux the kit picks EGL (offscreen,
  no display needed); on macOS and Windows it leaves MuJoCo its own default (CGL on macOS,
  GLFW on Windows), since MuJoCo refuses ``MUJOCO_GL=egl`` there. ``import snakekit`` calls
  it, so it happens before MuJoCo is loaded. A value the user set is kept.
- :func:`missing`: what this system lacks to run the lessons natively, each with what to
  install on this system. ``snakekit start`` (what ``make lab`` runs) prints them.
- :func:`realtime`: the threads that keep the arm's timing (the loop that sends goals to the
  servos, the watchdog's keep-alive, the emulated servos' responder) run under Linux's
  ``SCHED_FIFO`` where the system allows it, so other work on the computer does not delay them.
- :func:`kernel_sockets`: how the kit's own notebook runs (``snakekit check``, the grader's
  instructor run) reach their Jupyter kernel: Unix sockets where the system has them, so two
  kernels started at once never race for a TCP port.

The platform table in README.md says which system runs what; ``tests/system/test_platform.py``
keeps it true. Only the standard library is used here, so the checks run even when the
locked packages are not installed.
"""

from __future__ import annotations

import importlib.util
import os
import sys
from collections.abc import Callable, Iterator, MutableMapping
from contextlib import contextmanager
from dataclasses import dataclass

#: the oldest Python the kit runs on (pyproject.toml's requires-python)
MIN_PYTHON = (3, 11)

#: ``MUJOCO_GL`` values MuJoCo accepts on each system, besides its on/off words
#: (mujoco/rendering/classic/gl_context.py refuses any other value when it is imported)
MUJOCO_GL_VALUES = {"linux": ("glfw", "glx", "egl", "osmesa"), "darwin": ("glfw", "cgl"), "win32": ("glfw", "wgl")}
_MUJOCO_GL_SWITCHES = ("", "enable", "enabled", "on", "true", "1", "disable", "disabled", "off", "false", "0")

#: the Python packages the lessons import, by import name -> distribution name
LESSON_PACKAGES = {"jupyterlab": "jupyterlab", "nbgrader": "nbgrader", "pinocchio": "pin", "mujoco": "mujoco",
                   "meshcat": "meshcat", "ipywidgets": "ipywidgets", "matplotlib": "matplotlib"}

#: Linux shared libraries the locked wheels load from the system -> the Debian package with it
#: (tools/setup installs the same packages): EGL and Mesa for offscreen MuJoCo, GCC's OpenMP
#: and quad-precision run-times for Pinocchio's wheels (quadmath exists on x86 only)
LINUX_LIBRARIES = {"libEGL.so.1": "libegl1", "libEGL_mesa.so.0": "libegl-mesa0", "libGLESv2.so.2": "libgles2",
                   "libgomp.so.1": "libgomp1", "libquadmath.so.0": "libquadmath0"}
_EGL_LIBRARIES = ("libEGL.so.1", "libEGL_mesa.so.0", "libGLESv2.so.2")
_QUADMATH_MACHINES = ("x86_64", "amd64", "i386", "i686", "ppc64le")

CONTAINER = "docker compose -f docker/compose.yaml up lab"
BRIDGE = "snakekit bridge PORT"


@dataclass(frozen=True)
class Need:
    """One thing this system lacks for the lessons, and what to do about it."""

    what: str
    fix: str

    def __str__(self) -> str:
        return f"{self.what}\n  -> {self.fix}"


def _find_spec(name: str):
    """``importlib.util.find_spec``, also for a module already loaded without a spec (the viewer
    loads part of meshcat that way): loaded counts as found."""
    if sys.modules.get(name) is not None:
        return sys.modules[name]
    return importlib.util.find_spec(name)


def system(platform: str | None = None) -> str:
    """``"linux"``, ``"darwin"`` or ``"win32"`` for ``platform`` (default: ``sys.platform``);
    any other system is returned as it is."""
    platform = sys.platform if platform is None else platform
    return "linux" if platform.startswith("linux") else platform


def mujoco_gl(platform: str | None = None) -> str | None:
    """The ``MUJOCO_GL`` the kit picks on ``platform`` (default: this system).

    Returns:
        ``"egl"`` on Linux (offscreen rendering, no display needed); None elsewhere, which
        leaves MuJoCo its own default (CGL on macOS, GLFW on Windows).
    """
    return "egl" if system(platform) == "linux" else None


def choose_mujoco_gl(environ: MutableMapping[str, str] | None = None, *, platform: str | None = None) -> str | None:
    """Set ``MUJOCO_GL`` in ``environ`` (default: ``os.environ``) to :func:`mujoco_gl` unless it
    is set already. Call it before MuJoCo is imported (``import snakekit`` does).

    Returns:
        the ``MUJOCO_GL`` now in ``environ``, or None when MuJoCo picks its own.
    """
    environ = os.environ if environ is None else environ
    chosen = mujoco_gl(platform)
    if chosen is not None:
        environ.setdefault("MUJOCO_GL", chosen)
    return environ.get("MUJOCO_GL")


def machine() -> str:
    """This computer's processor, as ``platform.machine()`` says (``x86_64``, ``arm64``...)."""
    import platform  # only here: `import snakekit` does not need it

    return platform.machine()


def describe(platform: str | None = None, machine_name: str | None = None) -> str:
    """This system in a few words, e.g. ``"macOS arm64"``."""
    name = {"linux": "Linux", "darwin": "macOS", "win32": "Windows"}.get(system(platform), system(platform))
    return f"{name} {machine_name or machine()}"


def loadable(library: str) -> bool:
    """Whether the dynamic loader finds and loads ``library`` (a file name such as
    ``libEGL.so.1``), as it will when a wheel's extension needs it."""
    import ctypes

    try:
        ctypes.CDLL(library)
    except OSError:
        return False
    return True


def _install_python(sysname: str) -> str:
    if sysname == "darwin":
        return ("install Python 3.11 or newer (the installer from python.org, or `brew install python@3.12`), "
                "then `make lab PYTHON=python3.12`")
    if sysname == "linux":
        return ("install Python 3.11 or newer with its venv module (Debian 12, Ubuntu 24.04: "
                "`sudo apt-get install python3 python3-venv`), then `make lab`")
    return f"use the container: `{CONTAINER}`"


def missing(*, platform: str | None = None, machine_name: str | None = None, python: tuple[int, int] | None = None,
            environ: MutableMapping[str, str] | None = None,
            find_spec: Callable[[str], object] | None = None,
            load_library: Callable[[str], bool] = loadable) -> list[Need]:
    """What this system lacks to run the lessons natively (empty when nothing).

    Args:
        platform: ``sys.platform`` of the system to check (default: this one).
        machine_name: ``platform.machine()`` of it (default: this one).
        python: the Python version (default: the running one).
        environ: its environment (default: ``os.environ``).
        find_spec: finds an importable module (default: ``importlib.util.find_spec``, a loaded module counting as found).
        load_library: whether a shared library loads (default: :func:`loadable`; Linux only).
    """
    sysname = system(platform)
    cpu = (machine_name or machine()).lower()
    python = tuple(python or sys.version_info[:2])
    environ = os.environ if environ is None else environ
    needs: list[Need] = []
    if python < MIN_PYTHON:
        needs.append(Need(f"this is Python {python[0]}.{python[1]}; the kit needs {MIN_PYTHON[0]}.{MIN_PYTHON[1]} "
                          "or newer", _install_python(sysname)))
    # packages with no wheels for this system: the locked versions cannot be installed here
    unsupported = set()
    if sysname == "win32":
        unsupported = {"pinocchio"}
        needs.append(Need("Pinocchio publishes no Windows wheels, so the kit does not run natively on Windows",
                          f"use the container (Docker Desktop): `{CONTAINER}`; for the real arm, run "
                          f"`{BRIDGE}` on Windows (docs/hardware.md)"))
    elif sysname == "darwin" and cpu != "arm64":
        unsupported = {"mujoco"}
        needs.append(Need(f"this Python is {cpu}, and MuJoCo publishes macOS wheels for Apple silicon "
                          "(arm64) only",
                          "on an Apple-silicon Mac, use an arm64 Python (python.org's installer, or Homebrew "
                          "in /opt/homebrew) and run `make lab` again; on an Intel Mac, use the container "
                          f"(Docker Desktop): `{CONTAINER}`"))
    elif sysname not in MUJOCO_GL_VALUES:
        needs.append(Need(f"the kit is made for Linux, macOS and the container, not {sysname}",
                          f"use the container: `{CONTAINER}`"))
    gl = environ.get("MUJOCO_GL", "").lower().strip()
    valid = MUJOCO_GL_VALUES.get(sysname)
    if valid is not None and gl not in valid + _MUJOCO_GL_SWITCHES:
        default = {"linux": "EGL", "darwin": "MuJoCo's default, CGL", "win32": "MuJoCo's default, GLFW"}[sysname]
        needs.append(Need(f"MUJOCO_GL={gl} is set, which MuJoCo refuses on {describe(platform, cpu)} "
                          f"(it takes {', '.join(valid)})",
                          f"unset MUJOCO_GL (`unset MUJOCO_GL`); the kit then uses {default}"))
    find_spec = find_spec or _find_spec
    absent = [name for name in LESSON_PACKAGES if name not in unsupported and find_spec(name) is None]
    if absent:
        needs.append(Need("the kit's Python packages are not installed here: "
                          + ", ".join(LESSON_PACKAGES[n] for n in absent),
                          "run `make setup` (tools/setup) in the kit's folder: it installs environment.lock "
                          "into .venv; then start with `make lab` or `.venv/bin/snakekit start`"))
    if sysname == "linux":
        libraries = [n for n in LINUX_LIBRARIES if not n.startswith("libquadmath") or cpu in _QUADMATH_MACHINES]
        if gl != "egl":
            libraries = [n for n in libraries if n not in _EGL_LIBRARIES]
        lacking = [n for n in libraries if not load_library(n)]
        if lacking:
            packages = " ".join(LINUX_LIBRARIES[n] for n in lacking)
            needs.append(Need("these system libraries are missing: " + ", ".join(lacking),
                              f"on Debian or Ubuntu: `sudo apt-get install {packages}` (`make setup` does it "
                              "as root); elsewhere, your distribution's packages of the same libraries"))
    return needs


#: the real-time priority (``SCHED_FIFO``, 1-99) of the threads that keep the arm's timing: low,
#: so the kernel's own real-time threads (interrupts, watchdogs) come first
REALTIME_PRIORITY = 10


@contextmanager
def realtime() -> Iterator[bool]:
    """Run the calling thread under ``SCHED_FIFO`` while the block runs; yields whether it does.

    A thread of the arm's timing (the goals' 100 Hz loop, the watchdog's keep-alive, the
    emulated servos' responder) waits most of the time and works a few milliseconds when it
    wakes; other work on the computer (a browser, a build, a class's notebooks being graded) must
    not hold it back past the Bus Watchdog's 0.5 s or the servos' reply timeout. Under
    ``SCHED_FIFO`` it runs as soon as it wakes. Processes it starts do not inherit the policy
    (``SCHED_RESET_ON_FORK``), and the thread's policy is put back when the block ends.

    Linux only, and only with the right to: root (``CAP_SYS_NICE``), or ``RLIMIT_RTPRIO`` (``ulimit
    -r``, ``rtprio`` in ``/etc/security/limits.conf``) of at least :data:`REALTIME_PRIORITY`.
    Elsewhere nothing changes and it yields False; the kit's timing checks still hold on a quiet
    computer.
    """
    try:
        before = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(REALTIME_PRIORITY))
    except (AttributeError, OSError):  # not Linux, or no right to
        yield False
        return
    try:
        yield True
    finally:
        try:
            os.sched_setscheduler(0, *before)
        except OSError:
            pass


#: the longest path of a Unix socket (108 bytes with its terminating zero on Linux, 104 on macOS),
#: less room for the kernel's "-<n>" suffixes
_SOCKET_PATH_MAX = 96


def kernel_sockets(folder: str | os.PathLike, *, platform: str | None = None) -> dict:
    """The Jupyter kernel manager's settings for a kernel reached over Unix sockets in ``folder``.

    A kernel that listens on TCP gets its five ports from the client, which picks free ones and
    closes them again; the kernel binds them a moment later. Another kernel started in that moment
    (a class graded beside a lesson being checked) can take one, and the first kernel dies before it
    answers ("Kernel died before replying to kernel_info"). Sockets in a folder of the run's own
    have no such race. Pass the result as the notebook client's ``config``
    (``nbclient.NotebookClient(..., config=traitlets.config.Config(kernel_sockets(folder)))``);
    one kernel per folder.

    Returns ``{"KernelManager": {"transport": "ipc", "ip": "<folder>/kernel"}}``; ``{}`` (TCP, as
    Jupyter's default) on Windows, whose ZeroMQ has no Unix sockets, and when ``folder``'s path is
    too long for a socket's.
    """
    ip = os.path.join(os.path.abspath(folder), "kernel")
    if system(platform) == "win32" or len(os.fsencode(ip)) > _SOCKET_PATH_MAX:
        return {}
    return {"KernelManager": {"transport": "ipc", "ip": ip}}
