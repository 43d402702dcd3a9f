"""Grade a class: every submission of one assignment, in parallel sandboxes.

For each ``<course>/submitted/<student>/<assignment>/`` the grader

1. reads the notebook (not valid JSON / nbformat -> ``invalid notebook``, nothing runs) and
   compares each autograded test cell with the released one (edited, deleted or duplicated
   -> those cells score 0, status ``tests tampered``);
2. copies the submission into a fresh folder with a gradebook that holds only this
   assignment, and runs nbgrader's ``autograde`` there in a sandbox (:mod:`grader.sandbox`)
   with ``SNAKEKIT_HANDIN_DIR`` set, so the hidden tests hand their results out;
3. scores every test cell in its own process from the hand-ins and the reference
   (:mod:`grader.score`); a test cell without a reference keeps nbgrader's in-kernel result;
4. writes the scores into the course's gradebook (only this process writes it, one
   submission at a time), the executed notebook into ``autograded/``, and the feedback HTML.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import secrets
import shutil
import stat
import sys
import tempfile
import threading
import time
import warnings
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path

import nbformat

from snakekit.errors import SnakekitError
from snakekit.host import mujoco_gl

from . import feedback, sandbox
from .cases import CaseServer, cases_path, draw
from .course import CourseError, course_id, db_url, generate
from .references import REFERENCES, Reference
from .score import ExerciseScore, read_handin, score_exercise

MAX_FILE = 64 << 20  # the largest notebook or hand-in the grader reads back [bytes]
CSV_COLUMNS = ["student", "assignment", "score", "max_score", "status", "raw_score", "late_penalty", "submitted_at",
               "detail"]


class GradingError(SnakekitError):
    """The batch cannot be graded (no such assignment, no gradebook entry, bad course...)."""


@dataclass(frozen=True)
class SubmissionResult:
    """One student's grade: ``status`` is ``graded`` or the reason it went wrong."""

    student: str
    assignment: str
    score: float
    max_score: float
    status: str
    detail: str = ""
    exercises: tuple[ExerciseScore, ...] = ()
    wall: float = 0.0
    feedback: Path | None = None


@dataclass
class _Cell:
    grade_id: str
    notebook: str
    max_score: float
    source: str  # the instructor's, with hidden tests
    cell_type: str


@dataclass
class _Assignment:
    name: str
    notebooks: list[str]
    tests: dict[str, _Cell]  # autograded test cells by grade id
    locked: dict[str, dict]  # every grade/locked/solution cell's released facts, by grade id
    max_score: float = 0.0
    reference: Reference | None = None
    course_id: str = "default_course"
    source_files: list[Path] = field(default_factory=list)


# --- safe reading of what came back from a sandbox --------------------------------------------


def read_inside(root: Path, rel: str, *, limit: int = MAX_FILE) -> bytes | None:
    """Bytes of ``root/rel`` if it is a regular file reached without symlinks, else None.

    The sandbox could leave a symlink to any file the grader can read (a solution, the
    gradebook); nothing is followed.
    """
    path = root
    for part in Path(rel).parts:
        path = path / part
        try:
            st = os.lstat(path)
        except OSError:
            return None
        if stat.S_ISLNK(st.st_mode):
            return None
    if not stat.S_ISREG(st.st_mode) or st.st_size > limit:
        return None
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    with os.fdopen(fd, "rb") as f:
        return f.read(limit + 1)[:limit]


# --- the assignment, from the course's gradebook ----------------------------------------------


def _course_id(course: Path) -> str:
    return course_id(course)


def _db_url(course: Path) -> str:
    return db_url(course)


def ensure_released(course: Path, assignment: str) -> None:
    """Make sure the gradebook knows the assignment (``nbgrader generate_assignment`` if not)."""
    from nbgrader.api import Gradebook, MissingEntry

    if (course / "gradebook.db").exists():
        with Gradebook(_db_url(course), _course_id(course)) as gb:
            try:
                if gb.find_assignment(assignment).notebooks:
                    return
            except MissingEntry:
                pass
    if not (course / "source" / assignment).is_dir():
        raise GradingError(f"no assignment '{assignment}' in {course}/source and none in its gradebook")
    print(f"snakekit grade: '{assignment}' is not in the gradebook yet; running nbgrader generate_assignment",
          file=sys.stderr)
    try:
        generate(course, course, assignment)
    except CourseError as e:
        raise GradingError(str(e)) from e


