"""grader/README.md is all a TA needs: its commands do what it says.

* Every example file name of the download layouts ("Collect") is read as its row says.
* Every command block of "A week of a course" runs as written, in order, in a scratch folder
  holding the test course (``06_coded_sweep`` is the test course's ``t1_sweep``, and ``grade``
  is given the test course's references), and each block's effect is checked: the release and
  its due date, the collected notebooks and times, the grades with the late penalty, formgrader
  answering with the students' names, a resubmission, the returned pages (a score set by hand
  on them), the export and the worked solution after the due date.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import os
import re
import secrets
import shlex
import signal
import subprocess
import sys
import time
import urllib.request
import zipfile
from pathlib import Path

import pytest

from conftest import free_port, need_program
from grader_helpers import ASSIGNMENT, REFERENCES, good_notebook, make_course

REPO = Path(__file__).resolve().parents[2]
README = (REPO / "grader" / "README.md").read_text()
LESSON = "06_coded_sweep"  # the README's assignment; the test course's is t1_sweep


def section(title: str, until: str = "\n### ") -> str:
    start = README.index(f"\n## {title}\n")
    return README[start:README.index(until, start + 1)]


def blocks(text: str) -> list[list[str]]:
    """The fenced blocks of ``text`` (indented ones too), each as its lines."""
    return [[line.strip() for line in b.splitlines() if line.strip()]
            for b in re.findall(r"^[ \t]*```[a-z]*\n(.*?)^[ \t]*```", text, re.S | re.M)]


# --- the download layouts ------------------------------------------------------------------------

def layouts() -> list[tuple[str, str]]:
    table = README[README.index("| layout | names | for example |"):]
    rows = [r for r in table.split("\n\n")[0].splitlines()[2:]]
    return [(cells[1].strip(), cells[3].strip().strip("`")) for cells in (r.split("|") for r in rows)]


#: What each layout's example name says: (the LMS, its id of the student, Canvas's late mark)
SAYS = {"Canvas": ("canvas", "101", True), "Canvas, uploaded again": ("canvas", "101", False),
        "Moodle": ("moodle", "2041", False), "Moodle, without folders": ("moodle", "2041", False),
        "a folder": ("folder", "alice", False), "a folder of folders": ("folder", "alice", False)}


def test_the_layouts_table_has_an_example_for_each_layout():
    assert [name for name, _ in layouts()] == list(SAYS)


@pytest.mark.parametrize("layout,example", layouts())
def test_each_example_download_name_is_read_as_its_row_says(layout, example):
    from grader.lms.download import classify

    u = classify(example, b"")
    assert (u.lms, u.lms_id, u.late) == SAYS[layout]
    assert u.file.endswith(".ipynb")


# --- a week, block by block --------------------------------------------------------------------------

DUE = dt.datetime(2026, 3, 2, 22, 59, tzinfo=dt.timezone.utc)  # the README's "2026-03-02 23:59 Europe/Zurich"


def week_blocks() -> list[list[str]]:
    return blocks(section("A week of a course"))


def test_the_week_is_one_block_per_step():
    firsts = [b[0].split()[:2] for b in week_blocks()]
    assert firsts == [["snakekit", "release"], ["snakekit", "collect"], ["snakekit", "grade"], ["cd", "course"],
                      ["snakekit", "collect"], ["snakekit", "return"], ["snakekit", "export"], ["snakekit", "release"]]


def as_run(line: str) -> str:
    """A README line as this test runs it: the test course's assignment, and its references for grade."""
    line = line.replace(LESSON, ASSIGNMENT)
    if line.startswith("snakekit grade "):
        line += f" --references {shlex.quote(str(REFERENCES))} --jobs 2"
    return line


