"""``snakekit collect ASSIGNMENT --from DOWNLOAD``: an LMS's download into nbgrader's ``submitted/``.

    snakekit collect 06_coded_sweep --from submissions.zip [--roster roster.csv] [--times times.csv]

Reads three layouts (a zip, or the folder it was unpacked into):

* Canvas ("Download Submissions"): ``<sortablename>[_LATE]_<userid>_<fileid>_<filename>``;
  ``LATE`` is Canvas's late mark, ``<fileid>`` grows with every upload, and a file uploaded
  again under the same name is renamed ``<name>-1.ipynb`` by Canvas. The download carries no
  submission times (every zip entry is stamped with the time the zip was made).
* Moodle ("Download all submissions"): a folder ``<Full Name>_<participantid>_assignsubmission_file[_]/``
  per student (or, without folders, ``<Full Name>_<participantid>_assignsubmission_file_<filename>``).
  Moodle's times are in its grading worksheet ("Download grading worksheet"), which ``--times`` reads.
* a plain folder (or zip) of ``<student>.ipynb`` or ``<student>/<anything>.ipynb``.

A roster CSV (``--roster``, default ``<course>/roster.csv``) maps the LMS's ids and names to
student ids: a column ``student`` and any of ``canvas_id``, ``moodle_id``, ``name`` (the full
name as the LMS shows it), ``email``, ``sis_id``, ``login_id``, ``section``. A roster on which
two rows share a student id, LMS id, SIS id, login or e-mail is refused, naming the rows (two
people merged would get one grade). A file whose student the roster does not name (or whose
name two students share) is reported and kept aside in
``<course>/collected/<assignment>-unmatched/``, never guessed.

Per student the newest notebook of the assignment wins (latest time, then Canvas's file id,
then the ``-N`` resubmission number); earlier ones are kept in ``submitted/<student>/<a>/attempts/``
and not graded. A notebook under another name that holds the assignment's cells (its grade
ids) is found and saved under the assignment's name; a download none of whose notebooks is
the assignment's, while some are another assignment's (by their grade ids), is refused, naming
that assignment. The submission time becomes nbgrader's
``timestamp.txt`` (so the gradebook's due date and the course's late-penalty plugin apply); a
submission Canvas marks LATE without a time is stamped one second after the due date. A time
collected before is never replaced by that guess: a file collected again unchanged keeps its
time, and the new files that have no time are named. What was
collected is listed in ``<course>/collected/<assignment>.csv`` (``snakekit return`` reads it
to name the LMS's feedback files). Exit codes: 0 every file placed, 1 some could not be (see
the report), 2 bad arguments.
"""

from __future__ import annotations

import csv
import datetime as dt
import json
import shutil
import sys
from pathlib import Path

from snakekit.errors import SnakekitError

from grader.course.folder import default_course, default_roster, gradebook, require
from grader.errors import CollectInterrupted, CourseError
from grader.files import CommandParser, excerpt, file_name, one_line, read_table, student_id, uninterrupted, unique_in
from grader.lms.download import RESUBMISSION, Upload, read_download
from grader.lms.roster import Roster, no_roster_who, normal_name

MANIFEST_COLUMNS = ["student", "lms", "lms_id", "lms_name", "file", "notebook", "submitted_at", "late", "attempts", "note"]


# --- submission times ---------------------------------------------------------------------------

TIME_COLUMNS = ("submitted_at", "time", "timestamp", "Last modified (submission)")
ID_COLUMNS = ("student", "canvas_id", "moodle_id", "Identifier", "email", "Email address", "name", "Full name")


def read_times(path: Path, zone: dt.tzinfo) -> list[tuple[str, str, dt.datetime]]:
    """``(column, value, time)`` rows of a times CSV (Moodle's grading worksheet reads as is)."""
    import dateutil.parser

    cols, rows = read_table(path, "times file")
    tcol = next((c for c in TIME_COLUMNS if c in cols), None)
    icol = next((c for c in ID_COLUMNS if c in cols), None)
    if tcol is None or icol is None:
        raise CourseError(f"times file {path} needs a time column ({', '.join(TIME_COLUMNS)}) and an id column "
                          f"({', '.join(ID_COLUMNS)}); it has {excerpt(', '.join(cols))}")
    out = []
    for line, r in enumerate(rows, start=2):
        raw = r.get(tcol, "")
        if not raw or raw in ("-", "No submission"):
            continue
        try:
            t = dateutil.parser.parse(raw[:100])
        except (ValueError, OverflowError) as e:
            raise CourseError(f"times file {path}, row {line}: cannot read the time {excerpt(raw)} "
                              f"({excerpt(e, 100)})") from None
        if t.tzinfo is None:
            t = t.replace(tzinfo=zone)
        value = r.get(icol, "")
        if icol == "Identifier":  # Moodle: "Participant 12345"
            value = value.split()[-1] if value else value
        out.append((icol, value, t.astimezone(dt.timezone.utc)))
    return out