def load_assignment(course: Path, assignment: str, references: Path | None) -> _Assignment:
    from nbgrader.api import Gradebook, MissingEntry

    ensure_released(course, assignment)
    cid = _course_id(course)
    with Gradebook(_db_url(course), cid) as gb:
        try:
            a = gb.find_assignment(assignment)
        except MissingEntry as e:
            raise GradingError(f"no assignment '{assignment}' in the gradebook") from e
        tests, locked, notebooks = {}, {}, []
        for nb in a.notebooks:
            notebooks.append(nb.name)
            sources = {c.name: c for c in nb.source_cells}
            solution = {c.name for c in nb.solution_cells}
            for g in nb.grade_cells:
                src = sources[g.name]
                if g.cell_type == "code" and g.name not in solution:
                    tests[g.name] = _Cell(g.name, nb.name, float(g.max_score), src.source, g.cell_type)
            for name, src in sources.items():
                locked[name] = {"notebook": nb.name, "locked": bool(src.locked), "source": src.source,
                                "grade": name in {g.name for g in nb.grade_cells}, "solution": name in solution,
                                "cell_type": src.cell_type}
        max_score = float(a.max_score)
    ref = None
    if references is not None and (references / f"{assignment}.npz").exists():
        ref = Reference.load(references / f"{assignment}.npz")
        ref.check_current()
    src_dir = course / "source" / assignment
    files = [p for p in src_dir.rglob("*") if p.is_file() and p.suffix != ".ipynb"
             and ".ipynb_checkpoints" not in p.parts] if src_dir.is_dir() else []
    return _Assignment(assignment, notebooks, tests, locked, max_score, ref, cid, files)


def _template_gradebook(course: Path, a: _Assignment, dest: Path) -> None:
    """A gradebook with this assignment only: no students, no other grades, no free pages."""
    import sqlite3

    from nbgrader.api import Gradebook

    shutil.copy(course / "gradebook.db", dest)
    with Gradebook(f"sqlite:///{dest}", a.course_id) as gb:
        for s in list(gb.students):
            gb.remove_student(s.id)
        for other in list(gb.assignments):
            if other.name != a.name:
                gb.remove_assignment(other.name)
    con = sqlite3.connect(dest)
    con.execute("VACUUM")
    con.close()


# --- checking a submission before it runs -----------------------------------------------------


def _norm(s: str) -> str:
    return "\n".join(line.rstrip() for line in s.splitlines() if line.strip())


def tampered_cells(nb, a: _Assignment, notebook: str) -> dict[str, str]:
    """Test cells (and locked cells) that were edited, deleted, duplicated or un-locked."""
    from nbgrader.utils import compute_checksum

    found: dict[str, list] = {}
    for cell in nb.cells:
        gid = cell.get("metadata", {}).get("nbgrader", {}).get("grade_id")
        if gid:
            found.setdefault(gid, []).append(cell)
    out = {}
    for gid, info in a.locked.items():
        if info["notebook"] != notebook or gid not in a.tests:
            continue
        cells = found.get(gid, [])
        if not cells:
            out[gid] = "deleted"
            continue
        if len(cells) > 1:
            out[gid] = f"duplicated ({len(cells)} copies)"
            continue
        cell = cells[0]
        meta = cell.metadata.nbgrader
        want = _norm(feedback.visible_part(info["source"]))
        if cell.cell_type != info["cell_type"] or not meta.get("locked", False) and info["locked"]:
            out[gid] = "its nbgrader metadata changed"
        elif gid in a.tests and (not meta.get("grade") or float(meta.get("points", -1)) != a.tests[gid].max_score):
            out[gid] = "its points or grade flag changed"
        elif _norm(cell.source) != want and _norm(cell.source) != _norm(info["source"]):
            out[gid] = "edited"
        elif meta.get("checksum") and meta["checksum"] != compute_checksum(cell):
            out[gid] = "its checksum does not match"
    for gid, cells in found.items():
        if gid not in a.locked and any(c.metadata.nbgrader.get("grade") for c in cells):
            out[gid] = "a test cell that the assignment does not have"
    return out


# --- one submission ---------------------------------------------------------------------------


