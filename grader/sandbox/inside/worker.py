"""Inside the sandbox: nbgrader's autograde of one submission, on the sandbox's own course copy.

``python -m grader.sandbox.inside.worker COURSE_DIR ASSIGNMENT STUDENT TIMEOUT CELL_TIMEOUT [NOTEBOOKS]`` runs
nbgrader's ``autograde`` (its sanitising, hidden-test injection from the gradebook copy, execution
and scoring) and writes ``result.json`` next to the course copy: whether nbgrader succeeded, the
tail of its log, and where a notebook was stopped. The grader's parent process trusts none of it
for points.

Hidden cases: while a test cell runs, the worker tells the grader which (:mod:`grader.sandbox.inside.case_gate`).

Time: each notebook has ``TIMEOUT`` seconds of wall clock in all (from its kernel's start), and
each cell at most ``CELL_TIMEOUT`` of them. A cell over its own limit is interrupted and the
notebook goes on; a cell still running when the notebook's time is up is interrupted, marked
with a note, and the cells after it do not run. nbgrader then saves the notebook as it is, so
the feedback shows every output up to the stopped cell.

A cell the kernel has finished (IOPub: its outputs, then idle) whose reply never comes on the
shell channel counts as finished ``snakekit.kernel_client.LATE_REPLY`` s after the idle
(``late_replies`` in ``result.json``), instead of waiting out the notebook's time.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from grader.sandbox.inside.case_gate import open_gate
from grader.sandbox.inside.case_gate import say as gate_says

#: beside the course copy in a second run: {"tests": [the test cells whose hand-ins are read]}
ONLY = "only.json"
#: the note put on the cell that was running when a notebook's time ran out (``{timeout}``: seconds)
STOPPED_NOTE = "stopped here: the notebook ran longer than {timeout:g} s"
_stopped: list[dict] = []  # where each notebook was stopped, filled in by the execute preprocessor
_late: list[dict] = []  # the cells whose reply never came after the kernel had finished them
def main(argv: list[str], *, warm: bool = False) -> int:
    """Autograde one submission; ``warm``: fork the kernels from this process (see :mod:`grader.sandbox.inside.warmkernel`)."""
    course, assignment, student = Path(argv[0]), argv[1], argv[2]
    timeout, cell_timeout = float(argv[3]), float(argv[4])
    result_path = course.parent / "result.json"
    result = {"success": False, "error": "", "log": ""}
    result_path.write_text(json.dumps(result))  # replaced below; its presence means the worker started
    # jsonschema (under nbformat) imports rfc3987_syntax when installed, which builds a parser
    # at import: about 1 s per sandbox, for an "iri" string format no notebook schema uses.
    sys.modules.setdefault("rfc3987_syntax", None)
    try:
        open_gate()
        if warm:
            from grader.sandbox.inside import warmkernel

            warmkernel.prefork(int(argv[5]) if len(argv) > 5 else 1)  # one kernel per notebook
        _throwaway_gradebook()
        from nbgrader.apps import NbGraderAPI
        from nbgrader.coursedir import CourseDirectory
        from traitlets.config import Config

        config = Config()
        config.CourseDirectory.root = str(course)
        config.Execute.timeout = max(1, int(cell_timeout))
        config.Execute.interrupt_on_timeout = True
        only = course.parent / ONLY
        tests = set(json.loads(only.read_text())["tests"]) if only.is_file() else None
        config.Autograde.autograde_preprocessors = _with_deadline(timeout, cell_timeout, tests)
        config.Execute.extra_arguments = ["--HistoryManager.hist_file=:memory:"]
        config.NbGraderAPI.timezone = "UTC"
        if warm:
            from nbgrader.preprocessors import execute

            execute.AsyncKernelManager = warmkernel.WarmKernelManager  # Execute passes it as kernel_manager_class
        api = NbGraderAPI(CourseDirectory(config=config), config=config)
        out = api.autograde(assignment, student, force=True, create=True)
        result = {"success": bool(out.get("success")), "error": str(out.get("error", ""))[-4000:],
                  "log": str(out.get("log", ""))[-8000:], "stopped": _stopped,
                  "late_replies": _late}
    except BaseException as e:  # noqa: BLE001 - report whatever stopped nbgrader
        result = {"success": False, "error": f"{type(e).__name__}: {e}"[-4000:], "log": ""}
    if "grader.sandbox.inside.warmkernel" in sys.modules:
        sys.modules["grader.sandbox.inside.warmkernel"].discard()
    result_path.write_text(json.dumps(result))
    return 0 if result["success"] else 3


def runs_cell(cells: list, index: int, tests: set) -> bool:
    """Whether a second run (:mod:`grader.scoring.rerun`), which reads only the hand-ins of the test cells
    ``tests``, runs cell ``index``: the lesson's cells before its first exercise (its imports),
    every answer cell and those test cells, up to the last of them. The other test cells and
    the lesson's cells between the exercises (its demonstrations: plots, the Task 2 run) are
    not run, nor anything after the last of ``tests``.
    """
    def meta(c):
        return c.get("metadata", {}).get("nbgrader", {})

    last = max((i for i, c in enumerate(cells) if meta(c).get("grade_id") in tests), default=-1)
    first = min((i for i, c in enumerate(cells) if meta(c).get("grade_id")), default=len(cells))
    m = meta(cells[index])
    return index <= last and (index < first or bool(m.get("solution")) or m.get("grade_id") in tests)


def _with_deadline(timeout: float, cell_timeout: float, tests: set | None = None) -> list:
    """nbgrader's autograde steps, with its ``Execute`` replaced by one that keeps the notebook's
    deadline (and, in a second run, runs only the cells :func:`runs_cell` names)."""
    from nbgrader.converters import Autograde
    from nbgrader.preprocessors import Execute

    from snakekit.kernel_client import LateReplies

    class DeadlineExecute(LateReplies, Execute):
        """nbgrader's ``Execute`` with a wall clock for the whole notebook beside the per-cell one, and
        a lost reply taken as the cell's end (:class:`snakekit.kernel_client.LateReplies`)."""

        def preprocess(self, nb, resources=None, km=None):
            self._deadline = time.monotonic() + timeout
            self._stopped_at = None
            self._cells = nb.cells
            self._notebook = ((resources or {}).get("nbgrader") or {}).get("notebook", "")
            # each cell: its own limit, or what is left of the notebook's, whichever is shorter
            self.timeout_func = lambda cell: max(0.05, min(cell_timeout, self._deadline - time.monotonic()))
            return super().preprocess(nb, resources, km)

        def preprocess_cell(self, cell, resources, index):
            self._index = index
            if self._stopped_at is not None:
                return cell, resources  # the notebook's time is up: not run
            if tests is not None and not runs_cell(self._cells, index, tests):
                return cell, resources
            meta = cell.get("metadata", {}).get("nbgrader", {})
            test = cell.cell_type == "code" and meta.get("grade") and not meta.get("solution") and meta.get("grade_id")
            try:
                if test:
                    gate_says(f"open {meta['grade_id']}")
                cell, resources = super().preprocess_cell(cell, resources, index)
                late = time.monotonic() >= self._deadline - 0.05
                timed_out = any(o.get("ename") == "CellTimeoutError" for o in cell.get("outputs", []))
            except Exception:  # noqa: BLE001 - the kernel did not come back after the interrupt
                if time.monotonic() < self._deadline - 0.05:
                    raise
                late = timed_out = True
            finally:
                if test:
                    gate_says("close")
            if late and timed_out and cell.cell_type == "code":
                from nbformat.v4 import new_output

                self._stopped_at = index
                cell.outputs.append(new_output("stream", name="stderr", text=STOPPED_NOTE.format(timeout=timeout) + "\n"))
                _stopped.append({"notebook": self._notebook, "cell": index, "id": cell.get("id", "")})
            return cell, resources

        def reply_never_came(self, cell):
            _late.append({"notebook": self._notebook, "cell": self._index, "id": cell.get("id", "")})
            super().reply_never_came(cell)

    steps = list(Autograde.class_traits()["autograde_preprocessors"].default())
    return [DeadlineExecute if step is Execute else step for step in steps]


def _throwaway_gradebook() -> None:
    """This course copy's gradebook is deleted after the run (the grader keeps the real one):
    SQLite need not wait for the disk at each of nbgrader's commits."""
    from sqlalchemy import event
    from sqlalchemy.engine import Engine

    @event.listens_for(Engine, "connect")
    def _no_sync(dbapi_connection, _record):
        dbapi_connection.execute("PRAGMA synchronous=OFF")
        dbapi_connection.execute("PRAGMA journal_mode=MEMORY")


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
