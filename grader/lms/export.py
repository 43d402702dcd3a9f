"""``snakekit export`` and ``snakekit return``: grades and feedback back to the students.

    snakekit export [--course DIR] [--lms canvas|moodle] [-o grades.csv] [--assignment A]...
    snakekit return ASSIGNMENT [--course DIR] [--exchange DIR] [-o feedback.zip]

``export`` writes one row per student and one column per assignment (the gradebook's score
minus nbgrader's late penalty, so a score changed in formgrader is there; no submission: 0 once
the gradebook's due date has passed, an empty cell before it) and the total:

* ``--lms canvas``: Canvas's gradebook import ("Import" in Grades): ``Student, ID, SIS User
  ID, SIS Login ID, Section``, one column per assignment, a ``Points Possible`` row, and the
  total as ``Final Points`` (a column Canvas computes itself and ignores on import). Canvas
  matches a student by ``ID`` (the roster's ``canvas_id``), else the SIS ids or the name, and
  an assignment column by its title: name the Canvas assignments as the lessons, or Canvas
  creates new ones.
* ``--lms moodle``: Moodle's "Import grades: CSV file": ``Full name, Email address, ID
  number, Username``, the assignments and ``Total``; in Moodle map "Email address" (or
  "Username") to the user field and each assignment column to its grade item.
* no ``--lms``: ``student``, the assignments, ``total``.

``nbgrader export`` (its long format, one row per student and assignment) keeps working: the
grader writes nbgrader's own gradebook.

``return`` hands back each student's safe feedback page (``<course>/feedback/<student>/<a>/``,
written by ``snakekit grade``):

* collected from a hub's exchange (``nbgrader collect``): the page goes where ``nbgrader
  fetch_feedback`` finds it (nbgrader's own ``release_feedback``, after copying the
  submission's ``timestamp.txt`` and ``submission_secret.txt`` beside it);
* collected from an LMS (``snakekit collect``): one zip for the LMS's bulk upload, each page
  named as the LMS's download named the submission (Canvas: "Re-Upload Submissions", which
  attaches each file as a comment to the submission named by its user and file ids; Moodle:
  "Upload multiple feedback files in a zip", folders ``<Full Name>_<participant id>_assignfeedback_file_/``).
"""

from __future__ import annotations

import contextlib
import csv
import datetime as dt
import os
import re
import shutil
import sys
import zipfile
from pathlib import Path

from grader.files import STUDENT_ID
from grader.lms.collect import read_manifest
from grader.lms.roster import Roster
from snakekit.errors import SnakekitError

from grader.course.folder import config, course_id, default_course, default_roster, gradebook, require
from grader.course.gradebook import NO_TIME, untimed
from grader.errors import CourseError, ReturnInterrupted
from grader.files import CommandParser, check_output, excerpt, one_line, uninterrupted

CANVAS_PREFIX = re.compile(r"^(?P<prefix>.*?_(?:\d+|anon_[A-Za-z0-9]+)_\d+_)")


# --- export -----------------------------------------------------------------------------------


def scores(course: Path, assignments: list[str] | None = None):
    """(assignments, their max scores, {student: {assignment: score after the late penalty}}, their due
    dates (naive UTC, as nbgrader keeps them, or None))."""
    with gradebook(course) as gb:
        graded = [a for a in gb.assignments if a.submissions and a.notebooks]
        if assignments:
            known = {a.name: a for a in gb.assignments}
            missing = [a for a in assignments if a not in known]
            if missing:
                raise CourseError(f"no assignment {', '.join(missing)} in the gradebook; it has "
                                  f"{', '.join(sorted(known)) or 'none'}")
            graded = [known[a] for a in assignments]
        names = [a.name for a in sorted(graded, key=lambda a: (a.duedate is None, a.duedate or 0, a.name))]
        maxes = {a.name: float(a.max_score) for a in graded}
        table: dict[str, dict] = {}
        for a in graded:
            for sub in a.submissions:
                penalty = float(sub.late_submission_penalty or 0.0)
                table.setdefault(sub.student.id, {})[a.name] = round(float(sub.score or 0.0) - penalty, 4)
        dues = {a.name: a.duedate for a in graded}
        return names, maxes, table, dues


