"""The worker's line to the grader's case server: which test cell runs now.

The sandbox's first process connects to the grader's gate socket (outside the sandbox, root's
only) before it drops its privileges and hands the connection on as ``SNAKEKIT_GATE_FD``. The
worker says ``open <grade id>`` before a test cell runs and ``close`` after it (each answered
``ok``); the case socket answers only that grade id in between (:class:`grader.scoring.cases.CaseServer`).
The kernel has no way to the gate: it does not inherit the descriptor, and the worker is not
dumpable, so the kernel (the same user) cannot take it through ``/proc`` or ptrace.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import socket

PR_SET_DUMPABLE = 4

_gate = None  # the grader's gate (a file object over the socket), when it gave one
_gate_sock = None


def open_gate() -> None:
    """Take the gate's descriptor out of the environment (the kernels inherit the environment, never
    the descriptor) and make this process undumpable, so no process of the same user reaches it."""
    global _gate, _gate_sock
    fd = os.environ.pop("SNAKEKIT_GATE_FD", None)
    if fd is None:
        return
    ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True).prctl(PR_SET_DUMPABLE, 0, 0, 0, 0)
    sock = socket.socket(fileno=int(fd))
    os.set_inheritable(sock.fileno(), False)
    _gate, _gate_sock = sock.makefile("rwb", buffering=0), sock


def close_gate() -> None:
    """In a forked kernel: the gate is the worker's, never the kernel's."""
    global _gate, _gate_sock
    if _gate_sock is not None:
        os.close(_gate_sock.detach())  # this process's copy, inherited by fork; nothing left to close later
    _gate = _gate_sock = None


def say(word: str) -> None:
    """Tell the grader which test cell runs (``open <grade id>``) or that none does (``close``)."""
    if _gate is None:
        return
    try:
        _gate.write(word.encode() + b"\n")
        _gate.readline()  # "ok": the grader has switched before the cell runs
    except OSError:
        pass