class Grader:
    """Grades every submission of ``assignment`` in ``course``; see :func:`grade`."""

    def __init__(self, course: Path, assignment: str, *, jobs: int | None = None, timeout: float = 120.0,
                 references: Path | None = REFERENCES, memory: int = 4 << 30, progress=None,
                 workroot: Path | None = None, use_sandbox: bool = True, cell_timeout: float | None = None,
                 seed: int | None = None):
        """``timeout``: each notebook's wall clock [s]; ``cell_timeout``: one cell's (default: ``timeout``);
        ``seed``: the batch's hidden cases (default: drawn from ``os.urandom``, printed)."""
        self.course = Path(course).resolve()
        self.assignment = assignment
        self.jobs = jobs or os.cpu_count() or 1
        self.timeout = float(timeout)
        self.cell_timeout = min(float(cell_timeout or timeout), self.timeout)
        self.references = references
        self.limits = sandbox.Limits(wall=self.timeout + 30, cpu=self.timeout * 2 + 30, memory=memory)
        self.progress = progress
        self.workroot = workroot
        self.use_sandbox = use_sandbox
        self.late_plugin = None
        self.server = None
        self.seed = seed
        self.draw = None
        self.cases = None
        self._lock = threading.Lock()

    def students(self) -> list[str]:
        sub = self.course / "submitted"
        if not sub.is_dir():
            return []
        return sorted(p.name for p in sub.iterdir() if (p / self.assignment).is_dir() and not p.name.startswith("."))

    def run(self, students: list[str] | None = None) -> list[SubmissionResult]:
        students = self.students() if students is None else students
        from nbformat.warnings import DuplicateCellId, MissingIDFieldWarning

        # a submission's duplicated or missing cell ids are repaired on reading; nothing for the TA to do
        warnings.filterwarnings("ignore", category=DuplicateCellId)
        warnings.filterwarnings("ignore", category=MissingIDFieldWarning)
        base = Path(tempfile.mkdtemp(prefix="snakekit-grade-", dir=self.workroot))
        os.chmod(base, 0o711)  # the sandbox user may pass through, never list
        server = None
        try:
            self.base = base
            if self.use_sandbox:
                sandbox.check_available()
                server = self._start_fork_server(base)  # it imports for a second while the batch is set up
            self.a = load_assignment(self.course, self.assignment, self.references)
            if cases_path(self.course, self.assignment).is_file():
                self.draw = draw(self.course, self.assignment, self.seed)
                self.cases = CaseServer(self.draw)
                print(f"snakekit grade: {self.assignment}'s hidden cases drawn with seed {self.draw.seed} "
                      f"(--seed {self.draw.seed} draws them again)", file=sys.stderr)
            from nbgrader.preprocessors import AssignLatePenalties

            from .course import _on_path, config

            with _on_path(self.course):  # a plugin module beside the course's config (nbgrader's late.py)
                self.late_plugin = AssignLatePenalties(config=config(self.course))
            # every notebook has its own deadline inside the sandbox; this one is the backstop
            self.limits = dataclasses.replace(self.limits, wall=self.timeout * max(1, len(self.a.notebooks)) + 30)
            _template_gradebook(self.course, self.a, base / "template.db")
            self.server = self._fork_server_ready(server)  # it built matplotlib's font cache in base/mplcache
            if not (base / "mplcache").is_dir():
                self._mpl_cache(base / "mplcache")
            return self._grade_all(students)
        finally:
            if server is not None:
                server.close()
            if self.cases is not None:
                self.cases.close()
            self.server = None
            shutil.rmtree(base, ignore_errors=True)

    def _grade_all(self, students: list[str]) -> list[SubmissionResult]:
        """Sandboxes run ``jobs`` at a time; scoring and feedback run beside them, in this process."""
        results = []
        bar = Progress(len(students), self.progress, self.jobs)
        with ThreadPoolExecutor(self.jobs) as pool, ThreadPoolExecutor(1) as post:
            pending = {pool.submit(self._grade_one, s): s for s in students}
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    s = pending.pop(fut)
                    try:
                        r = fut.result()
                    except Exception as e:  # noqa: BLE001 - one submission never stops the batch
                        r = SubmissionResult(s, self.assignment, 0.0, self.a.max_score, "grader error",
                                             f"{type(e).__name__}: {e}")
                    if callable(r):  # ran: score it and write the feedback, while the next sandbox runs
                        pending[post.submit(r)] = s
                        continue
                    try:
                        self._record(r)  # only this thread writes the gradebook
                    except Exception as e:  # noqa: BLE001
                        raise GradingError(f"cannot write {s}'s grade to the gradebook: {e}") from e
                    results.append(r)
                    bar.update(r.status != "graded")
        bar.close()
        return sorted(results, key=lambda r: r.student)

    def _mpl_cache(self, path: Path) -> None:
        """Build matplotlib's font list once; each sandbox starts with a copy."""
        import subprocess

        path.mkdir()
        subprocess.run([sys.executable, "-c", "import matplotlib.font_manager"], env={**os.environ, "MPLCONFIGDIR": str(path)},
                       capture_output=True, timeout=120)

    def _start_fork_server(self, base: Path):
        """Start the batch's warm fork server (:mod:`grader.forkserver`), or None if it cannot start."""
        from .forkserver import ForkServer

        try:
            extra = {k: os.environ[k] for k in ("SNAKEKIT_FORKSERVER_PRELOAD",) if k in os.environ}
            return ForkServer({**self._env(base), "MPLCONFIGDIR": str(base / "mplcache"), **extra})
        except Exception as e:  # noqa: BLE001
            self._no_server(e)
            return None

    def _fork_server_ready(self, server):
        """The started server once it has imported everything; None (each sandbox then starts
        Python afresh: slower, same grades) if it could not."""
        if server is None:
            return None
        try:
            return server.wait_ready()
        except Exception as e:  # noqa: BLE001
            self._no_server(e)
            return None

    @staticmethod
    def _no_server(e: Exception) -> None:
        warnings.warn(f"grading without the fork server (each submission starts Python afresh): {e}", stacklevel=3)

    def _grade_one(self, student: str):
        """Run one submission's sandbox; returns its result, or (it ran) the call that scores it."""
        t0 = time.monotonic()
        a = self.a
        src = self.course / "submitted" / student / a.name
        nbs, tampered, problems = {}, {}, []
        for name in a.notebooks:
            raw = read_inside(src, f"{name}.ipynb")
            if raw is None:
                path = src / f"{name}.ipynb"
                if path.is_file() and not path.is_symlink() and path.stat().st_size > MAX_FILE:
                    return self._zero(student, "invalid notebook", f"{name}.ipynb is {path.stat().st_size / 2**20:.0f} MB, "
                                      f"more than the {MAX_FILE >> 20} MB the grader reads", t0)
                problems.append(f"{name}.ipynb is missing")
                continue
            try:
                nb = nbformat.reads(raw.decode("utf-8"), as_version=4)
                nbformat.validate(nb)
            except Exception as e:  # noqa: BLE001 - anything that is not a notebook
                msg = str(e).splitlines()[0][:200] if str(e) else type(e).__name__
                return self._zero(student, "invalid notebook", f"{name}.ipynb is not a valid notebook: {msg}", t0)
            nbs[name] = nb
            tampered.update(tampered_cells(nb, a, name))
        if not nbs:  # nothing of the assignment to run: say so, and what the folder does hold
            others = sorted(p.name for p in src.glob("*.ipynb"))
            detail = "; ".join(problems) + (f" (the folder has {', '.join(others)}; `snakekit collect {a.name} --from "
                                            f"<that folder>` finds a renamed notebook by its cells)" if others else
                                            " (no notebook in the folder)")
            return self._zero(student, "missing notebook", detail, t0)
        work = self.base / secrets.token_hex(8)
        course = work / "course"
        (course / "submitted" / student).mkdir(parents=True)
        shutil.copytree(src, course / "submitted" / student / a.name, symlinks=True,
                        ignore=shutil.ignore_patterns(".ipynb_checkpoints"))
        for name, nb in nbs.items():
            if any(why.startswith("duplicated") for why in tampered.values()):
                # nbgrader refuses a notebook with a grade id twice: run it with the first copy only
                # (the duplicated cells score 0 anyway), so the other exercises are still graded
                seen, cells = set(), []
                for cell in nb.cells:
                    gid = cell.get("metadata", {}).get("nbgrader", {}).get("grade_id")
                    if gid not in seen:
                        cells.append(cell)
                    if gid:
                        seen.add(gid)
                dst = course / "submitted" / student / a.name / f"{name}.ipynb"
                dst.unlink()
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
        if self.cases is not None:  # in the sandbox's own folder: it sees the socket at the same path
            self.cases.listen(work / "cases.sock")
        try:
            outcome = self._execute(work, student)
        finally:
            if self.cases is not None:
                self.cases.stop(work / "cases.sock")

        def finish() -> SubmissionResult:
            try:
                return self._collect(work, student, nbs, tampered, problems, outcome, t0)
            finally:
                shutil.rmtree(work, ignore_errors=True)
        return finish

    def _env(self, work: Path) -> dict:
        venv_bin = str(Path(os.path.abspath(sys.executable)).parent)
        return {"PATH": f"{venv_bin}:/usr/local/bin:/usr/bin:/bin", "HOME": str(work / "home"),
                "SNAKEKIT_HANDIN_DIR": str(work / "handin"), "SNAKEKIT_CASES": str(work / "cases.sock"),
                "MPLBACKEND": "Agg",
                "MPLCONFIGDIR": str(work / "home" / ".mpl"), "JUPYTER_RUNTIME_DIR": str(work / "home" / ".jupyter-runtime"),
                "IPYTHONDIR": str(work / "home" / ".ipython"), "TMPDIR": "/tmp", "LANG": "C.UTF-8",
                "MUJOCO_GL": mujoco_gl("linux"), "PYTHONDONTWRITEBYTECODE": "1", "OMP_NUM_THREADS": "1",  # sandbox: Linux
                "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MALLOC_ARENA_MAX": "2",
                "PYDEVD_DISABLE_FILE_VALIDATION": "1", "JUPYTER_PLATFORM_DIRS": "1"}

    def _execute(self, work: Path, student: str) -> sandbox.Outcome:
        argv = [os.path.abspath(sys.executable), "-m", "grader.worker", str(work / "course"), self.a.name, student,
                f"{self.timeout:g}", f"{self.cell_timeout:g}", str(len(self.a.notebooks))]
        if self.use_sandbox and self.server is not None:
            return sandbox.run_forked(self.server, argv, workdir=work, env=self._env(work), limits=self.limits,
                                      hide=[str(self.course)], log=work.parent / f".{work.name}.log")
        with open(work.parent / f".{work.name}.log", "wb") as log:
            if self.use_sandbox:
                return sandbox.run(argv, workdir=work, env=self._env(work), limits=self.limits,
                                   hide=[str(self.course)], stdout=log, stderr=log)
            import subprocess

            t0 = time.monotonic()
            p = subprocess.Popen(argv, cwd=work, env={**self._env(work), "PYTHONPATH": str(sandbox.PACKAGE_ROOT)},
                                 stdout=log, stderr=log, start_new_session=True)
            try:
                p.wait(timeout=self.limits.wall)
                return sandbox.Outcome(p.returncode, False, time.monotonic() - t0)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, 9)
                p.wait()
                return sandbox.Outcome(None, True, time.monotonic() - t0)

    def _collect(self, work, student, nbs, tampered, problems, outcome, t0) -> SubmissionResult:
        a = self.a
        raw = read_inside(work, "result.json", limit=1 << 20)
        try:
            worker = json.loads(raw) if raw else {}
            worker = worker if isinstance(worker, dict) else {}
        except ValueError:
            worker = {}
        executed = {}
        for name in a.notebooks:
            raw = read_inside(work, f"course/autograded/{student}/{a.name}/{name}.ipynb")
            if raw:
                try:
                    executed[name] = nbformat.reads(raw.decode("utf-8"), as_version=4)
                except Exception:  # noqa: BLE001 - a notebook the submission mangled: not used
                    pass
        errors = set()
        for nb in executed.values():
            for cell in nb.cells:
                for out in cell.get("outputs", []):
                    if out.get("output_type") == "error":
                        errors.add(str(out.get("ename")))
        log = str(worker.get("log", "")) + str(worker.get("error", ""))
        scores = []
        for gid, cell in a.tests.items():
            if gid in tampered:
                scores.append(ExerciseScore(gid, 0.0, cell.max_score, "tampered",
                                            f"tests tampered: this test cell was {tampered[gid]}, so it scores 0."))
                continue
            if a.reference is not None and gid in a.reference.exercises:
                raw = read_inside(work, f"handin/{gid}.npz")
                try:
                    handin = read_handin(_bytes_io(raw)) if raw is not None else None
                except ValueError as e:
                    scores.append(ExerciseScore(gid, 0.0, cell.max_score, "inconsistent", f"hand-in unreadable: {e}."))
                    continue
                sc = score_exercise(gid, handin, a.reference, cell.max_score)
                if sc.status == "missing" and handin is None:
                    sc = dataclasses.replace(sc, message=_why_missing(_find_cell(executed.get(cell.notebook), gid),
                                                                      sc.message))
                scores.append(sc)
            else:
                scores.append(self._kernel_score(gid, cell, executed.get(cell.notebook)))
        stopped = _stopped_cells(worker.get("stopped"), executed)
        if outcome.timed_out or stopped:
            status, detail = "timeout", f"the notebook ran longer than {self.timeout:g} s and was stopped"
        elif "CellTimeoutError" in errors:
            status, detail = "timeout", f"a cell ran longer than {self.cell_timeout:g} s and was interrupted"
        elif "MemoryError" in errors or "MemoryError" in log:
            status, detail = "memory limit", f"the notebook used more than {self.limits.memory >> 20} MB"
        elif "DeadKernelError" in log or "kernel died" in log.lower():
            status, detail = "kernel died", "the Python kernel stopped while the notebook ran"
        elif tampered:
            status = "tests tampered"
            detail = "; ".join(f"{g}: {why}" for g, why in sorted(tampered.items()))
        elif not executed:
            last = (str(worker.get("error", "")).strip().splitlines() or ["no result"])[-1][:300]
            status = "kernel died" if outcome.returncode not in (0, 3) else "autograde failed"
            detail = (f"nbgrader stopped (exit {outcome.returncode}): {last}" if status == "autograde failed"
                      else "the notebook's processes stopped before it finished")
        elif problems:
            status, detail = "missing notebook", "; ".join(problems)
        else:
            status, detail = "graded", ""
        score = round(sum(s.score for s in scores), 4)
        result = SubmissionResult(student, a.name, score, a.max_score, status, detail, tuple(scores),
                                  time.monotonic() - t0)
        dest = self.course / "autograded" / student / a.name
        if executed:  # for the TA (formgrader): the notebook as it ran, hidden tests included, with the verdicts
            shutil.rmtree(dest, ignore_errors=True)
            dest.mkdir(parents=True)
            for name, nb in executed.items():
                mine = [s for s in scores if a.tests[s.grade_id].notebook == name]
                nbformat.write(feedback.record(nb, dataclasses.replace(result, exercises=tuple(mine)),
                                               stopped=stopped.get(name), timeout=self.timeout), dest / f"{name}.ipynb")
        return self._feedback(result, nbs, executed, stopped)

    @staticmethod
    def _kernel_score(gid, cell, nb) -> ExerciseScore:
        """No reference: nbgrader's own verdict (the cell ran without an error).

        The error's message is shown only if a visible check raised it; a hidden test's
        message (its inputs, its expected values) stays hidden.
        """
        if nb is None:
            return ExerciseScore(gid, 0.0, cell.max_score, "missing", "the notebook did not finish running.")
        c = _find_cell(nb, gid)
        if c is None:
            return ExerciseScore(gid, 0.0, cell.max_score, "missing", "the test cell is missing.")
        if c.get("execution_count") is None and not c.get("outputs"):
            return ExerciseScore(gid, 0.0, cell.max_score, "missing",
                                 "the test cell did not run: the notebook was stopped before it.")
        err = feedback.cell_error(c)
        if err is None:
            return ExerciseScore(gid, cell.max_score, cell.max_score, "scored", "the test cell passed.")
        ename, evalue, where = err
        if where == "visible":
            msg = f"a visible check failed: {ename}: {evalue}"
        else:
            msg = (f"a hidden test failed ({ename}). Test your code on more cases than the visible checks use: "
                   "other inputs, edge cases.")
        return ExerciseScore(gid, 0.0, cell.max_score, "scored", msg)

    def _zero(self, student, status, detail, t0) -> SubmissionResult:
        scores = tuple(ExerciseScore(g, 0.0, c.max_score, "missing", detail) for g, c in self.a.tests.items())
        r = SubmissionResult(student, self.a.name, 0.0, self.a.max_score, status, detail, scores, time.monotonic() - t0)
        return self._feedback(r, {}, {})

    def _feedback(self, result, submitted, executed, stopped=None) -> SubmissionResult:
        a = self.a
        sources = {g: c.source for g, c in a.tests.items()}
        path = self.course / "feedback" / result.student / a.name
        if path.exists():
            shutil.rmtree(path)
        written = None
        for name in a.notebooks or [a.name]:
            nb = executed.get(name) or submitted.get(name)
            if nb is None:
                nb = nbformat.v4.new_notebook()
            elif name not in executed:
                nb = nbformat.from_dict(nb)
                for c in nb.cells:
                    if c.cell_type == "code":
                        c.outputs = []
            fb = feedback.build(nb, student=result.student, assignment=a.name, result=result, test_sources=sources,
                                stopped=(stopped or {}).get(name), timeout=self.timeout,
                                hide_paths={str(self.base): "<sandbox>"})
            written = feedback.write_html(fb, path / f"{name}.html")
        return SubmissionResult(**{**result.__dict__, "feedback": written})

    # --- the gradebook and autograded/ (called from the main thread only) --------------------

    def _record(self, r: SubmissionResult) -> None:
        from nbgrader.api import Gradebook
        from nbgrader.coursedir import CourseDirectory

        a = self.a
        src = self.course / "submitted" / r.student / a.name
        timestamp = CourseDirectory(root=str(self.course)).get_existing_timestamp(str(src))
        by_id = {e.grade_id: e for e in r.exercises}
        with self._lock, warnings.catch_warnings(), Gradebook(_db_url(self.course), a.course_id) as gb:
            warnings.simplefilter("ignore")  # nbgrader's SQLAlchemy session warnings; nothing to act on
            gb.update_or_create_student(r.student)
            sub = gb.update_or_create_submission(a.name, r.student, **({"timestamp": timestamp} if timestamp else {}))
            for nb in sub.notebooks:
                for grade in nb.grades:
                    if grade.name in by_id:
                        grade.auto_score = by_id[grade.name].score
                        # as nbgrader's autograde: a score a grader entered by hand stays, flagged for review
                        grade.needs_manual_grade = grade.manual_score is not None
                nb.flagged = r.status != "graded"  # formgrader shows the flag: look at this one
            gb.db.commit()
        late_penalties(self.course, a.name, r.student, self.late_plugin)
        fb = self.course / "feedback" / r.student / a.name
        for name in ("timestamp.txt", "submission_secret.txt"):  # what nbgrader's release_feedback reads
            if fb.is_dir() and (src / name).is_file() and not (src / name).is_symlink():
                shutil.copyfile(src / name, fb / name)


