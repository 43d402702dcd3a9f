"""A warm start for the grader's sandboxes: import the heavy libraries once, fork one sandbox per submission.

Every sandbox used to start a fresh Python, import nbgrader (0.8 s), then start a fresh kernel
that imported ipykernel, numpy, matplotlib, Pinocchio and MuJoCo (1 s) - for each student. The
fork server is one process that imports all of that once (:data:`PRELOAD`; nothing of any course:
no references, tests or gradebook are ever read in it), started by a grading process's first batch
and kept for its later ones (:func:`grader.sandbox.runner.fork_server`). For each submission:

1. the grader sends the sandbox's configuration (the same one :func:`grader.sandbox.namespaces.run` uses)
   and one end of a socket pair over a Unix socket;
2. the server forks a *supervisor*, which starts its own session, sends the log there, makes
   new mount, network and PID namespaces (and a user namespace without root), and forks
3. the sandbox's first process (PID 1 of its namespace, killed if the supervisor dies). It
   builds the private root, drops to the sandbox user with its limits
   (:func:`grader.sandbox.inside.enter.enter`, as the exec'd sandbox does) and runs
   :func:`grader.sandbox.inside.worker.main` in-process, which forks its kernels from itself
   (:mod:`grader.sandbox.inside.warmkernel`).

The supervisor reports its process id, then the sandbox's exit code, on the socket pair; the
grader's deadline kills the supervisor's whole process group, and with it the namespace.
The server is single-threaded and holds no ZeroMQ context or event loop, so forking it is safe.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import json
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from grader.sandbox.namespaces import STOP, TICK
from grader.errors import SandboxError, Stopped

CLONE_NEWNS, CLONE_NEWUSER, CLONE_NEWPID, CLONE_NEWNET = 0x00020000, 0x10000000, 0x20000000, 0x40000000
PR_SET_PDEATHSIG = 1

#: imported once by the server: what the worker and a lesson kernel import at start
#: (``SNAKEKIT_FORKSERVER_PRELOAD``, comma-separated, adds modules a course's lessons need)
PRELOAD = (
    "nbgrader.apps", "nbgrader.coursedir", "nbgrader.converters", "nbgrader.preprocessors",
    "jupyter_client.manager", "ipykernel.kernelapp", "ipykernel.ipkernel", "IPython",
    "ipykernel.debugger", "numpy", "matplotlib.pyplot",
    # not the modules that set up their importer's shell (warmkernel.SET_UP_AT_IMPORT): each kernel imports those
    "snakekit", "snakekit.kinematics", "snakekit.trajectory", "snakekit.sim", "snakekit.plots",
    "snakekit.profile_planner", "snakekit.viewer",
    "grader.sandbox.inside.worker", "grader.sandbox.inside.warmkernel", "grader.sandbox.inside.enter",
    # what each sandbox imported after the fork, about 50 ms of every run: the worker's SQLite gradebook and the
    # kit's kernel client, jupyter_client's and ipykernel's psutil, and what a kernel's shell loads as it starts
    "nbgrader.api", "sqlite3", "sqlalchemy.dialects.sqlite", "psutil", "snakekit.kernel_client", "ipykernel.kernelspec",
    "IPython.core.magics", "IPython.core.debugger", "IPython.core.oinspect", "IPython.extensions.storemagic", "pdb",
)


# --- the server process -----------------------------------------------------------------------


def _preload() -> None:
    import importlib
    import io

    from grader.sandbox.inside.warmkernel import INLINE_BACKEND, shell_modules_loaded

    sys.modules.setdefault("rfc3987_syntax", None)  # see grader.sandbox.inside.worker
    os.environ.setdefault("MPLBACKEND", INLINE_BACKEND)  # matplotlib reads the backend a fresh kernel's reads
    extra = [m for m in os.environ.get("SNAKEKIT_FORKSERVER_PRELOAD", "").split(",") if m]
    for name in (*PRELOAD, *extra):
        importlib.import_module(name)
    if loaded := shell_modules_loaded():
        raise RuntimeError(f"preloading imported {', '.join(loaded)}, which set up the shell that "
                           "imports them: a kernel forked from here would have no figures as pictures, no widgets' "
                           "comm target or no note on a missing name. Leave them to the kernels.")
    from matplotlib.figure import Figure

    fig = Figure()  # load the fonts and the PNG writer once (not through pyplot: no backend is chosen here)
    fig.subplots().plot([0, 1])
    fig.savefig(io.BytesIO(), format="png")
    from sqlalchemy.orm import configure_mappers

    configure_mappers()  # nbgrader's gradebook models, set up at their first query: about 30 ms of every run
    from snakekit.kinematics import workspace_boundary

    workspace_boundary()  # the kit's arm's reach (lru_cache'd; 1 s), drawn by lesson 00's viewer
    from nbformat import v4, validator

    for relax in (False, True):  # the notebook schema, compiled (70 ms) once, not in every sandbox
        validator.get_validator(4, v4.nbformat_minor, relax_add_props=relax)
    if threading.active_count() != 1:
        raise RuntimeError(f"a preloaded module started threads ({threading.enumerate()}); forking would be unsafe")
    # what is loaded now lives until the server ends: the collector leaves it alone from here on, in the
    # server and in every process forked from it (no pages copied for its bookkeeping, collections that
    # scan only the sandbox's own objects), and the server's exit does not sweep it (about 1 s of CPU)
    gc.freeze()


def serve(fd: int) -> None:
    """The server's loop: one fork per request on the control socket ``fd``, until it closes."""
    _preload()
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)  # supervisors are reaped by the kernel
    ctl = _blocking(fd)
    ctl.sendall(b"ready")
    while True:
        msg, fds, _, _ = socket.recv_fds(ctl, 1 << 20, 1)
        if not msg:
            return  # the grader is gone
        if len(fds) != 1:
            for f in fds:
                os.close(f)
            continue
        pid = _fork()
        if pid is None:  # the machine's process limit, for all of FORK_WAIT: this sandbox is not made
            _not_made(msg, fds[0], "fork: [Errno 11] Resource temporarily unavailable (the machine's process "
                      f"limit), still after {FORK_WAIT:g} s")
            continue
        if pid == 0:
            code = 125
            try:
                ctl.close()
                signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                code = _supervise(json.loads(msg), fds[0])
            except BaseException:  # noqa: BLE001 - into the log if it is open, else the server's errors
                import traceback

                traceback.print_exc()
            finally:
                os._exit(code)
        os.close(fds[0])