def require_graded(course: Path, assignment: str, command: str) -> None:
    """Refuses (CourseError) when a student's submission was collected again after it was graded: the
    gradebook's score and the page would be the earlier attempt's, under the new hand-in's name."""
    from nbgrader.api import MissingEntry

    from grader.scoring.draws import ungraded_attempts

    with gradebook(course) as gb:
        try:
            notebooks = [nb.name for nb in gb.find_assignment(assignment).notebooks]
        except MissingEntry:
            return
    stale = ungraded_attempts(course, assignment, notebooks)
    if stale:
        raise CourseError(f"{assignment}: {len(stale)} student(s) handed in again after they were graded "
                          f"({excerpt(', '.join(stale), quote=False)}): their score and page are the earlier "
                          f"attempt's; grade them first (`snakekit grade {assignment} "
                          + " ".join(f"--student {s}" for s in stale[:5]) + ("..." if len(stale) > 5 else "")
                          + f"`), then run {command} again; nothing was written")


def not_due(dues: dict, now: dt.datetime | None = None) -> dict:
    """The assignments whose due date is still ahead (UTC), with it."""
    now = (now or dt.datetime.now(dt.timezone.utc)).astimezone(dt.timezone.utc).replace(tzinfo=None)
    return {a: due for a, due in dues.items() if due is not None and due > now}


def export(course: Path, lms: str | None, path: Path, roster: Roster | None, assignments=None, out=None) -> int:
    """Write the grades CSV; a student with no submission of an assignment not due yet gets an empty
    cell (no grade, not 0: Moodle's import reads an empty cell as no grade), after its due date 0 (as
    nbgrader export)."""
    names, maxes, table, dues = scores(course, assignments)
    if not names:
        print(f"nothing is graded yet in {course}'s gradebook: the CSV has the students and no assignment's "
              "column; grade an assignment first (`snakekit grade ASSIGNMENT`) before importing it",
              file=out or sys.stdout)
    for a in names:
        require_graded(course, a, "snakekit export")
    ahead = not_due(dues)
    students = sorted(set(table) | (roster.students if roster else set()))
    fmt = lambda x: f"{x:g}"  # noqa: E731
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        if lms == "canvas":
            w.writerow(["Student", "ID", "SIS User ID", "SIS Login ID", "Section", *names, "Final Points"])
            w.writerow(["Points Possible", "", "", "", "", *[fmt(maxes[a]) for a in names], fmt(sum(maxes.values()))])
        elif lms == "moodle":
            w.writerow(["Full name", "Email address", "ID number", "Username", *names, "Total"])
        else:
            w.writerow(["student", *names, "total"])
        for s in students:
            got = [table.get(s, {}).get(a, None if a in ahead else 0.0) for a in names]
            r = roster.row(s) if roster else {}
            if lms == "canvas":
                ident = [r.get("name", s), r.get("canvas_id", ""), r.get("sis_id", ""), r.get("login_id", ""),
                         r.get("section", "")]
            elif lms == "moodle":
                ident = [r.get("name", s), r.get("email", ""), r.get("sis_id", ""), s]
            else:
                ident = [s]
            w.writerow([*ident, *["" if x is None else fmt(x) for x in got],
                        fmt(round(sum(x for x in got if x is not None), 4))])
    for a in names:
        unknown = [s for s in students if a in table.get(s, {}) and untimed(course, a, s)]
        if unknown:
            print(f"{a}: {len(unknown)} student(s) graded without a submission time "
                  f"({excerpt(', '.join(unknown), quote=False)}; '{NO_TIME}' in snakekit grade's CSV): exported as "
                  "on time, no late penalty; collect them again with --times TIMES.csv and grade them before "
                  "importing", file=out or sys.stdout)
    for a in (a for a in names if a in ahead):
        empty = [s for s in students if a not in table.get(s, {})]
        if empty:
            print(f"{a} is due {ahead[a]:%Y-%m-%d %H:%M} UTC: {len(empty)} student(s) with no submission yet "
                  f"({excerpt(', '.join(empty), quote=False)}) get an empty cell (no grade, "
                  "not 0); export after the due date gives them 0", file=out or sys.stdout)
    return len(students)


