"""The slips a tired TA makes in a week of a course, each made as the TA makes it (the
``snakekit`` commands): none misroutes or loses a grade, and the message says what to do.

* A roster on which two rows share a student id, an LMS id, a login or an e-mail merges two
  people: every command that reads a roster refuses it, naming the rows, and writes nothing.
* A second download collected without ``--times`` keeps the times collected before (the same
  file keeps its time, never a guess) and names the new files that have none.
"""

from __future__ import annotations

import csv
import datetime as dt
import shutil
import zipfile
from pathlib import Path

import pytest

from grader_helpers import ASSIGNMENT, make_course
from test_grader_files import notebook, one_line_error, run, tree

A = ASSIGNMENT
DUE = dt.datetime(2026, 3, 2, 12, 0, tzinfo=dt.timezone.utc)


@pytest.fixture(scope="module")
def released(tmp_path_factory):
    return make_course(tmp_path_factory.mktemp("released"))


@pytest.fixture
def course(released, tmp_path):
    """A copy of the released test course with a due date."""
    from grader.course import gradebook

    course = tmp_path / "course"
    shutil.copytree(released, course)
    with gradebook(course) as gb:
        gb.update_or_create_assignment(A, duedate=DUE.replace(tzinfo=None))
    return course


def canvas_zip(path: Path, files: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)
    return path


def manifest(course: Path) -> dict[str, dict]:
    with open(course / "collected" / f"{A}.csv", newline="") as f:
        return {r["student"]: r for r in csv.DictReader(f)}


# --- a roster that would merge two people -------------------------------------------------------

ROSTER_COLUMNS = ["student", "name", "canvas_id", "moodle_id", "sis_id", "login_id", "email"]
ROSTER_ROWS = [["ann", "Ann Lee", "101", "9001", "S-1", "al1", "ann@uni.test"],
               ["ben", "Ben Ode", "102", "9002", "S-2", "bo2", "ben@uni.test"],
               ["cat", "Cat Park", "103", "9003", "S-3", "cp3", "cat@uni.test"]]
#: Every roster column no two rows may share, and how the message names it.
UNIQUE = {"student": "student id", "canvas_id": "canvas_id", "moodle_id": "moodle_id", "sis_id": "sis_id",
          "login_id": "login_id", "email": "email"}
#: The commands that read a roster, as the TA types them (the roster is the course's own).
READERS = {
    "collect": lambda course, dl: ["collect", A, "--course", course, "--from", dl],
    "export": lambda course, dl: ["export", "--course", course, "--lms", "canvas"],
}


def test_every_column_that_must_not_repeat_is_checked():
    from grader.collect import ROSTER_IDS, UNIQUE as checked

    assert set(checked) == set(UNIQUE)
    assert set(ROSTER_IDS) - set(checked) == {"name"}  # two students may share a name: reported when it matters


@pytest.mark.parametrize("column", sorted(UNIQUE))
@pytest.mark.parametrize("command", sorted(READERS))
def test_a_roster_that_repeats_an_id_is_refused_naming_the_rows(course, tmp_path, command, column, capsys):
    rows = [list(r) for r in ROSTER_ROWS]
    i = ROSTER_COLUMNS.index(column)
    # cat's row (row 4) repeats ann's (row 2), as a copy-paste leaves it; an e-mail or login in other case
    rows[2][i] = rows[0][i].upper() if column in ("email", "login_id") else rows[0][i]
    with open(course / "roster.csv", "w", newline="") as f:
        csv.writer(f).writerows([ROSTER_COLUMNS, *rows])
    dl = canvas_zip(tmp_path / "dl.zip", {f"leeann_101_5001_{A}.ipynb": notebook(course, "ann"),
                                          f"parkcat_103_5003_{A}.ipynb": notebook(course, "cat")})
    (course / "grades-canvas.csv").write_text("Student,ID,SIS User ID,SIS Login ID,Section,t1_sweep,Final Points\n"
                                             "Ann Lee,101,S-1,al1,,7,7\n")  # last week's export
    before = tree(course)
    r = run(capsys, *READERS[command](course, dl))
    value = rows[0][i].casefold() if column in ("email", "login_id") else rows[0][i]
    one_line_error(r, f"roster {course / 'roster.csv'}: the {UNIQUE[column]} '{value}' is on rows 2 and 4",
                   "each student has one row", "merge or correct the rows")
    assert tree(course) == before  # no notebook placed, no manifest, last week's CSV as it was


