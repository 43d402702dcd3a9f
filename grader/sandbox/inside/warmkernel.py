"""Kernels forked from a warm process instead of started as a fresh ``python -m ipykernel_launcher``.

A lesson kernel spends about a second starting Python, importing ipykernel, numpy, matplotlib,
Pinocchio and MuJoCo, before the notebook's first line runs. Inside the grader's fork server
those libraries are already imported, so the worker forks its kernels from itself instead:

* :func:`prefork` forks one waiting child per notebook *before* nbgrader starts its event loop
  and ZeroMQ threads (a fork after those would copy a half-shared event loop and sockets);
* :class:`WarmKernelManager` is the ``AsyncKernelManager`` nbgrader uses, with the launch step
  (``_async_launch_kernel``, the documented place to launch kernels differently) handing the
  kernel command, environment and folder to a waiting child. The child starts its own session,
  takes that environment, and runs ipykernel's ``IPKernelApp`` on the connection file exactly as
  ``ipykernel_launcher`` would. With no waiting child left, the launch is the usual subprocess.

Everything else (the connection file, interrupts, shutdown, the kernel's process group) is
jupyter_client's own: the provisioner gets a process object with ``Popen``'s methods.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from typing import NoReturn

from jupyter_client.manager import AsyncKernelManager

_waiting: list["_WaitingKernel"] = []

#: Modules that set up, as they are imported, the IPython shell that imports them: matplotlib_inline's backend (a
#: figure becomes a picture), ipywidgets (the widgets' comm target), the kit's checks (its note on a NameError of an
#: answer cell that did not run) and widgets. A process that kernels are forked from must not have imported them, or
#: no kernel's shell is set up: each kernel imports them itself, as a fresh kernel does.
SET_UP_AT_IMPORT = ("matplotlib_inline.backend_inline", "ipywidgets", "snakekit.checks", "snakekit.widgets")
#: the backend ipykernel puts in a kernel's environment as it starts (MPLBACKEND), before a lesson imports
#: matplotlib: a process that kernels are forked from sets it before its imports, so matplotlib reads the same
INLINE_BACKEND = "module://matplotlib_inline.backend_inline"


def shell_modules_loaded() -> list[str]:
    """The modules of :data:`SET_UP_AT_IMPORT` this process has imported (none, to fork kernels from it)."""
    return sorted(m for m in SET_UP_AT_IMPORT if m in sys.modules)


def exit_child(body) -> NoReturn:
    """End a forked child with ``body()``'s exit code, never unwinding into the parent's stack.

    ``sys.exit`` gives its code; any other error is printed (to the child's stderr) and exits 1.
    """
    code = 1
    try:
        code = body()
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else 1
    except BaseException:  # noqa: BLE001 - report, then leave
        import traceback

        traceback.print_exc()
        code = 1
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


class ForkedProcess:
    """The ``Popen`` methods jupyter_client's local provisioner calls, for a forked child."""

    stdin = stdout = stderr = None

    def __init__(self, pid: int):
        self.pid = pid
        self.returncode: int | None = None

    def poll(self) -> int | None:
        if self.returncode is None:
            try:
                pid, status = os.waitpid(self.pid, os.WNOHANG)
            except ChildProcessError:
                self.returncode = -signal.SIGKILL  # reaped elsewhere: gone
                return self.returncode
            if pid:
                self.returncode = os.waitstatus_to_exitcode(status)
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        deadline = None if timeout is None else time.monotonic() + timeout
        while self.poll() is None:
            if deadline is not None and time.monotonic() > deadline:
                import subprocess

                raise subprocess.TimeoutExpired(str(self.pid), timeout)
            time.sleep(0.01)
        return self.returncode

    def send_signal(self, signum: int) -> None:
        if self.poll() is None:
            os.kill(self.pid, signum)

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


class _WaitingKernel:
    """A forked child blocked on a pipe until it is told which kernel to become."""

    def __init__(self):
        r, w = os.pipe()
        pid = os.fork()
        if pid == 0:  # the child: wait, then become the kernel; never return into the caller
            def child() -> int:
                os.close(w)
                for other in _waiting:  # the other waiting kernels' pipes are not this kernel's to write
                    os.close(other._pipe)
                _waiting.clear()
                return _become_kernel(r)
            exit_child(child)
        os.close(r)
        self.pid, self._pipe = pid, w

    def launch(self, cmd: list[str], env: dict, cwd: str) -> ForkedProcess:
        os.write(self._pipe, json.dumps({"cmd": cmd, "env": env, "cwd": cwd}).encode())
        os.close(self._pipe)
        return ForkedProcess(self.pid)

    def discard(self) -> None:
        os.close(self._pipe)  # the child reads end-of-file and exits
        ForkedProcess(self.pid).wait(5)


def _become_kernel(pipe: int) -> int:
    chunks = []
    while chunk := os.read(pipe, 1 << 16):
        chunks.append(chunk)
    os.close(pipe)
    from grader.sandbox.inside.case_gate import close_gate

    close_gate()  # the worker's line to the grader stays the worker's
    if not chunks:
        return 0  # not needed
    return become(json.loads(b"".join(chunks)))


def become(req: dict) -> int:
    """Become the kernel ``req`` asks for (``cmd``, ``env``, ``cwd``: what jupyter_client would launch) in this
    freshly forked process: its own session, that environment and folder, then ipykernel's ``IPKernelApp`` as
    ``ipykernel_launcher`` runs it (any other command is exec'd). Returns the kernel's exit code."""
    os.setsid()  # as jupyter_client's launcher: the kernel leads its own process group
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.close(null)
    os.environ.clear()
    os.environ.update(req["env"])
    os.chdir(req["cwd"])
    cmd = req["cmd"]
    if cmd[1:3] != ["-m", "ipykernel_launcher"]:
        os.execvpe(cmd[0], cmd, req["env"])  # not the Python kernel: start it the usual way
    import importlib.util

    # ipykernel read JPY_PARENT_PID when this process imported it, before there was a parent to name
    sys.argv = [importlib.util.find_spec("ipykernel_launcher").origin, *cmd[3:],
                f"--IPKernelApp.parent_handle={req['env'].get('JPY_PARENT_PID', 0)}"]
    # `python -m` put the server's folder first; ipykernel_launcher takes it out, and the kernel's shell puts the
    # notebook's folder ('') back after the standard library: a student's random.py does not hide the library's
    del sys.path[0]
    from ipykernel import kernelapp

    try:
        kernelapp.launch_new_instance()
    except SystemExit as e:
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    return 0


def prefork(n: int) -> None:
    """Fork ``n`` waiting kernels now, while this process has no event loop or ZeroMQ threads; none when it has
    imported a module that sets up its importer's shell (:data:`SET_UP_AT_IMPORT`): kernels then start fresh."""
    if not shell_modules_loaded():
        _waiting.extend(_WaitingKernel() for _ in range(n))


def discard() -> None:
    """Release the waiting kernels that were not used."""
    while _waiting:
        _waiting.pop().discard()


class WarmKernelManager(AsyncKernelManager):
    """``AsyncKernelManager`` that starts its kernel from a waiting fork when there is one."""

    async def _async_launch_kernel(self, kernel_cmd: list[str], **kw) -> None:
        prov = self.provisioner
        if not _waiting or type(prov).__name__ != "LocalProvisioner":
            return await super()._async_launch_kernel(kernel_cmd, **kw)
        env = dict(kw.get("env") or os.environ)
        env["JPY_PARENT_PID"] = str(os.getpid())
        cwd = str(kw.get("cwd") or os.getcwd())
        process = _waiting.pop(0).launch([os.path.expanduser(s) for s in kernel_cmd], env, cwd)
        prov.process, prov.pid, prov.pgid, prov.cwd = process, process.pid, process.pid, cwd
        self._reconcile_connection_info(prov.connection_info)