def late_penalties(course: Path, assignment: str, student: str, plugin=None) -> None:
    """Each notebook's late penalty, as nbgrader's ``AssignLatePenalties`` (with the course's
    ``LateSubmissionPlugin`` or ``AssignLatePenalties.plugin_class``) sets it in autograde."""
    from nbgrader.preprocessors import AssignLatePenalties

    from .course import _on_path, config

    with _on_path(Path(course)), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pre = plugin or AssignLatePenalties(config=config(course))
        with _throwaway_log(pre):
            for nb in _notebook_names(course, assignment):
                resources = {"nbgrader": {"notebook": nb, "assignment": assignment, "student": student,
                                          "db_url": _db_url(course)}}
                pre.preprocess(nbformat.v4.new_notebook(), resources)


def _notebook_names(course: Path, assignment: str) -> list[str]:
    from .course import gradebook

    with gradebook(course) as gb:
        return [nb.name for nb in gb.find_assignment(assignment).notebooks]


class _throwaway_log:
    """nbgrader's preprocessors log each penalty at warning level; the CSV shows it instead."""

    def __init__(self, pre):
        self.log = pre.log

    def __enter__(self):
        self.level = self.log.level
        self.log.setLevel(50)

    def __exit__(self, *exc):
        self.log.setLevel(self.level)


