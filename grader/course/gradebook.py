"""What a batch writes for the TA: scores into nbgrader's gradebook (with nbgrader's late
penalties), and the class CSV; and a submission's scores as the gradebook holds them
(:func:`submission_scores`), which the CSV, ``snakekit export``, formgrader and the feedback
pages (:mod:`grader.feedback.scores`) all show."""

from __future__ import annotations

import contextlib
import csv
import os
import shutil
import warnings
from dataclasses import dataclass
from pathlib import Path

import nbformat

from grader.course.folder import db_url as _db_url

#: The class CSV's columns; after them, one per graded cell (its grade id) with its points in the gradebook.
CSV_COLUMNS = ["student", "assignment", "score", "max_score", "status", "raw_score", "late_penalty", "submitted_at",
               "detail"]


@dataclass(frozen=True)
class ExerciseGrade:
    """One graded cell's points as the gradebook holds them: the grader's (``auto``), a TA's
    (``manual``, which replaces it) and a TA's extra credit, as nbgrader's ``Grade.score`` adds them."""

    grade_id: str
    notebook: str
    max_score: float
    auto: float | None
    manual: float | None = None
    extra: float = 0.0

    @property
    def score(self) -> float:
        base = self.manual if self.manual is not None else self.auto
        return 0.0 if base is None else round(base + self.extra, 4)


@dataclass(frozen=True)
class SubmissionScores:
    """A submission's numbers in the gradebook: every graded cell, nbgrader's late penalty
    (``raw - late_penalty`` is the score every place shows) and the TA's comments
    (``(notebook, cell, text)``)."""

    student: str
    assignment: str
    max_score: float
    raw: float
    late_penalty: float
    seconds_late: float
    exercises: tuple[ExerciseGrade, ...]
    comments: tuple[tuple[str, str, str], ...] = ()

    @property
    def score(self) -> float:
        return round(self.raw - self.late_penalty, 4)


def cell_order(course: Path, assignment: str) -> dict[str, int]:
    """Each cell's place in the assignment's source notebooks (grade id -> index), to list exercises as the
    lesson does; empty when the course has no source (then the gradebook's order)."""
    from grader.course.restore import release_order

    names = sorted(p.stem for p in (Path(course) / "source" / assignment).glob("*.ipynb"))
    cells = [gid for name in names for gid, _ in release_order(course, assignment, name) if gid]
    return {gid: i for i, gid in enumerate(cells)}


def submission_scores(gb, sub, order: dict[str, int] | None = None) -> SubmissionScores:
    """The numbers of ``sub`` (an nbgrader ``SubmittedAssignment`` of the open gradebook ``gb``)."""
    order = order or {}
    grades, comments = [], []
    for nb in sorted(sub.notebooks, key=lambda n: n.name):
        for g in nb.grades:
            grades.append(ExerciseGrade(g.name, nb.name, float(g.max_score), g.auto_score, g.manual_score,
                                        float(g.extra_credit or 0.0)))
        comments += [(nb.name, c.name, c.manual_comment) for c in nb.comments if c.manual_comment]
    grades.sort(key=lambda g: (order.get(g.grade_id, len(order)), g.notebook, g.grade_id))
    return SubmissionScores(sub.student.id, sub.assignment.name, float(sub.max_score), float(sub.score or 0.0),
                            float(sub.late_submission_penalty or 0.0), float(sub.total_seconds_late or 0.0),
                            tuple(grades), tuple(sorted(comments)))


def scores_of(course: Path, assignment: str, students=None) -> dict[str, SubmissionScores]:
    """:class:`SubmissionScores` of every submission of ``assignment`` in the gradebook (or of ``students``)."""
    from grader.course.folder import gradebook

    order = cell_order(course, assignment)
    with gradebook(course) as gb:
        subs = gb.find_assignment(assignment).submissions
        return {sub.student.id: submission_scores(gb, sub, order) for sub in subs
                if students is None or sub.student.id in students}


#: The class CSV's status of a new attempt whose earlier attempt had a score set by hand (not carried over).
NOT_CARRIED = "hand-set score not carried over"


