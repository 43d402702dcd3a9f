"""A lesson's checks from a terminal (``snakekit check LESSON.ipynb``).

The notebook runs top to bottom in a fresh kernel, in its own folder as in JupyterLab, and
each graded cell becomes one row: grade id, points, passed or failed, and the message the
student would see under the cell (in full: its hint lines follow, indented under the row). The file itself is not changed.

What can go wrong before or while it runs is said in one line, never as a traceback: a file
that is not a notebook (empty, plain text, JSON of another kind, not UTF-8), a graded cell
whose nbgrader metadata was edited, a cell that runs past the time limit, a kernel that dies.
"""

from __future__ import annotations

import json
import math
import sys
import tempfile
import warnings
from pathlib import Path

from . import host
from .cells import cell_name
from .errors import FileFormatError
from .kernel_client import NotebookClient

#: What to do with a lesson file that can't be used as it is.
FRESH_COPY = "take a fresh copy of the lesson from the kit's notebooks/ folder and copy your answers into it"


def read_lesson(path):
    """The notebook at ``path`` (nbformat v4; an nbformat 3 notebook is converted to it, as
    ``nbformat.read(..., as_version=4)`` does), with its graded cells' metadata checked.

    Raises:
        FileFormatError: the file is empty, not UTF-8, not JSON, not a Jupyter notebook, or a
            graded cell lacks its grade id or has points that are not a number.
    """
    import nbformat

    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise FileFormatError(f"{path} could not be read ({e.strerror or e})") from None
    if not data.strip():
        raise FileFormatError(f"{path} is empty, not a notebook; {FRESH_COPY}")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        kind = " (it looks like UTF-16)" if data[:2] in (b"\xff\xfe", b"\xfe\xff") or b"\x00" in data[:8] else ""
        raise FileFormatError(f"{path} is not UTF-8 text{kind}: byte {e.start} is 0x{data[e.start]:02x}. Jupyter "
                              "saves notebooks as UTF-8; open it in JupyterLab and save it again there, or "
                              f"{FRESH_COPY}") from None
    try:
        raw = json.loads(text)
    except ValueError:
        start = text.strip().splitlines()[0][:40]
        raise FileFormatError(f"{path} is not a Jupyter notebook: it is not JSON (it starts with {start!r}), "
                              f"perhaps another file renamed to .ipynb; {FRESH_COPY}") from None
    old_format = isinstance(raw, dict) and isinstance(raw.get("nbformat"), int) and raw["nbformat"] < 4 \
        and isinstance(raw.get("worksheets"), list)  # nbformat 3 keeps its cells in worksheets: converted below
    if not isinstance(raw, dict) or not (isinstance(raw.get("cells"), list) or old_format):
        raise FileFormatError(f"{path} is JSON but not a Jupyter notebook (a notebook is a JSON object with a list "
                              f"of cells; this has no 'cells' list); {FRESH_COPY}")
    try:
        with warnings.catch_warnings():  # nbformat's own warnings (a cell without an id...): not the student's
            warnings.simplefilter("ignore")
            nb = nbformat.reads(text, as_version=4)
            nbformat.validate(nb)
    except Exception as e:  # nbformat's ValidationError, or its own errors on JSON of another shape
        why = str(e).strip().splitlines()[0][:160] if str(e).strip() else type(e).__name__
        raise FileFormatError(f"{path} is JSON but not a Jupyter notebook ({why}); {FRESH_COPY}") from None
    for index, cell in enumerate(nb.cells):
        meta = cell.metadata.get("nbgrader")
        if cell.cell_type != "code" or not isinstance(meta, dict) or not meta.get("grade"):
            continue
        gid, points = meta.get("grade_id"), meta.get("points", 0)
        if not isinstance(gid, str) or not gid:
            raise FileFormatError(f"{path}: {cell_name(nb.cells, index)} is a graded cell without a grade id (its nbgrader "
                                  f"metadata was changed); {FRESH_COPY}")
        if isinstance(points, bool) or not isinstance(points, (int, float)) or not math.isfinite(points) \
                or points < 0:
            raise FileFormatError(f"{path}: {cell_name(nb.cells, index)} has points {points!r}, not a number >= 0 (its "
                                  f"nbgrader metadata was changed); {FRESH_COPY}")
    return nb


