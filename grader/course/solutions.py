"""The worked solution students get after the due date: ``snakekit release ASSIGNMENT --solutions``.

It is an assignment of its own, ``<assignment>-solutions``, in nbgrader's ``release/`` folder,
so the exchange's usual route takes it to the students (``nbgrader fetch_assignment``, the
Assignments tab) into a folder beside their own work, which it never overwrites. It holds the
instructor's notebooks with their solutions, the answers to the "predict, then run" questions and
the visible checks; no hidden test (:data:`grader.markup.HIDDEN`), no output, no cell metadata but
nbgrader's (the checks' Validate still runs); the other files are those the students' release
already has. The hidden cases (``cases/``), the seeds each attempt met (``draws/``) and whatever
a run wrote beside the instructor's notebook are never read.
"""

from __future__ import annotations

import datetime as dt
import os
import shutil
from pathlib import Path

from grader.course.folder import gradebook
from grader.errors import CourseError
from grader.markup import visible_part, without_solution_markers

SUFFIX = "-solutions"
#: The only notebook metadata the solution keeps (the kernel to run it with).
NOTEBOOK_METADATA = ("kernelspec", "language_info")


def name(assignment: str) -> str:
    """The solution's assignment name in the exchange: ``06_coded_sweep-solutions``."""
    return assignment + SUFFIX


def solution_notebook(nb, *, assignment: str, due: dt.datetime | None):
    """The instructor's notebook ``nb`` (nbformat, changed in place and returned) as students get
    it: hidden tests and solution markers out, outputs cleared, a first cell saying what it is."""
    import nbformat
    from nbconvert.preprocessors import ClearOutputPreprocessor

    ClearOutputPreprocessor().preprocess(nb, {})
    nb.metadata = nbformat.from_dict({k: v for k, v in nb.metadata.items() if k in NOTEBOOK_METADATA})
    for cell in nb.cells:
        cell.metadata = nbformat.from_dict({k: v for k, v in cell.metadata.items() if k == "nbgrader"})
        cell.source = without_solution_markers(visible_part(cell.source))
    when = f" (due {due:%Y-%m-%d %H:%M} UTC)" if due is not None else ""
    nb.cells.insert(0, nbformat.v4.new_markdown_cell(
        f"**Worked solution of {assignment}**{when}: the instructor's answers and the visible checks. "
        f"Your own notebook stays in your `{assignment}/` folder."))
    return nb


def due_date(course: Path, assignment: str) -> dt.datetime | None:
    """The assignment's due date as the gradebook holds it (aware, UTC), or None (also with no gradebook,
    which is not made here)."""
    if not (Path(course) / "gradebook.db").is_file():
        return None
    with gradebook(course) as gb:
        found = [a.duedate for a in gb.assignments if a.name == assignment]
    return found[0].replace(tzinfo=dt.timezone.utc) if found and found[0] is not None else None


def check(course: Path, assignment: str, *, force: bool, now: dt.datetime | None = None) -> dt.datetime | None:
    """The due date, once the solution may go out; a :class:`CourseError` saying what to do if not yet:
    the assignment was never released, or its due date has not passed (or is not set) and not ``force``."""
    if not sorted((Path(course) / "release" / assignment).glob("*.ipynb")):
        raise CourseError(f"{assignment} was never released (no {Path(course) / 'release' / assignment}/ notebook): "
                          f"release it first (snakekit release {assignment} --due TIME); its solution follows after "
                          "the due date")
    due = due_date(course, assignment)
    now = now or dt.datetime.now(dt.timezone.utc)
    if force:
        return due
    if due is None:
        raise CourseError(f"{assignment} has no due date in the gradebook, so its solution cannot wait for it: "
                          f"set one (snakekit release {assignment} --due TIME), or add --force to release it now")
    if now < due:
        raise CourseError(f"{assignment} is due {due:%Y-%m-%d %H:%M} UTC, not yet passed: its solution goes out "
                          "after that; add --force to release it now (late students could then copy it)")
    return due


def write(course: Path, assignment: str, due: dt.datetime | None) -> Path:
    """``release/<assignment>-solutions/``: each source notebook as :func:`solution_notebook` makes it
    (named ``<notebook>-solutions.ipynb``), with the other files of the students' release."""
    import nbformat

    course = Path(course)
    students = course / "release" / assignment
    dest = course / "release" / name(assignment)
    tmp = dest.with_name(f".{dest.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    for path in sorted(students.rglob("*")):
        if path.is_file() and not path.is_symlink():
            target = tmp / path.relative_to(students)
            target.parent.mkdir(parents=True, exist_ok=True)
            if path.suffix == ".ipynb":
                source = course / "source" / assignment / path.relative_to(students)
                if not source.is_file():
                    shutil.rmtree(tmp, ignore_errors=True)
                    raise CourseError(f"release/{assignment}/{path.relative_to(students)} has no instructor version "
                                      f"in {course / 'source' / assignment}/: release {assignment} again first")
                nb = solution_notebook(nbformat.read(source, as_version=4), assignment=assignment, due=due)
                nbformat.write(nb, target.with_name(target.stem + SUFFIX + ".ipynb"))
            else:
                shutil.copyfile(path, target)
    shutil.rmtree(dest, ignore_errors=True)
    os.replace(tmp, dest)
    return dest
