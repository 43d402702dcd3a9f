"""What a sandbox gave back, made into a grade: the executed notebooks and the hand-ins read
safely, every test cell scored in this process (:mod:`grader.scoring.score`), the submission's status,
the notebook for the TA (``autograded/``) and the feedback page for the student."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

import nbformat

from snakekit.cells import cell_name
from snakekit.errors import CheckFailed
from snakekit.verdicts import NOTE

from grader.feedback import scrub
from grader.feedback import notebook as feedback
from grader.scoring import rerun
from grader.course.assignment import read_inside
from grader.files import fitted
from grader.hooks import NO_HOOKS, BatchHooks
from grader.scoring.compare import GUESSES
from grader.scoring.score import ExerciseScore, read_handin, score_exercise
from grader.scoring.wording import title


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


class Verdicts:
    """Scores what came back from one batch's sandboxes and writes the pages.

    ``expected``: grade id -> :class:`grader.scoring.score.Expected`, the batch's instructor results
    (set once the reference run is in); test cells without them keep nbgrader's verdict.
    """

    def __init__(self, course: Path, a, base: Path, *, timeout: float, cell_timeout: float, memory: int,
                 hooks: BatchHooks = NO_HOOKS):
        self.course, self.a, self.base, self.hooks = course, a, base, hooks
        self.timeout, self.cell_timeout, self.memory = timeout, cell_timeout, memory
        self.expected: dict = {}
        self.draw = None  # the batch's cases (set with the expected results)
        self.pending: dict[str, dict] = {}  # student -> the notebooks their pages are made of (see feedback)
        self.mended: dict[str, dict] = {}  # a run's folder -> grade id -> {case: result} (grader.batch.mend_faults)

    def mend(self, work, mended: dict[str, dict[int, object]]) -> None:
        """Grade the run in ``work`` with these cases' results in place of its own (a fault of the arm's bus in
        a second run, where the first run's same case had a result: :func:`grader.batch.mend_faults`)."""
        self.mended[str(work)] = mended

    def handin(self, work, gid: str):
        """The hand-in of ``gid`` in ``work`` (None: there is none), with its mended cases; ValueError: unreadable."""
        raw = read_inside(work, f"handin/{gid}.npz")
        handin = read_handin(raw) if raw is not None else None
        for k, result in self.mended.get(str(work), {}).get(gid, {}).items():
            if handin is not None and k < len(handin):
                handin[k] = result
        return handin

    def handin_scores(self, work, tampered) -> dict[str, ExerciseScore]:
        """The score of every test cell with expected results, from the hand-ins in ``work``."""
        out = {}
        for gid, e in self.expected.items():
            if gid in self.a.tests and gid not in tampered:
                try:
                    handin = self.handin(work, gid)
                except ValueError:
                    continue
                out[gid] = score_exercise(gid, handin, e, self.a.tests[gid].max_score)
        return out

    def ran(self, work, student) -> tuple[dict, dict]:
        """What the worker reported (``result.json``), and the executed notebooks (name -> notebook) in ``work``."""
        raw = read_inside(work, "result.json", limit=1 << 20)
        try:
            worker = json.loads(raw) if raw else {}
            worker = worker if isinstance(worker, dict) else {}
        except ValueError:
            worker = {}
        executed = {}
        for name in self.a.notebooks:
            raw = read_inside(work, f"course/autograded/{student}/{self.a.name}/{name}.ipynb")
            if raw:
                try:
                    executed[name] = nbformat.reads(raw.decode("utf-8"), as_version=4)
                except Exception:  # noqa: BLE001 - a notebook the submission mangled: not used
                    pass
        return worker, executed

    def unreached(self, work, student) -> set[str]:
        """The test cells the notebook's clock stopped before they ran to their end: the cell the
        worker stopped in and every test cell after it (:func:`grader.scoring.rerun.needed`)."""
        worker, executed = self.ran(work, student)
        out = set()
        for name, index in stopped_cells(worker.get("stopped"), executed).items():
            out |= {gid for c in executed[name].cells[index:]
                    if (gid := c.get("metadata", {}).get("nbgrader", {}).get("grade_id")) in self.a.tests}
        return out

    def collect(self, work, student, nbs, tampered, problems, outcome, t0, second=None, runs=1, first_run="",
                restored=None, not_made: str | None = None) -> SubmissionResult:
        """``second``: grade id -> (its hand-in, the answer cells replaced) from a second run with the
        instructor's answers in those cells (:mod:`grader.scoring.rerun`); the better score counts. ``runs``: 2
        when the first run was stopped by a clock (or had a fault of the arm's bus: ``first_run`` says which)
        and this is the run from scratch after it.
        ``restored``: test cells put back as released before the run (:mod:`grader.course.restore`): no
        points lost, the status says so for the TA. ``not_made``: the sandbox could not be made (its words), so
        nothing of the notebook ran: a grader error, never the student's score."""
        a = self.a
        worker, executed = self.ran(work, student)
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
            if gid in self.expected:
                try:
                    handin = self.handin(work, gid)
                except ValueError as e:
                    scores.append(ExerciseScore(gid, 0.0, cell.max_score, "inconsistent", f"hand-in unreadable: {e}."))
                    continue
                sc = score_exercise(gid, handin, self.expected[gid], cell.max_score)
                if sc.status == "missing":
                    sc = dataclasses.replace(sc, message=why_missing(find_cell(executed.get(cell.notebook), gid),
                                                                     sc.message, cell_timeout=self.cell_timeout,
                                                                     timeout=self.timeout))
                elif sc.score < sc.max_score:
                    sc = with_local_check(sc, find_cell(executed.get(cell.notebook), gid))
                if second and gid in second:   # after the first run's message is made: the line goes before it
                    again, replaced = second[gid]
                    sc = rerun.better(sc, score_exercise(gid, again, self.expected[gid], cell.max_score), replaced)
                scores.append(sc)
            else:
                scores.append(kernel_score(gid, cell, executed.get(cell.notebook)))
        stopped = stopped_cells(worker.get("stopped"), executed)
        if outcome.timed_out or stopped:
            where = "".join(f" in {cell_name(executed[n].cells, i)}"    # as a student finds it, not counted from the top
                            + (f" of {n}.ipynb" if len(a.notebooks) > 1 else "")
                            for n, i in sorted(stopped.items())[:1])
            status, detail = "timeout", f"the notebook ran longer than {self.timeout:g} s and was stopped{where}"
        elif "CellTimeoutError" in errors:
            status, detail = "timeout", f"a cell ran longer than {self.cell_timeout:g} s and was interrupted"
        elif "MemoryError" in errors or "MemoryError" in log:
            status, detail = "memory limit", f"the notebook used more than {self.memory >> 20} MB"
        elif "DeadKernelError" in log or "kernel died" in log.lower():
            status, detail = "kernel died", "the Python kernel stopped while the notebook ran"
        elif tampered:
            status = "tests tampered"
            detail = "; ".join(f"{g}: {why}" for g, why in sorted(tampered.items()))
        elif restored:
            status = "tests restored"
            detail = "; ".join(f"{g}: {why}" for g, why in sorted(restored.items())) + \
                " (the released tests gave the points)"
        elif not_made is not None and not executed:
            status = "grader error"
            said = not_made or "it said nothing"
            detail = (f"the grader could not make the sandbox to run the notebook in, three times ({said}): nothing of "
                      "it ran, so this is no score of the student's; grade the student again")
        elif not executed:
            last = (str(worker.get("error", "")).strip().splitlines() or ["no result"])[-1][:300]
            status = "kernel died" if outcome.returncode not in (0, 3) else "autograde failed"
            detail = (f"nbgrader stopped (exit {outcome.returncode}): {last}" if status == "autograde failed"
                      else "the notebook's processes stopped before it finished")
        elif problems:
            status, detail = "missing notebook", "; ".join(problems)
        else:
            status, detail = "graded", ""
        if status == "timeout" and runs > 1:
            detail += " (run twice, so that a busy grading machine is not the cause, and stopped both times)"
        elif runs > 1:
            detail = (detail + "; " if detail else "") + (f"{SECOND_RUN}: the first "
                                                           f"{first_run or 'was stopped by the clock'}, so it ran "
                                                           "once more from the start")
        mended = self.mended.pop(str(work), {})
        if mended:
            cases = ", ".join(f"{gid} at hidden case {k}" for gid, ks in sorted(mended.items()) for k in sorted(ks))
            detail += f"; {cases} had a fault of the arm's bus in the second run too, and took the first run's " \
                      "result there"
        # the graded run's own cells that stopped on a fault of the arm's bus (a first run's made it run again)
        faults = check_faults(work, student, a) if errors & REAL_TIME_FAULTS else []
        if faults:
            more = f" (and {len(faults) - 1} more cell(s))" if len(faults) > 1 else ""
            detail = "; ".join(x for x in (detail, f"{faults[0]}{more}" + (" in the second run too" if runs > 1 else
                                                                           " in the run graded")) if x)
        # a note of the load only where the graded run itself shows a busy machine's marks: a second run that
        # ran clean is a sound grade
        if (status == "timeout" or faults or mended) and real_time(a):
            busy = busy_machine()
            detail = "; ".join(x for x in (detail, busy) if x)
        score = round(sum(s.score for s in scores), 4)
        result = SubmissionResult(student, a.name, score, a.max_score, status, detail, tuple(scores),
                                  time.monotonic() - t0)
        dest = self.course / "autograded" / student / a.name
        if executed:  # for the TA (formgrader): the notebook as it ran, hidden tests included, with the verdicts
            shutil.rmtree(dest, ignore_errors=True)
            dest.mkdir(parents=True)
            for name, nb in executed.items():
                mine = [s for s in scores if a.tests[s.grade_id].notebook == name]
                executed[name] = feedback.annotate_notebook(nb, dataclasses.replace(result, exercises=tuple(mine)),
                                                            stopped=stopped.get(name), timeout=self.timeout)
                nbformat.write(executed[name], dest / f"{name}.ipynb")
            if self.draw is not None:  # the trajectory at the spec's values, for `snakekit lab`
                self.hooks.graded(self.course, a.name, student, work, self.draw)
        return self.feedback(result, nbs, executed, stopped)

    def zero(self, student, status, detail, t0) -> SubmissionResult:
        scores = tuple(ExerciseScore(g, 0.0, c.max_score, "missing", detail) for g, c in self.a.tests.items())
        r = SubmissionResult(student, self.a.name, 0.0, self.a.max_score, status, detail, scores, time.monotonic() - t0)
        return self.feedback(r, {}, {})

    def feedback(self, result, submitted, executed, stopped=None) -> SubmissionResult:
        """Keep what the student's pages are made of until the gradebook has the scores (:meth:`grader.batch.Grader.pages`):
        the executed notebook (annotated: the verdicts kept in it), else the submitted one without outputs,
        else an empty one."""
        bases = {}
        for name in self.a.notebooks or [self.a.name]:
            nb = executed.get(name) or submitted.get(name)
            if nb is None:
                nb = nbformat.v4.new_notebook()
            elif name not in executed:
                nb = nbformat.from_dict(nb)
                for c in nb.cells:
                    if c.cell_type == "code":
                        c.outputs = []
            bases[name] = nb
        self.pending[result.student] = bases
        return result


