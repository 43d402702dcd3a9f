"""One number everywhere: the feedback pages written from the gradebook's scores only.

nbgrader's gradebook is the one place a score lives: the grader's points, a score, extra credit
or comment a TA set in formgrader, and nbgrader's late penalty. The class CSV
(:func:`grader.course.gradebook.class_rows`), ``snakekit export`` and formgrader read it; the
pages are written from it here, after every action that changes a score: a batch (once the
student's scores are in the gradebook), a score or comment saved in formgrader
(:mod:`grader.commands.nbgrader_plugins`), and ``snakekit return`` (any page whose numbers are no
longer the gradebook's). The grader's messages, checks and plots come from what the batch kept in
the autograded notebook (:func:`grader.feedback.notebook.recorded`); only the numbers are the
gradebook's. A page carries a stamp of the numbers it shows (:func:`stamp`), so a stale page is
found without reading the gradebook twice.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
from pathlib import Path

import nbformat

from grader.course.gradebook import SubmissionScores, class_rows, read_class_csv, scores_of, write_csv
from grader.feedback.notebook import build, page_head, recorded
from grader.feedback.exporter import page_exporter
from grader.scoring.wording import points, title

#: The page's ``<meta>`` that holds the stamp of the gradebook's numbers it shows.
STAMP = "snakekit-gradebook"
_STAMP = re.compile(rf'<meta name="{STAMP}" content="([0-9a-f]+)">')


def stamp(numbers: SubmissionScores) -> str:
    """A short digest of everything of ``numbers`` a page shows (a page with another stamp is stale)."""
    raw = json.dumps(dataclasses.asdict(numbers), sort_keys=True, default=str)
    return hashlib.blake2b(raw.encode(), digest_size=8).hexdigest()


def page_stamp(path: Path) -> str | None:
    """The stamp a written page carries (None: no page, or one written before stamps)."""
    try:
        m = _STAMP.search(Path(path).read_text(encoding="utf-8", errors="replace")[:4096])
    except OSError:
        return None
    return m.group(1) if m else None


def _duration(seconds: float) -> str:
    """A time late in a student's words (whole minutes, at least one).

    >>> _duration(9000), _duration(2 * 86400 + 3 * 3600 + 300), _duration(5)
    ('2 h 30 min', '2 days 3 h 5 min', '1 min')
    """
    minutes = max(1, round(seconds / 60))
    days, rest = divmod(minutes, 1440)
    hours, minutes = divmod(rest, 60)
    parts = [f"{days} day{'s' if days != 1 else ''}" if days else "", f"{hours} h" if hours else "",
             f"{minutes} min" if minutes else ""]
    return " ".join(p for p in parts if p)


def head(numbers: SubmissionScores, status: str, detail: str, tests: dict | None = None) -> str:
    """The page's first cell: the score every place shows, each exercise's points (a score the teacher
    set and extra credit said so), and what a late penalty took. Each exercise is named as its lesson names
    it (``tests``: the test cells' sources by grade id, :func:`grader.scoring.wording.title`)."""
    rows = []
    for g in numbers.exercises:
        note = "ok" if g.score >= g.max_score else "see below"
        if g.manual is not None:
            note += f"; set by your teacher (the grader gave {points(g.auto or 0)})"
        if g.extra:
            note += f"; {g.extra:+g} extra from your teacher"
        name = title(g.grade_id, (tests or {}).get(g.grade_id, ""))
        rows.append((name, g.score, g.max_score, note))
    late = ""
    if numbers.late_penalty:
        when = f" ({_duration(numbers.seconds_late)} after the due date)" if numbers.seconds_late > 0 else ""
        late = (f"Handed in late{when}: the late penalty took "
                f"{numbers.late_penalty:g} point(s) off the {round(numbers.raw, 4):g} your exercises scored, "
                f"so your score is {numbers.score:g}.\n\n")
    return page_head(numbers.assignment, numbers.student, numbers.score, numbers.max_score, status, detail, rows,
                     tests, late)


def test_sources(gb, assignment: str, notebook: str) -> dict[str, str]:
    """Each autograded test cell of ``notebook`` by grade id, with its instructor source (hidden tests in it)."""
    source = gb.find_notebook(notebook, assignment)
    solution = {c.name for c in source.solution_cells}
    sources = {c.name: c.source for c in source.source_cells}
    return {g.name: sources[g.name] for g in source.grade_cells if g.cell_type == "code" and g.name not in solution}


def page(nb, numbers: SubmissionScores, notebook: str, tests: dict[str, str], *, kept=None,
         hide_paths: dict[str, str] | None = None):
    """The feedback notebook of ``notebook``: ``nb`` (the autograded notebook, or what stands for it) with
    the grader's verdicts (kept in ``nb`` by :func:`grader.feedback.notebook.annotate_notebook`, else
    ``kept``, as :func:`grader.feedback.notebook.recorded` gives them) and the gradebook's ``numbers``. A score the teacher set replaces the grader's and the
    verdict says so; a notebook with no verdicts kept gets the gradebook's points with no messages."""
    from grader.scoring.score import ExerciseScore
    from grader.scoring.verdict import SubmissionResult

    kept = recorded(nb) or kept
    status, detail, stopped, timeout, exercises, plots = kept or ("graded", "", None, None, [], {})
    by_id = {e.grade_id: e for e in exercises}
    final = []
    for g in numbers.exercises:
        if g.notebook != notebook or g.grade_id not in tests:
            continue
        mine = by_id.get(g.grade_id) or ExerciseScore(g.grade_id, g.score, g.max_score, "scored", "")
        said = ""
        if g.manual is not None and abs(g.manual - (g.auto or 0.0)) > 1e-9:
            said = f"Your teacher set the points to {g.manual:g} (the grader gave {g.auto or 0:g}). "
        if g.extra:
            said += f"Your teacher gave {g.extra:+g} extra point(s). "
        final.append(dataclasses.replace(mine, score=g.score, max_score=g.max_score, message=said + mine.message))
    result = SubmissionResult(numbers.student, numbers.assignment, numbers.score, numbers.max_score, status, detail,
                              tuple(final))
    comments = {cell: text for where, cell, text in numbers.comments if where == notebook}
    return build(nb, student=numbers.student, assignment=numbers.assignment, result=result,
                 test_sources=tests, stopped=stopped, timeout=timeout, plots=plots, comments=comments,
                 hide_paths=hide_paths, head=head(numbers, status, detail, tests))


def html(feedback_nb, numbers: SubmissionScores) -> str:
    """The page's HTML, stamped with the numbers it shows."""
    body, _ = page_exporter().from_notebook_node(feedback_nb)
    return re.sub(r"<head([^>]*)>", lambda m: f'{m.group(0)}\n<meta name="{STAMP}" content="{stamp(numbers)}">',
                  body, count=1)


def write_pages(course: Path, assignment: str, student: str, *, numbers: SubmissionScores | None = None,
                bases: dict | None = None, kept=None, hide_paths: dict[str, str] | None = None) -> list[Path]:
    """Write the student's page of every notebook of ``assignment`` from the gradebook.

    ``bases``: the notebook each page is made of, by notebook name (default: the autograded
    notebook, else an empty one); ``kept``: the grader's verdicts for a notebook that does not keep
    them (a submission that never ran); ``numbers``: the gradebook's, when already read.
    """
    from grader.course.folder import gradebook

    course = Path(course)
    if numbers is None:
        numbers = scores_of(course, assignment, {student})[student]
    with gradebook(course) as gb:
        names = sorted(nb.name for nb in gb.find_assignment(assignment).notebooks)
        tests = {name: test_sources(gb, assignment, name) for name in names}
    folder = course / "feedback" / student / assignment
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name in names:
        nb = (bases or {}).get(name)
        graded = course / "autograded" / student / assignment / f"{name}.ipynb"
        if nb is None:
            nb = nbformat.read(graded, as_version=4) if graded.is_file() else nbformat.v4.new_notebook()
        body = html(page(nb, numbers, name, tests[name], kept=kept, hide_paths=hide_paths), numbers)
        tmp = folder / f".{name}.html.tmp"
        tmp.write_text(body, encoding="utf-8")
        os.replace(tmp, folder / f"{name}.html")
        written.append(folder / f"{name}.html")
    return written


def stale(course: Path, assignment: str, numbers: SubmissionScores) -> bool:
    """Whether a page of the student's is missing or shows other numbers than the gradebook's."""
    folder = Path(course) / "feedback" / numbers.student / assignment
    pages = sorted(folder.glob("*.html"))
    return not pages or any(page_stamp(p) != stamp(numbers) for p in pages)


def refresh(course: Path, assignment: str, students=None, *, after=None, csv: Path | None = None) -> list[str]:
    """After an action that changed scores outside a batch (formgrader, a late penalty): every page of
    ``students`` (default: the class) whose numbers are not the gradebook's is written again, and the
    class CSV (default: ``<course>/grades-<assignment>.csv``, if it exists) gets the gradebook's rows.
    ``after(course, assignment, student)``: what runs after a student's pages are written (the lab's part).
    Returns the students whose pages were written."""
    course = Path(course)
    done = []
    for student, numbers in scores_of(course, assignment, students).items():
        if stale(course, assignment, numbers):
            write_pages(course, assignment, student, numbers=numbers)
            if after is not None:
                after(course, assignment, student)
            done.append(student)
    path = csv or course / f"grades-{assignment}.csv"
    if path.is_file():
        write_csv(class_rows(course, assignment, previous=read_class_csv(path)), path)
    return done