def export_main(argv: list[str] | None = None, out=None) -> int:
    out = out or sys.stdout
    p = CommandParser(prog="snakekit export", description="One row per student, one column per assignment and the "
                "total (late penalties applied), for Canvas's or Moodle's grade import.")
    p.add_argument("--course", type=Path, default=default_course(),
                   help="the nbgrader course folder (default: the current folder when it holds "
                        "nbgrader_config.py, else course/)")
    p.add_argument("--lms", choices=["canvas", "moodle"], default=None, help="the LMS's import format")
    p.add_argument("-o", "--out", type=Path, default=None, help="the CSV (default: <course>/grades-<lms or all>.csv)")
    p.add_argument("--roster", type=Path, default=None, help="the roster CSV (default: <course>/roster.csv)")
    p.add_argument("--assignment", action="append", default=None, help="only this assignment (repeatable)")
    args = p.parse_args(argv)
    course = args.course
    path = args.out or course / f"grades-{args.lms or 'all'}.csv"
    try:
        if not (course / "gradebook.db").is_file():
            raise CourseError(f"no gradebook in {course} (not a course folder, or nothing graded yet: run it in the "
                              "course folder or give --course DIR; grade an assignment first)")
        check_output(path, course, suffix=".csv", what="-o", command="snakekit export", reads={args.roster: "the roster"})
        roster = Roster.load(default_roster(course, args.roster))
        if args.lms == "canvas" and roster is not None and not any(r.get("canvas_id") for r in roster.rows):
            print("snakekit export: the roster has no canvas_id column: Canvas will match students by name",
                  file=sys.stderr)
        n = export(course, args.lms, path, roster, args.assignment, out=out)
    except (SnakekitError, OSError) as e:
        print(f"snakekit export: {one_line(e)}", file=sys.stderr)
        return 2
    print(f"exported {n} student(s) to {path}" + (f" ({args.lms} import format)" if args.lms else ""), file=out)
    return 0


# --- return -----------------------------------------------------------------------------------


def _pages(course: Path, assignment: str) -> dict[str, list[Path]]:
    root = course / "feedback"
    out = {}
    if root.is_dir():
        for d in sorted(root.iterdir()):
            pages = sorted((d / assignment).glob("*.html")) if (d / assignment).is_dir() else []
            if pages:
                out[d.name] = pages
    return out


def nbgrader_api(course: Path, exchange: Path | None):
    """nbgrader's API as its own commands see the course: the Jupyter config folders'
    ``nbgrader_config.py`` (on a hub's server, the hub's exchange: docker/hub/nbgrader_config.py),
    then the course's; ``exchange`` (if given) as the exchange's root."""
    from jupyter_core.paths import jupyter_config_path
    from nbgrader.apps import NbGraderAPI
    from nbgrader.coursedir import CourseDirectory
    from traitlets.config import Config
    from traitlets.config.loader import ConfigFileNotFound, PyFileConfigLoader

    cfg = Config()
    for folder in reversed(jupyter_config_path()):
        with contextlib.suppress(ConfigFileNotFound):
            cfg.merge(PyFileConfigLoader("nbgrader_config.py", path=folder).load_config())
    cfg.merge(config(course))
    cfg.merge(Config({"CourseDirectory": {"root": str(course), "course_id": course_id(course)}}))
    if exchange is not None:
        cfg.merge(Config({"Exchange": {"root": str(exchange)}}))
    return NbGraderAPI(CourseDirectory(config=cfg), config=cfg)