#: How a result's detail begins when its second run was graded (the TA's terminal counts them).
SECOND_RUN = "graded on its second run"


def first_run_fault(fault: str) -> str:
    """Why a first run was not the one graded, when it had a fault of the arm's bus (``fault``: the first of
    :func:`check_faults` or :func:`grader.batch.bus_faults`), as the TA's line and the detail say it."""
    return f"had a fault of the arm's bus ({fault}), which a busy machine causes"

#: The errors a run on the arm's bus emulator raises when a reply comes too late (the emulated servos answer
#: in real time), or when the program stalled past the servos' Bus Watchdog (0.5 s without a packet: a stall
#: of the machine in the middle of a run): on a busy machine the student's code is not their cause.
REAL_TIME_FAULTS = frozenset({"CommunicationError", "PortLostError", "BusWatchdogError"})


def is_fault(result) -> bool:
    """Whether one case's hand-in is a fault of the arm's bus (:data:`REAL_TIME_FAULTS`), as the kit writes a raise."""
    return isinstance(result, str) and result.split(":", 1)[0].strip() in REAL_TIME_FAULTS


def check_faults(work: Path, student: str, a) -> list[str]:
    """The cells of a run that stopped on a fault of the arm's bus (:data:`REAL_TIME_FAULTS`), each as "<grade id>'s
    check raised <error>" (a test cell) or "cell <n> raised <error>" (any other, counted from 1 in its notebook):
    the student's page would show "servo 1 did not answer" where the check's own words belong, or a Bus Watchdog
    stop in one of the lesson's demonstrations and the errors it leaves in the cells after it (a late reply of the
    emulated servos, a stall of a busy machine, whatever the answer)."""
    out = []
    for name in a.notebooks:
        raw = read_inside(work, f"course/autograded/{student}/{a.name}/{name}.ipynb")
        if not raw or not any(f'"ename": "{e}"'.encode() in raw for e in REAL_TIME_FAULTS):
            continue
        try:
            cells = json.loads(raw).get("cells", [])
        except (ValueError, AttributeError):
            continue
        where = f" of {name}.ipynb" if len(a.notebooks) > 1 else ""
        for n, cell in enumerate(cells, 1):
            meta = (cell.get("metadata") or {}).get("nbgrader") or {}
            for o in cell.get("outputs") or [] if cell.get("cell_type") == "code" else []:
                if o.get("output_type") == "error" and o.get("ename") in REAL_TIME_FAULTS:
                    what = f"{meta['grade_id']}'s check" if meta.get("grade") and not meta.get("solution") \
                        and meta.get("grade_id") else f"cell {n}{where}"
                    out.append(f"{what} raised {fitted(o['ename'] + ': ' + str(o.get('evalue', '')))}")
    return out


