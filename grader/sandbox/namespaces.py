"""Run one command in a sandbox: its own view of the files, no network, limits, a deadline.

Linux namespaces (``unshare`` from util-linux) give each submission:

* a private root file system built from read-only binds of only what Python needs (the
  system's ``/usr``, ``/etc``, the interpreter, the virtual environment, the ``snakekit`` and
  ``grader`` packages) plus one writable folder, the submission's own copy. The course (with
  its references; the course beside the packages, and the one graded, hidden under an empty
  mount where a bind would show it), the gradebook, the other submissions and the home
  folders do not exist in it. ``/tmp`` and ``/dev/shm`` are small private tmpfs.
* a network namespace with only a loopback interface (the kernel talks to nbgrader over it);
* a PID namespace: when the sandbox's first process ends or is killed, every process the
  submission started dies with it, even those that escaped to a new session;
* a non-root user (``snakekit-grader``, created on first use) when the grader runs as root;
* rlimits: address space (memory), CPU seconds, file size, core dumps off; and a wall-clock
  deadline enforced from outside by killing the whole process group.

Without root, the same is done in an unprivileged user namespace where the system allows
it (the submission then runs under the grader's own uid, but still sees only its copy).
"""

from __future__ import annotations

import contextlib
import json
import os
import pwd
import signal
import subprocess
import sys
import sysconfig
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from snakekit.errors import SnakekitError
from grader.errors import SandboxError, Stopped

USER = "snakekit-grader"
INIT = Path(__file__).resolve().parent / "inside" / "enter.py"
PACKAGE_ROOT = Path(__file__).resolve().parents[2]  # holds snakekit/ and grader/


#: Set when the batch is interrupted (Ctrl-C): every sandbox still running is killed within
#: :data:`TICK` and its run raises :class:`Stopped`; the batch clears it when it starts.
STOP = threading.Event()
#: How often a running sandbox looks at :data:`STOP` [s].
TICK = 0.2


@dataclass(frozen=True)
class Limits:
    """What one submission may use.

    Attributes:
        wall: wall-clock time for the whole notebook [s].
        cpu: CPU time per process [s].
        memory: address space per process [bytes].
        file_size: largest file a process may write [bytes].
        tmp_size: size of the private /tmp [bytes].
    """

    wall: float = 120.0
    cpu: float = 240.0
    memory: int = 4 << 30
    file_size: int = 256 << 20
    tmp_size: int = 64 << 20


#: the exit status of a sandbox that could not be made (its namespaces, mounts or user): nothing of the
#: notebook ran (grader.sandbox.inside.enter, grader.sandbox.forkserver)
NOT_MADE = 125


@dataclass(frozen=True)
class Outcome:
    """How a sandboxed command ended: ``returncode`` (negative: killed by that signal)."""

    returncode: int | None
    timed_out: bool
    wall: float


def ensure_user(name: str = USER) -> tuple[int, int]:
    """The uid and gid of the sandbox user, created (system user, no home, no shell) if missing."""
    try:
        pw = pwd.getpwnam(name)
    except KeyError:
        r = subprocess.run(["useradd", "--system", "--no-create-home", "--home-dir", "/nonexistent",
                            "--shell", "/usr/sbin/nologin", "--user-group", name],
                           capture_output=True, text=True)
        if r.returncode not in (0, 9):  # 9: created meanwhile by another grader
            raise SandboxError(f"cannot create the sandbox user '{name}': {r.stderr.strip()}")
        pw = pwd.getpwnam(name)
    return pw.pw_uid, pw.pw_gid


def _unshare_base() -> list[str]:
    base = ["unshare", "--mount", "--net", "--pid", "--fork", "--kill-child"]
    if os.geteuid() != 0:
        base.insert(1, "--map-root-user")
    return base


def check_available() -> None:
    """Raise :class:`SandboxError` with what to do if namespaces cannot be made here."""
    try:
        r = subprocess.run(_unshare_base() + ["true"], capture_output=True, text=True, timeout=20)
    except FileNotFoundError as e:
        raise SandboxError("the sandbox needs `unshare` (util-linux); install it (apt install util-linux)") from e
    if r.returncode != 0:
        raise SandboxError(f"cannot make Linux namespaces here ({r.stderr.strip()}); run the grader as root, "
                           "or enable unprivileged user namespaces (sysctl kernel.unprivileged_userns_clone=1)")