@dataclass(frozen=True)
class HandSet:
    """A score a TA set by hand in formgrader on a cell of an earlier attempt (``manual``, None if only
    extra credit was given), and its extra credit."""

    grade_id: str
    manual: float | None
    extra: float

    def said(self) -> str:
        parts = ([f"score {self.manual:g}"] if self.manual is not None else []) + \
            ([f"extra credit {self.extra:+g}"] if self.extra else [])
        return f"{self.grade_id} ({' and '.join(parts)})"


def not_carried(dropped: list[HandSet]) -> str:
    """What the TA reads of the hand-set scores a new attempt did not take over (the CSV's detail, the terminal).

    >>> not_carried([HandSet("ex1_test", 2.0, 0.0), HandSet("ex2_test", None, 0.5)])
    "set by hand on the earlier attempt, not carried over to this new one (graded on its own): ex1_test (score 2), ex2_test (extra credit +0.5); set it again in formgrader if it is meant for this attempt (the earlier values stay in the gradebook's backup made before this grading, in backups/ beside the gradebook)"
    """
    return ("set by hand on the earlier attempt, not carried over to this new one (graded on its own): "
            + ", ".join(h.said() for h in dropped) + "; set it again in formgrader if it is meant for this attempt "
            "(the earlier values stay in the gradebook's backup made before this grading, in backups/ beside the gradebook)")


def write_grade(course: Path, a, r, late_plugin=None, lock=None, *, new_attempt: bool = False) -> list[HandSet]:
    """Write one submission's scores to the course's gradebook (one writer: the batch's main
    thread) and its late penalty. A score set by hand belongs to the attempt it was set on: for a
    ``new_attempt`` (a resubmission) the earlier attempt's hand-set scores and extra credit are cleared,
    and returned, so the TA is told; otherwise they stay."""
    from nbgrader.api import Gradebook
    from nbgrader.coursedir import CourseDirectory

    src = course / "submitted" / r.student / a.name
    timestamp = CourseDirectory(root=str(course)).get_existing_timestamp(str(src))
    by_id = {e.grade_id: e for e in r.exercises}
    dropped = []
    with (lock or contextlib.nullcontext()), warnings.catch_warnings(), Gradebook(_db_url(course), a.course_id) as gb:
        warnings.simplefilter("ignore")  # nbgrader's SQLAlchemy session warnings; nothing to act on
        gb.update_or_create_student(r.student)
        # the time belongs to the file: a notebook without timestamp.txt has no time, never the one an earlier
        # attempt left in the gradebook (nbgrader's autograde would keep that)
        sub = gb.update_or_create_submission(a.name, r.student, timestamp=timestamp)
        for nb in sub.notebooks:
            for grade in nb.grades:
                if new_attempt and (grade.manual_score is not None or grade.extra_credit):
                    dropped.append(HandSet(grade.name, grade.manual_score, float(grade.extra_credit or 0.0)))
                    grade.manual_score, grade.extra_credit = None, None
                if grade.name in by_id:
                    grade.auto_score = by_id[grade.name].score
                    # as nbgrader's autograde: a score a grader entered by hand stays, flagged for review
                    grade.needs_manual_grade = grade.manual_score is not None
            nb.flagged = r.status != "graded" or bool(dropped)  # formgrader shows the flag: look at this one
        gb.db.commit()
    late_penalties(course, a.name, r.student, late_plugin)
    return dropped


#: The class CSV's status of a submission graded without a time while an earlier attempt had one.
NO_TIME = "no submission time"


def untimed(course: Path, assignment: str, student: str) -> bool:
    """The notebook to grade has no submission time, while an earlier attempt of the student had one
    (``snakekit collect`` keeps that time beside the earlier file in ``attempts/``): its lateness is unknown."""
    folder = Path(course) / "submitted" / student / assignment
    return not (folder / "timestamp.txt").is_file() and \
        any((folder / "attempts").glob("previously-collected-*-timestamp.txt"))


