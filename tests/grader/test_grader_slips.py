"""The slips a tired TA makes in a week of a course, each made as the TA makes it (the
``snakekit`` commands): none misroutes or loses a grade, and the message says what to do.

* A roster on which two rows share a student id, an LMS id, a login or an e-mail merges two
  people: every command that reads a roster refuses it, naming the rows, and writes nothing.
* A second download collected without ``--times`` keeps the times collected before (the same
  file keeps its time, never a guess) and names the new files that have none.
* Ctrl-C in ``grade`` or ``collect`` stops between two students: those done before are in the
  gradebook, the CSV or the manifest, the others as they were.
* Another assignment's download is refused, naming the assignment its notebooks belong to, in the
  command the TA typed (every option kept).
* A resubmission collected without ``--times`` is graded without a time, marked, never with the
  earlier attempt's time.
* ``export`` before an assignment's due date gives a student with no submission an empty cell, not 0.
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
    from grader.course.folder import gradebook

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
    from grader.lms.roster import ROSTER_IDS, UNIQUE as checked

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
    from grader.lms.roster import Roster
    from grader.errors import CourseError

    path = tmp_path / "roster.csv"
    path.write_text("student,canvas_id,email\nann,101,a@x\nben,101,b@x\nann,103,B@X\n")
    with pytest.raises(CourseError) as e:
        Roster.load(path)
    assert str(e.value).startswith(f"roster {path}: the student id 'ann' is on rows 2 and 4; the canvas_id '101' is "
                                   "on rows 2 and 3; the email 'b@x' is on rows 3 and 4; each student has one row")


def test_two_students_may_share_a_name(tmp_path):
    from grader.lms.roster import Roster

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
    # cat's file is the one collected on Wednesday: not new, and still without its time
    assert "still no submission time for the file(s) of 1 student(s), the same as collected before: cat (neither " \
        "download gave one)" in r.stdout and "new file(s)" not in r.stdout, r.stdout


def test_a_resubmission_without_a_time_is_graded_marked_never_with_the_earlier_time(course, tmp_path, capsys):
    from conftest import need_program
    from grader_helpers import REFERENCES, good_notebook, read_csv
    from test_grader_week import LATE_PLUGIN

    from grader.course.folder import gradebook

    need_program("unshare")
    (course / "late.py").write_text(LATE_PLUGIN)  # 1 point per hour late
    with open(course / "nbgrader_config.py", "a") as f:
        f.write("c.AssignLatePenalties.plugin_class = 'late.PerHour'\n")
    (course / "roster.csv").write_text("student,name,canvas_id\nann,Ann Lee,101\n")
    on_time = DUE - dt.timedelta(minutes=2)
    (tmp_path / "times.csv").write_text(f"canvas_id,submitted_at\n101,{on_time:%Y-%m-%d %H:%M:%S}\n")
    first = {f"leeann_101_5001_{A}.ipynb": good_notebook(course, "ann")}
    grade = ["grade", A, "--course", course, "--references", REFERENCES, "--student", "ann"]
    assert run(capsys, "collect", A, "--course", course, "--from", canvas_zip(tmp_path / "monday.zip", first),
               "--times", tmp_path / "times.csv").returncode == 0
    r = run(capsys, *grade)
    assert r.returncode == 0, r.stdout + r.stderr
    row = read_csv(course / f"grades-{A}.csv")["ann"]
    assert (row["score"], row["late_penalty"], row["status"], row["submitted_at"]) == \
        ("7", "0", "graded", f"{on_time:%Y-%m-%d %H:%M:%S} UTC")

    # she hands in again after the due date (Canvas marks it not LATE); the download is collected without --times
    second = {**first, f"leeann_101_5007_{A}-1.ipynb": good_notebook(course, "ann again")}
    r = run(capsys, "collect", A, "--course", course, "--from", canvas_zip(tmp_path / "friday.zip", second))
    assert r.returncode == 0, r.stdout + r.stderr
    assert manifest(course)["ann"]["submitted_at"] == ""
    # collected, not graded yet: return and export would hand out the earlier attempt's page and score
    for command in (["return", A], ["export", "--lms", "canvas"]):
        listing = sorted(p.name for p in course.rglob("*") if p.is_file())
        r = run(capsys, *command, "--course", course)
        assert r.returncode == 2 and r.stderr == (
            f"snakekit {command[0]}: {A}: 1 student(s) handed in again after they were graded (ann): their score and "
            f"page are the earlier attempt's; grade them first (`snakekit grade {A} --student ann`), then run "
            f"snakekit {command[0]} again; nothing was written\n"), r.stderr
        assert sorted(p.name for p in course.rglob("*") if p.is_file()) == listing
    r = run(capsys, *grade)
    assert r.returncode == 0, r.stdout + r.stderr
    row = read_csv(course / f"grades-{A}.csv")["ann"]
    assert (row["score"], row["late_penalty"], row["status"], row["submitted_at"]) == \
        ("7", "0", "no submission time", "")  # never the earlier attempt's time, and said in the CSV
    assert row["detail"] == "graded as on time: this notebook has no submission time (the earlier attempt's stays " \
        "with it in attempts/)"
    with gradebook(course) as gb:
        assert gb.find_submission(A, "ann").timestamp is None
    assert [line for line in r.stdout.splitlines() if line.startswith("no submission time")] == [
        f"no submission time for the notebook of 1 student(s): ann (graded as on time, status 'no submission time' "
        f"in the CSV; the earlier attempt's time stays with it in attempts/); give them theirs: `snakekit collect {A} "
        f"--course {course} --from ZIP --times TIMES.csv`, then `snakekit grade {A} --course {course} --student ann`"]

    # the fix the line gives: her real time (3 h 10 min late) costs 3 points (one per hour, rounded)
    late = DUE + dt.timedelta(hours=3, minutes=10)
    (tmp_path / "times2.csv").write_text(f"canvas_id,submitted_at\n101,{late:%Y-%m-%d %H:%M:%S}\n")
    assert run(capsys, "collect", A, "--course", course, "--from", tmp_path / "friday.zip",
               "--times", tmp_path / "times2.csv").returncode == 0
    r = run(capsys, *grade)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "no submission time" not in r.stdout
    row = read_csv(course / f"grades-{A}.csv")["ann"]
    assert (row["score"], row["raw_score"], row["late_penalty"], row["status"], row["submitted_at"]) == \
        ("4", "7", "3", "graded", f"{late:%Y-%m-%d %H:%M:%S} UTC")
    assert manifest(course)["ann"]["submitted_at"] == f"{late:%Y-%m-%d %H:%M:%S}.000000 UTC"


# --- Ctrl-C ------------------------------------------------------------------------------------------

#: A bound for a hang, not a speed: Ctrl-C stops within 5 s (measured); the test waits 30 s.
HANG = 30.0


def interrupt(argv: list, course: Path, ready, *, timeout: float = 600) -> tuple[int, float, str, str]:
    """Run a ``snakekit`` command as the TA does, press Ctrl-C (SIGINT to its process group, as a
    terminal sends it) once ``ready()`` holds; (exit code, seconds from Ctrl-C to exit, stdout, stderr)."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out, err = course.parent / "out.txt", course.parent / "err.txt"
    with open(out, "w") as o, open(err, "w") as e:
        p = subprocess.Popen([sys.executable, "-m", "snakekit.cli", *map(str, argv)], stdout=o, stderr=e,
                             cwd=Path(__file__).resolve().parents[2], start_new_session=True)
        try:
            end = time.monotonic() + timeout
            while not ready() and p.poll() is None and time.monotonic() < end:
                time.sleep(0.02)
            assert p.poll() is None, f"it ended before Ctrl-C: {p.returncode}\n{err.read_text()[-3000:]}"
            t0 = time.monotonic()
            os.killpg(p.pid, signal.SIGINT)
            code = p.wait(HANG)
            return code, time.monotonic() - t0, out.read_text(), err.read_text()
        finally:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def gradebook_rows(course: Path) -> dict[str, float]:
    from grader.course.folder import gradebook

    with gradebook(course) as gb:
        return {sub.student.id: float(sub.score or 0.0) for sub in gb.find_assignment(A).submissions}