def test_a_roster_names_every_repeat_at_once(tmp_path):
    from grader.collect import Roster
    from grader.course import CourseError

    path = tmp_path / "roster.csv"
    path.write_text("student,canvas_id,email\nann,101,a@x\nben,101,b@x\nann,103,B@X\n")
    with pytest.raises(CourseError) as e:
        Roster.load(path)
    assert str(e.value).startswith(f"roster {path}: the student id 'ann' is on rows 2 and 4; the canvas_id '101' is "
                                   "on rows 2 and 3; the email 'b@x' is on rows 3 and 4; each student has one row")


def test_two_students_may_share_a_name(tmp_path):
    from grader.collect import Roster

    path = tmp_path / "roster.csv"
    path.write_text("student,name,canvas_id\nsam1,Sam Lee,101\nsam2,Sam Lee,102\n")
    assert Roster.load(path).students == {"sam1", "sam2"}


# --- a second download without --times --------------------------------------------------------------


def test_a_second_collect_without_times_keeps_the_times_it_had(course, tmp_path, capsys):
    (course / "roster.csv").write_text("student,name,canvas_id\nann,Ann Lee,101\nben,Ben Ode,102\ncat,Cat Park,103\n")
    ann_at, ben_at = DUE + dt.timedelta(hours=3, minutes=7), DUE - dt.timedelta(hours=1)
    (tmp_path / "times.csv").write_text(f"canvas_id,submitted_at\n101,{ann_at:%Y-%m-%d %H:%M:%S}\n"
                                        f"102,{ben_at:%Y-%m-%d %H:%M:%S}\n")
    first = {f"leeann_LATE_101_5001_{A}.ipynb": notebook(course, "ann"),
             f"odeben_102_5002_{A}.ipynb": notebook(course, "ben")}
    r = run(capsys, "collect", A, "--course", course, "--from", canvas_zip(tmp_path / "monday.zip", first),
            "--times", tmp_path / "times.csv")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "no submission time" not in r.stdout
    sub = course / "submitted"
    ann_stamp = (sub / "ann" / A / "timestamp.txt").read_bytes()
    assert ann_stamp == f"{ann_at:%Y-%m-%d %H:%M:%S}.000000 UTC".encode()
    rows = manifest(course)

    # Wednesday's full download, collected without --times: ann's file unchanged (still LATE), ben
    # handed in again after the due date, cat for the first time
    second = {**first, f"odeben_LATE_102_5004_{A}-1.ipynb": notebook(course, "ben again"),
              f"parkcat_LATE_103_5005_{A}.ipynb": notebook(course, "cat")}
    r = run(capsys, "collect", A, "--course", course, "--from", canvas_zip(tmp_path / "wednesday.zip", second))
    assert r.returncode == 0, r.stdout + r.stderr
    # ann: the exact time stays, not "1 s after the due date"
    assert (sub / "ann" / A / "timestamp.txt").read_bytes() == ann_stamp
    assert manifest(course)["ann"] == rows["ann"]
    # ben: the earlier notebook keeps its time beside it; the new one has the LMS's late mark only
    attempts = sub / "ben" / A / "attempts"
    assert (attempts / f"previously-collected-1-{A}.ipynb").read_bytes() == notebook(course, "ben")
    assert (attempts / "previously-collected-1-timestamp.txt").read_text() == \
        f"{ben_at:%Y-%m-%d %H:%M:%S}.000000 UTC"
    guess = f"{DUE + dt.timedelta(seconds=1):%Y-%m-%d %H:%M:%S}.000000 UTC"
    assert (sub / "ben" / A / "timestamp.txt").read_text() == guess
    assert (sub / "cat" / A / "timestamp.txt").read_text() == guess
    said = [line for line in r.stdout.splitlines() if line.startswith("no submission time")]
    assert said == ["no submission time for the new file(s) of 2 student(s): ben, cat (the download has none; times "
                    "collected before stay with the files they belong to); for their real times collect again with "
                    "--times TIMES.csv"]

    # the times come later: collected again with them, ben's real time replaces the guess
    ben_again = DUE + dt.timedelta(hours=5)
    (tmp_path / "times2.csv").write_text(f"canvas_id,submitted_at\n102,{ben_again:%Y-%m-%d %H:%M:%S}\n")
    r = run(capsys, "collect", A, "--course", course, "--from", tmp_path / "wednesday.zip",
            "--times", tmp_path / "times2.csv")
    assert (sub / "ben" / A / "timestamp.txt").read_text() == f"{ben_again:%Y-%m-%d %H:%M:%S}.000000 UTC"
    assert (sub / "ann" / A / "timestamp.txt").read_bytes() == ann_stamp
    assert manifest(course)["ann"] == rows["ann"]
    assert "no submission time for the new file(s) of 1 student(s): cat" in r.stdout
