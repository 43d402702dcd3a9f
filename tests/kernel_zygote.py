"""The suite's lesson kernels, forked from a warm process instead of started as ``python -m ipykernel_launcher``.

A fresh lesson kernel spends 1.1 to 1.5 CPU-s starting Python and importing ipykernel, numpy, matplotlib,
Pinocchio and MuJoCo before its notebook's first line does anything; the suite starts about 160 of them
(``conftest.notebook_client``). Each test process starts one server (this file, ``python -m
tests.kernel_zygote SOCKET``) that imports those once, then forks a kernel per request; the child becomes the
kernel exactly as the grader's warm kernels do (:func:`grader.sandbox.inside.warmkernel.become`): its own
session, the environment and folder jupyter_client gives it, ipykernel's ``IPKernelApp`` on the connection file.

:class:`ZygoteKernelManager` is the ``AsyncKernelManager`` of the suite's notebook runs. It forks only a
Python kernel of this interpreter whose environment is the session's in every variable an import may read
(:data:`READ_AT_IMPORT`; otherwise, or for another kernel: the usual subprocess), and the server leaves the
modules that set up their shell at import to the kernel (``grader.sandbox.inside.warmkernel.SET_UP_AT_IMPORT``, as the grader's fork server does), so a kernel forked here and
one started fresh run the same code on the same settings (tests/kit/test_kernel_zygote.py runs a notebook
both ways). The kernel is the server's child, not the test's: :class:`ForkedKernel` gives jupyter_client the
``Popen`` methods it calls, by process id (and start time, so a reused id is never taken for the kernel). The
server ends when the test process that started it ends; a kernel ends when its server does (ipykernel's
parent poller).
"""

from __future__ import annotations

import gc
import importlib
import io
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from jupyter_client.manager import AsyncKernelManager

from grader.sandbox.inside.warmkernel import INLINE_BACKEND, ForkedProcess, shell_modules_loaded

ROOT = Path(__file__).resolve().parents[1]

#: imported once by the server: what a lesson kernel imports as it starts and in its first cells
PRELOAD = (
    "ipykernel.kernelapp", "ipykernel.ipkernel", "ipykernel.debugger", "IPython", "IPython.core.magics",
    "IPython.core.debugger", "IPython.core.oinspect", "IPython.extensions.storemagic", "pdb", "psutil",
    # (the kernel's part ends here)
    "numpy", "matplotlib.pyplot", "snakekit", "snakekit.kinematics",
    "snakekit.trajectory", "snakekit.sim", "snakekit.plots", "snakekit.profile_planner",
    "grader.sandbox.inside.warmkernel",
)

#: the last module of :data:`PRELOAD` that a fresh kernel imports as it starts
KERNEL_PART = "psutil"

#: the variables the server's imports may have read as they ran (the kit's, MuJoCo's, matplotlib's, Python's,
#: the BLAS's, the locale): a test's own value of one makes its kernel a fresh one. Any other (PATH, a grader's
#: variable, JUPYTER_CONFIG_PATH) the forked kernel has as it is asked, as the environment it runs in is that one
READ_AT_IMPORT = ("SNAKEKIT_", "MUJOCO_", "MPL", "PYTHON", "PYOPENGL_", "PYDEVD", "OMP_", "OPENBLAS_", "MKL_",
                  "NUMPY_", "LD_", "IPYTHON", "HOME", "XDG_", "LANG", "LC_", "TZ", "TMPDIR")

#: the session's environment, as the suite started (a test's own changes make its kernels fresh ones)
SESSION_ENV = dict(os.environ)