def test_ctrl_c_stops_grade_between_two_students(course, capsys):
    from conftest import need_program
    from grader_helpers import REFERENCES, submit

    need_program("unshare")
    submit(course, "ann")
    for s in ("ben", "cat", "dan"):  # each still running when the TA presses Ctrl-C
        submit(course, s, {"ex3_peak_speed": "import time\ntime.sleep(600)\npeak_speed = 0.0"})
    csv_path = course / f"grades-{A}.csv"
    r = interrupt(["grade", A, "--course", course, "--references", REFERENCES, "--jobs", "2", "--timeout", "900"],
                  course, lambda: csv_path.exists() or "ann" in gradebook_rows(course))
    code, took, out, err = r
    assert code == 130, err[-3000:]
    assert took < HANG
    # ann's grade is in the gradebook and the CSV; the others are as they were (nowhere)
    assert gradebook_rows(course) == {"ann": 7.0}
    with open(csv_path, newline="") as f:
        assert [(row["student"], row["score"], row["status"]) for row in csv.DictReader(f)] == [("ann", "7", "graded")]
    assert err.strip().splitlines()[-1] == (
        f"snakekit grade: interrupted; 1 submission(s) graded before it are in the gradebook and {csv_path}, the other "
        f"3 are as they were (grade them: `snakekit grade {A} --course {course} --student ben --student cat "
        "--student dan`)")
    assert not list((course / "autograded").glob("ben/*/*.ipynb"))