def shell(line: str, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", "-c", as_run(line)], cwd=cwd, env=env, capture_output=True, text=True, timeout=1500)


def formgrader(line: str, cwd: Path, env: dict, home: Path) -> str:
    """Start formgrader as the README's block does, fetch its students' page, stop it."""
    token, port = secrets.token_hex(16), free_port()
    env = dict(env, JUPYTER_PORT=str(port), JUPYTER_TOKEN=token, JUPYTER_CONFIG_DIR=str(home / "config"),
               JUPYTER_RUNTIME_DIR=str(home / "runtime"), JUPYTER_DATA_DIR=str(home / "data"), HOME=str(home))
    log = open(home / "formgrader.log", "wb")
    proc = subprocess.Popen(["bash", "-c", f"exec {line.split('&&', 1)[1].strip()} --ServerApp.port_retries=0",
                             ], cwd=cwd / line.split()[1], env=env, stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 300  # a bound for a hang: it starts in about 10 s on a quiet machine
        while True:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/formgrader/api/students?token={token}",
                                            timeout=10) as r:
                    return r.read().decode()
            except OSError:
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise AssertionError(f"formgrader did not answer: {(home / 'formgrader.log').read_text()[-3000:]}")
                time.sleep(1)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
        log.close()


def canvas(path: Path, files: dict[str, bytes]) -> None:
    with zipfile.ZipFile(path, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)


def test_a_week_runs_block_by_block_as_written(tmp_path):
    from grader.course.folder import gradebook

    need_program("unshare")
    need_program("bash")
    work = tmp_path / "kit"
    work.mkdir()
    course = make_course(work)
    (course / "roster.csv").write_text("student,name,canvas_id,email,login_id,section\n"
                                       "alice,Alice Smith,101,alice@uni.test,as1,A\n"
                                       "bob,Bob Jones,102,bob@uni.test,bj2,A\n")
    alice, bob, bob2 = (good_notebook(course, who) for who in ("alice", "bob", "bob again"))
    canvas(work / "submissions.zip", {f"smithalice_101_5001_{ASSIGNMENT}.ipynb": alice,
                                      f"jonesbob_LATE_102_5002_{ASSIGNMENT}.ipynb": bob})
    bob_at, bob2_at = DUE + dt.timedelta(hours=2), DUE + dt.timedelta(hours=4, minutes=30)
    (work / "times.csv").write_text(f"canvas_id,submitted_at\n101,{DUE - dt.timedelta(days=1):%Y-%m-%d %H:%M:%S}\n"
                                    f"102,{bob_at:%Y-%m-%d %H:%M:%S}\n")
    canvas(work / "submissions-2.zip", {f"smithalice_101_5001_{ASSIGNMENT}.ipynb": alice,
                                        f"jonesbob_LATE_102_5002_{ASSIGNMENT}.ipynb": bob,
                                        f"jonesbob_LATE_102_5007_{ASSIGNMENT}-1.ipynb": bob2})
    (work / "times-2.csv").write_text(f"canvas_id,submitted_at\n102,{bob2_at:%Y-%m-%d %H:%M:%S}\n")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    home = tmp_path / "home"
    home.mkdir()
    grades = course / f"grades-{ASSIGNMENT}.csv"

    def csv_rows() -> dict:
        with open(grades, newline="") as f:
            return {r["student"]: (r["raw_score"], r["late_penalty"], r["score"]) for r in csv.DictReader(f)}

    steps = week_blocks()
    # 1. the release: the student version, the due date in the gradebook, the rule in the config
    (line,) = steps[0]
    r = shell(line, work, env)
    assert r.returncode == 0, r.stderr
    assert (course / "release" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").is_file()
    with gradebook(course) as gb:
        assert gb.find_assignment(ASSIGNMENT).duedate == DUE.replace(tzinfo=None)
    # 2. collect: each notebook in place with its time; the names reach nbgrader's student table
    (line,) = steps[1]
    r = shell(line, work, env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (course / "submitted" / "bob" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").read_bytes() == bob
    assert (course / "submitted" / "bob" / ASSIGNMENT / "timestamp.txt").read_text() == \
        f"{bob_at:%Y-%m-%d %H:%M:%S}.000000 UTC"
    with gradebook(course) as gb:
        assert {(s.id, s.first_name, s.last_name, s.email) for s in gb.students} == {
            ("alice", "Alice", "Smith", "alice@uni.test"), ("bob", "Bob", "Jones", "bob@uni.test")}
    # 3. grade: bob 2 hours late at per-hour:1 loses 2 of his 7
    (line,) = steps[2]
    r = shell(line, work, env)
    assert r.returncode == 0, r.stderr[-3000:]
    assert csv_rows() == {"alice": ("7", "0", "7"), "bob": ("7", "2", "5")}
    # formgrader, started as written, lists the students by name
    (line,) = steps[3]
    students = formgrader(line, work, env, home)
    assert '"first_name": "Alice"' in students and '"last_name": "Jones"' in students, students[:2000]
    with gradebook(course) as gb:  # the TA sets alice's 3rd exercise to 0 in formgrader
        g = gb.find_grade("ex3_peak_speed_test", ASSIGNMENT, ASSIGNMENT, "alice")
        g.manual_score = 0.0
        gb.db.commit()
    # 4. bob's resubmission, 4.5 hours late: collected with its time, bob graded again, alice's row kept
    collect_again, grade_bob = steps[4]
    r = shell(collect_again, work, env)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (course / "submitted" / "bob" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb").read_bytes() == bob2
    r = shell(grade_bob, work, env)
    assert r.returncode == 0, r.stderr[-3000:]
    assert csv_rows() == {"alice": ("6", "0", "6"), "bob": ("7", "5", "2")}
    # 5. return: the Canvas zip, alice's page saying the score set by hand
    (line,) = steps[5]
    r = shell(line, work, env)
    assert r.returncode == 0, r.stdout + r.stderr
    with zipfile.ZipFile(course / f"feedback-{ASSIGNMENT}-canvas.zip") as z:
        pages = {n: z.read(n).decode() for n in z.namelist()}
    by_id = {re.search(r"_(\d+_\d+)_", n)[1]: page for n, page in pages.items()}
    assert sorted(by_id) == ["101_5001", "102_5007"], sorted(pages)  # bob's page goes to his newest upload
    assert "Your teacher set the points to 0 (the grader gave 1)" in by_id["101_5001"]
    # 6. export: the numbers Canvas imports
    (line,) = steps[6]
    r = shell(line, work, env)
    assert r.returncode == 0, r.stderr
    lines = list(csv.reader(io.StringIO((course / "grades-canvas.csv").read_text())))
    assert lines[2:] == [["Alice Smith", "101", "", "as1", "A", "6", "6"], ["Bob Jones", "102", "", "bj2", "A", "2", "2"]]
    # 7. after the due date, the worked solution: the instructor's answers, for the LMS
    (line,) = steps[7]
    r = shell(line, work, env)
    assert r.returncode == 0, r.stderr
    solution = course / "release" / f"{ASSIGNMENT}-solutions" / f"{ASSIGNMENT}-solutions.ipynb"
    assert f"is in {solution.parent.resolve()}/" in r.stdout
    assert "phi = np.cumsum(q)" in solution.read_text()  # ex1's answer, as the instructor wrote it