def default_binds() -> list[str]:
    """Host paths the sandbox sees read-only: the system, the interpreter, the packages."""
    # not /opt as a whole: the grader's image keeps the instructor's course there
    # (/opt/snakekit/course, solutions included); the venv under it is bound as the prefix below
    paths = ["/usr", "/bin", "/sbin", "/lib", "/lib64", "/lib32", "/libx32", "/etc"]
    for p in {sys.base_prefix, sys.prefix, sys.exec_prefix, sysconfig.get_paths()["purelib"]}:
        paths.append(os.path.realpath(p))
    paths += [str(PACKAGE_ROOT / "snakekit"), str(PACKAGE_ROOT / "grader")]
    return [p for p in dict.fromkeys(paths) if os.path.lexists(p)]


def run(argv: list[str], *, workdir: Path, env: dict, limits: Limits, hide: list[str] = (),
        stdout=None, stderr=None, user: str | None = USER, gate: Path | None = None) -> Outcome:
    """Run ``argv`` in a sandbox whose only writable folder is ``workdir`` (same path inside).

    ``hide`` lists host paths to cover with an empty mount even if a bind would show them.
    The call returns when the command ends or ``limits.wall`` passes (then every process
    of the sandbox is killed). ``gate``: a Unix socket outside the sandbox that its first process
    connects to before it drops its privileges (:class:`grader.scoring.cases.CaseServer`); the
    connection is handed to the command as the file descriptor ``SNAKEKIT_GATE_FD``.
    """
    workdir = Path(workdir)
    config = _config(argv, workdir, env, limits, hide, user, gate)
    cfg = workdir.parent / f".{workdir.name}.sandbox.json"  # outside the sandbox's view
    cfg.write_text(json.dumps(config))
    t0 = time.monotonic()
    proc = subprocess.Popen(_unshare_base() + [sys.executable, "-I", "-S", str(INIT), str(cfg)],
                            stdin=subprocess.DEVNULL, stdout=stdout, stderr=stderr, start_new_session=True)
    timed_out = False
    try:
        while proc.poll() is None:  # a Ctrl-C of the batch (STOP) ends the sandbox within a tick
            if STOP.is_set():
                raise Stopped("the batch was interrupted")
            left = limits.wall - (time.monotonic() - t0)
            if left <= 0:
                timed_out = True
                break
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=min(left, TICK))
    finally:
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()
        cfg.unlink(missing_ok=True)
    return Outcome(None if timed_out else proc.returncode, timed_out, time.monotonic() - t0)


def run_forked(server, argv: list[str], *, workdir: Path, env: dict, limits: Limits, log: Path,
               hide: list[str] = (), user: str | None = USER, gate: Path | None = None) -> Outcome:
    """:func:`run`, forked from a warm :class:`grader.sandbox.forkserver.ForkServer`; output goes to ``log``."""
    workdir = Path(workdir)
    config = {**_config(argv, workdir, env, limits, hide, user, gate), "log": str(log)}
    t0 = time.monotonic()
    code, timed_out = server.run(config, limits.wall)
    return Outcome(code, timed_out, time.monotonic() - t0)


def _config(argv, workdir: Path, env: dict, limits: Limits, hide, user, gate=None) -> dict:
    """What the sandbox's first process needs (read by :func:`grader.sandbox.inside.enter.enter`)."""
    uid = gid = None
    if os.geteuid() == 0 and user:
        uid, gid = ensure_user(user)
        _chown_tree(workdir, uid, gid)
    (workdir / ".root").mkdir(exist_ok=True)
    return {
        "root": str(workdir / ".root"),
        "binds": default_binds(),
        "hide": [str(PACKAGE_ROOT / "course"), *map(str, hide)],
        "workdir": str(workdir),
        "uid": uid, "gid": gid,
        "limits": {"as": limits.memory, "cpu": int(limits.cpu), "fsize": limits.file_size,
                   "tmp": limits.tmp_size},
        "argv": list(argv), "env": env, "gate": None if gate is None else str(gate),
    }


def _chown_tree(root: Path, uid: int, gid: int) -> None:
    os.chown(root, uid, gid)
    for dirpath, dirnames, filenames in os.walk(root):
        for n in dirnames + filenames:
            os.chown(os.path.join(dirpath, n), uid, gid, follow_symlinks=False)