def test_ctrl_c_stops_collect_between_two_students(course, tmp_path):
    students = [f"s{i:03d}" for i in range(600)]
    files = {s: notebook(course, s) for s in students}
    dl = canvas_zip(tmp_path / "dl.zip", {f"{s}.ipynb": data for s, data in files.items()})
    sub = course / "submitted"
    code, took, out, err = interrupt(["collect", A, "--course", course, "--from", dl], course,
                                     lambda: sub.is_dir() and len(list(sub.iterdir())) >= 20)
    assert code == 130, err[-3000:]
    assert took < HANG
    placed = sorted(p.name for p in sub.iterdir())
    assert 20 <= len(placed) < len(students)
    # every student placed is whole and listed; none half-placed; the others untouched
    assert sorted(manifest(course)) == placed
    assert all((sub / s / A / f"{A}.ipynb").read_bytes() == files[s] for s in placed)
    assert err.strip().splitlines()[-1] == (
        f"snakekit collect: interrupted; {len(placed)} of {len(students)} student(s) placed and listed in "
        f"{course}/collected/{A}.csv, the others as they were; collect the same download again to finish")
    r = run_collect(course, dl)
    assert r.returncode == 0, r.stderr[-2000:]
    assert sorted(manifest(course)) == students
    assert all((sub / s / A / f"{A}.ipynb").read_bytes() == files[s] for s in students)
    assert not list(sub.glob(f"*/{A}/attempts"))  # collected again: the same files, nothing kept aside


def run_collect(course: Path, dl: Path):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "snakekit.cli", "collect", A, "--course", str(course), "--from",
                           str(dl)], capture_output=True, text=True, cwd=Path(__file__).resolve().parents[2],
                          timeout=600)


# --- another assignment's download -------------------------------------------------------------------


#: The options a TA may give collect, each as typed and as the suggested command repeats it.
COLLECT_OPTIONS = {
    "none": lambda course, tmp: [],
    "--times": lambda course, tmp: ["--times", tmp / "times.csv"],
    "--roster": lambda course, tmp: ["--roster", course / "roster.csv"],
    "--timezone": lambda course, tmp: ["--timezone", "Europe/Zurich"],
    "all": lambda course, tmp: ["--roster", course / "roster.csv", "--times", tmp / "times.csv", "--timezone",
                                "Europe/Zurich"],
}


