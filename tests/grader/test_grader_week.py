"""A week of a course, as a TA runs it: collect, grade, fix a grade, regrade, return, export.

One temporary copy of the small test course (``tests/grader/grader_course``) lives through a semester
week: a Canvas download (a resubmission, a late notebook, a renamed notebook, a notebook of
another assignment, an unknown Canvas id), one student on the hub's nbgrader exchange, a
score changed by hand in the gradebook (as formgrader does), one student regraded, the
feedback returned both ways, the grades exported. Every number is checked against what the
scores and nbgrader's late-penalty plugin make of it.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import nbformat
import pytest

from conftest import need_program
from grader_helpers import ASSIGNMENT, GOOD, REFERENCES, make_course, read_csv, release_notebook

REPO = Path(__file__).resolve().parents[2]
COURSE_ID = "snakekit-test-course"
#: Due in a week (the hub student hands in now, on time); the Canvas student bob 3 hours after it.
DUE = (dt.datetime.now(dt.timezone.utc) + dt.timedelta(days=7)).replace(hour=12, minute=0, second=0, microsecond=0)
BOB = DUE + dt.timedelta(hours=3)
WRONG_XY = "def tool_xy(q):\n    return np.array([0.3315, 0.0]) + 0 * q[:2]"  # right at q = 0 only: 0 of 2

#: A late-penalty plugin as nbgrader's documentation writes one: 1 point per hour late.
LATE_PLUGIN = '''from nbgrader.plugins import BasePlugin


class PerHour(BasePlugin):
    def late_submission_penalty(self, student_id, score, total_seconds_late):
        return round(total_seconds_late / 3600, 0)
'''


def snakekit(*args, cwd=REPO, env=None):
    return subprocess.run([sys.executable, "-m", "snakekit.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600, env=env)


def run(capsys, *args):
    """The same command in this process (for the checks that stop before anything runs)."""
    from snakekit.cli import main

    capsys.readouterr()
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return subprocess.CompletedProcess(args, code, out.out, out.err)


def notebook_bytes(course, answers=None, *, strip_ids=False) -> bytes:
    nb = release_notebook(course)
    chosen = {**GOOD, **(answers or {})}
    for cell in nb.cells:
        gid = cell.metadata.get("nbgrader", {}).get("grade_id")
        if gid in chosen and cell.metadata.nbgrader.get("solution"):
            cell.source = chosen[gid]
    return nbformat.writes(nb).encode()


def canvas_zip(course, path: Path) -> Path:
    other = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("print('my notes')")])
    files = {
        # alice: a first attempt (wrong tool_xy) and a resubmission Canvas renamed -1, with a larger file id
        "smithalice_101_5001_t1_sweep.ipynb": notebook_bytes(course, {"ex1_tool_xy": WRONG_XY}),
        "smithalice_101_5002_t1_sweep-1.ipynb": notebook_bytes(course),
        # bob: late; his time comes from the times file (3 h after the due date)
        "jonesbob_LATE_102_5003_t1_sweep.ipynb": notebook_bytes(course),
        # carol: the right notebook under another name
        "leecarol_103_5004_my work (2).ipynb": notebook_bytes(course),
        # dave: only a notebook of something else
        "kimdave_104_5005_scratch.ipynb": nbformat.writes(other).encode(),
        # a Canvas user the roster does not have
        "nobody_999_5006_t1_sweep.ipynb": notebook_bytes(course),
    }
    with zipfile.ZipFile(path, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)
    return path


def nbgrader_cli(*args, cwd, env):
    return subprocess.run([str(Path(sys.executable).parent / "nbgrader"), *args], capture_output=True, text=True,
                          cwd=cwd, env=env, timeout=300)


@pytest.fixture(scope="module")
def week(tmp_path_factory):
    need_program("unshare")
    tmp = tmp_path_factory.mktemp("week")
    course = make_course(tmp)  # released: nbgrader generate_assignment
    refs = tmp / "references"
    shutil.copytree(REFERENCES, refs)
    (course / "late.py").write_text(LATE_PLUGIN)
    with open(course / "nbgrader_config.py", "a") as f:
        f.write("c.AssignLatePenalties.plugin_class = 'late.PerHour'\n")
    from grader.course.folder import gradebook

    with gradebook(course) as gb:  # the due date, as formgrader's "Manage Assignments" or `nbgrader db` sets it
        gb.update_or_create_assignment(ASSIGNMENT, duedate=DUE)
    (course / "roster.csv").write_text("student,name,canvas_id,email,login_id,section\n"
                                       "alice,Alice Smith,101,alice@uni.test,as1,A\n"
                                       "bob,Bob Jones,102,bob@uni.test,bj2,A\n"
                                       "carol,Carol Lee,103,carol@uni.test,cl3,B\n"
                                       "dave,Dave Kim,104,dave@uni.test,dk4,B\n"
                                       "erin,Erin Wu,,erin@uni.test,ew5,B\n")
    (tmp / "times.csv").write_text(f"canvas_id,submitted_at\n102,{BOB:%Y-%m-%d %H:%M:%S}\n")

    # erin works on the hub: release, fetch, submit through nbgrader's exchange
    exchange = tmp / "exchange"
    exchange.mkdir()
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    ex = [f"--Exchange.root={exchange}", f"--CourseDirectory.course_id={COURSE_ID}"]
    r = nbgrader_cli("release_assignment", ASSIGNMENT, *ex, cwd=course, env=env)
    assert r.returncode == 0, r.stderr[-2000:]
    home = tmp / "erin"
    home.mkdir()
    student_env = {**env, "USER": "erin", "LOGNAME": "erin", "HOME": str(home)}
    for step in ("fetch_assignment", "submit"):
        if step == "submit":
            (home / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").write_bytes(notebook_bytes(course))
        r = nbgrader_cli(step, ASSIGNMENT, *ex, "--student=erin", cwd=home, env=student_env)
        assert r.returncode == 0, r.stderr[-2000:]
    r = nbgrader_cli("collect", ASSIGNMENT, *ex, cwd=course, env=env)
    assert r.returncode == 0, r.stderr[-2000:]

    steps = {"course": course, "refs": refs, "exchange": exchange, "home": home, "env": env, "ex": ex}
    steps["collect"] = snakekit("collect", ASSIGNMENT, "--course", course, "--from", canvas_zip(course, tmp / "dl.zip"),
                                "--times", tmp / "times.csv")
    # frank's notebook (copied in by hand) is 65 MB: more than the grader reads
    big = nbformat.reads(notebook_bytes(course).decode(), as_version=4)
    big.cells.append(nbformat.v4.new_markdown_cell("x" * (65 << 20)))
    (course / "submitted" / "frank" / ASSIGNMENT).mkdir(parents=True)
    nbformat.write(big, course / "submitted" / "frank" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb")
    grade = ["grade", ASSIGNMENT, "--course", course, "--references", refs, "--timeout", "60", "--jobs", "2"]
    steps["grade"] = snakekit(*grade)
    assert steps["grade"].returncode == 0, steps["grade"].stderr[-3000:] + steps["collect"].stdout
    steps["csv1"] = read_csv(course / f"grades-{ASSIGNMENT}.csv")
    with gradebook(course) as gb:  # a grader overrides carol's ex3 in formgrader: 0 of 1
        g = gb.find_grade("ex3_peak_speed_test", ASSIGNMENT, ASSIGNMENT, "carol")
        g.manual_score = 0.0
        gb.db.commit()
    steps["regrade"] = snakekit(*grade, "--student", "alice")
    steps["csv2"] = read_csv(course / f"grades-{ASSIGNMENT}.csv")
    steps["return"] = snakekit("return", ASSIGNMENT, "--course", course, "--exchange", exchange)
    steps["fetch"] = nbgrader_cli("fetch_feedback", ASSIGNMENT, *ex, "--student=erin", cwd=home, env=student_env)
    steps["export"] = snakekit("export", "--course", course, "--lms", "canvas")
    steps["nbgrader_export"] = nbgrader_cli("export", f"--CourseDirectory.course_id={COURSE_ID}", cwd=course, env=env)
    return steps


def test_collect_places_the_newest_attempt_and_reports_the_unknown_id(week):
    course, r = week["course"], week["collect"]
    assert r.returncode == 1, r.stderr  # one file could not be placed
    assert "not collected: nobody_999_5006_t1_sweep.ipynb: Canvas user 999 (nobody) is not in the roster" in r.stdout
    assert (course / "collected" / f"{ASSIGNMENT}-unmatched" / "nobody_999_5006_t1_sweep.ipynb").exists()
    sub = course / "submitted"
    assert sorted(p.name for p in sub.iterdir()) == ["alice", "bob", "carol", "dave", "erin", "frank"]
    # alice: the resubmission is graded, the first attempt kept beside it
    assert (sub / "alice" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").read_bytes() == notebook_bytes(course)
    assert [p.name for p in (sub / "alice" / ASSIGNMENT / "attempts").iterdir()] == ["smithalice_101_5001_t1_sweep.ipynb"]
    # bob's time from the times file, carol's renamed notebook found by its cells, dave's missing
    assert (sub / "bob" / ASSIGNMENT / "timestamp.txt").read_text() == f"{BOB:%Y-%m-%d %H:%M:%S}.000000 UTC"
    assert not (sub / "alice" / ASSIGNMENT / "timestamp.txt").exists()
    assert (sub / "carol" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").exists()
    assert "my work (2).ipynb saved as t1_sweep.ipynb" in r.stdout
    assert not (sub / "dave" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").exists()
    assert "missing notebook" in r.stdout
    manifest = {row["student"]: row for row in csv.DictReader(open(course / "collected" / f"{ASSIGNMENT}.csv"))}
    assert (manifest["bob"]["lms"], manifest["bob"]["lms_id"], manifest["bob"]["late"]) == ("canvas", "102", "yes")


def test_grades_with_the_late_penalty_and_missing_notebook(week):
    r = week["grade"]
    assert r.returncode == 0, r.stderr[-3000:]
    rows = week["csv1"]
    got = {s: (rows[s]["score"], rows[s]["raw_score"], rows[s]["late_penalty"], rows[s]["status"]) for s in rows}
    # bob: 7 points, 3 hours late at 1 point per hour (the course's plugin, as nbgrader's autograde applies it)
    assert got == {"alice": ("7", "7", "0", "graded"), "bob": ("4", "7", "3", "graded"),
                   "carol": ("7", "7", "0", "graded"), "dave": ("0", "0", "0", "missing notebook"),
                   "erin": ("7", "7", "0", "graded"), "frank": ("0", "0", "0", "invalid notebook")}
    assert rows["frank"]["detail"] == "t1_sweep.ipynb is 65 MB, more than the 64 MB the grader reads"
    assert rows["bob"]["submitted_at"] == f"{BOB:%Y-%m-%d %H:%M:%S} UTC"
    assert rows["dave"]["detail"] == "t1_sweep.ipynb is missing (no notebook in the folder)"
    assert "   4 / 7  graded  (late: 7 - 3)" in r.stdout
    assert list((week["course"] / "backups").glob("gradebook-*.db"))


def test_regrade_of_one_student_keeps_the_others_and_shows_a_hand_set_score(week):
    r = week["regrade"]
    assert r.returncode == 0, r.stderr[-3000:]
    rows = week["csv2"]
    assert set(rows) == {"alice", "bob", "carol", "dave", "erin", "frank"}
    assert (rows["alice"]["score"], rows["bob"]["score"], rows["carol"]["score"]) == ("7", "4", "6")
    assert "ex3_peak_speed_test set by hand in formgrader" in rows["carol"]["detail"]
    assert rows["dave"]["status"] == "missing notebook"  # from the previous CSV: dave was not regraded
    assert "graded 1 submission(s)" in r.stdout and "CSV (6 student(s))" in r.stdout


def test_return_releases_to_the_exchange_and_zips_for_canvas(week):
    course, r = week["course"], week["return"]
    assert r.returncode == 1, r.stdout + r.stderr  # frank's page: neither from the LMS nor from the exchange
    assert (f"not returned: frank: neither collected (no row in {course}/collected/{ASSIGNMENT}.csv) nor from the "
            f"exchange (no submission_secret.txt): the page stays in {course}/feedback/frank/{ASSIGNMENT}/ for you to "
            "hand out (`snakekit collect` the notebooks, and `return` bundles their pages)") in r.stdout
    with zipfile.ZipFile(course / f"feedback-{ASSIGNMENT}-canvas.zip") as z:
        names = sorted(z.namelist())
        # Canvas's Re-Upload matches <name>_<user id>_<file id>_ to the submission
        assert names == ["jonesbob_LATE_102_5003_t1_sweep-feedback.html", "kimdave_104_5005_t1_sweep-feedback.html",
                         "leecarol_103_5004_t1_sweep-feedback.html", "smithalice_101_5002_t1_sweep-feedback.html"]
        page = z.read("leecarol_103_5004_t1_sweep-feedback.html")
    assert page == (course / "feedback" / "carol" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_bytes()
    assert b"BEGIN HIDDEN TESTS" not in page
    assert "released 1 student(s)' feedback to the exchange" in r.stdout


def test_a_hub_student_fetches_the_safe_page(week):
    r = week["fetch"]
    assert r.returncode == 0, r.stderr[-2000:]
    fetched = list((week["home"] / ASSIGNMENT / "feedback").glob(f"*/{ASSIGNMENT}.html"))
    assert len(fetched) == 1
    safe = (week["course"] / "feedback" / "erin" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_bytes()
    assert fetched[0].read_bytes() == safe and b"Grader: 1 tool_xy: 2 / 2 points" in safe
    assert b"t / (t[-1] / sweeps)" not in safe  # the instructor's solution stays out


def test_export_for_canvas_has_every_number(week):
    r = week["export"]
    assert r.returncode == 0, r.stderr
    lines = list(csv.reader(io.StringIO((week["course"] / "grades-canvas.csv").read_text())))
    assert lines == [
        ["Student", "ID", "SIS User ID", "SIS Login ID", "Section", ASSIGNMENT, "Final Points"],
        ["Points Possible", "", "", "", "", "7", "7"],
        ["Alice Smith", "101", "", "as1", "A", "7", "7"],
        ["Bob Jones", "102", "", "bj2", "A", "4", "4"],
        ["Carol Lee", "103", "", "cl3", "B", "6", "6"],
        ["Dave Kim", "104", "", "dk4", "B", "0", "0"],
        ["Erin Wu", "", "", "ew5", "B", "7", "7"],
        ["frank", "", "", "", "", "0", "0"],  # not in the roster: Canvas reports the unknown name on import
    ]


def test_nbgraders_own_export_keeps_its_long_format_with_the_penalty(week):
    r = week["nbgrader_export"]
    assert r.returncode == 0, r.stderr[-2000:]
    rows = {row["student_id"]: row for row in csv.DictReader(open(week["course"] / "grades.csv"))}
    assert (float(rows["bob"]["raw_score"]), float(rows["bob"]["late_submission_penalty"]),
            float(rows["bob"]["score"])) == (7.0, 3.0, 4.0)
    assert float(rows["carol"]["score"]) == 6.0 and float(rows["alice"]["score"]) == 7.0


def test_a_changed_test_cell_is_refused_until_regenerated(week, capsys):
    course = week["course"]
    path = course / "source" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb"
    before = path.read_text()
    nb = nbformat.read(path, as_version=4)
    test = next(c for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") == "ex1_tool_xy_test")
    test.source = test.source.replace("at q = 0 the tool is at [0.3315, 0] m", "at q = 0 the tool is at (0.3315, 0) m")
    nbformat.write(nb, path)
    try:
        csv_before = (course / f"grades-{ASSIGNMENT}.csv").read_bytes()
        r = run(capsys, "grade", ASSIGNMENT, "--course", course, "--references", week["refs"], "--student", "alice")
        assert r.returncode == 2
        assert f"nbgrader generate_assignment {ASSIGNMENT} --force" in r.stderr
        assert "the gradebook's cells differ from the source's (ex1_tool_xy_test)" in r.stderr
        assert f"python -m grader.scoring.references {ASSIGNMENT} --course {course} --out {week['refs']}" in r.stderr
        assert "nothing was graded" in r.stderr
        assert (course / f"grades-{ASSIGNMENT}.csv").read_bytes() == csv_before
    finally:
        path.write_text(before)


def test_a_changed_cases_module_is_refused_until_the_reference_is_recorded_again(week, capsys):
    course = week["course"]
    path = course / "cases" / f"{ASSIGNMENT}.py"
    before = path.read_text()
    path.write_text(before.replace("for _ in range(8)", "for _ in range(9)"))
    try:
        csv_before = (course / f"grades-{ASSIGNMENT}.csv").read_bytes()
        r = run(capsys, "grade", ASSIGNMENT, "--course", course, "--references", week["refs"], "--student", "alice")
        assert r.returncode == 2 and f"{course}/cases/{ASSIGNMENT}.py changed since" in r.stderr, r.stderr
        assert f"python -m grader.scoring.references {ASSIGNMENT} --course {course} --out {week['refs']}" in r.stderr
        assert (course / f"grades-{ASSIGNMENT}.csv").read_bytes() == csv_before
    finally:
        path.write_text(before)


# --- what a TA may type wrong: refused before anything runs ----------------------------------------


@pytest.fixture(scope="module")
def released(tmp_path_factory):
    """The test course, released once; each test below works on its own copy."""
    return make_course(tmp_path_factory.mktemp("released"))


def copy_of(released, tmp: Path) -> Path:
    shutil.copytree(released, tmp / "course")
    return tmp / "course"


@pytest.fixture(scope="module")
def small(released, tmp_path_factory):
    course = copy_of(released, tmp_path_factory.mktemp("small"))
    (course / "submitted" / "ann" / ASSIGNMENT).mkdir(parents=True)
    (course / "submitted" / "ann" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").write_bytes(notebook_bytes(course))
    return course


@pytest.mark.parametrize("target, says", [
    ("gradebook.db", "would write over a gradebook"),
    ("submitted", "is a folder"),
    (f"source/{ASSIGNMENT}/{ASSIGNMENT}.ipynb", "would write over a notebook"),
    (f"release/{ASSIGNMENT}/grades.csv", "is inside"),
    ("roster.csv", "is the roster"),
])
def test_csv_that_would_write_over_the_course_is_refused(small, target, says, capsys):
    (small / "roster.csv").write_text("student\nann\n")
    db = (small / "gradebook.db").read_bytes()
    r = run(capsys, "grade", ASSIGNMENT, "--course", small, "--references", REFERENCES, "--csv", small / target)
    assert r.returncode == 2 and says in r.stderr, r.stderr
    assert (small / "gradebook.db").read_bytes() == db and (small / "roster.csv").read_text() == "student\nann\n"


def test_unknown_assignment_missing_references_and_empty_class_are_errors(small, released, tmp_path, capsys):
    r = run(capsys, "grade", "t2_nothing", "--course", small, "--references", REFERENCES)
    assert r.returncode == 2 and f"no assignment 't2_nothing' in {small}; the course has: {ASSIGNMENT}" in r.stderr
    r = run(capsys, "grade", ASSIGNMENT, "--course", small, "--references", tmp_path / "no_refs")
    assert r.returncode == 2 and f"no references folder {tmp_path / 'no_refs'}" in r.stderr
    (tmp_path / "empty_refs").mkdir()
    r = run(capsys, "grade", ASSIGNMENT, "--course", small, "--references", tmp_path / "empty_refs")
    assert r.returncode == 2 and "every test cell would keep the kernel's own verdict" in r.stderr
    empty = copy_of(released, tmp_path)
    r = run(capsys, "grade", ASSIGNMENT, "--course", empty, "--references", REFERENCES)
    assert r.returncode == 2 and "no submissions of t1_sweep" in r.stderr and "snakekit collect" in r.stderr


# --- Moodle and a plain folder ---------------------------------------------------------------------


def test_moodle_folders_with_the_grading_worksheets_times(released, tmp_path, capsys):
    course = copy_of(released, tmp_path)
    from grader.course.folder import gradebook

    with gradebook(course) as gb:
        gb.update_or_create_assignment(ASSIGNMENT, duedate=dt.datetime(2026, 3, 2, 12, 0))
    dl = tmp_path / "moodle"
    for folder, name, data in [
        ("Alice Smith_9001_assignsubmission_file", f"{ASSIGNMENT}.ipynb", notebook_bytes(course)),
        ("Bob Jones_9002_assignsubmission_file_", "lesson (final).ipynb", notebook_bytes(course)),
        ("Chris Park_9003_assignsubmission_file", f"{ASSIGNMENT}.ipynb", notebook_bytes(course)),
        ("Sam Lee_9004_assignsubmission_file", f"{ASSIGNMENT}.ipynb", notebook_bytes(course)),
    ]:
        (dl / folder).mkdir(parents=True)
        (dl / folder / name).write_bytes(data)
    roster = tmp_path / "roster.csv"
    roster.write_text("student,name,email\nalice,Alice Smith,a@uni.test\nbob,Bob Jones,b@uni.test\n"
                      "sam1,Sam Lee,s1@uni.test\nsam2,Sam Lee,s2@uni.test\n")
    worksheet = tmp_path / "worksheet.csv"  # Moodle's "Download grading worksheet", times in Zurich
    worksheet.write_text("Identifier,Full name,Email address,Status,Grade,Last modified (submission)\n"
                         "Participant 9001,Alice Smith,a@uni.test,Submitted,,\"Monday, 2 March 2026, 10:30 AM\"\n"
                         "Participant 9002,Bob Jones,b@uni.test,Submitted,,\"Tuesday, 3 March 2026, 1:00 PM\"\n")
    r = run(capsys, "collect", ASSIGNMENT, "--course", course, "--from", dl, "--roster", roster, "--times", worksheet,
                 "--timezone", "Europe/Zurich")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "Moodle participant 9003 (Chris Park) is not in the roster" in r.stdout
    assert "Moodle participant 9004 (Sam Lee) matches 2 students of the roster (sam1, sam2); not guessed" in r.stdout
    sub = course / "submitted"
    assert sorted(p.name for p in sub.iterdir()) == ["alice", "bob"]
    assert (sub / "alice" / ASSIGNMENT / "timestamp.txt").read_text() == "2026-03-02 09:30:00.000000 UTC"  # CET
    assert (sub / "bob" / ASSIGNMENT / "timestamp.txt").read_text() == "2026-03-03 12:00:00.000000 UTC"
    assert (sub / "bob" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").read_bytes() == notebook_bytes(course)
    from grader.lms.collect import read_manifest
    from grader.lms.export import lms_name

    row = read_manifest(course, ASSIGNMENT)["bob"]
    assert (row["late"], lms_name(row, Path(f"{ASSIGNMENT}.html"))) == \
        ("yes", f"Bob Jones_9002_assignfeedback_file_/{ASSIGNMENT}-feedback.html")


def test_plain_folder_of_student_notebooks_and_a_second_download(released, tmp_path, capsys):
    course = copy_of(released, tmp_path)
    dl = tmp_path / "plain"
    dl.mkdir()
    (dl / "ann.ipynb").write_bytes(notebook_bytes(course, {"ex1_tool_xy": WRONG_XY}))
    (dl / "ben.ipynb").write_bytes(notebook_bytes(course))
    r = run(capsys, "collect", ASSIGNMENT, "--course", course, "--from", dl)
    assert r.returncode == 0, r.stdout + r.stderr
    first = (course / "submitted" / "ann" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").read_bytes()
    assert first == notebook_bytes(course, {"ex1_tool_xy": WRONG_XY})
    (dl / "ann.ipynb").write_bytes(notebook_bytes(course))  # ann hands in again: the first is kept, not lost
    r = run(capsys, "collect", ASSIGNMENT, "--course", course, "--from", dl)
    assert r.returncode == 0
    folder = course / "submitted" / "ann" / ASSIGNMENT
    assert (folder / f"{ASSIGNMENT}.ipynb").read_bytes() == notebook_bytes(course)
    assert (folder / "attempts" / f"previously-collected-1-{ASSIGNMENT}.ipynb").read_bytes() == first
    r = run(capsys, "collect", "t9_none", "--course", course, "--from", dl)
    assert r.returncode == 2 and f"the course has: {ASSIGNMENT}" in r.stderr
    # graded and returned: a zip with a folder per student, each page the one grade wrote
    need_program("unshare")
    r = run(capsys, "grade", ASSIGNMENT, "--course", course, "--references", REFERENCES, "--jobs", "2")
    assert r.returncode == 0, r.stdout + r.stderr
    r = run(capsys, "return", ASSIGNMENT, "--course", course)
    assert r.returncode == 0, r.stdout + r.stderr
    path = course / f"feedback-{ASSIGNMENT}-folder.zip"
    assert (f"wrote {path}: 2 page(s) of students collected from a folder, one folder per student "
            "(<student>/<notebook>-feedback.html): hand each its own as their notebooks came in") in r.stdout
    with zipfile.ZipFile(path) as z:
        assert sorted(z.namelist()) == [f"ann/{ASSIGNMENT}-feedback.html", f"ben/{ASSIGNMENT}-feedback.html"]
        for student in ("ann", "ben"):
            assert z.read(f"{student}/{ASSIGNMENT}-feedback.html") == \
                (course / "feedback" / student / ASSIGNMENT / f"{ASSIGNMENT}.html").read_bytes()