def _stopped_cells(reported, executed: dict) -> dict[str, int]:
    """Where the worker stopped each notebook whose time ran out: notebook name -> cell index.

    Only a report that points at a cell of a notebook that came back counts (the worker's
    ``result.json`` shows where, never how many points).
    """
    out = {}
    for item in reported if isinstance(reported, list) else []:
        if not isinstance(item, dict):
            continue
        name, index = item.get("notebook"), item.get("cell")
        if isinstance(name, str) and name in executed and isinstance(index, int) \
                and 0 <= index < len(executed[name].cells):
            out[name] = index
    return out


def _find_cell(nb, gid):
    if nb is None:
        return None
    return next((c for c in nb.cells if c.get("metadata", {}).get("nbgrader", {}).get("grade_id") == gid), None)


def _why_missing(cell, message: str) -> str:
    """The reason a test cell handed nothing in, from how it stopped (never a hidden test's words).

    The course's test cells hand in at the start of their hidden part, so a cell that handed
    nothing in stopped before it: in its visible checks, whose message the student would see
    by running the cell. A traceback that points into the hidden part keeps its message.
    """
    err = feedback.cell_error(cell) if cell is not None else None
    if err is None:
        return message
    ename, evalue, where = err
    if where == "hidden":
        return f"nothing was handed in: the test cell stopped in its hidden tests with {ename}."
    return (f"nothing was handed in: the test cell stopped at a visible check, before the hidden tests ran. "
            f"It said: {ename}: {evalue}")


