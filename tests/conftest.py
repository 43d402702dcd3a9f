"""Shared test helpers.

``need(module)`` imports an optional dependency: outside CI a missing one skips the test,
with ``CI=true`` it fails, so a missing install step can't hide behind a skip.
"""

from __future__ import annotations

import importlib
import os
import shutil
import socket

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
IN_CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


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