def keep_release_files(course: Path, assignment: str, student: str) -> None:
    """Copy what nbgrader's ``release_feedback`` reads beside the student's pages."""
    src, fb = course / "submitted" / student / assignment, course / "feedback" / student / assignment
    for name in ("timestamp.txt", "submission_secret.txt"):
        if fb.is_dir() and (src / name).is_file() and not (src / name).is_symlink():
            shutil.copyfile(src / name, fb / name)


def late_penalties(course: Path, assignment: str, student: str, plugin=None) -> None:
    """Each notebook's late penalty, as nbgrader's ``AssignLatePenalties`` (with the course's
    ``LateSubmissionPlugin`` or ``AssignLatePenalties.plugin_class``) sets it in autograde."""
    from nbgrader.preprocessors import AssignLatePenalties

    from grader.course.folder import on_path, config

    with on_path(Path(course)), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pre = plugin or AssignLatePenalties(config=config(course))
        with _throwaway_log(pre):
            for nb in _notebook_names(course, assignment):
                resources = {"nbgrader": {"notebook": nb, "assignment": assignment, "student": student,
                                          "db_url": _db_url(course)}}
                pre.preprocess(nbformat.v4.new_notebook(), resources)


def _notebook_names(course: Path, assignment: str) -> list[str]:
    from grader.course.folder import gradebook

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


def class_rows(course: Path, assignment: str, results: list = (), previous: dict | None = None) -> list[dict]:
    """One row per student with a submission of ``assignment`` in the gradebook.

    Scores are the gradebook's (so a score a grader changed in formgrader is there) minus
    nbgrader's late penalty, and each graded cell's points under its grade id; the status is
    this run's, else the previous CSV's.
    """
    from grader.course.folder import gradebook

    now = {r.student: r for r in results}
    previous = previous or {}
    rows = []
    order = cell_order(course, assignment)
    with gradebook(course) as gb:
        a = gb.find_assignment(assignment)
        for sub in sorted(a.submissions, key=lambda s: s.student.id):
            s = sub.student.id
            got = submission_scores(gb, sub, order)
            if s in now:
                status, detail = now[s].status, now[s].detail
            else:
                status, detail = previous.get(s, {}).get("status") or "graded", previous.get(s, {}).get("detail", "")
            if status == "graded" and untimed(course, assignment, s):
                status = NO_TIME
                detail = "; ".join(x for x in (detail, "graded as on time: this notebook has no submission time "
                                               "(the earlier attempt's stays with it in attempts/)") if x)
            manual = [g.grade_id for g in got.exercises if g.manual is not None]
            if manual and "set by hand" not in detail:
                detail = "; ".join(x for x in (detail, f"score of {', '.join(manual)} set by hand in formgrader") if x)
            rows.append({"student": s, "assignment": assignment, "score": f"{got.score:g}",
                         "max_score": f"{float(a.max_score):g}", "status": status, "raw_score": f"{round(got.raw, 4):g}",
                         "late_penalty": f"{round(got.late_penalty, 4):g}",
                         "submitted_at": sub.timestamp.strftime("%Y-%m-%d %H:%M:%S UTC") if sub.timestamp else "",
                         "detail": detail, **{g.grade_id: f"{g.score:g}" for g in got.exercises}})
    return rows


def read_class_csv(path: Path) -> dict[str, dict]:
    """The rows of an earlier class CSV by student (empty if there is none)."""
    from grader.files import read_table

    if not Path(path).is_file():
        return {}
    return {r["student"]: r for r in read_table(path, "class CSV", need=("student",))[1] if r.get("student")}


def write_csv(rows: list[dict], path: Path) -> Path:
    """Write the class CSV (to a temporary file first, then in place: never a half-written CSV): the
    :data:`CSV_COLUMNS`, then one column per graded cell, in the order the rows give them."""
    columns = list(CSV_COLUMNS)
    for r in rows:
        columns += [k for k in r if k not in columns]
    tmp = Path(path).with_name(f".{Path(path).name}.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, columns)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in columns})
    os.replace(tmp, path)
    return Path(path)