class _bytes_io:  # np.load wants a file; a tiny read-only one over bytes
    def __new__(cls, data: bytes):
        import io

        return io.BytesIO(data)


class Progress:
    """``grading: [#####.....] 12/60 done, 48 left, 3 failed`` on stderr (or a given stream)."""

    def __init__(self, total: int, stream=None, jobs: int = 1):
        self.total, self.done, self.failed = total, 0, 0
        self.stream = stream if stream is not None else sys.stderr
        self.tty = getattr(self.stream, "isatty", lambda: False)()
        self.t0 = time.monotonic()
        self.jobs = jobs
        self._show()

    def _line(self) -> str:
        width = 30
        fill = int(width * self.done / max(self.total, 1))
        rate = (time.monotonic() - self.t0) / self.done if self.done else 0
        return (f"grading [{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total}: done {self.done}, "
                f"left {self.total - self.done}, failed {self.failed}"
                + (f" ({rate:.1f} s per student, {self.jobs} workers)" if self.done else ""))

    def _show(self):
        if self.tty:
            print("\r" + self._line(), end="", file=self.stream, flush=True)
        else:
            print(self._line(), file=self.stream, flush=True)

    def update(self, failed: bool) -> None:
        self.done += 1
        self.failed += bool(failed)
        self._show()

    def close(self):
        if self.tty:
            print(file=self.stream, flush=True)


