"""Grade a class: every submission of one assignment, in parallel sandboxes.

For each ``<course>/submitted/<student>/<assignment>/`` the grader

1. reads the notebook (not valid JSON / nbformat -> ``invalid notebook``, nothing runs) and
   puts every test cell back as released (edited, deleted, duplicated, un-locked, or its
   metadata stripped by an editor -> run as released, status ``tests restored``, no points
   lost) (:mod:`grader.course.restore`); what still differs from the release scores 0 (``tests
   tampered``, :mod:`grader.course.assignment`);
2. copies the submission into a fresh folder with a gradebook that holds only this
   assignment, and runs nbgrader's ``autograde`` there in a sandbox (:mod:`grader.sandbox.runner`,
   :mod:`grader.sandbox.namespaces`), with the batch's hidden cases served on a socket in that folder
   (:mod:`grader.scoring.cases`) and ``SNAKEKIT_HANDIN_DIR`` set, so each test cell hands in its results;
3. scores every test cell in its own process from the hand-ins, case by case, against the
   instructor notebook's results at the same cases: the batch runs it first, in a sandbox like
   the students' (:mod:`grader.scoring.verdict`, :mod:`grader.scoring.score`, :func:`grader.scoring.references.expected`);
4. writes the scores into the course's gradebook (only this process writes it, one
   submission at a time), the executed notebook into ``autograded/``, and then the feedback HTML
   from the gradebook, a score set by hand and the late penalty included
   (:mod:`grader.course.gradebook`, :mod:`grader.feedback.scores`).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import sys
import threading
import time
import warnings
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from pathlib import Path

import nbformat

from snakekit import kernel_client
from grader.scoring import rerun
from grader.sandbox import namespaces as sandbox
from grader.sandbox.inside import worker
from grader.course.assignment import MAX_FILE, load_assignment, read_inside, tampered_cells, template_gradebook
from grader.scoring.cases import CaseServer, draw
from grader.errors import CasesError, GradeInterrupted, GradingError, InstructorReferenceError
from grader.files import fitted, uninterrupted
from grader.hooks import NO_HOOKS, BatchHooks
from grader.course.gradebook import NOT_CARRIED, keep_release_files, not_carried, write_grade
from grader.feedback import scores
from grader.scoring.references import course_references, expected
from grader.sandbox.runner import Runner, grader_folder, release
from grader.scoring.verdict import (SubmissionResult, Verdicts, busy_machine, check_faults, first_run_fault,
                                    is_fault, real_time)
from grader.scoring.score import read_handin
from grader.scoring.wording import signatures
from grader.course.restore import release_order, restore

#: The student id the instructor notebook runs under in its sandbox (never a row of the gradebook).
INSTRUCTOR = "_instructor_reference"


#: One cell's default share of the notebook's wall clock. The slowest cells of the course take about 6 s
#: each on a loaded 2-core machine without their hidden cases (lesson 07's 7.2 check, whose moves run on
#: the bus emulator in real time, and lesson 06's Task 2 run), two to three times that with them; a
#: third of the default 120 s (40 s) holds them, and a cell that runs away is interrupted with two
#: thirds of the notebook's time left for the exercises after it.
CELL_SHARE = 1 / 3


class Grader:
    """Grades every submission of ``assignment`` in ``course``; see :func:`grade`."""

    def __init__(self, course: Path, assignment: str, *, jobs: int | None = None, timeout: float = 120.0,
                 references: Path | None = None, memory: int = 4 << 30, progress=None,
                 workroot: Path | None = None, use_sandbox: bool = True, cell_timeout: float | None = None,
                 seed: int | None = None, retry_timeouts: bool = True, hooks: BatchHooks = NO_HOOKS,
                 new_attempts=frozenset()):
        """``timeout``: each notebook's wall clock [s]; ``cell_timeout``: one cell's (default: a third of
        ``timeout``, :data:`CELL_SHARE`: a runaway cell is interrupted and the exercises after it still run);
        ``references``: the folder of the instructor's references (default: the course's, ``<course>/references/``);
        ``seed``: the batch's hidden cases (default: drawn from ``os.urandom``, printed);
        ``retry_timeouts``: a submission stopped by a clock runs once more before the timeout counts;
        ``hooks``: what an optional part adds (the arm's lab: :data:`grader.arm.keep.HOOKS`, given by the command);
        ``new_attempts``: the students whose notebooks changed since they were graded (a resubmission): a score
        set by hand on the earlier attempt is not carried over (:func:`grader.course.gradebook.write_grade`)."""
        self.course = Path(course).resolve()
        self.assignment = assignment
        self.hooks = hooks
        self.jobs = jobs or default_jobs()
        self.timeout = float(timeout)
        self.cell_timeout = min(float(cell_timeout or timeout * CELL_SHARE), self.timeout)
        self.references = references or course_references(self.course)
        self.memory = memory
        self.limits = sandbox.Limits(wall=self.timeout + 30, cpu=self.timeout * 2 + 30, memory=memory)
        self.progress = progress
        self.workroot = workroot
        self.use_sandbox = use_sandbox
        self.seed = seed
        self.retry_timeouts = retry_timeouts
        self.new_attempts = frozenset(new_attempts)
        self.draw = None
        self.late_plugin = None
        self._lock = threading.Lock()
        self.first_runs: dict[str, str] = {}  # student -> why their first run was not the one graded

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
        base = grader_folder("snakekit-grade-", self.workroot)
        os.chmod(base, 0o711)  # the sandbox user may pass through, never list
        self.base = base
        self.runner = Runner(self.course, None, base, timeout=self.timeout, cell_timeout=self.cell_timeout,
                             limits=self.limits, use_sandbox=self.use_sandbox)
        server = None
        try:
            if self.use_sandbox:
                sandbox.check_available()
                server = self.runner.start_fork_server(base)  # it imports for a second while the batch is set up
            self.a = a = load_assignment(self.course, self.assignment, self.references)
            if a.reference is not None:  # the hidden cases of this batch, drawn anew
                try:
                    self.draw = draw(self.course, self.assignment, self.seed)
                    self.draw = self.hooks.cases(self.draw, self.course)  # the lab's case too, kept for `snakekit lab`
                except CasesError as e:
                    raise GradingError(str(e)) from e
                self.runner.cases = CaseServer(self.draw)
                print(f"snakekit grade: {self.assignment}'s hidden cases drawn with seed {self.draw.seed} "
                      f"(--seed {self.draw.seed} draws them again)", file=sys.stderr)
            from nbgrader.preprocessors import AssignLatePenalties

            from grader.course.folder import on_path, config

            with on_path(self.course):  # a plugin module beside the course's config (nbgrader's late.py)
                self.late_plugin = AssignLatePenalties(config=config(self.course))
            # every notebook has its own deadline inside the sandbox; this one is the backstop
            self.limits = dataclasses.replace(self.limits, wall=self.timeout * max(1, len(a.notebooks)) + 30)
            self.runner.a, self.runner.limits = a, self.limits
            self.verdicts = Verdicts(self.course, a, base, timeout=self.timeout, cell_timeout=self.cell_timeout,
                                     memory=self.limits.memory, hooks=self.hooks)
            template_gradebook(self.course, a, base / "template.db")
            self.runner.server = self.runner.fork_server_ready(server)  # it built matplotlib's font cache
            if not (base / "mplcache").is_dir():
                self.runner.mpl_cache(base / "mplcache")
            return self._grade_all(students)
        finally:
            release(server)
            if self.runner.cases is not None:
                self.runner.cases.close()
            self.runner.server = None
            shutil.rmtree(base, ignore_errors=True)

    @property
    def server(self):
        return self.runner.server

    def _grade_all(self, students: list[str]) -> list[SubmissionResult]:
        """Sandboxes run ``jobs`` at a time, the instructor notebook's first; scoring and feedback
        run beside them, in this process, once the instructor's results are in."""
        results, waiting = [], []
        bar = Progress(len(students), self.progress, min(self.jobs, max(len(students), 1)))  # those that run
        sandbox.STOP.clear()
        pending = {}
        try:
            with ThreadPoolExecutor(self.jobs) as pool, ThreadPoolExecutor(1) as post:
                try:
                    self._loop(students, pool, post, pending, results, waiting, bar)
                except KeyboardInterrupt:  # Ctrl-C: the running sandboxes are killed, nothing more runs
                    sandbox.STOP.set()
                    for f in pending:
                        f.cancel()
                    pool.shutdown(wait=False, cancel_futures=True)
                    post.shutdown(wait=False, cancel_futures=True)
                    raise GradeInterrupted(sorted(results, key=lambda r: r.student)) from None
        finally:
            bar.close()
        return sorted(results, key=lambda r: r.student)

    def _loop(self, students, pool, post, pending, results, waiting, bar) -> None:
        """Submit every sandbox, then score and write each result as it comes (``results``)."""
        if self.draw is not None:
            pending[pool.submit(self._run_reference)] = INSTRUCTOR
        else:
            waiting = None  # nothing to wait for
        pending.update({pool.submit(self._grade_one, s): s for s in students})
        while pending:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                s = pending.pop(fut)
                if s == INSTRUCTOR:
                    try:
                        self.verdicts.expected = fut.result()
                        self.verdicts.draw = self.draw
                    except Exception:
                        for f in pending:
                            f.cancel()
                        raise
                    for s2, call in waiting:  # the submissions that ran meanwhile: score them now
                        pending[post.submit(call)] = s2
                    waiting = None
                    continue
                try:
                    r = fut.result()
                except Exception as e:  # noqa: BLE001 - one submission never stops the batch
                    r = SubmissionResult(s, self.assignment, 0.0, self.a.max_score, "grader error",
                                         f"{type(e).__name__}: {e}")
                if isinstance(r, Again):  # a second run (grader.scoring.rerun): a sandbox like the first
                    pending[pool.submit(r)] = s
                    continue
                if callable(r):  # ran: score it and write the feedback, while the next sandbox runs
                    if waiting is not None:
                        waiting.append((s, r))
                    else:
                        pending[post.submit(r)] = s
                    continue
                with uninterrupted():  # a Ctrl-C waits until the student's rows and pages are written whole
                    try:  # only this thread writes
                        dropped = write_grade(self.course, self.a, r, self.late_plugin, self._lock,
                                              new_attempt=s in self.new_attempts)
                    except Exception as e:  # noqa: BLE001
                        raise GradingError(f"cannot write {s}'s grade to the gradebook: {e}") from e
                    if dropped:  # a hand-set score belongs to the attempt it was set on: the TA is told
                        r = dataclasses.replace(r, status=NOT_CARRIED if r.status == "graded" else r.status,
                                                detail="; ".join(x for x in (r.detail, not_carried(dropped)) if x))
                    try:
                        r = self.pages(r)
                    except Exception as e:  # noqa: BLE001 - the grade is in the gradebook; only its page is missing
                        print(f"snakekit grade: {s}: the feedback page was not written ({type(e).__name__}: {e}); "
                              f"`snakekit return {self.a.name}` writes it", file=sys.stderr)
                    results.append(r)
                bar.update(r.status != "graded")

    def pages(self, r: SubmissionResult) -> SubmissionResult:
        """The student's feedback pages, written from the gradebook now that it holds ``r``'s scores
        (:mod:`grader.feedback.scores`): a score set by hand and the late penalty are on them."""
        folder = self.course / "feedback" / r.student / self.a.name
        if folder.exists():
            shutil.rmtree(folder)
        kept = (r.status, r.detail, None, None, list(r.exercises), {})  # for a notebook that never ran
        bases = self.verdicts.pending.pop(r.student, None) or {n: nbformat.v4.new_notebook() for n in self.a.notebooks}
        written = scores.write_pages(self.course, self.a.name, r.student, bases=bases, kept=kept,
                                     hide_paths={str(self.base): "<sandbox>"})
        self.hooks.pages(self.course, self.a.name, r.student)  # the lab's result, when the lab ran the student's sweep
        keep_release_files(self.course, self.a.name, r.student)
        return dataclasses.replace(r, feedback=written[-1] if written else None)

    def _run_reference(self) -> dict:
        """The instructor notebook, run in a sandbox at the batch's cases: the expected results."""
        a = self.a
        src = self.course / "source" / a.name
        where = f"the instructor notebook source/{a.name}/{a.name}.ipynb (run at the cases of seed {self.draw.seed})"
        nbs = {}
        for name in a.notebooks:
            path = src / f"{name}.ipynb"
            if not path.is_file():
                raise GradingError(f"{where}: {path} is missing, so the batch has no expected results")
            nbs[name] = nbformat.read(path, as_version=4)
        for attempt in range(1, REFERENCE_TRIES + 1):
            work, outcome, _ = self._run(INSTRUCTOR, src, nbs, {})
            faults = bus_faults(work, self.draw.cases)
            if not faults:
                break
            if attempt == REFERENCE_TRIES:
                shutil.rmtree(work, ignore_errors=True)
                busy = busy_machine()
                raise GradingError(f"{where}: {faults[0]}, in each of its {REFERENCE_TRIES} runs. That error is "
                                   "the arm's bus's (a reply of the emulated servos came too late, or the port went), "
                                   "never an expected result, so the batch has no expected results; "
                                   + (f"{busy}; " if busy else "") + "nothing was graded")
            print(f"snakekit grade: the instructor notebook's run at the batch's cases: {faults[0]}; a fault of the "
                  "arm's bus, not of the solution (a busy machine makes the emulated servos' replies late): running it "
                  "again", file=sys.stderr, flush=True)
            shutil.rmtree(work, ignore_errors=True)
        try:
            handins = {}
            for gid in self.draw.cases:
                raw = read_inside(work, f"handin/{gid}.npz")
                if raw is not None:
                    handins[gid] = read_handin(raw)
            try:
                return expected(self.a.reference, self.draw, handins, where=where,
                                sources={g: c.source for g, c in a.tests.items()},
                                signatures=signatures(c.source for nb in nbs.values() for c in nb.cells
                                                      if c.cell_type == "code"))
            except InstructorReferenceError as e:
                if outcome.returncode == sandbox.NOT_MADE:
                    detail = (f" (its sandbox could not be made, three times: {self.runner.not_made(work) or 'it said nothing'}"
                              "; nothing of the notebook ran: grade the batch again)")
                else:
                    detail = "" if outcome.returncode == 0 else f" (its sandbox ended with {outcome.returncode}" + \
                        (", timed out" if outcome.timed_out else "") + ")"
                busy = busy_machine() if real_time(a) else ""
                detail += f"; {busy}" if busy else ""
                raise GradingError(f"{e}{detail}; nothing was graded") from e
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def _run(self, student: str, src: Path, nbs: dict, tampered: dict):
        """Stage and run one notebook set in a sandbox: (its folder, how it ended, runs). A busy or
        stuck machine must not cost points: a student's run stopped by a clock, or whose hand-ins hold a fault
        of the arm's bus (:func:`bus_faults`: a reply of the emulated servos came late), is run once more from
        scratch, and only the second run counts (an endless loop costs the batch twice its timeout); why, in
        :attr:`first_runs`, for the TA's line."""
        work, outcome = self._sandboxed(student, src, nbs, tampered)
        late_replies(work, student)
        if not self.retry_timeouts:
            return work, outcome, 1
        first = {}
        if stopped_by_clock(work, outcome, student, self.a):
            why = "was stopped by the clock"
        elif student != INSTRUCTOR and (faults := (bus_faults(work, self.draw.cases) if self.draw is not None else [])
                                        or check_faults(work, student, self.a)):
            why = first_run_fault(faults[0])
            first = handin_results(work, self.draw.cases) if self.draw is not None else {}
        else:
            return work, outcome, 1
        with self._lock:
            self.first_runs[student] = why
        shutil.rmtree(work, ignore_errors=True)
        work, outcome = self._sandboxed(student, src, nbs, tampered)
        mended = mend_faults(handin_results(work, first), first)
        if mended:
            self.verdicts.mend(work, mended)
        return work, outcome, 2

    def _sandboxed(self, student: str, src: Path, nbs: dict, tampered: dict, tries: int = 3):
        """Stage and run one notebook set: (its folder, how it ended). A sandbox that could not be made (its
        namespaces or mounts refused, on a machine short of something for a moment) ran nothing of the
        notebook: it is made again from scratch, at most ``tries`` times in all, and never costs a point."""
        for attempt in range(tries):
            work = self.runner.stage(student, src, nbs, tampered)
            outcome = self.runner.run(work, student)
            if outcome.returncode != sandbox.NOT_MADE or attempt == tries - 1:
                return work, outcome
            said = self.runner.not_made(work)
            print(f"{student}: the sandbox could not be made ({said or 'it said nothing'}); making it again",
                  file=sys.stderr, flush=True)
            shutil.rmtree(work, ignore_errors=True)

    def _grade_one(self, student: str):
        """Run one submission's sandbox; returns its result, or (it ran) the call that scores it."""
        t0 = time.monotonic()
        a = self.a
        src = self.course / "submitted" / student / a.name
        nbs, tampered, problems, restored = {}, {}, [], {}
        for name in a.notebooks:
            raw = read_inside(src, f"{name}.ipynb")
            if raw is None:
                path = src / f"{name}.ipynb"
                if path.is_file() and not path.is_symlink() and path.stat().st_size > MAX_FILE:
                    return self.verdicts.zero(student, "invalid notebook", f"{name}.ipynb is "
                                              f"{path.stat().st_size / 2**20:.0f} MB, more than the {MAX_FILE >> 20} MB "
                                              "the grader reads", t0)
                problems.append(f"{name}.ipynb is missing")
                continue
            try:
                nb = nbformat.reads(raw.decode("utf-8"), as_version=4)
                nbformat.validate(nb)
            except Exception as e:  # noqa: BLE001 - anything that is not a notebook
                msg = str(e).splitlines()[0][:200] if str(e) else type(e).__name__
                return self.verdicts.zero(student, "invalid notebook", f"{name}.ipynb is not a valid notebook: {msg}",
                                          t0)
            nbs[name], repaired = restore(nb, a, name, release_order(self.course, a.name, name))
            restored.update(repaired)
            tampered.update(tampered_cells(nbs[name], a, name))
        if not nbs:  # nothing of the assignment to run: say so, and what the folder does hold
            others = sorted(p.name for p in src.glob("*.ipynb"))
            detail = "; ".join(problems) + (f" (the folder has {', '.join(others)}; `snakekit collect {a.name} --from "
                                            f"<that folder>` finds a renamed notebook by its cells)" if others else
                                            " (no notebook in the folder)")
            return self.verdicts.zero(student, "missing notebook", detail, t0)
        work, outcome, runs = self._run(student, src, nbs, tampered)

        def finish(second=None):
            keep = False
            try:
                again = {} if second is not None or self.draw is None or tampered else rerun.needed(
                    self.draw.depends, self.verdicts.handin_scores(work, tampered), self._written(nbs),
                    self.verdicts.unreached(work, student))
                if again:  # run once more with the lesson's own parts, in the pool; score both then
                    keep = True
                    return Again(lambda: self._run_again(student, src, nbs, tampered, again, finish))
                return self.verdicts.collect(work, student, nbs, tampered, problems, outcome, t0, second, runs,
                                             first_run=self.first_runs.get(student, ""), restored=restored,
                                             not_made=self.runner.not_made(work)
                                             if outcome.returncode == sandbox.NOT_MADE else None)
            finally:
                if not keep:
                    shutil.rmtree(work, ignore_errors=True)
        return finish

    def _written(self, nbs: dict) -> dict[str, bool]:
        """Answer cell grade id -> whether the submission changed it from the release."""
        out = {}
        for nb in nbs.values():
            for c in nb.cells:
                gid = c.get("metadata", {}).get("nbgrader", {}).get("grade_id")
                facts = self.a.locked.get(gid)
                if facts and facts.get("solution"):
                    out[gid] = c.source.strip() != str(facts.get("source", "")).strip()
        return out

    def _run_again(self, student, src, nbs, tampered, again: dict, finish):
        """The submission run once more with the instructor's answers in the cells ``again`` names
        (:mod:`grader.scoring.rerun`); only the dependent exercises' hand-ins are read from it."""
        cells = {c for replaced in again.values() for c in replaced}
        work, second = None, {}
        try:
            source = {name: nbformat.read(self.course / "source" / self.a.name / f"{name}.ipynb", as_version=4)
                      for name in nbs}
            work = self.runner.stage(student, src, nbs, tampered)
            for name, nb in rerun.with_answers(nbs, source, cells).items():
                nbformat.write(nb, work / "course" / "submitted" / student / self.a.name / f"{name}.ipynb")
            (work / worker.ONLY).write_text(json.dumps({"tests": sorted(again)}))
            self.runner.run(work, student)
            for gid, replaced in again.items():
                try:
                    raw = read_inside(work, f"handin/{gid}.npz")
                    second[gid] = (read_handin(raw) if raw is not None else None, replaced)
                except ValueError:
                    continue
        except Exception:  # noqa: BLE001 - the second run is a chance, never a loss: the first run's grade stands
            second = {}
        finally:
            if work is not None:
                shutil.rmtree(work, ignore_errors=True)
        return lambda: finish(second)


def late_replies(work: Path, student: str) -> None:
    """Say (on stderr, for the TA) where a kernel finished a cell whose reply never came, which the
    worker took as finished (:data:`snakekit.kernel_client.LATE_REPLY`): the kernel's fault, never a score."""
    raw = read_inside(work, "result.json", limit=1 << 20)
    try:
        late = json.loads(raw).get("late_replies") or [] if raw else []
        where = ", ".join(f"{d['notebook']} cell {int(d['cell'])}" for d in late)
    except (ValueError, AttributeError, KeyError, TypeError):
        return
    if where:
        print(f"snakekit grade: {student}: the kernel finished {where} but its reply never came; taken as finished "
              f"after {kernel_client.LATE_REPLY:g} s (the grade is not affected)", file=sys.stderr)


#: runs of the instructor notebook a batch makes at most while a hidden case of it raises a fault of the arm's bus
REFERENCE_TRIES = 3


def bus_faults(work: Path, cases: dict) -> list[str]:
    """The hidden cases at which a run's hand-ins hold a fault of the arm's bus (:data:`REAL_TIME_FAULTS`:
    CommunicationError, PortLostError, BusWatchdogError), each as "<grade id> raised <error> at hidden case <k>".
    The instructor's solution raising one is the machine's doing (a late reply of the emulated servos on a busy
    machine, a stall past the servos' Bus Watchdog, an unplugged port), never what an exercise asks for: as an
    expected result it would cost every student who computed the case right. (An exercise that asks for an error
    asks for another type: LimitError, ...)"""
    return [f"{gid} raised {fitted(r)} at hidden case {k}" for gid, results in handin_results(work, cases).items()
            for k, r in enumerate(results) if is_fault(r)]


def handin_results(work: Path, cases) -> dict[str, list]:
    """The hand-ins of a run's folder, grade id -> its results per case, for the grade ids ``cases`` names (an
    unreadable or missing file: left out)."""
    out = {}
    for gid in cases:
        raw = read_inside(work, f"handin/{gid}.npz")
        try:
            if raw is not None:
                out[gid] = read_handin(raw)
        except ValueError:
            continue
    return out


def mend_faults(second: dict[str, list], first: dict[str, list]) -> dict[str, dict[int, object]]:
    """The cases of a second run (a student's, after a first with a fault of the arm's bus) that faulted again
    where the first run's same case did not: grade id -> {case: the first run's result}. A fault is the busy
    machine's (a late reply of the emulated servos), which strikes at a case by chance; the same student's code at
    the same case gave that result in the first run, so the case is graded on it instead of lost. A case that
    faulted in both runs stays as it is (the student's code may ask a servo that is not there)."""
    out = {}
    for gid, results in second.items():
        before = first.get(gid, [])
        for k, r in enumerate(results):
            if is_fault(r) and k < len(before) and before[k] is not None and not is_fault(before[k]):
                out.setdefault(gid, {})[k] = before[k]
    return out


def stopped_by_clock(work: Path, outcome, student: str, a) -> bool:
    """Whether a sandbox's run ended by a clock: its wall limit, the notebook's ``--timeout`` or a
    cell's ``--cell-timeout`` (read from what the worker wrote, which is only ever a reason to run
    again, never a score)."""
    if outcome.timed_out:
        return True
    raw = read_inside(work, "result.json", limit=1 << 20)
    try:
        if raw and json.loads(raw).get("stopped"):
            return True
    except (ValueError, AttributeError):
        pass
    for name in a.notebooks:
        raw = read_inside(work, f"course/autograded/{student}/{a.name}/{name}.ipynb")
        if raw and b'"ename": "CellTimeoutError"' in raw:
            return True
    return False


def default_jobs() -> int:
    """Sandboxes at once unless told: one more than the cores. A sandbox leaves its core idle at
    times (its kernel starting and stopping, nbgrader reading and writing): with two cores, two
    sandboxes kept them busy 85 % of a batch of lesson 06 and three 92 % (126 s and 112 s for 60
    submissions, bench/grading.py)."""
    return (os.cpu_count() or 1) + 1


class Again:
    """A second sandbox run a submission needs (:mod:`grader.scoring.rerun`): it goes to the pool."""

    def __init__(self, call):
        self.call = call

    def __call__(self):
        return self.call()


class Progress:
    """``grading: [#####.....] 12/60 done, 48 left, 3 with problems`` on stderr (or a given stream): a
    submission whose status is not ``graded`` (tests restored, a timeout...), the summary's count.

    >>> import io
    >>> bar = Progress(2, io.StringIO(), jobs=1)
    >>> bar.done = 1
    >>> bar._line()[-10:]
    ' 1 worker)'
    """

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
                f"left {self.total - self.done}, {self.failed} with problems"
                + (f" ({rate:.1f} s per student, {self.jobs} worker{'s' if self.jobs != 1 else ''})" if self.done
                   else ""))

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
