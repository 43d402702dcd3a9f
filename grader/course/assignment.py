"""The assignment as the grader sees it: its test cells from the course's gradebook, and the
checks made on a submission before it runs (safe reading, tampered test cells)."""

from __future__ import annotations

import os
import shutil
import stat
import sys
from dataclasses import dataclass, field
from pathlib import Path

from snakekit.errors import SnakekitError

from grader.markup import visible_part
from grader.course.folder import course_id, db_url, generate
from grader.errors import CourseError, GradingError
from grader.files import MAX_FILE  # the largest notebook or hand-in the grader reads back [bytes]
from grader.scoring.references import Reference


@dataclass
class TestCell:
    __test__ = False  # a graded cell, not a test class for pytest to collect
    grade_id: str
    notebook: str
    max_score: float
    source: str  # the instructor's, with hidden tests
    cell_type: str


@dataclass
class Assignment:
    name: str
    notebooks: list[str]
    tests: dict[str, TestCell]  # autograded test cells by grade id
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


def load_assignment(course: Path, assignment: str, references: Path | None) -> Assignment:
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
                    tests[g.name] = TestCell(g.name, nb.name, float(g.max_score), src.source, g.cell_type)
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
    return Assignment(assignment, notebooks, tests, locked, max_score, ref, cid, files)


def template_gradebook(course: Path, a: Assignment, dest: Path) -> None:
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


def tampered_cells(nb, a: Assignment, notebook: str) -> dict[str, str]:
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
        want = _norm(visible_part(info["source"]))
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
