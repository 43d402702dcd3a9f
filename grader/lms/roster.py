"""The roster: which student of the course an LMS's upload is.

``<course>/roster.csv`` has a column ``student`` (the student's folder name) and any of
``canvas_id``, ``moodle_id``, ``name`` (the full name as the LMS shows it), ``email``,
``sis_id``, ``login_id``, ``section``. A roster on which two rows share a student id, an LMS
id, a SIS id, a login or an e-mail is refused, naming the rows: two people merged would get
one grade. Two students may share a name; an upload matched only by that name is not guessed.
"""

from __future__ import annotations

import re
from pathlib import Path

from grader.errors import CourseError
from grader.files import ALLOWED_ID, STUDENT_ID, excerpt, read_table, student_id

COURSE = Path("course")
ROSTER_IDS = ("canvas_id", "moodle_id", "name", "email", "sis_id", "login_id")


def normal_name(s: str) -> str:
    return " ".join(str(s).split()).casefold()


def _canvas_name(s: str) -> str:  # Canvas writes the sortable name lower-case, letters and digits only
    return re.sub(r"[\W_]", "", str(s)).casefold()


#: Roster columns no two rows may share (compared as the LMS does: e-mails and logins in any case).
UNIQUE = {"student": str, "canvas_id": str, "moodle_id": str, "sis_id": str, "login_id": str.casefold,
          "email": str.casefold}


def _repeated(rows: list[dict]) -> list[str]:
    """What repeats in a roster: ``the canvas_id '102' is on rows 3 and 5`` for each value two rows share."""
    out = []
    for column, key in UNIQUE.items():
        lines: dict[str, list[int]] = {}
        for line, r in enumerate(rows, start=2):
            if r.get(column) and r.get("student"):
                lines.setdefault(key(r[column]), []).append(line)
        for value, at in lines.items():
            if len(at) > 1:
                where = ", ".join(map(str, at[:-1])) + f" and {at[-1]}"
                out.append(f"the {'student id' if column == 'student' else column} {excerpt(value)} is on rows {where}")
    if len(out) > 5:
        out = out[:5] + [f"and {len(out) - 5} more repeated id(s)"]
    return out


class Roster:
    """Students by LMS id and name (``<course>/roster.csv``)."""

    def __init__(self, rows: list[dict], path: Path | None = None):
        self.rows, self.path = rows, path
        self.students = {r["student"] for r in rows}

    @classmethod
    def load(cls, path: Path | None) -> "Roster | None":
        """The roster at ``path``; :class:`CourseError` naming the row of a student id that is not
        a folder name (``../source``, ``/etc``, a name with ``/`` or a newline)."""
        if path is None:
            return None
        _, rows = read_table(path, "roster", need=("student",),
                             fix=f"give student and any of {', '.join(ROSTER_IDS)}")
        for line, r in enumerate(rows, start=2):
            if r.get("student"):
                student_id(r["student"], f"roster {path}, row {line}")
        repeated = _repeated(rows)
        if repeated:
            raise CourseError(f"roster {path}: {'; '.join(repeated)}; each student has one row and ids of their own "
                              "(a name may repeat): merge or correct the rows, then run the command again")
        return cls([r for r in rows if r.get("student")], path)

    def find(self, column: str, value: str, *, norm=normal_name) -> list[str]:
        return sorted({r["student"] for r in self.rows if r.get(column) and norm(r[column]) == norm(value)})

    def row(self, student: str) -> dict:
        return next((r for r in self.rows if r["student"] == student), {"student": student})

    def who(self, u) -> tuple[str | None, str]:
        """The student id of an upload (a :class:`grader.lms.collect.Upload`), or None and why not."""
        if u.lms == "canvas":
            found = self.find("canvas_id", u.lms_id)
            if not found and u.lms_name:
                found = self.find("name", u.lms_name, norm=_canvas_name)
                if not found:  # Canvas writes "last, first" as lastfirst: the roster's "First Last" reversed
                    found = sorted({r["student"] for r in self.rows if r.get("name") and
                                    _canvas_name(" ".join(r["name"].split()[-1:] + r["name"].split()[:-1])) == _canvas_name(u.lms_name)})
            what = f"Canvas user {u.lms_id} ({excerpt(u.lms_name, quote=False) if u.lms_name else 'anonymous'})"
        elif u.lms == "moodle":
            found = self.find("moodle_id", u.lms_id) or self.find("name", u.lms_name)
            what = f"Moodle participant {u.lms_id} ({excerpt(u.lms_name, quote=False)})"
        else:
            found = [u.lms_id] if u.lms_id in self.students else self.find("login_id", u.lms_id) or self.find("email", u.lms_id)
            what = excerpt(u.lms_id)
        if len(found) == 1:
            return found[0], ""
        if not found:
            return None, f"{what} is not in the roster {self.path}"
        return None, f"{what} matches {len(found)} students of the roster ({excerpt(', '.join(found), quote=False)}); not guessed"


def no_roster_who(u) -> tuple[str | None, str]:
    """The student of an upload when there is no roster: a folder's name if it can be a student id."""
    if u.lms == "folder" and STUDENT_ID.fullmatch(u.lms_id):
        return u.lms_id, ""
    what = {"canvas": f"Canvas user {u.lms_id}", "moodle": f"Moodle participant {u.lms_id} ({excerpt(u.lms_name, quote=False)})"}.get(
        u.lms, excerpt(u.lms_id))
    if u.lms == "folder":
        return None, f"{what} cannot be a student's folder name (a student id is {ALLOWED_ID})"
    return None, f"{what}: no roster to map it to a student (give --roster, or write {COURSE}/roster.csv)"