def release_to_exchange(course: Path, assignment: str, student: str, exchange: Path | None) -> str:
    """nbgrader's own release_feedback for one student (after the files it needs are beside the page)."""
    src = course / "submitted" / student / assignment
    fb = course / "feedback" / student / assignment
    for name in ("timestamp.txt", "submission_secret.txt"):
        shutil.copyfile(src / name, fb / name)
    result = nbgrader_api(course, exchange).release_feedback(assignment, student)
    if not result.get("success"):
        raise CourseError(f"nbgrader release_feedback for {student} failed: "
                          f"{(result.get('error') or result.get('log') or '').strip()[-500:]}")
    return "exchange"


def lms_name(row: dict, page: Path) -> str | None:
    """The zip entry the LMS's bulk upload matches to this student's submission."""
    if row.get("lms") == "canvas":
        m = CANVAS_PREFIX.match(row.get("file", ""))
        return f"{m['prefix']}{page.stem}-feedback.html" if m else None
    if row.get("lms") == "moodle":  # the name and id as Moodle's own folder names them, or None
        folder = f"{row['lms_name']}_{row['lms_id']}_assignfeedback_file_"
        return None if re.search(r"[/\\\x00-\x1f]", folder) or folder.startswith(".") else \
            f"{folder}/{page.stem}-feedback.html"
    if row.get("lms") == "folder":  # a folder of hand-ins: a folder per student (a student id is a safe name)
        return f"{row['student']}/{page.stem}-feedback.html" if STUDENT_ID.fullmatch(row.get("student", "")) else None
    return None


def return_feedback(course: Path, assignment: str, *, exchange: Path | None, zip_path: Path | None, out,
                    before=None) -> tuple[int, list]:
    """Hand the pages back; ``before(course, assignment, out)`` runs once the pages and the manifest
    are read (``snakekit return`` writes the pages whose scores are not the gradebook's again there:
    :func:`grader.commands.nbgrader_plugins.return_main`)."""
    pages = _pages(course, assignment)
    if not pages:
        raise CourseError(f"no feedback pages of {assignment} in {course}/feedback/<student>/{assignment}/; "
                          f"run `snakekit grade {assignment}` first")
    manifest = read_manifest(course, assignment)  # a damaged manifest stops it before anything is written
    require_graded(course, assignment, "snakekit return")
    if before is not None:
        before(course, assignment, out)
    problems, done = [], {"exchange": 0, "zip": 0}
    entries: dict[str, dict[str, Path]] = {}
    written: list[Path] = []
    try:  # a Ctrl-C: what was released and the zips written whole are said, nothing half-written stays
        for student, files in pages.items():
            row = manifest.get(student)
            src = course / "submitted" / student / assignment
            if row and row.get("lms") in ("canvas", "moodle", "folder"):
                names = {lms_name(row, p): p for p in files}
                if None in names:
                    problems.append(f"{student}: the collected file name {excerpt(row.get('file'))} does not carry the "
                                    "LMS's ids")
                    continue
                entries.setdefault(row["lms"], {}).update(names)
                done["zip"] += 1
            elif (src / "submission_secret.txt").is_file() and (src / "timestamp.txt").is_file():
                try:
                    with uninterrupted():  # a Ctrl-C stops between two students
                        release_to_exchange(course, assignment, student, exchange)
                        done["exchange"] += 1
                except CourseError as e:
                    problems.append(str(e))
            else:
                problems.append(f"{student}: neither collected (no row in {course}/collected/{assignment}.csv) "
                                f"nor from the exchange (no submission_secret.txt): the page stays in "
                                f"{course}/feedback/{student}/{assignment}/ for you to hand out (`snakekit collect` the "
                                "notebooks, and `return` bundles their pages)")
        for lms, names in sorted(entries.items()):
            path = zip_path or course / f"feedback-{assignment}-{lms}.zip"
            if len(entries) > 1 and zip_path is not None:
                path = zip_path.with_name(f"{zip_path.stem}-{lms}{zip_path.suffix}")
            check_output(path, course, suffix=".zip", what="the feedback zip", command="snakekit return")
            tmp = path.with_name(f".{path.name}.tmp")
            try:  # written aside, then put in place: a Ctrl-C never leaves half a zip
                with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
                    for name, page in sorted(names.items()):
                        z.write(page, name)
                with uninterrupted():
                    os.replace(tmp, path)
                    written.append(path)
            except KeyboardInterrupt:
                tmp.unlink(missing_ok=True)
                raise
            if lms == "folder":
                print(f"wrote {path}: {len(names)} page(s) of students collected from a folder, one folder per student "
                      "(<student>/<notebook>-feedback.html): hand each its own as their notebooks came in", file=out)
                continue
            how = {"canvas": "Canvas: the assignment's page > Re-Upload Submissions",
                   "moodle": "Moodle: View all submissions > Upload multiple feedback files in a zip"}[lms]
            print(f"wrote {path}: {len(names)} page(s) for the {lms} bulk upload ({how})", file=out)
    except KeyboardInterrupt:
        raise ReturnInterrupted(done["exchange"], written) from None
    if done["exchange"]:
        print(f"released {done['exchange']} student(s)' feedback to the exchange: they get it with Fetch Feedback "
              f"(JupyterLab's Nbgrader > Assignment List) or `nbgrader fetch_feedback {assignment}`", file=out)
    for p in problems:
        print(f"not returned: {p}", file=out)
    return done["exchange"] + done["zip"], problems