def _time_for(student: str, uploads: list[Upload], roster: Roster | None, times) -> dt.datetime | None:
    row = roster.row(student) if roster else {"student": student}
    keys = {("student", student)}
    for u in uploads:
        keys |= {("canvas_id", u.lms_id), ("moodle_id", u.lms_id), ("Identifier", u.lms_id),
                 ("name", normal_name(u.lms_name)), ("Full name", normal_name(u.lms_name))}
    for col in ("email", "name", "moodle_id", "canvas_id"):
        if row.get(col):
            keys |= {(col, normal_name(row[col]) if col == "name" else row[col])}
    keys |= {("Email address", row.get("email", "")), ("Full name", normal_name(row.get("name", "")))}
    found = [t for col, value, t in times if (col, normal_name(value) if "name" in col.lower() else value) in keys and value]
    return max(found) if found else None


# --- matching notebooks to the assignment -----------------------------------------------------


def assignment_cells(course: Path, assignment: str) -> dict[str, set[str]]:
    """Grade ids of the assignment's graded and answer cells, per notebook (from the gradebook)."""
    from nbgrader.api import MissingEntry

    from grader.course.assignment import ensure_released

    ensure_released(course, assignment)
    with gradebook(course) as gb:
        try:
            a = gb.find_assignment(assignment)
        except MissingEntry as e:
            raise CourseError(f"'{assignment}' is not in the gradebook; run nbgrader generate_assignment {assignment}") from e
        return {nb.name: {c.name for c in nb.grade_cells} | {c.name for c in nb.solution_cells} for nb in a.notebooks}


def grade_ids(data: bytes) -> set[str] | None:
    try:
        nb = json.loads(data.decode("utf-8"))
        return {c.get("metadata", {}).get("nbgrader", {}).get("grade_id") for c in nb.get("cells", [])} - {None}
    except (ValueError, UnicodeDecodeError, AttributeError):
        return None


def which_notebook(u: Upload, cells: dict[str, set[str]]) -> str | None:
    """The assignment notebook an upload is (by name, or else by its cells), or None."""
    stem = Path(u.file).stem
    m = RESUBMISSION.match(stem)
    if stem in cells:
        return stem
    if m and m["stem"] in cells:
        return m["stem"]
    ids = grade_ids(u.data) or set()
    best = max(cells, key=lambda nb: len(ids & cells[nb]), default=None)
    return best if best is not None and len(ids & cells[best]) * 2 >= max(len(cells[best]), 1) else None


def _not_another_assignments(course: Path, assignment: str, source: Path, uploads: list[Upload], cells,
                             options: str = "") -> None:
    """Refuse a download none of whose notebooks is ``assignment``'s while some are another
    assignment's of the gradebook (by their grade ids): nothing of it is placed."""
    if not uploads or any(which_notebook(u, cells) for u in uploads):
        return
    with gradebook(course) as gb:
        others = {a.name: {nb.name: {c.name for c in nb.grade_cells} | {c.name for c in nb.solution_cells}
                           for nb in a.notebooks} for a in gb.assignments if a.name != assignment}
    found: dict[str, int] = {}
    for u in uploads:
        ids = grade_ids(u.data) or set()
        for name, nbs in others.items():
            if ids and any(len(ids & c) * 2 >= max(len(c), 1) for c in nbs.values()):
                found[name] = found.get(name, 0) + 1
    if found:
        other = max(found, key=lambda name: (found[name], name))
        raise CourseError(f"{source}: its notebooks are {other}'s, not {assignment}'s ({found[other]} of "
                          f"{len(uploads)} hold {other}'s cells, none {assignment}'s); nothing was collected. Collect it "
                          f"as `snakekit collect {other} --from {source}{options}`, or download {assignment}'s "
                          "submissions")


