"""What a batch writes for the TA: scores into nbgrader's gradebook (with nbgrader's late
penalties), and the class CSV."""

from __future__ import annotations

import contextlib
import csv
import os
import shutil
import warnings
from pathlib import Path

import nbformat

from grader.course.folder import db_url as _db_url

CSV_COLUMNS = ["student", "assignment", "score", "max_score", "status", "raw_score", "late_penalty", "submitted_at",
               "detail"]


def write_grade(course: Path, a, r, late_plugin=None, lock=None) -> None:
    """Write one submission's scores to the course's gradebook (one writer: the batch's main
    thread), its late penalty, and what nbgrader's ``release_feedback`` reads beside its page."""
    from nbgrader.api import Gradebook
    from nbgrader.coursedir import CourseDirectory

    src = course / "submitted" / r.student / a.name
    timestamp = CourseDirectory(root=str(course)).get_existing_timestamp(str(src))
    by_id = {e.grade_id: e for e in r.exercises}
    with (lock or contextlib.nullcontext()), warnings.catch_warnings(), Gradebook(_db_url(course), a.course_id) as gb:
        warnings.simplefilter("ignore")  # nbgrader's SQLAlchemy session warnings; nothing to act on
        gb.update_or_create_student(r.student)
        sub = gb.update_or_create_submission(a.name, r.student, **({"timestamp": timestamp} if timestamp else {}))
        for nb in sub.notebooks:
            for grade in nb.grades:
                if grade.name in by_id:
                    grade.auto_score = by_id[grade.name].score
                    # as nbgrader's autograde: a score a grader entered by hand stays, flagged for review
                    grade.needs_manual_grade = grade.manual_score is not None
            nb.flagged = r.status != "graded"  # formgrader shows the flag: look at this one
        gb.db.commit()
    late_penalties(course, a.name, r.student, late_plugin)
    fb = course / "feedback" / r.student / a.name
    for name in ("timestamp.txt", "submission_secret.txt"):  # what nbgrader's release_feedback reads
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


def class_rows(course: Path, assignment: str, results: list[SubmissionResult] = (), previous: dict | None = None) -> list[dict]:
    """One row per student with a submission of ``assignment`` in the gradebook.

    Scores are the gradebook's (so a score a grader changed in formgrader is there) minus
    nbgrader's late penalty; the status is this run's, else the previous CSV's.
    """
    from grader.course.folder import gradebook

    now = {r.student: r for r in results}
    previous = previous or {}
    rows = []
    with gradebook(course) as gb:
        a = gb.find_assignment(assignment)
        for sub in sorted(a.submissions, key=lambda s: s.student.id):
            s = sub.student.id
            raw = float(sub.score or 0.0)
            penalty = float(sub.late_submission_penalty or 0.0)
            if s in now:
                status, detail = now[s].status, now[s].detail
            else:
                status, detail = previous.get(s, {}).get("status") or "graded", previous.get(s, {}).get("detail", "")
            manual = [g.name for nb in sub.notebooks for g in nb.grades if g.manual_score is not None]
            if manual and "set by hand" not in detail:
                detail = "; ".join(x for x in (detail, f"score of {', '.join(manual)} set by hand in formgrader") if x)
            rows.append({"student": s, "assignment": assignment, "score": f"{round(raw - penalty, 4):g}",
                         "max_score": f"{float(a.max_score):g}", "status": status, "raw_score": f"{round(raw, 4):g}",
                         "late_penalty": f"{round(penalty, 4):g}",
                         "submitted_at": sub.timestamp.strftime("%Y-%m-%d %H:%M:%S UTC") if sub.timestamp else "",
                         "detail": detail})
    return rows


def read_class_csv(path: Path) -> dict[str, dict]:
    """The rows of an earlier class CSV by student (empty if there is none)."""
    from grader.files import read_table

    if not Path(path).is_file():
        return {}
    return {r["student"]: r for r in read_table(path, "class CSV", need=("student",))[1] if r.get("student")}


def write_csv(rows: list[dict], path: Path) -> Path:
    """Write the class CSV (to a temporary file first, then in place: never a half-written CSV)."""
    tmp = Path(path).with_name(f".{Path(path).name}.tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, CSV_COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k, "") for k in CSV_COLUMNS})
    os.replace(tmp, path)
    return Path(path)