def check_notebook(path, *, out=None, timeout: float = 300.0) -> int:
    """Run a lesson notebook top to bottom and report each exercise's check.

    Prints one row per graded cell (grade id, points, passed or failed, the whole message,
    its later lines indented under the row) and a total; returns 0 when every check passed, 1 otherwise. A cell that
    runs longer than ``timeout`` [s] is interrupted and fails with that reason, and the run goes
    on with the next cell, as in the grader (a runaway cell costs only its own exercise). A
    kernel that dies, or a cell that does not stop when interrupted, stops the run: the rows say
    which cell, and the graded cells after it count as not run.

    Raises:
        FileFormatError: the file is not a lesson notebook (:func:`read_lesson`).
    """
    from nbclient.exceptions import CellTimeoutError, DeadKernelError
    from traitlets.config import Config

    out = out or sys.stdout
    path = Path(path)
    nb = read_lesson(path)
    graded = [c for c in nb.cells if c.cell_type == "code" and c.metadata.get("nbgrader", {}).get("grade")]
    if not graded:
        print(f"{path}: no graded exercise in this notebook (a lesson from notebooks/ has them)", file=out)
        return 1
    running, interrupted = [], set()

    class Client(NotebookClient):   # a lost execute_reply costs LATE_REPLY s, not the cell's timeout
        async def _async_handle_timeout(self, timeout, cell=None):
            if running[-1] in interrupted:   # interrupted once and still running: the run stops here
                raise CellTimeoutError.error_from_timeout_and_cell("Cell execution timed out", timeout, cell)
            interrupted.add(running[-1])
            return await super()._async_handle_timeout(timeout, cell)

    stopped = ""
    # The kernel's own log (its start-up notes, or a traceback when it is shut down in the middle of
    # a cell) is not the student's output: it goes to a file, and its last line is shown if it dies.
    # Its sockets are in a folder of this run's own (host.kernel_sockets).
    with tempfile.TemporaryFile("w+") as log, tempfile.TemporaryDirectory(prefix="snakekit-kernel-") as sockets:
        client = Client(nb, timeout=timeout, kernel_name="python3", allow_errors=True, interrupt_on_timeout=True,
                        on_cell_start=lambda cell, cell_index: running.append(cell_index),
                        resources={"metadata": {"path": str(path.resolve().parent)}},
                        config=Config(host.kernel_sockets(sockets)))
        try:
            client.execute(stderr=log)
        except CellTimeoutError:
            stopped = (f"{cell_name(nb.cells, running[-1])} ran longer than {timeout:g} s and did not stop when interrupted "
                       "(a loop inside a compiled library, or a long run: run it in JupyterLab to see, or give "
                       "more time with --timeout)")
        except DeadKernelError:
            log.seek(0)
            said = [line.strip() for line in log if line.strip() and "WARNING" not in line]
            where = f"while running {cell_name(nb.cells, running[-1])}" if running else "before the first cell"
            stopped = (f"the Python kernel died {where} (the process ended: os._exit, a crash in a compiled "
                       "library, or out of memory)" + (f"; its last words: {said[-1][:200]}" if said else "")
                       + "; restart the kernel in JupyterLab and run that cell to see")
    last = (running[-1] if running else 0) if stopped else len(nb.cells)
    rows, got, total, failed = [], 0, 0, 0
    others = []
    for index, cell in enumerate(nb.cells):
        if cell.cell_type != "code":
            continue
        errors = [o for o in cell.get("outputs", []) if o.output_type == "error"]
        meta = cell.metadata.get("nbgrader", {})
        if meta.get("grade"):
            points = meta.get("points", 0)
            total += points
            if index >= last:
                failed += 1
                rows.append((meta["grade_id"], points, "FAILED", "stopped here (see below)" if index == last
                             else f"not run ({cell_name(nb.cells, last)} stopped the run)"))
            elif index in interrupted:
                failed += 1
                rows.append((meta["grade_id"], points, "FAILED", _runaway(timeout)))
            elif errors:
                failed += 1
                e = errors[0]
                text = str(e.get("evalue", "")).strip()
                message = text if e.ename in ("CheckFailed", "ShortcutError") else f"{e.ename}: {text}"
                rows.append((meta["grade_id"], points, "FAILED", message))
            else:
                got += points
                rows.append((meta["grade_id"], points, "passed", ""))
        elif errors or index in interrupted:
            where = cell_name(nb.cells, index)
            others.append(f"{where}: " + (_runaway(timeout) if index in interrupted
                                          else f"{errors[0].ename}: {str(errors[0].evalue).strip()}"))
    width = max(len(r[0]) for r in rows)
    print(f"{path.name}", file=out)
    for grade_id, points, status, message in rows:
        first, *more = message.splitlines() or [""]
        print(f"  {grade_id:<{width}}  {points:>2} pt  {status:<6}  {first}".rstrip(), file=out)
        for line in more:   # the rest of the message (its hint), under the first line
            print(f"  {'':<{width}}  {'':>2}     {'':<6}  {line}".rstrip(), file=out)
    print(f"  {len(rows) - failed} of {len(rows)} exercises passed, {got:g} of {total:g} points", file=out)
    for message in others:   # whole: the first line after "also failed:", the rest under it
        first, *more = message.splitlines()
        print(f"  also failed: {first}", file=out)
        for line in more:
            print(f"               {line}".rstrip(), file=out)
    if stopped:
        print(f"  stopped: {stopped}", file=out)
    return 0 if failed == 0 else 1


def _runaway(timeout: float) -> str:
    """What a student reads for a cell that ran past the limit and was interrupted."""
    return (f"stopped after {timeout:g} s, the limit for one cell: most likely an endless loop (a while whose "
            "condition never becomes false, or a counter that is never advanced)\n"
            "run the cell in JupyterLab to see where it hangs (Kernel > Interrupt stops it there), "
            "or give a long run more time with --timeout")
