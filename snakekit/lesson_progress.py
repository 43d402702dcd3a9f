"""A student's own progress across the lessons (``snakekit progress [FOLDER]``, and a cell of lesson 0).

It reads the lesson notebooks in a folder (``notebooks/`` by default) as they were last saved,
and runs nothing: an exercise has *passed* when its check cell ran without an error, *failed*
when it stopped with one (its first line is shown), is *not written* while its answer cell
still raises ``NotImplementedError``, and *not checked* while its check cell has not run since
the notebook was last opened or its outputs were cleared. Points are the exercises' points as
the lessons state them; "passed" here is the notebook's own check, not a grade (the grader
also tries hidden cases).
"""

from __future__ import annotations

import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from .errors import FileFormatError
from .notebook_check import read_lesson

__all__ = ["ExerciseState", "lesson_states", "progress_report"]

_LESSON = re.compile(r"^\d\d_\w+\.ipynb$")
_ANSI = re.compile(r"\x1b\[[0-9;]*m")


@dataclass(frozen=True)
class ExerciseState:
    """One exercise as the saved notebook shows it.

    Attributes:
        number: as the lesson numbers it ("3.2").
        grade_id: its check cell's id.
        points: what it is worth.
        state: ``passed``, ``failed``, ``not written`` or ``not checked``.
        message: the first line of the check's message when it failed.
    """

    number: str
    grade_id: str
    points: float
    state: str
    message: str = ""


def _number(grade_id: str) -> str:
    m = re.match(r"ex(\d+)_(\d+)_", grade_id)
    return f"{int(m.group(1))}.{m.group(2)}" if m else grade_id


def lesson_states(path) -> list[ExerciseState]:
    """The state of every exercise of the lesson notebook at ``path``, in lesson order."""
    nb = read_lesson(Path(path))
    answers = {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells
               if c.metadata.get("nbgrader", {}).get("solution")}
    out = []
    for cell in nb.cells:
        meta = cell.metadata.get("nbgrader", {})
        if cell.cell_type != "code" or not meta.get("grade"):
            continue
        gid = meta["grade_id"]
        errors = [o for o in cell.get("outputs", []) if o.get("output_type") == "error"]
        answer = answers.get(gid.removesuffix("_test"), "")
        if "raise NotImplementedError" in answer:
            state, message = "not written", ""
        elif errors:
            text = _ANSI.sub("", str(errors[0].get("evalue", ""))).strip()
            state, message = "failed", (text.splitlines() or [str(errors[0].get("ename", ""))])[0]
        elif cell.get("execution_count") is None and not cell.get("outputs"):
            state, message = "not checked", ""
        else:
            state, message = "passed", ""
        out.append(ExerciseState(_number(gid), gid, float(meta.get("points", 0)), state, message))
    return out


def _folder(folder) -> Path:
    if folder is not None:
        return Path(folder)
    here = Path.cwd()
    return here if any(_LESSON.match(p.name) for p in here.iterdir()) else here / "notebooks"


def progress_report(folder=None, *, out=None) -> int:
    """Print each lesson's exercises passed and points, then what to do next. Returns 0, or 2 when
    ``folder`` holds no lesson notebook (said in one line)."""
    out = out or sys.stdout
    if os.environ.get("SNAKEKIT_HANDIN_DIR"):  # run by the grader, in a copy of this one notebook
        print("Your progress across the lessons shows when you run this cell in your own notebooks; "
              "the graded copy holds this lesson only.", file=out)
        return 0
    where = _folder(folder)
    lessons = sorted(p for p in where.glob("*.ipynb") if _LESSON.match(p.name)) if where.is_dir() else []
    if not lessons:
        print(f"snakekit progress: no lesson notebooks (00_meet_the_arm.ipynb ...) in {where}; give the folder "
              "that holds them, e.g. `snakekit progress notebooks`", file=sys.stderr)
        return 2
    print(f"Your progress, from the lessons in {where} as last saved (passed = your notebook's own check):",
          file=out)
    width = max(len(p.stem) for p in lessons)
    rows, total, done_pts, done = [], 0.0, 0.0, 0
    for path in lessons:
        try:
            states = lesson_states(path)
        except FileFormatError as e:
            print(f"  {path.stem:<{width}}  can't be read: {e}", file=out)
            continue
        passed = [s for s in states if s.state == "passed"]
        pts = sum(s.points for s in passed)
        worth = sum(s.points for s in states)
        total, done_pts, done = total + worth, done_pts + pts, done + len(passed)
        rows.extend((path.stem, s) for s in states)
        left = [f"{s.number} {s.state}" for s in states if s.state != "passed"]
        started = any(s.state in ("passed", "failed") for s in states)
        note = "done" if not left else f"({', '.join(left)})" if started else "(not started)"
        print(f"  {path.stem:<{width}}  {len(passed)} of {len(states)} exercises passed, {pts:g} of {worth:g} points"
              f"  {note}", file=out)
    exercises = len(rows)
    print(f"  {'total':<{width}}  {done} of {exercises} exercises passed, {done_pts:g} of {total:g} points", file=out)
    nxt = next(((lesson, s) for lesson, s in rows if s.state != "passed"), None)
    if nxt is None:
        print("Next: every exercise passes its check. Hand the lessons in; the grader also tries hidden cases.",
              file=out)
        return 0
    lesson, s = nxt
    todo = {"failed": f"fix it: its check says \"{s.message}\"",
            "not written": "write it in its answer cell, then run its check cell",
            "not checked": "run its check cell (and the cells above it)"}[s.state]
    print(f"Next: exercise {s.number} in {lesson} ({s.points:g} point{'' if s.points == 1 else 's'}): {todo}", file=out)
    return 0