@pytest.mark.parametrize("given", COLLECT_OPTIONS)
def test_another_assignments_download_is_refused_naming_it(course, tmp_path, capsys, given):
    import nbformat

    from grader.course.folder import gradebook

    with gradebook(course) as gb:  # lesson t0_intro, released earlier: its notebook and cells
        gb.add_assignment("t0_intro")
        gb.add_notebook("t0_intro", "t0_intro")
        for gid in ("t0_hello", "t0_hello_test"):
            gb.add_solution_cell(gid, "t0_intro", "t0_intro")
        gb.add_grade_cell("t0_hello_test", "t0_intro", "t0_intro", max_score=1, cell_type="code")

    def t0_notebook(who: str) -> bytes:
        cells = [nbformat.v4.new_code_cell(f"x = '{who}'", metadata={"nbgrader": {"grade_id": "t0_hello",
                                                                                   "solution": True}}),
                 nbformat.v4.new_code_cell("assert x", metadata={"nbgrader": {"grade_id": "t0_hello_test",
                                                                               "grade": True, "points": 1}})]
        return nbformat.writes(nbformat.v4.new_notebook(cells=cells)).encode()

    (course / "roster.csv").write_text("student,canvas_id\nann,101\nben,102\n")
    first = canvas_zip(tmp_path / "t1.zip", {f"leeann_101_5001_{A}.ipynb": notebook(course, "ann"),
                                             f"odeben_102_5002_{A}.ipynb": notebook(course, "ben")})
    r = run(capsys, "collect", A, "--course", course, "--from", first)
    assert r.returncode == 0, r.stdout + r.stderr
    before = tree(course)
    # the TA picks last week's download: t0_intro's notebooks, collected as t1_sweep
    wrong = canvas_zip(tmp_path / "t0.zip", {"leeann_101_4001_t0_intro.ipynb": t0_notebook("ann"),
                                             "odeben_102_4002_t0_intro.ipynb": t0_notebook("ben")})
    (tmp_path / "times.csv").write_text("canvas_id,submitted_at\n101,2026-03-01 10:00\n")
    options = [str(x) for x in COLLECT_OPTIONS[given](course, tmp_path)]
    r = run(capsys, "collect", A, "--course", course, "--from", wrong, *options)
    again = " ".join(["--course", str(course), *options])  # every option the TA gave, in the order collect lists them
    one_line_error(r, f"{wrong}: its notebooks are t0_intro's, not {A}'s (2 of 2 hold t0_intro's cells, none {A}'s); "
                      f"nothing was collected. Collect it as `snakekit collect t0_intro --from {wrong} {again}`, or "
                      f"download {A}'s submissions")
    assert tree(course) == before  # the manifest's rows, the notebooks, their times: as they were


# --- what a second download changes, said -------------------------------------------------------------


def scratch() -> bytes:
    import nbformat

    return nbformat.writes(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("print('notes')")])).encode()


def test_a_download_without_a_students_notebook_keeps_the_one_collected_before(course, tmp_path, capsys):
    (course / "roster.csv").write_text("student,canvas_id\nann,101\nben,102\n")
    ann, ben = notebook(course, "ann"), notebook(course, "ben")
    first = canvas_zip(tmp_path / "monday.zip", {f"leeann_101_5001_{A}.ipynb": ann, f"odeben_102_5002_{A}.ipynb": ben})
    assert run(capsys, "collect", A, "--course", course, "--from", first).returncode == 0
    rows = manifest(course)
    # Wednesday's download: ann uploaded only her notes this time (Canvas keeps the newest upload only)
    notes = scratch()
    second = canvas_zip(tmp_path / "wednesday.zip", {"leeann_101_5003_notes.ipynb": notes,
                                                     f"odeben_102_5002_{A}.ipynb": ben})
    r = run(capsys, "collect", A, "--course", course, "--from", second)
    assert r.returncode == 0, r.stdout + r.stderr
    assert manifest(course) == rows  # ann's row (her notebook's Canvas file id 5001) stays
    assert (course / "submitted" / "ann" / A / f"{A}.ipynb").read_bytes() == ann
    assert (course / "submitted" / "ann" / A / "attempts" / "leeann_101_5003_notes.ipynb").read_bytes() == notes
    assert (f"no notebook of {A} in this download for 1 student(s): ann (leeann_101_5003_notes.ipynb); their files "
            "are kept in attempts/, and the notebook collected before stays, to be graded, with its row in the "
            "manifest") in r.stdout