def real_time(a) -> bool:
    """Whether the assignment's test cells run the arm's bus emulator (or the arm): in real time, so a busy
    machine can stop them by the clock or make a reply late, whatever the student wrote."""
    return any(re.search(r"make_robot\(\s*[\"'](emulator|hardware)", cell.source) for cell in a.tests.values())


def busy_machine(load=None, cores=None) -> str:
    """The TA's note when the grading machine was busier than its cores (the last minute's load average,
    ``os.getloadavg``), "" when it was not.

    >>> busy_machine(load=7.9, cores=2)[:65]
    "the grading machine's load was 7.9 on 2 cores (more than one task"
    >>> busy_machine(load=1.5, cores=2)
    ''
    """
    load = os.getloadavg()[0] if load is None else load
    cores = len(os.sched_getaffinity(0)) if cores is None else cores
    if load <= cores:
        return ""
    return (f"the grading machine's load was {load:.1f} on {cores} cores (more than one task a core): this "
            "assignment runs the arm's bus emulator in real time, which a busy machine slows, so the load may be "
            "the cause; grade it again on a quiet machine (`--student` for this one)")


def kernel_score(gid, cell, nb) -> ExerciseScore:
    """No reference: nbgrader's own verdict (the cell ran without an error).

    The error's message is shown only if a visible check raised it; a hidden test's
    message (its inputs, its expected values) stays hidden.
    """
    if nb is None:
        return ExerciseScore(gid, 0.0, cell.max_score, "missing", "the notebook did not finish running.")
    c = find_cell(nb, gid)
    if c is None:
        return ExerciseScore(gid, 0.0, cell.max_score, "missing", "the test cell is missing.")
    if c.get("execution_count") is None and not c.get("outputs"):
        return ExerciseScore(gid, 0.0, cell.max_score, "missing",
                             "the test cell did not run: the notebook was stopped before it.")
    err = scrub.cell_error(c)
    if err is None:
        return ExerciseScore(gid, cell.max_score, cell.max_score, "scored", "the test cell passed.")
    ename, evalue, where = err
    if where == "visible":
        msg = f"a visible check failed: {ename}: {evalue}"
    else:
        msg = (f"a hidden test failed ({ename}). Test your code on more cases than the visible checks use: "
               "other inputs, edge cases.")
    return ExerciseScore(gid, 0.0, cell.max_score, "scored", msg)