def _blocking(fd: int) -> socket.socket:
    """The socket over ``fd``, blocking. The grader made it, and a grader process with a default timeout
    (``socket.setdefaulttimeout``, set by a library or a TA's script) makes its sockets non-blocking, the
    flag shared by every copy of the descriptor: the server's first wait for a request then raised
    BlockingIOError and ended it."""
    sock = socket.socket(fileno=fd)
    sock.setblocking(True)
    return sock


#: how long the server tries again to fork a sandbox the machine's process limit refuses (EAGAIN) [s]
FORK_WAIT = 20.0


def _fork(wait: float | None = None) -> int | None:
    """``os.fork()``, tried again while the machine refuses it for now (EAGAIN: its process limit, with
    many kernels and sandboxes alive on a busy machine); None if it still does after ``wait`` s."""
    end = time.monotonic() + (FORK_WAIT if wait is None else wait)
    delay = 0.05
    while True:
        try:
            return os.fork()
        except BlockingIOError:
            if time.monotonic() + delay > end:
                return None
            time.sleep(delay)
            delay = min(2 * delay, 1.0)


def _not_made(msg: bytes, report_fd: int, why: str) -> None:
    """Tell the grader a sandbox was not made (exit 125, which it makes again), with why in the sandbox's log."""
    try:
        with open(json.loads(msg)["log"], "a") as log:
            print(f"sandbox: {why}", file=log)
    except (OSError, ValueError, KeyError, TypeError):
        pass
    with _blocking(report_fd) as report:
        try:
            report.sendall(b"exit 125\n")
        except OSError:
            pass