def _start_time(pid: int) -> str | None:
    """The process's start time (clock ticks after boot), or None when it is gone or a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return None if fields[0] in ("Z", "X") else fields[19]


def _read_all(sock: socket.socket) -> bytes:
    """What the other end sent until it closed its side."""
    data = b""
    while chunk := sock.recv(1 << 16):
        data += chunk
    return data


# --- the server ------------------------------------------------------------------------------------------------


def serve(path: str, owner: int) -> None:
    """Preload, then fork a kernel per request on the socket ``path`` until the process ``owner`` (the test
    process that started this server) is gone."""
    try:
        _serve(path, owner)
    finally:
        shutil.rmtree(os.path.dirname(path), ignore_errors=True)


def _serve(path: str, owner: int) -> None:
    # what ipykernel sets as it starts, before a lesson imports matplotlib: set here before the server does, so
    # matplotlib reads the same backend as in a fresh kernel (the kernel sets it again in its own environment)
    before = dict(os.environ)
    os.environ.setdefault("MPLBACKEND", INLINE_BACKEND)
    for name in PRELOAD:
        importlib.import_module(name)
        if name == "numpy":  # its BLAS's pool of threads, which the BLAS stops and starts again around a fork
            blas_tasks = len(os.listdir("/proc/self/task"))
        if name == KERNEL_PART:
            # what ipykernel's imports set in the environment (PYDEVD_USE_FRAME_EVAL), as a fresh kernel's have by its
            # first cell: given again to each kernel, whose environment is the one it is asked for (what the kit's
            # imports set, as MuJoCo's PYOPENGL_PLATFORM, a fresh kernel sets only when a lesson uses the simulator)
            imported_env = {k: v for k, v in os.environ.items() if before.get(k) != v}
    # what all the imports set (the kit's too, as MuJoCo's PYOPENGL_PLATFORM): the same values in the test's
    # environment leave a kernel forkable, as the test process sets them when it imports the same modules
    Path(path + ".env").write_text(json.dumps({k: v for k, v in os.environ.items() if before.get(k) != v}))
    from matplotlib.figure import Figure

    fig = Figure()  # the fonts and the PNG writer, loaded once (not through pyplot: no backend chosen here)
    fig.subplots().plot([0, 1])
    fig.savefig(io.BytesIO(), format="png")
    # modules that set themselves up for the shell that imports them, at their import: the kernel's shell imports
    # them, as a fresh kernel's does (the server would set up no shell: no figure as a picture, no widget's comm
    # target, no note on a NameError of an answer that did not run)
    preloaded = shell_modules_loaded()
    assert not preloaded, f"{preloaded} would set up no kernel's shell"
    tasks = len(os.listdir("/proc/self/task"))  # threads of C libraries too, which threading does not see
    if threading.active_count() != 1 or tasks != blas_tasks:
        raise RuntimeError(f"a preloaded module started threads ({threading.enumerate()}; {tasks} tasks, "
                           f"{blas_tasks} with numpy's BLAS); forking would be unsafe")
    gc.freeze()
    server = socket.socket(socket.AF_UNIX)
    server.bind(path + ".tmp")
    server.listen(64)
    os.rename(path + ".tmp", path)  # the address appears once it takes connections
    server.settimeout(1.0)
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # the kernels are reaped by the system
    while os.getppid() == owner:  # until the test process is gone (also when it went during the imports)
        try:
            conn, _ = server.accept()
        except socket.timeout:
            continue
        try:
            with conn:
                conn.settimeout(30)
                pid = _fork_kernel(json.loads(_read_all(conn)), imported_env, server, conn)
                conn.sendall(json.dumps({"pid": pid, "start": _start_time(pid)}).encode())
        except Exception as e:  # noqa: BLE001 - a request that failed (a client gone, no fork) ends only itself
            print(f"tests/kernel_zygote.py: a request failed: {e!r}", file=sys.stderr)


def _fork_kernel(req: dict, imported_env: dict, server, conn) -> int:
    from grader.sandbox.inside.warmkernel import become, exit_child

    me = os.getpid()
    sys.stdout.flush()
    sys.stderr.flush()
    pid = os.fork()
    if pid:
        return pid
    signal.signal(signal.SIGCHLD, signal.SIG_DFL)  # the kernel waits for its own subprocesses
    server.close()
    conn.close()
    req["env"] = {**imported_env, **req["env"], "JPY_PARENT_PID": str(me)}  # the kernel ends when the server does
    for name in [m for m in sys.modules if m.split(".")[0] in ("tests", "grader")]:
        del sys.modules[name]  # the suite's and the grader's code are no modules of a lesson's
    import numpy as np

    np.random.seed()  # the legacy global generator, seeded at numpy's import: each kernel its own, as a fresh one

    def kernel() -> int:
        import atexit

        try:
            return become(req)
        finally:  # what a fresh kernel's interpreter does as it exits: wait for its threads, run the atexit functions
            threading._shutdown()  # type: ignore[attr-defined]
            atexit._run_exitfuncs()

    exit_child(kernel)


# --- the test process's side -------------------------------------------------------------------------------------


class ForkedKernel(ForkedProcess):
    """The ``Popen`` methods jupyter_client's local provisioner calls, for a kernel forked by the server: known
    by its id and start time, not waited for (the server's system reaps it, so its exit code is not known here)."""

    def __init__(self, pid: int, start: str | None):
        super().__init__(pid)
        self._start = start
        if start is None:
            self.returncode = 0  # gone before it was looked at

    def poll(self) -> int | None:
        if self.returncode is None and _start_time(self.pid) != self._start:
            self.returncode = 0
        return self.returncode

    def send_signal(self, signum: int) -> None:
        """The signal to the kernel's process group (it leads its own session, as jupyter_client's launcher makes
        it), once it is known to be this kernel."""
        if self.poll() is None:
            try:
                os.killpg(self.pid, signum)
            except ProcessLookupError:
                pass  # it ended between the look and the signal


class _Server:
    """This test process's server, started at its first kernel."""

    lock = threading.Lock()
    path: str | None = None
    imported: dict = {}
    last_fresh = ""  # why the last kernel that was not forked was not
    proc: subprocess.Popen | None = None
    failed = ""

    @classmethod
    def address(cls) -> str | None:
        with cls.lock:
            if cls.path is None and not cls.failed:  # (once failed, fresh kernels for the rest of the process)
                folder = tempfile.mkdtemp(prefix="snakekit-zygote-")
                path = os.path.join(folder, "s")
                cls.proc = subprocess.Popen([sys.executable, "-m", "tests.kernel_zygote", path, str(os.getpid())],
                                            cwd=ROOT, env=SESSION_ENV, stdin=subprocess.DEVNULL, start_new_session=True)
                deadline = time.monotonic() + 120
                while not os.path.exists(path):
                    if cls.proc.poll() is not None or time.monotonic() > deadline:
                        cls.failed = f"the kernel server did not start (exit code {cls.proc.poll()})"
                        cls.proc.kill()
                        print(f"tests/kernel_zygote.py: {cls.failed}; fresh kernels from here on", file=sys.stderr)
                        return None
                    time.sleep(0.05)
                cls.imported = json.loads(Path(path + ".env").read_text())
                cls.path = path
            return None if cls.failed else cls.path


def why_fresh(cmd: list[str], env: dict, imported: dict) -> str:
    """Why this kernel cannot be forked ("" when it can): it must be a Python kernel of this interpreter, in the
    session's environment as far as an import reads it (``imported``: what the server's imports set, which the
    test process may have set too by importing the same modules)."""
    if cmd[1:3] != ["-m", "ipykernel_launcher"] or os.path.abspath(cmd[0]) != os.path.abspath(sys.executable):
        return f"not this Python's ipykernel: {cmd[:3]}"
    keys = {k for k in set(env) | set(SESSION_ENV) if k.startswith(READ_AT_IMPORT)}
    other = sorted(k for k in keys if env.get(k) != SESSION_ENV.get(k) and not (
        k in imported and env.get(k) in (None, imported[k]) and SESSION_ENV.get(k) in (None, imported[k])))
    return f"the environment differs from the session's in {', '.join(other)}" if other else ""


def _fork(path: str, cmd: list[str], env: dict, cwd: str) -> ForkedKernel:
    with socket.socket(socket.AF_UNIX) as s:
        s.settimeout(60)
        s.connect(path)
        s.sendall(json.dumps({"cmd": cmd, "env": env, "cwd": cwd}).encode())
        s.shutdown(socket.SHUT_WR)
        reply = json.loads(_read_all(s))
    return ForkedKernel(reply["pid"], reply["start"])


class ZygoteKernelManager(AsyncKernelManager):
    """``AsyncKernelManager`` that forks its kernel from this test process's warm server when it can."""

    async def _async_launch_kernel(self, kernel_cmd: list[str], **kw) -> None:
        prov = self.provisioner
        cmd = [os.path.expanduser(s) for s in kernel_cmd]
        env = dict(kw.get("env") or os.environ)
        path = _Server.address() if type(prov).__name__ == "LocalProvisioner" else None
        why = why_fresh(cmd, env, _Server.imported) if path else (_Server.failed or "another provisioner")
        if why:
            _Server.last_fresh = why
            return await super()._async_launch_kernel(kernel_cmd, **kw)
        cwd = str(kw.get("cwd") or os.getcwd())
        try:
            process = _fork(path, cmd, env, cwd)
        except (OSError, ValueError) as e:  # the server is gone or said nothing: fresh kernels from here on
            _Server.failed = f"the kernel server did not answer ({e!r})"
            print(f"tests/kernel_zygote.py: {_Server.failed}; fresh kernels from here on", file=sys.stderr)
            return await super()._async_launch_kernel(kernel_cmd, **kw)
        # no process group for the provisioner: it would signal the group by its id alone (os.killpg), which the
        # system may have given to another process once the kernel ended; ForkedKernel looks first
        prov.process, prov.pid, prov.pgid, prov.cwd = process, process.pid, None, cwd
        self._reconcile_connection_info(prov.connection_info)


if __name__ == "__main__":
    serve(sys.argv[1], int(sys.argv[2]))