def test_collect_names_each_notebook_it_moves_aside(course, tmp_path, capsys):
    (course / "roster.csv").write_text("student,canvas_id\nann,101\n")
    ann = notebook(course, "ann")
    first = canvas_zip(tmp_path / "monday.zip", {f"leeann_101_5001_{A}.ipynb": ann})
    assert run(capsys, "collect", A, "--course", course, "--from", first).returncode == 0
    second = canvas_zip(tmp_path / "wednesday.zip", {f"leeann_101_5001_{A}.ipynb": ann,
                                                     f"leeann_101_5004_{A}-1.ipynb": notebook(course, "ann again")})
    r = run(capsys, "collect", A, "--course", course, "--from", second)
    assert r.returncode == 0, r.stdout + r.stderr
    attempts = course / "submitted" / "ann" / A / "attempts"
    assert (attempts / f"previously-collected-1-{A}.ipynb").read_bytes() == ann
    assert (attempts / f"leeann_101_5001_{A}.ipynb").read_bytes() == ann
    line = next(x for x in r.stdout.splitlines() if x.startswith("ann "))
    assert f"the {A}.ipynb collected before moved to attempts/previously-collected-1-{A}.ipynb" in line
    assert f"1 earlier or other file(s) kept in attempts/, not graded: leeann_101_5001_{A}.ipynb" in line
    assert manifest(course)["ann"]["note"] in line


#: Several files of the same name from one student, in each layout that can hold them.
TWINS = {
    "canvas": {f"leeann_101_5001_{A}.ipynb": "first", f"leeann_101_5007_{A}.ipynb": "second"},
    "moodle": {f"Ann Lee_201_assignsubmission_file_/{A}.ipynb": "first",
               f"Ann Lee_201_assignsubmission_file_/old/{A}.ipynb": "second"},
    "folder": {f"monday/ann/{A}.ipynb": "first", f"wednesday/ann/{A}.ipynb": "second"},
}


@pytest.mark.parametrize("layout", sorted(TWINS))
def test_the_report_names_which_of_several_same_name_files_is_graded(course, tmp_path, layout, capsys):
    (course / "roster.csv").write_text("student,name,canvas_id,moodle_id\nann,Ann Lee,101,201\n")
    files = {entry: notebook(course, note) for entry, note in TWINS[layout].items()}
    r = run(capsys, "collect", A, "--course", course, "--from", canvas_zip(tmp_path / "dl.zip", files))
    graded = (course / "submitted" / "ann" / A / f"{A}.ipynb").read_bytes()
    entry = next(e for e, data in files.items() if data == graded)
    said = f"graded {entry} (the newest of 2 files named {A}.ipynb)"
    assert said in next(x for x in r.stdout.splitlines() if x.startswith("ann ")), r.stdout
    assert said in manifest(course)["ann"]["note"]


# --- student data never lands in git -----------------------------------------------------------------


def git(repo: Path, *args) -> str:
    import subprocess

    r = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_every_file_a_week_writes_is_ignored_by_git(released, tmp_path, capsys):
    """The project's .gitignore over a course a TA ran a week in: after collect, grade, return
    and export, a `git add -A` would add nothing (no file is untracked and not ignored), and
    each file that holds names, ids, e-mails or grades is listed as ignored."""
    from conftest import need_program
    from grader_helpers import REFERENCES

    need_program("git")
    need_program("unshare")
    repo = tmp_path / "kit"
    repo.mkdir()
    shutil.copyfile(Path(__file__).resolve().parents[2] / ".gitignore", repo / ".gitignore")
    course = repo / "course"
    shutil.copytree(released, course)
    git(repo, "init", "-q")
    git(repo, "add", "-A")  # what the repository keeps of a course: sources, cases, the config
    kept = set(git(repo, "diff", "--cached", "--name-only").split())
    assert kept >= {".gitignore", "course/nbgrader_config.py", f"course/source/{A}/{A}.ipynb"}
    assert not {k for k in kept if k.startswith(("course/release/", "course/gradebook"))}

    (course / "roster.csv").write_text("student,name,canvas_id,email\nann,Ann Lee,101,ann@uni.test\n")
    dl = canvas_zip(tmp_path / "dl.zip", {f"leeann_101_5001_{A}.ipynb": notebook(course, "ann"),
                                          f"nobody_999_5002_{A}.ipynb": notebook(course, "who")})
    week = [["collect", A, "--course", course, "--from", dl],
            ["grade", A, "--course", course, "--references", REFERENCES, "--jobs", "1"],
            ["return", A, "--course", course],
            ["export", "--course", course, "--lms", "canvas"],
            ["export", "--course", course]]
    for argv in week:
        r = run(capsys, *argv)
        assert r.returncode in (0, 1), (argv, r.stdout[-2000:], r.stderr[-2000:])
    assert git(repo, "status", "--porcelain", "--untracked-files=all") == "".join(f"A  {k}\n" for k in sorted(kept))
    ignored = set(git(repo, "status", "--porcelain", "--ignored", "--untracked-files=all").split("\n"))
    for path in ["course/roster.csv", "course/gradebook.db", f"course/collected/{A}.csv",
                 f"course/collected/{A}-unmatched/nobody_999_5002_{A}.ipynb", f"course/submitted/ann/{A}/{A}.ipynb",
                 f"course/autograded/ann/{A}/{A}.ipynb", f"course/feedback/ann/{A}/{A}.html",
                 f"course/grades-{A}.csv", "course/grades-canvas.csv", "course/grades-all.csv",
                 f"course/feedback-{A}-canvas.zip"]:
        assert (course.parent / path).is_file(), path
        assert f"!! {path}" in ignored, path
    backups = [p for p in ignored if p.startswith("!! course/backups/gradebook-")]
    assert len(backups) == 1