def return_main(argv: list[str] | None = None, out=None, *, before=None) -> int:
    """``snakekit return``; ``before`` as :func:`return_feedback`'s."""
    out = out or sys.stdout
    p = CommandParser(prog="snakekit return", description="Hand each student's safe feedback page back: to the hub's "
                "exchange (nbgrader fetch_feedback), as one zip for the LMS's bulk feedback upload, or (collected from "
                "a folder) as one zip with a folder per student.")
    p.add_argument("assignment", help="assignment name, e.g. 06_coded_sweep")
    p.add_argument("--course", type=Path, default=default_course(),
                   help="the nbgrader course folder (default: the current folder when it holds "
                        "nbgrader_config.py, else course/)")
    p.add_argument("--exchange", type=Path, default=None, help="nbgrader's exchange folder (default: the "
                   "course's Exchange.root, else nbgrader's /srv/nbgrader/exchange)")
    p.add_argument("-o", "--out", type=Path, default=None, help="the LMS zip (default: <course>/feedback-<a>-<lms>.zip)")
    args = p.parse_args(argv)
    course = args.course
    try:
        require(course, args.assignment)
        if args.out is not None:
            check_output(args.out, course, suffix=".zip", what="-o", command="snakekit return")
        if args.exchange is not None and not args.exchange.is_dir():
            raise CourseError(f"--exchange {args.exchange} is not a folder")
        n, problems = return_feedback(course.resolve(), args.assignment, exchange=args.exchange,
                                      zip_path=args.out, out=out, before=before)
    except (SnakekitError, OSError) as e:
        print(f"snakekit return: {one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        released, zips = (e.released, e.zips) if isinstance(e, ReturnInterrupted) else (0, [])
        print(f"snakekit return: interrupted; {released} student(s)' feedback released to the exchange, "
              f"{len(zips)} LMS zip(s) written whole{' (' + ', '.join(map(str, zips)) + ')' if zips else ''}, "
              f"no zip half-written; run `snakekit return {args.assignment}` again to finish", file=sys.stderr)
        return 130
    print(f"returned {n} student(s)' feedback of {args.assignment}" + (f"; {len(problems)} not" if problems else ""),
          file=out)
    return 1 if problems else 0