def class_rows(course: Path, assignment: str, results: list[SubmissionResult] = (), previous: dict | None = None) -> list[dict]:
    """One row per student with a submission of ``assignment`` in the gradebook.

    Scores are the gradebook's (so a score a grader changed in formgrader is there) minus
    nbgrader's late penalty; the status is this run's, else the previous CSV's.
    """
    from .course import gradebook

    now = {r.student: r for r in results}
    previous = previous or {}
    rows = []
    with gradebook(course) as gb:
        a = gb.find_assignment(assignment)
        for sub in sorted(a.submissions, key=lambda s: s.student.id):
            s = sub.student.id
            raw = float(sub.score or 0.0)
            penalty = float(sub.late_submission_penalty or 0.0)
            if s in now:
                status, detail = now[s].status, now[s].detail
            else:
                status, detail = previous.get(s, {}).get("status") or "graded", previous.get(s, {}).get("detail", "")
            manual = [g.name for nb in sub.notebooks for g in nb.grades if g.manual_score is not None]
            if manual and "set by hand" not in detail:
                detail = "; ".join(x for x in (detail, f"score of {', '.join(manual)} set by hand in formgrader") if x)
            rows.append({"student": s, "assignment": assignment, "score": f"{round(raw - penalty, 4):g}",
                         "max_score": f"{float(a.max_score):g}", "status": status, "raw_score": f"{round(raw, 4):g}",
                         "late_penalty": f"{round(penalty, 4):g}",
                         "submitted_at": sub.timestamp.strftime("%Y-%m-%d %H:%M:%S UTC") if sub.timestamp else "",
                         "detail": detail})
    return rows


def read_class_csv(path: Path) -> dict[str, dict]:
    if not Path(path).is_file():
        return {}
    with open(path, newline="", encoding="utf-8-sig") as f:
        return {r["student"]: r for r in csv.DictReader(f) if r.get("student")}


def write_csv(rows: list[dict], path: Path) -> Path:
    """Write the class CSV (to a temporary file first, then in place: never a half-written CSV)."""
    tmp = Path(path).with_name(f".{Path(path).name}.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, CSV_COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in CSV_COLUMNS})
    os.replace(tmp, path)
    return Path(path)