def _supervise(cfg: dict, report_fd: int) -> int:
    report = _blocking(report_fd)
    os.setsid()
    log = os.open(cfg["log"], os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    null = os.open(os.devnull, os.O_RDONLY)
    for src, dst in ((null, 0), (log, 1), (log, 2)):
        os.dup2(src, dst)
    os.close(null)
    os.close(log)
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    uid, gid = os.getuid(), os.getgid()
    flags = CLONE_NEWNS | CLONE_NEWNET | CLONE_NEWPID | (0 if uid == 0 else CLONE_NEWUSER)
    if libc.unshare(flags) != 0:
        print(f"sandbox: unshare: {os.strerror(ctypes.get_errno())}", file=sys.stderr, flush=True)
        report.sendall(b"exit 125\n")
        return 0
    if uid != 0:  # as `unshare --map-root-user`
        Path("/proc/self/setgroups").write_text("deny")
        Path("/proc/self/uid_map").write_text(f"0 {uid} 1")
        Path("/proc/self/gid_map").write_text(f"0 {gid} 1")
    report.sendall(f"pid {os.getpid()}\n".encode())
    pid = os.fork()
    if pid == 0:  # PID 1 of the new namespace
        from grader.sandbox.inside.warmkernel import exit_child  # preloaded: already imported

        def sandbox() -> int:
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)  # the supervisor only waits for it
            report.close()
            from grader.sandbox.inside import enter
            from grader.sandbox.inside import worker

            try:
                enter.enter(cfg)
            except Exception as e:  # noqa: BLE001 - as the exec'd sandbox: status 125
                print(f"sandbox: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
                return 125
            os.environ.clear()
            os.environ.update(cfg["env"])
            return worker.main(cfg["argv"][3:], warm=True)
        exit_child(sandbox)
    try:
        ended = os.pidfd_open(pid)  # readable when the sandbox ends (Linux 5.3)
    except (AttributeError, OSError):
        ended = None
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        # the grader only reads this socket: readable means it closed, the grader is gone (killed with
        # SIGKILL, say), and nobody will wait for this sandbox or kill it at its deadline: end it now
        ready = select.select([report] + ([ended] if ended is not None else []), [], [], 0.05 if ended is None else None)[0]
        if report in ready:
            os.kill(pid, signal.SIGKILL)  # PID 1 of the namespace: every process in it goes too
            os.waitpid(pid, 0)
            return 0
    report.sendall(f"exit {os.waitstatus_to_exitcode(status)}\n".encode())
    return 0


# --- the grader's side ------------------------------------------------------------------------


class ForkServer:
    """A warm fork server (one per grading process: :func:`grader.sandbox.runner.fork_server`); :meth:`run` is
    :func:`grader.sandbox.namespaces.run` through it (thread-safe)."""

    def __init__(self, env: dict, *, start_timeout: float = 120.0):
        """Start the server; :meth:`wait_ready` before the first :meth:`run`."""
        self._lock = threading.Lock()
        self._env = env
        self._start_timeout = start_timeout
        self.restarts = 0
        self._start()

    def _start(self) -> None:
        self._ready = False
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        theirs.set_inheritable(True)
        self._ctl = ours
        self._errors = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "grader.sandbox.forkserver", str(theirs.fileno())], env=self._env,
            cwd=str(Path(__file__).resolve().parents[2]), pass_fds=(theirs.fileno(),),
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self._errors)
        theirs.close()

    def _last_words(self) -> str:
        """The server's exit status and the last line it wrote, once it has ended."""
        try:
            code = self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            code = self.proc.wait()
        self._errors.seek(0)
        lines = self._errors.read().decode(errors="replace").strip().splitlines()
        why = f"signal {signal.Signals(-code).name}" if code < 0 else f"exit status {code}"
        return why + (f"; its last words: {lines[-1][:300]}" if lines else "")

    def _send(self, cfg: dict, child: socket.socket) -> None:
        """Hand one sandbox to the server. A server that has ended (killed by the system, or out of
        processes) is started again once, and said so on stderr: the batch goes on, no student's
        notebook is lost; a second failure raises SandboxError with what the server said."""
        request = [json.dumps(cfg).encode()], [child.fileno()]
        with self._lock:
            if self._ctl.fileno() < 0:
                raise Stopped("the batch's sandboxes were closed")
            try:
                socket.send_fds(self._ctl, *request)
                return
            except OSError as e:
                if not isinstance(e, (BrokenPipeError, ConnectionError)):
                    raise
            said = self._last_words()
            self._ctl.close()
            self._errors.close()
            print(f"snakekit grade: the grader's fork server ended ({said}); starting it again", file=sys.stderr,
                  flush=True)
            self.restarts += 1
            self._start()
            try:
                self.wait_ready()
                socket.send_fds(self._ctl, *request)
            except (OSError, RuntimeError) as e:
                raise SandboxError(f"the grader's fork server ended ({said}) and did not start again ({e}); "
                                   "nothing was graded wrong: grade the ungraded students again") from None

    def wait_ready(self) -> "ForkServer":
        """Wait until the server has imported everything (at once when it said so before); raises RuntimeError
        if it could not."""
        if self._ready:
            return self
        self._ctl.settimeout(self._start_timeout)
        try:
            ready = self._ctl.recv(16)
        except OSError:
            ready = b""
        if ready != b"ready":
            self.proc.kill()
            self._errors.seek(0)
            lines = self._errors.read().decode(errors="replace").strip().splitlines()
            self.close()
            raise RuntimeError(f"the grader's fork server did not start: {lines[-1] if lines else 'no message'}")
        self._ctl.settimeout(None)
        self._ready = True
        return self

    @property
    def ready(self) -> bool:
        """Whether the server said it has imported everything."""
        return self._ready

    def alive(self) -> bool:
        """Whether the server can take a sandbox now (neither closed nor ended)."""
        return self._ctl.fileno() >= 0 and self.proc.poll() is None

    def run(self, cfg: dict, wall: float) -> tuple[int | None, bool]:
        """Run one sandbox (``cfg`` as grader.sandbox.namespaces builds it, plus ``log``): (exit code or None, timed out)."""
        mine, child = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self._send(cfg, child)
            child.close()
            deadline = time.monotonic() + wall
            pid, code, buf, stopped = None, None, b"", False
            while code is None:
                left = deadline - time.monotonic()
                if left <= 0 or stopped:
                    break
                mine.settimeout(min(left, TICK))
                try:
                    data = mine.recv(4096)
                except TimeoutError:
                    stopped = STOP.is_set()  # the batch was interrupted: kill it now
                    continue
                if not data:
                    return (-signal.SIGKILL if pid else 125), False  # the supervisor died
                buf += data
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    key, _, value = line.decode().partition(" ")
                    if key == "pid":
                        pid = int(value)
                    elif key == "exit":
                        code = int(value)
            if code is not None:
                return code, False
            if pid:
                try:
                    os.killpg(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                mine.settimeout(30)  # the report socket closes when the supervisor is gone
                try:
                    while mine.recv(4096):
                        pass
                except OSError:
                    pass
            if stopped:
                raise Stopped("the batch was interrupted")
            return None, True
        finally:
            mine.close()

    def close(self) -> None:
        """Stop the server (sandboxes still running finish on their own deadline); safe to call twice."""
        if self._ctl.fileno() < 0:
            return
        self._ctl.close()  # the server reads end-of-file and exits
        if STOP.is_set():  # interrupted: nothing of the server's is worth the wait of its exit
            self.proc.kill()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._errors.close()


if __name__ == "__main__":
    serve(int(sys.argv[1]))