# --- collecting ---------------------------------------------------------------------------------


def _stamp(t: dt.datetime) -> str:
    return t.astimezone(dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S.%f UTC")


def collect(course: Path, assignment: str, source: Path, *, roster: Roster | None = None, times=(), out=None,
            options: str = ""):
    """Place the download's notebooks in ``submitted/``; returns (collected rows, problems).

    ``options``: the command's other options as the TA typed them, for a command it suggests."""
    out = out or sys.stdout
    cells = assignment_cells(course, assignment)
    with gradebook(course) as gb:
        due = gb.find_assignment(assignment).duedate
    uploads, problems = read_download(source)
    if not uploads and not problems:
        raise CourseError(f"{source} holds no notebook (.ipynb)")
    old = read_manifest(course, assignment)  # a damaged one stops collect before anything is placed
    _not_another_assignments(course, assignment, source, uploads, cells, options)
    by_student: dict[str, list[Upload]] = {}
    unmatched = []
    aside = course / "collected" / f"{assignment}-unmatched"
    for u in uploads:
        student, why = roster.who(u) if roster else no_roster_who(u)
        if student is None:
            aside.mkdir(parents=True, exist_ok=True)
            kept = unique_in(aside, Path(u.entry.replace("\\", "/")).name, u.data)
            kept.write_bytes(u.data)
            problems.append(f"{excerpt(u.entry, quote=False)}: {why} (kept as {kept.name})")
            unmatched.append(u)
        else:
            by_student.setdefault(student, []).append(u)
    rows, known = [], []
    try:
        for student, ups in sorted(by_student.items()):
            with uninterrupted():  # a Ctrl-C stops between two students, never inside one's folder
                row = _place(course, assignment, student, ups, cells, due, _time_for(student, ups, roster, times))
                if not row["notebook"] and old.get(student, {}).get("notebook"):  # nothing new to grade: keep what was
                    known.append(f"{student} ({excerpt(row['file'], quote=False)})")
                    row = {**old[student], "untimed": False}
                rows.append(row)
    except KeyboardInterrupt:
        with uninterrupted():
            _write_manifest(course, assignment, rows, old)  # the students placed before it are listed
        raise CollectInterrupted(len(rows), len(by_student)) from None
    _write_manifest(course, assignment, rows, old)
    if roster is not None:  # formgrader lists them by name
        roster.into_gradebook(course, [r["student"] for r in rows])
    width = max([len(r["student"]) for r in rows] + [7])
    for r in rows:
        print(f"{r['student']:<{width}}  {r['notebook'] or 'missing notebook':<24} "
              f"{r['submitted_at'] or '-':<27} {'late' if r['late'] == 'yes' else '':<4} {r['note']}".rstrip(), file=out)
    untimed = []
    for r in rows:
        same = r.pop("unchanged", False)
        if r.pop("untimed"):
            untimed.append((r["student"], same))
    new = [student for student, same in untimed if not same]
    again = [student for student, same in untimed if same]
    if new:
        print(f"no submission time for the new file(s) of {len(new)} student(s): "
              f"{excerpt(', '.join(new), quote=False)} (the download has none; times collected before stay with "
              "the files they belong to); for their real times collect again with --times TIMES.csv", file=out)
    if again:
        print(f"still no submission time for the file(s) of {len(again)} student(s), the same as collected before: "
              f"{excerpt(', '.join(again), quote=False)} (neither download gave one); for their real times collect "
              "again with --times TIMES.csv", file=out)
    if known:
        print(f"no notebook of {assignment} in this download for {len(known)} student(s): "
              f"{excerpt(', '.join(known), quote=False)}; their files are kept in attempts/, and the notebook "
              "collected before stays, to be graded, with its row in the manifest", file=out)
    for p in problems:
        print(f"not collected: {p}", file=out)
    print(f"collected {len(rows)} student(s) of {assignment} into {course}/submitted/ from {source}"
          + (f"; {len(unmatched)} file(s) not placed, kept in {course}/collected/{assignment}-unmatched/" if unmatched else ""),
          file=out)
    return rows, problems


def _place(course, assignment, student, ups, cells, due, when) -> dict:
    folder = course / "submitted" / student_id(student, "collect") / assignment
    attempts = folder / "attempts"
    ours = [(u, which_notebook(u, cells)) for u in ups]
    ours.sort(key=lambda x: x[0].order)
    newest = {}
    for u, nb in ours:
        if nb is not None:
            newest[nb] = u
    notes = []
    folder.mkdir(parents=True, exist_ok=True)
    same = bool(newest) and all((folder / f"{nb}.ipynb").is_file() and (folder / f"{nb}.ipynb").read_bytes() == u.data
                                for nb, u in newest.items())
    known = _read_stamp(folder / "timestamp.txt") if same and when is None else None
    if known is not None and due is not None and known == _guess(due):  # collect's own guess is no known time
        known = None
    for nb, u in newest.items():
        dest = folder / f"{nb}.ipynb"
        if dest.exists() and dest.read_bytes() != u.data:  # collected before: the earlier one is kept, not graded
            notes.append(f"the {dest.name} collected before moved to attempts/"
                         f"{_keep(dest, attempts, 'previously-collected')}")
            if (folder / "timestamp.txt").exists():
                _keep(folder / "timestamp.txt", attempts, "previously-collected")
        dest.write_bytes(u.data)
        twins = [x for x, _ in ours if x is not u and Path(x.file).name == Path(u.file).name]
        if twins:  # several files of that name: say which one is graded
            notes.append(f"graded {excerpt(u.entry, quote=False)} (the newest of {len(twins) + 1} files named "
                         f"{excerpt(Path(u.file).name, quote=False)})")
        if Path(u.file).name != dest.name:
            notes.append(f"{excerpt(u.file, quote=False)} saved as {dest.name}")
    older = [u for u, nb in ours if nb is None or newest.get(nb) is not u]
    kept = []
    for u in older:
        attempts.mkdir(exist_ok=True)
        path = unique_in(attempts, Path(u.entry.replace("\\", "/")).name, u.data)
        path.write_bytes(u.data)
        kept.append(path.name)
    if older:
        notes.append(f"{len(older)} earlier or other file(s) kept in attempts/, not graded: "
                     + excerpt(", ".join(kept), quote=False))
    late = any(u.late for u in newest.values())
    stamp = None
    if when is not None:
        stamp = when
    elif known is not None:  # the same file as collected before: its time stays (never replaced by a guess)
        stamp = known
    elif late and due is not None:
        stamp = _guess(due)
        notes.append("marked late by the LMS, which gives no time: stamped 1 s after the due date")
    elif late:
        notes.append("marked late by the LMS, but the assignment has no due date in nbgrader_config.py")
    if stamp is not None:
        (folder / "timestamp.txt").write_text(_stamp(stamp))
    elif (folder / "timestamp.txt").exists() and newest:
        _keep(folder / "timestamp.txt", attempts, "previously-collected")
    u0 = next(iter(newest.values()), ups[-1])
    is_late = late or (stamp is not None and due is not None and stamp > due.replace(tzinfo=dt.timezone.utc))
    return {"student": student, "lms": u0.lms, "lms_id": u0.lms_id, "lms_name": u0.lms_name,
            "file": file_name(u0.entry),
            "notebook": ", ".join(f"{nb}.ipynb" for nb in newest), "submitted_at": _stamp(stamp) if stamp else "",
            "late": "yes" if is_late else "", "attempts": str(len(older)), "untimed": bool(newest) and when is None and known is None,
            "unchanged": same,
            "note": "; ".join(notes) if newest else "missing notebook: no notebook of the assignment (kept in attempts/)"}


def _guess(due: dt.datetime) -> dt.datetime:
    """The time of a submission the LMS marks late without a time: one second after the due date."""
    return due.replace(tzinfo=dt.timezone.utc) + dt.timedelta(seconds=1)


def _read_stamp(path: Path) -> dt.datetime | None:
    """The time in a ``timestamp.txt`` (as collect or nbgrader wrote it), or None."""
    import dateutil.parser

    try:
        t = dateutil.parser.parse(path.read_text()[:100].strip())
    except (OSError, ValueError, OverflowError):
        return None
    return t if t.tzinfo is not None else t.replace(tzinfo=dt.timezone.utc)


def _keep(path: Path, attempts: Path, tag: str) -> str:
    """Move ``path`` into ``attempts`` under a name of its own; return that name."""
    attempts.mkdir(exist_ok=True)
    n = 1
    while (attempts / f"{tag}-{n}-{path.name}").exists():
        n += 1
    shutil.move(str(path), attempts / f"{tag}-{n}-{path.name}")
    return f"{tag}-{n}-{path.name}"


def _write_manifest(course: Path, assignment: str, rows: list[dict], old: dict[str, dict]) -> Path:
    """The manifest: ``rows`` over ``old`` (a later download of a few students keeps the others' rows)."""
    path = course / "collected" / f"{assignment}.csv"
    path.parent.mkdir(exist_ok=True)
    old = dict(old)
    old.update({r["student"]: r for r in rows})
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, MANIFEST_COLUMNS)
        w.writeheader()
        for s in sorted(old):
            w.writerow({k: old[s].get(k, "") for k in MANIFEST_COLUMNS})
    return path


