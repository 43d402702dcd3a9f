"""One lab session per course and per arm: locks the operating system lets go of when a session ends.

A session holds two ``flock`` locks while it runs: the course's, ``<course>/lab/.session.lock``,
and the arm's, a file named after the arm in :func:`lock_dir` (the same folder for every user
of the machine). The kernel releases a ``flock`` when the process holding it ends in any way
(a crash, ``kill -9``, a power cut of the process): a dead session never leaves the arm or the
course locked. The files stay; they hold who took the lock last (pid, host, user, start time,
course, assignment, arm), which a second session quotes when it is refused.

The arm is its serial port with symlinks resolved (``/dev/serial/by-id/...`` and
``/dev/ttyUSB0`` are one arm), or a bridge's URL with its host resolved (``socket://localhost:7800``
and ``socket://127.0.0.1:7800`` are one arm). The in-process emulator (``--emulator``) is an arm
of the session's own and takes no arm lock.
"""

from __future__ import annotations

import fcntl
import getpass
import hashlib
import ipaddress
import json
import os
import re
import socket
import stat
import time
from grader.errors import Busy
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import urlsplit

from grader.errors import LabError

#: How long a refused session waits for the holder's details to be written [s] (the holder
#: writes them right after taking the lock).
READ_HOLDER_WAIT = 2.0


def lock_dir() -> Path:
    """The folder of the arms' lock files, the same for every session on the machine:
    ``$SNAKEKIT_LOCK_DIR``, else ``/run/lock/snakekit`` where ``/run/lock`` is open to every
    user, else ``/tmp/snakekit-locks``."""
    given = os.environ.get("SNAKEKIT_LOCK_DIR")
    if given:
        return Path(given)
    try:
        mode = os.stat("/run/lock").st_mode
    except OSError:
        mode = 0
    shared = stat.S_ISDIR(mode) and mode & stat.S_IWOTH and mode & stat.S_ISVTX
    return Path("/run/lock/snakekit") if shared else Path("/tmp/snakekit-locks")


def arm_key(port: str) -> str:
    """The arm a port names, the same for every spelling of it.

    >>> arm_key("socket://LOCALHOST:7800") == arm_key("socket://127.0.0.1:7800")
    True
    """
    if "://" not in port:
        return os.path.realpath(port)
    u = urlsplit(port)
    host = (u.hostname or "").lower()
    try:
        addrs = sorted({a[4][0] for a in socket.getaddrinfo(host, None, proto=socket.IPPROTO_TCP)})
    except (OSError, UnicodeError):
        addrs = []
    if any(ipaddress.ip_address(a.split("%")[0]).is_loopback for a in addrs) or host in _own_names():
        host = "127.0.0.1"
    elif addrs:
        host = addrs[0]
    try:
        where = f"{host}:{u.port}" if u.port is not None else host
    except ValueError:
        where = host
    return f"{u.scheme.lower()}://{where}"


def _own_names() -> set[str]:
    names = {socket.gethostname().lower()}
    try:
        names.add(socket.getfqdn().lower())
    except OSError:
        pass
    return names


def arm_lock_path(port: str) -> Path:
    key = arm_key(port)
    slug = re.sub(r"[^A-Za-z0-9]+", "-", key).strip("-")[-40:]
    return lock_dir() / f"arm-{slug}-{hashlib.sha256(key.encode()).hexdigest()[:12]}.lock"


def course_lock_path(course: Path) -> Path:
    return Path(course) / "lab" / ".session.lock"


def _holder_text(fd: int) -> str:
    deadline = time.monotonic() + READ_HOLDER_WAIT
    while True:
        text = os.pread(fd, 4096, 0).decode("utf-8", "replace")
        if text.strip() or time.monotonic() > deadline:
            return text
        time.sleep(0.05)


def describe(text: str) -> str:
    """A holder's details as one phrase (``pid 812 on lab-pc, user ta1, since ...``)."""
    try:
        h = json.loads(text)
        return (f"pid {h['pid']} on {h['host']}, user {h['user']}, since {h['started']}, running "
                f"{h['assignment']} of the course {h['course']} on the arm {h['arm']}")
    except (ValueError, KeyError, TypeError):
        return "a session whose details are not readable"


def _take(path: Path, what: str, holder: dict, shared_folder: bool) -> int:
    """Open and ``flock`` ``path``, or raise :class:`Busy` naming its holder."""
    try:
        if not path.parent.is_dir():
            path.parent.mkdir(parents=True, exist_ok=True)
            if shared_folder:  # every user's sessions make their lock files here
                try:
                    os.chmod(path.parent, 0o1777)
                except PermissionError:
                    pass  # another user made it at the same moment (and opened it to all)
    except OSError as e:
        raise LabError(f"cannot make the lock folder {path.parent} ({e.strerror or e}): set SNAKEKIT_LOCK_DIR to a "
                       "folder every TA can write to") from e
    try:
        try:
            fd, writable = os.open(path, os.O_RDWR | os.O_CREAT, 0o666), True
        except PermissionError:  # another TA's lock file, not open to all: a lock all the same
            fd, writable = os.open(path, os.O_RDONLY), False
    except OSError as e:
        raise LabError(f"cannot open the lock {path} ({e.strerror or e}): make it writable by every TA "
                       "(chmod 666) or set SNAKEKIT_LOCK_DIR") from e
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        text = _holder_text(fd)
        os.close(fd)
        raise Busy(f"{what} is in use by another lab session ({describe(text)}): wait for it to end, or stop "
                   "it there (its lock goes with it)") from None
    except BaseException:
        os.close(fd)
        raise
    if writable:
        if shared_folder:
            try:
                os.fchmod(fd, 0o666)
            except OSError:
                pass
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(holder).encode(), 0)
    return fd


@contextmanager
def held(course: Path, assignment: str, port: str | None):
    """Hold the course's lock and, for a real arm or a bridge (``port``), the arm's for the block.

    Raises:
        Busy: another session holds either; the message names it.
    """
    arm = arm_key(port) if port else "the emulator"
    holder = {"pid": os.getpid(), "host": socket.gethostname(), "user": _user(),
              "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
              "course": str(Path(course).resolve()), "assignment": assignment, "arm": arm}
    fds = [_take(course_lock_path(course), f"the course {course}", holder, False)]
    try:
        if port:
            fds.append(_take(arm_lock_path(port), f"the arm {port}" + (f" ({arm})" if arm != port else ""),
                             holder, True))
        yield holder
    finally:
        for fd in reversed(fds):
            os.close(fd)  # closing the last descriptor lets go of the flock


def _user() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return str(os.getuid())
