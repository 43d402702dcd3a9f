"""Inside the sandbox: nbgrader's autograde of one submission, on the sandbox's own course copy.

``python -m grader.worker COURSE_DIR ASSIGNMENT STUDENT CELL_TIMEOUT [NOTEBOOKS]`` runs nbgrader's
``autograde`` (its sanitising, hidden-test injection from the gradebook copy, execution and
scoring) and writes ``result.json`` next to the course copy: whether nbgrader succeeded, and
the tail of its log. The grader's parent process trusts none of it for points.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def main(argv: list[str], *, warm: bool = False) -> int:
    """Autograde one submission; ``warm``: fork the kernels from this process (see :mod:`grader.warmkernel`)."""
    course, assignment, student, timeout = Path(argv[0]), argv[1], argv[2], int(argv[3])
    result_path = course.parent / "result.json"
    result = {"success": False, "error": "", "log": ""}
    result_path.write_text(json.dumps(result))  # replaced below; its presence means the worker started
    # jsonschema (under nbformat) imports rfc3987_syntax when installed, which builds a parser
    # at import: about 1 s per sandbox, for an "iri" string format no notebook schema uses.
    sys.modules.setdefault("rfc3987_syntax", None)
    try:
        if warm:
            from . import warmkernel

            warmkernel.prefork(int(argv[4]) if len(argv) > 4 else 1)  # one kernel per notebook
        _throwaway_gradebook()
        from nbgrader.apps import NbGraderAPI
        from nbgrader.coursedir import CourseDirectory
        from traitlets.config import Config

        config = Config()
        config.CourseDirectory.root = str(course)
        config.Execute.timeout = timeout
        config.Execute.interrupt_on_timeout = True
        config.Execute.extra_arguments = ["--HistoryManager.hist_file=:memory:"]
        config.NbGraderAPI.timezone = "UTC"
        if warm:
            from nbgrader.preprocessors import execute

            execute.AsyncKernelManager = warmkernel.WarmKernelManager  # Execute passes it as kernel_manager_class
        api = NbGraderAPI(CourseDirectory(config=config), config=config)
        out = api.autograde(assignment, student, force=True, create=True)
        result = {"success": bool(out.get("success")), "error": str(out.get("error", ""))[-4000:],
                  "log": str(out.get("log", ""))[-8000:]}
    except BaseException as e:  # noqa: BLE001 - report whatever stopped nbgrader
        result = {"success": False, "error": f"{type(e).__name__}: {e}"[-4000:], "log": ""}
    if "grader.warmkernel" in sys.modules:
        sys.modules["grader.warmkernel"].discard()
    result_path.write_text(json.dumps(result))
    return 0 if result["success"] else 3


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
