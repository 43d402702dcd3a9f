"""Shared test helpers.

``need(module)`` imports an optional dependency: outside CI a missing one skips the test,
with ``CI=true`` it fails, so a missing install step can't hide behind a skip.
"""

from __future__ import annotations

import importlib
import os
import shutil
import signal
import socket

import pytest

from snakekit.host import choose_mujoco_gl

choose_mujoco_gl()  # before anything imports MuJoCo: EGL on Linux
IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")

# A runner that starts the suite in the background (`make test &` in a script) starts it with
# SIGINT ignored, and the programs the tests start inherit that: Ctrl-C sent to them would be
# lost. The tests stand for a user at a terminal, so SIGINT gets its usual handler back here
# (a handled signal is reset to the default in a child, an ignored one is not).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def need(module: str):
    """Import ``module`` or skip (fail under CI=true)."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        if IN_CI:
            pytest.fail(f"{module} is missing under CI=true: {e}; `make setup` must install it")
        pytest.skip(f"{module} is not installed: {e}")


def need_program(name: str) -> str:
    """Path of an executable, or skip (fail under CI=true)."""
    path = shutil.which(name)
    if path is None:
        if IN_CI:
            pytest.fail(f"program '{name}' is missing under CI=true; `make setup` must install it")
        pytest.skip(f"program '{name}' is not installed")
    return path


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