# --- running the instructor's notebook is no change ---------------------------------------------------


def test_files_a_run_of_the_instructor_notebook_writes_do_not_block_grading(course, capsys):
    """An instructor runs the source notebook in its folder (lesson 06 saves task2_run.npz, lesson
    00 meet_the_arm.html): the reference still matches; a file the release would ship does not."""
    from conftest import need_program
    from grader_helpers import REFERENCES, submit

    need_program("unshare")
    submit(course, "ann")
    src = course / "source" / A
    (src / "task2_run.npz").write_bytes(b"PK\x03\x04 a run")
    (src / "meet_the_arm.html").write_text("<html>the arm</html>")
    (src / "sweep.png").write_bytes(b"\x89PNG")
    r = run(capsys, "grade", A, "--course", course, "--references", REFERENCES, "--student", "ann")
    assert r.returncode == 0, r.stderr[-3000:]
    assert "changed since" not in r.stderr
    csv_path = course / f"grades-{A}.csv"
    with open(csv_path, newline="") as f:
        assert [(row["student"], row["score"]) for row in csv.DictReader(f)] == [("ann", "7")]
    before = csv_path.read_bytes()
    (src / "hints.txt").write_text("a file the release hands out")  # released with the notebook: a change
    r = run(capsys, "grade", A, "--course", course, "--references", REFERENCES, "--student", "ann")
    assert r.returncode == 2
    assert f"{course}/source/{A} changed since {REFERENCES}/{A}.npz was recorded from it" in r.stderr
    assert csv_path.read_bytes() == before


@pytest.mark.parametrize("given, meant", [("Ann", "ann"), ("bem", "ben"), ("dave", None), ("ben ", "ben"),
                                          ("ann,ben", "--student ann --student ben? (one --student per student)"),
                                          ("ann, ben", "--student ann --student ben? (one --student per student)")])
def test_a_student_without_a_submission_is_refused_naming_who_has_one(course, capsys, given, meant):
    """``--student`` with a name that has no submission (another case, a typo, a student not in the class): nothing
    is graded, exit 2, and the TA reads the students who do have one, and the one meant when it is near."""
    from grader_helpers import REFERENCES, submit

    for student in ("ann", "ben"):
        submit(course, student)
    r = run(capsys, "grade", A, "--course", course, "--references", REFERENCES, "--student", "ann", "--student", given)
    assert r.returncode == 2
    shown = repr(given) if given != given.strip() else given   # a space at an end, seen
    meant = meant if meant is None or meant.endswith(")") else f"{meant}?"
    assert r.stderr.startswith(f"snakekit grade: no submission of {A} by {shown} in {course}/submitted"), r.stderr
    assert (f"by {shown} in {course}/submitted (did you mean {meant}); " in r.stderr) == (meant is not None), \
        r.stderr
    assert ("did you mean" in r.stderr) == (meant is not None), r.stderr
    # two such names: each one's own
    r = run(capsys, "grade", A, "--course", course, "--references", REFERENCES, "--student", "Ben", "--student", given)
    assert f"by Ben, {shown} in {course}/submitted (Ben: did you mean ben?" + (
        f"; {shown}: did you mean {meant}); " if meant else "); ") in r.stderr, r.stderr
    assert r.stderr.rstrip().endswith("; 2 student(s) have one: ann, ben; nothing was graded: give each --student as "
                                      "its folder in submitted/ names it"), r.stderr  # ann too: none of them
    assert not (course / f"grades-{A}.csv").exists() and not (course / "autograded").exists()


