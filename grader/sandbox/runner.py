"""Running one notebook in a sandbox: its private copy of the course, the case socket in its
folder, nbgrader's autograde (:mod:`grader.sandbox.inside.worker`) forked from the process's warm server."""

from __future__ import annotations

import atexit
import os
import secrets
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from pathlib import Path

import nbformat

from snakekit.host import mujoco_gl

from grader.sandbox import namespaces as sandbox


class Runner:
    """Stages and runs the notebooks of one batch (thread-safe: one call per submission)."""

    def __init__(self, course: Path, a, base: Path, *, timeout: float, cell_timeout: float, limits: sandbox.Limits,
                 use_sandbox: bool = True):
        self.course, self.a, self.base = course, a, base
        self.timeout, self.cell_timeout, self.limits = timeout, cell_timeout, limits
        self.use_sandbox = use_sandbox
        self.server = None
        self.cases = None  # the batch's grader.scoring.cases.CaseServer, once drawn

    def stage(self, student: str, src: Path, nbs: dict, tampered: dict) -> Path:
        """A fresh folder with the submission (``src``) as ``course/submitted/<student>/<a>/``, the
        assignment's gradebook template, and the folders the sandbox writes."""
        a = self.a
        work = self.base / secrets.token_hex(8)
        course = work / "course"
        (course / "submitted" / student).mkdir(parents=True)
        shutil.copytree(src, course / "submitted" / student / a.name, symlinks=True,
                        ignore=shutil.ignore_patterns(".ipynb_checkpoints"))
        for name, nb in nbs.items():
            # the notebook as the grader read it: its test cells as released, once each (grader.course.restore;
            # nbgrader refuses a notebook with a grade id twice)
            seen, cells = set(), []
            for cell in nb.cells:
                gid = cell.get("metadata", {}).get("nbgrader", {}).get("grade_id")
                if gid not in seen:
                    cells.append(cell)
                if gid:
                    seen.add(gid)
            dst = course / "submitted" / student / a.name / f"{name}.ipynb"
            dst.unlink(missing_ok=True)
            nbformat.write(nbformat.from_dict({**nb, "cells": cells}), dst)
        for f in a.source_files:
            dst = course / "source" / a.name / f.relative_to(self.course / "source" / a.name)
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(f, dst)
        shutil.copy(self.base / "template.db", course / "gradebook.db")
        (course / "nbgrader_config.py").write_text(
            f"c = get_config()\nc.CourseDirectory.course_id = {a.course_id!r}\n")
        for d in ("handin", "home", "home/.jupyter-runtime"):
            (work / d).mkdir()
        shutil.copytree(self.base / "mplcache", work / "home" / ".mpl")
        return work

    def run(self, work: Path, student: str) -> sandbox.Outcome:
        """Run the staged notebook, with the batch's cases served in its folder while it runs."""
        gate = None
        if self.cases is not None:  # in the sandbox's own folder: it sees the socket at the same path
            # the gate beside the folder, out of the sandbox's view: its worker says which test cell runs
            gate = work.parent / f".{work.name}.gate"
            self.cases.listen(work / "cases.sock", gate=gate if self.use_sandbox else None)
        try:
            return self.execute(work, student, gate=gate if self.use_sandbox else None)
        finally:
            if self.cases is not None:
                self.cases.stop(work / "cases.sock")

    def log(self, work: Path) -> Path:
        """Where the sandbox that runs ``work`` writes what it prints (beside the folder, out of its view)."""
        return work.parent / f".{work.name}.log"

    def not_made(self, work: Path) -> str:
        """Why the sandbox for ``work`` could not be made, in its own words (its ``sandbox: ...`` lines, else
        the last line it printed); "" when it said nothing."""
        try:
            with open(self.log(work), "rb") as f:
                f.seek(max(0, f.seek(0, os.SEEK_END) - 8192))
                lines = f.read().decode("utf-8", "replace").splitlines()
        except OSError:
            return ""
        said = list(dict.fromkeys(line.strip() for line in lines if line.startswith("sandbox:")))  # once each
        last = [line.strip() for line in lines if line.strip()][-1:]
        return "; ".join(said or last)[:500]

    def env(self, work: Path) -> dict:
        venv_bin = str(Path(os.path.abspath(sys.executable)).parent)
        return {"PATH": f"{venv_bin}:/usr/local/bin:/usr/bin:/bin", "HOME": str(work / "home"),
                "SNAKEKIT_HANDIN_DIR": str(work / "handin"), "SNAKEKIT_CASES": str(work / "cases.sock"),
                # no MPLBACKEND: ipykernel gives the kernel matplotlib's inline backend, as in the student's lab (a
                # figure shown without %matplotlib inline is a picture on the page too)
                "MPLCONFIGDIR": str(work / "home" / ".mpl"), "JUPYTER_RUNTIME_DIR": str(work / "home" / ".jupyter-runtime"),
                "IPYTHONDIR": str(work / "home" / ".ipython"), "TMPDIR": "/tmp", "LANG": "C.UTF-8",
                "MUJOCO_GL": mujoco_gl("linux"), "PYTHONDONTWRITEBYTECODE": "1", "OMP_NUM_THREADS": "1",  # sandbox: Linux
                "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MALLOC_ARENA_MAX": "2",
                "PYDEVD_DISABLE_FILE_VALIDATION": "1", "JUPYTER_PLATFORM_DIRS": "1"}

    def execute(self, work: Path, student: str, gate: Path | None = None) -> sandbox.Outcome:
        argv = [os.path.abspath(sys.executable), "-m", "grader.sandbox.inside.worker", str(work / "course"), self.a.name, student,
                f"{self.timeout:g}", f"{self.cell_timeout:g}", str(len(self.a.notebooks))]
        if self.use_sandbox and self.server is not None:
            return sandbox.run_forked(self.server, argv, workdir=work, env=self.env(work), limits=self.limits,
                                      hide=[str(self.course)], log=self.log(work), gate=gate)
        with open(self.log(work), "wb") as log:
            if self.use_sandbox:
                return sandbox.run(argv, workdir=work, env=self.env(work), limits=self.limits,
                                   hide=[str(self.course)], stdout=log, stderr=log, gate=gate)
            t0 = time.monotonic()
            p = subprocess.Popen(argv, cwd=work, env={**self.env(work), "PYTHONPATH": str(sandbox.PACKAGE_ROOT)},
                                 stdout=log, stderr=log, start_new_session=True)
            try:
                p.wait(timeout=self.limits.wall)
                return sandbox.Outcome(p.returncode, False, time.monotonic() - t0)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, 9)
                p.wait()
                return sandbox.Outcome(None, True, time.monotonic() - t0)

    def mpl_cache(self, path: Path) -> None:
        """matplotlib's font list, once a batch (the one the fork server made as it imported matplotlib, else
        built here); each sandbox starts with a copy."""
        made = getattr(self.server, "home", None)
        if made is not None and any((made / "mplcache").glob("fontlist-*.json")):
            shutil.copytree(made / "mplcache", path)
            return
        path.mkdir()
        subprocess.run([sys.executable, "-c", "import matplotlib.font_manager"], env={**os.environ, "MPLCONFIGDIR": str(path)},
                       capture_output=True, timeout=120)

    def start_fork_server(self, base: Path):
        """The process's warm fork server (:func:`fork_server`) for this batch, or None if it cannot start."""
        try:
            return fork_server(self.env)
        except Exception as e:  # noqa: BLE001
            self.no_server(e)
            return None

    def fork_server_ready(self, server):
        """The started server once it has imported everything; None (each sandbox then starts
        Python afresh: slower, same grades) if it could not."""
        if server is None:
            return None
        try:
            return server.wait_ready()
        except Exception as e:  # noqa: BLE001
            self.no_server(e)
            return None

    @staticmethod
    def no_server(e: Exception) -> None:
        warnings.warn(f"grading without the fork server (each submission starts Python afresh): {e}", stacklevel=3)