def with_local_check(sc: ExerciseScore, cell) -> ExerciseScore:
    """``sc`` with what the notebook's own check said, when it failed in the graded run: the visible case
    it failed at and its message, hint included, as the student reads them under the cell (and can run
    again). A hint of the check's is the only hint on the page: the grader's own guesses from the hidden
    cases' numbers (:data:`grader.scoring.compare.GUESSES`) give way to it, so the two never name two
    different mistakes.

    >>> from nbformat.v4 import new_code_cell, new_output
    >>> c = new_code_cell("ex.close(...)")
    >>> c.outputs = [new_output("error", ename="CheckFailed", traceback=[],
    ...              evalue="exercise 1.1 planar_fk: tool x is 331.5 m, expected 0.3315 m.\\nHint: millimetres?")]
    >>> print(with_local_check(ExerciseScore("ex01_1_planar_fk_test", 0.0, 3.0, "scored", "0 of 6 right."), c).message)
    0 of 6 right. Your notebook's check fails too: tool x is 331.5 m, expected 0.3315 m. Hint: millimetres?
    >>> print(with_local_check(ExerciseScore("ex01_1_planar_fk_test", 0.0, 3.0, "scored", "planar_fk returned a str"), c).message)
    planar_fk returned a str. Your notebook's check fails too: tool x is 331.5 m, expected 0.3315 m. Hint: millimetres?
    >>> print(with_local_check(ExerciseScore("ex01_1_planar_fk_test", 0.0, 3.0, "scored", "f(1): tool x is 331.5 m, expected 0.3315 m."), c).message)
    f(1): tool x is 331.5 m, expected 0.3315 m. Your notebook's check fails too: it says the same. Hint: millimetres?
    """
    err = next((o for o in (cell or {}).get("outputs", []) if o.get("output_type") == "error"), None)
    if err is None or err.get("ename") not in ("CheckFailed", "ShortcutError"):
        return sc
    text = scrub.neutral(str(err.get("evalue", "")), scrub.machine_paths())
    said, hint = text.partition(CheckFailed.HINT)[0], CheckFailed.hint_of(text)
    said = " ".join(re.sub(r"^exercise [\w.]+ \w+: ", "", said.strip()).split())   # the page names the exercise
    hint, message, checks = " ".join(hint.split()), sc.message, sc.checks
    if hint or NOTE.search(said):   # the check's hint, or a part's slip it names, is the cause: no guess of ours
        message = GUESSES.sub("", message)
        checks = tuple(dataclasses.replace(c, message=GUESSES.sub("", c.message)) for c in checks)
    flat = " ".join(message.split())
    if said and hint and not said.endswith((".", "!", "?", ":", ")")):
        said += "."   # the check's sentence ends before its hint begins
    told = [part for part in (said, f"Hint: {hint}" if hint else "") if part and part.removeprefix("Hint: ") not in flat]
    if told and said and said not in told:   # the grader's words are the check's: said once, its hint follows
        told.insert(0, "it says the same.")
    if told and message.strip() and not message.rstrip().endswith((".", "!", "?", ":", ")")):
        message = message.rstrip() + "."   # the grader's sentence ends before the check's begins
    return dataclasses.replace(sc, message=" ".join([message, LOCAL + " ".join(told)] if told else [message]),
                               checks=checks)