def read_manifest(course: Path, assignment: str) -> dict[str, dict]:
    """``collected/<a>.csv`` by student (empty if there is none); a damaged one is a :class:`CourseError`."""
    path = Path(course) / "collected" / f"{assignment}.csv"
    if not path.exists():
        return {}
    again = f"snakekit collect writes it: move it away and collect {assignment} again"
    _, rows = read_table(path, "manifest", need=("student", "lms", "file"), fix=again, unreadable=again)
    return {r["student"]: r for r in rows if r.get("student")}


# --- the command ----------------------------------------------------------------------------------


def _options(args, parser) -> str:
    """The options the TA gave besides ``--from`` (shell-quoted), to repeat in a suggested command."""
    import shlex

    given = [(opt, getattr(args, dest)) for opt, dest in (("--course", "course"), ("--roster", "roster"),
                                                         ("--times", "times"), ("--timezone", "timezone"))
             if getattr(args, dest) != parser.get_default(dest)]
    return "".join(f" {opt} {shlex.quote(str(value))}" for opt, value in given)


def main(argv: list[str] | None = None, out=None) -> int:
    import dateutil.tz

    p = CommandParser(prog="snakekit collect", description="Put an LMS's download (Canvas, Moodle, or a folder of "
                "<student>.ipynb) into the course's submitted/ folder, the newest attempt of each student.")
    p.add_argument("assignment", help="assignment name, e.g. 06_coded_sweep")
    p.add_argument("--from", dest="source", type=Path, required=True, help="the download: a zip or a folder")
    p.add_argument("--course", type=Path, default=default_course(),
                   help="the nbgrader course folder (default: the current folder when it holds "
                        "nbgrader_config.py, else course/)")
    p.add_argument("--roster", type=Path, default=None, help="CSV: student and canvas_id / moodle_id / name ... "
                   "(default: <course>/roster.csv if it exists)")
    p.add_argument("--times", type=Path, default=None, help="CSV of submission times (Moodle's grading worksheet, "
                   "or columns student/canvas_id/moodle_id and submitted_at)")
    p.add_argument("--timezone", default="UTC", help="zone of times without one in --times (default: UTC)")
    args = p.parse_args(argv)
    course = args.course
    try:
        require(course, args.assignment)
        if not args.source.exists():
            raise CourseError(f"--from {args.source} does not exist")
        roster = Roster.load(default_roster(course, args.roster))
        zone = dateutil.tz.gettz(args.timezone)
        if zone is None:
            raise CourseError(f"--timezone {excerpt(args.timezone)} is not a time zone (e.g. UTC, Europe/Zurich)")
        times = read_times(args.times, zone) if args.times else []
    except (SnakekitError, OSError) as e:
        print(f"snakekit collect: {one_line(e)}", file=sys.stderr)
        return 2
    try:
        _, problems = collect(course.resolve(), args.assignment, args.source, roster=roster, times=times, out=out,
                              options=_options(args, p))
    except (SnakekitError, OSError) as e:
        print(f"snakekit collect: {one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        placed = f"{e.placed} of {e.total} student(s) placed and listed in {course}/collected/{args.assignment}.csv, " \
            "the others as they were" if isinstance(e, CollectInterrupted) else "nothing was placed"
        print(f"snakekit collect: interrupted; {placed}; collect the same download again to finish", file=sys.stderr)
        return 130
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