# --- one warm fork server per process ------------------------------------------------------------
#: The process's warm fork servers, by what they preload. A batch hands its sandboxes to the server an earlier
#: batch of the same process started: a TA's `snakekit grade` (also the one the hub's grading service runs) grades
#: one batch, where the test suite's processes, or a script that calls ``grader.batch.Grader`` more than once, grade
#: many, and each server's imports cost about 2.4 s of CPU. A server reads nothing of any course or batch (each
#: sandbox's folder, environment and limits come with its own request), so one batch's students share nothing
#: with another's through it.
_SERVERS: dict[tuple, object] = {}
_SERVERS_LOCK = threading.Lock()


#: the grader's folders in the temporary root: a batch's (its sandboxes' copies of the course, the gradebook's
#: template) and a fork server's; each holds a stamp of the process that made it (:data:`OWNER`)
FOLDERS = ("snakekit-grade-", "snakekit-forkserver-")
#: the stamp: "<pid> <start time>" (the start time tells a process from a later one given the same pid)
OWNER = ".owner"


def _started(pid: int) -> str:
    """When process ``pid`` started (clock ticks since boot, /proc/<pid>/stat's 22nd field); "" when unknown."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return ""


def _running(pid: int, started: str) -> bool:
    """Whether the process that wrote a stamp still runs (another user's counts as running)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    now = _started(pid)
    return not (started and now and now != started)


def remove_leftovers(root: Path) -> list[Path]:
    """Remove the grader's folders in ``root`` whose process ended without removing them (a `kill -9`, the
    out-of-memory killer, a power cut): they hold copies of students' notebooks. Only this user's folders with
    a stamp are looked at; the folders of a grader that runs are left alone. Returns the removed ones."""
    removed = []
    for path in sorted(p for prefix in FOLDERS for p in Path(root).glob(f"{prefix}*")):
        try:
            if path.is_symlink() or not path.is_dir() or path.stat().st_uid != os.getuid():
                continue
            pid, _, started = (path / OWNER).read_text().strip().partition(" ")
            if _running(int(pid), started):
                continue
        except (OSError, ValueError):   # no stamp yet (being made), or not one of ours
            continue
        shutil.rmtree(path, ignore_errors=True)
        removed.append(path)
    return removed


def grader_folder(prefix: str, root: Path | None = None) -> Path:
    """A new folder of the grader's (``prefix`` one of :data:`FOLDERS`) in ``root`` (default: the temporary
    root), stamped with this process, once the folders of graders that ended without removing theirs are gone."""
    root = Path(root or tempfile.gettempdir())
    remove_leftovers(root)
    path = Path(tempfile.mkdtemp(prefix=prefix, dir=root))
    (path / OWNER).write_text(f"{os.getpid()} {_started(os.getpid())}\n")
    return path


def fork_server(env):
    """This process's running fork server, started (in a folder of its own, ``env(folder)`` its environment)
    when there is none, or the last one ended. Started, not yet ready: ``wait_ready`` before the first sandbox."""
    from grader.sandbox.forkserver import ForkServer

    extra = {k: os.environ[k] for k in ("SNAKEKIT_FORKSERVER_PRELOAD",) if k in os.environ}
    key = (os.path.abspath(sys.executable), extra.get("SNAKEKIT_FORKSERVER_PRELOAD", ""))
    with _SERVERS_LOCK:
        server = _SERVERS.pop(key, None)
        if server is not None and server.alive():
            _SERVERS[key] = server
            return server
        if server is not None:
            _close(server)
        home = grader_folder("snakekit-forkserver-")
        try:
            server = ForkServer({**env(home), "MPLCONFIGDIR": str(home / "mplcache"), **extra})
        except Exception:
            shutil.rmtree(home, ignore_errors=True)
            raise
        server.home = home  # matplotlib's font list, made there as the server imports it
        _SERVERS[key] = server
        return server


def release(server) -> None:
    """After a batch: its server stays for the next one, unless the batch was stopped (Ctrl-C: it is killed, as
    the batch's sandboxes are) or the server did not come up."""
    if server is None:
        return
    if sandbox.STOP.is_set() or not server.ready:
        with _SERVERS_LOCK:
            for key, s in list(_SERVERS.items()):
                if s is server:
                    del _SERVERS[key]
        _close(server)


def _close(server) -> None:
    server.close()
    if getattr(server, "home", None) is not None:
        shutil.rmtree(server.home, ignore_errors=True)


@atexit.register
def _close_all() -> None:
    with _SERVERS_LOCK:
        servers = list(_SERVERS.values())
        _SERVERS.clear()
    for server in servers:
        try:
            _close(server)
        except Exception:  # noqa: BLE001 - the process is ending
            pass