#: What starts the notebook's own check's words in a graded message (:func:`with_local_check`).
LOCAL = "Your notebook's check fails too: "


def stopped_cells(reported, executed: dict) -> dict[str, int]:
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


def find_cell(nb, gid):
    if nb is None:
        return None
    return next((c for c in nb.cells if c.get("metadata", {}).get("nbgrader", {}).get("grade_id") == gid), None)


#: What a student reads when a clock stopped the cell that was to hand in: what happened, and where to look.
LOOP_HINT = ("That usually means an endless loop: a `while` whose condition never becomes false, or a loop "
             "whose counter is never advanced. Run the cell in your notebook: if it does not finish, stop it "
             "(Kernel > Interrupt) and look at the loops{where}.")


def _clock_stop(cell, cell_timeout: float | None, timeout: float | None) -> str | None:
    """Why a test cell a clock interrupted handed nothing in, in a student's words; None if no clock stopped it.

    >>> from nbformat.v4 import new_code_cell, new_output
    >>> c = new_code_cell("ex = checks.Exercise('1', 'tool_xy'); ex.hand_in('ex1_test', tool_xy)", execution_count=4)
    >>> c.metadata["nbgrader"] = {"grade_id": "ex1_test"}
    >>> c.outputs = [new_output("error", ename="KeyboardInterrupt", evalue="", traceback=[
    ...     "Cell In[4], line 1, in <module>", "Cell In[2], line 3, in tool_xy(q)", "KeyboardInterrupt: "])]
    >>> print(_clock_stop(c, 15, 120))  # doctest: +NORMALIZE_WHITESPACE
    nothing was handed in: the cell was stopped after the per-cell limit of 15 s, while your `tool_xy` ran
    (exercise 1 tool_xy). That usually means an endless loop: a `while` whose condition never becomes false,
    or a loop whose counter is never advanced. Run the cell in your notebook: if it does not finish, stop it
    (Kernel > Interrupt) and look at the loops of `tool_xy`.
    """
    outs = cell.get("outputs", [])
    names = {str(o.get("ename")) for o in outs if o.get("output_type") == "error"}
    if not names & {"KeyboardInterrupt", "CellTimeoutError"}:
        return None
    whole = any("stopped here:" in "".join(o.get("text", "")) for o in outs if o.get("output_type") == "stream")
    limit = (f"the notebook's time of {timeout:g} s ran out" if whole and timeout
             else f"the cell was stopped after the per-cell limit of {cell_timeout:g} s" if cell_timeout
             else "the cell was stopped by the grader's clock")
    tb = scrub.strip_ansi("\n".join(str(line) for o in outs if o.get("output_type") == "error"
                                      for line in o.get("traceback", [])))
    frames = re.findall(r"Cell In\[\d+\], line \d+, in (\w+)", tb)  # "<module>" is not a function
    fn = f" of `{frames[-1]}`" if frames else ""
    gid = cell.get("metadata", {}).get("nbgrader", {}).get("grade_id", "")
    ran = f"while your `{frames[-1]}` ran" if frames else "while this test cell ran"
    return (f"nothing was handed in: {limit}, {ran}" + (f" (exercise {title(gid, cell.get('source', ''))})" if gid else "")
            + ". "
            + LOOP_HINT.format(where=fn))


def why_missing(cell, message: str, *, cell_timeout: float | None = None, timeout: float | None = None) -> str:
    """The reason a test cell handed nothing in, from how it stopped.

    A test cell hands in first, so a cell that handed nothing in stopped before that line
    (the function it hands in is not defined: an error in the answer cell, or it was never
    run), a clock stopped it (``cell_timeout``: one cell's limit, ``timeout``: the notebook's [s]),
    or the notebook stopped before the cell. The cell's error is the student's own to see.
    """
    err = scrub.cell_error(cell) if cell is not None else None
    if err is None:
        return message
    stopped = _clock_stop(cell, cell_timeout, timeout)
    if stopped:
        return stopped
    ename, evalue, _ = err
    evalue = str(evalue).strip()
    hint = ""
    # the kit's own note on a missing name (snakekit.checks, in the student's kernel and the graded one) says why
    if ename == "NameError" and "has not run yet" not in evalue:
        hint = (" The function is not defined: the answer cell above stopped with an error (see its output), or it "
                "was not run.")
    end = "" if evalue.endswith((".", "!", "?")) else "."
    return (f"nothing was handed in: the test cell stopped before it handed in your results, with {ename}: "
            f"{evalue}{end}{hint}")