# --- export before the due date ---------------------------------------------------------------------

#: Each export format: its header, and (for the roster's ann, ben, cat) the cells before the scores.
EXPORT_FORMATS = {
    "plain": ([], ["student", A, "total"], {"ann": ["ann"], "ben": ["ben"], "cat": ["cat"]}),
    "canvas": (["--lms", "canvas"], ["Student", "ID", "SIS User ID", "SIS Login ID", "Section", A, "Final Points"],
               {"ann": ["Ann Lee", "101", "", "", ""], "ben": ["Ben Ode", "102", "", "", ""],
                "cat": ["Cat Park", "103", "", "", ""]}),
    "moodle": (["--lms", "moodle"], ["Full name", "Email address", "ID number", "Username", A, "Total"],
               {"ann": ["Ann Lee", "ann@uni.test", "", "ann"], "ben": ["Ben Ode", "ben@uni.test", "", "ben"],
                "cat": ["Cat Park", "cat@uni.test", "", "cat"]}),
}


@pytest.mark.parametrize("lms", EXPORT_FORMATS)
def test_export_before_the_due_date_leaves_a_missing_submission_empty(course, tmp_path, capsys, lms):
    from grader.course.folder import gradebook

    options, header, ident = EXPORT_FORMATS[lms]
    (course / "roster.csv").write_text("student,name,canvas_id,email\nann,Ann Lee,101,ann@uni.test\n"
                                       "ben,Ben Ode,102,ben@uni.test\ncat,Cat Park,103,cat@uni.test\n")
    due = (dt.datetime.now(dt.timezone.utc) + dt.timedelta(days=3)).replace(second=0, microsecond=0, tzinfo=None)
    with gradebook(course) as gb:  # ann handed in and was graded: all right but her first exercise; ben and cat not yet
        gb.update_or_create_assignment(A, duedate=due)
        gb.update_or_create_student("ann")
        grades = list(gb.add_submission(A, "ann").notebooks[0].grades)
        for g in grades[1:]:
            g.auto_score = g.max_score
        grades[0].auto_score = 0.0
        gb.db.commit()
        max_score = f"{gb.find_assignment(A).max_score:g}"
        ann = f"{sum(g.max_score for g in grades[1:]):g}"
    assert ann not in ("0", max_score)
    out = tmp_path / "grades.csv"

    def export():
        r = run(capsys, "export", "--course", course, "-o", out, *options)
        assert r.returncode == 0, r.stdout + r.stderr
        with open(out, newline="") as f:
            return r.stdout.splitlines(), list(csv.reader(f))

    said, rows = export()
    possible = [["Points Possible", "", "", "", "", max_score, max_score]] if lms == "canvas" else []
    assert rows == [header, *possible, [*ident["ann"], ann, ann], [*ident["ben"], "", "0"], [*ident["cat"], "", "0"]]
    assert said[0] == (f"{A} is due {due:%Y-%m-%d %H:%M} UTC: 2 student(s) with no submission yet (ben, cat) get an "
                       "empty cell (no grade, not 0); export after the due date gives them 0")

    with gradebook(course) as gb:  # the due date has passed: no submission is 0, as nbgrader export
        gb.update_or_create_assignment(A, duedate=dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)
                                       - dt.timedelta(minutes=1))
    said, rows = export()
    assert rows == [header, *possible, [*ident["ann"], ann, ann], [*ident["ben"], "0", "0"], [*ident["cat"], "0", "0"]]
    assert said == [f"exported 3 student(s) to {out}" + (f" ({lms} import format)" if lms != "plain" else "")]

    # ann's graded notebook is a resubmission collected without its time (the earlier one's kept in attempts/)
    attempts = course / "submitted" / "ann" / A / "attempts"
    attempts.mkdir(parents=True)
    (attempts / "previously-collected-1-timestamp.txt").write_text("2026-03-02 11:00:00.000000 UTC")
    said, rows = export()
    assert said[0] == (f"{A}: 1 student(s) graded without a submission time (ann; 'no submission time' in snakekit "
                       "grade's CSV): exported as on time, no late penalty; collect them again with --times TIMES.csv "
                       "and grade them before importing")
