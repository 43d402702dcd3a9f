"""``snakekit release``: the release, the due date and the late penalty in one command.

For each late-penalty rule a TA may give, a late notebook is collected from a Canvas download
with its time after the due date, graded, and exported: the gradebook, the grades CSV and the
Canvas export each show the penalty the rule says (computed here from the rule's words). Every
bad value is refused in one line, exit 2, with nothing written.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import shutil
import zipfile
from pathlib import Path

import pytest

from conftest import need_program
from grader_helpers import ASSIGNMENT, REFERENCES, good_notebook, make_course, snakekit
from test_grader_files import one_line_error, run, tree

A = ASSIGNMENT
REPO = Path(__file__).resolve().parents[2]
#: The due date as a TA in Zurich types it: 23:59 local is 22:59 UTC (winter time).
DUE_TEXT, DUE_UTC = "2026-03-02 23:59 Europe/Zurich", dt.datetime(2026, 3, 2, 22, 59, tzinfo=dt.timezone.utc)
FULL = 7.0  # the good notebook's points (every test cell right)

#: rule -> (how late bob hands in, the penalty the rule's words give for that, worked by hand)
RULES = {
    "per-hour:1": (dt.timedelta(hours=2, minutes=30), 3.0),        # 3 started hours, 1 point each
    "per-day:10%": (dt.timedelta(days=1, hours=6), 0.2 * FULL),    # 2 started days, 10 % of 7 each: 1.4
    "zero": (dt.timedelta(minutes=1), FULL),                       # all of it
}


@pytest.fixture(scope="module")
def released(tmp_path_factory):
    return make_course(tmp_path_factory.mktemp("released"))


@pytest.fixture
def course(released, tmp_path):
    course = tmp_path / "course"
    shutil.copytree(released, course)
    (course / "roster.csv").write_text("student,name,canvas_id,email,login_id,section\n"
                                       "alice,Alice Smith,101,alice@uni.test,as1,A\n"
                                       "bob,Bob Jones,102,bob@uni.test,bj2,A\n")
    return course


def test_every_rule_in_the_help_is_read_as_it_says():
    from grader.commands.late import parse

    assert parse("per-hour:1").penalty(7, 1) == 1 and parse("per-hour:1").penalty(7, 3601) == 2
    assert parse("per-day:10%").penalty(5, 86400) == 0.5 and parse("per-week:2").penalty(7, 1) == 2
    assert parse("zero").penalty(6, 1) == 6 and parse("none").penalty(6, 10**6) == 0
    assert parse("per-minute:1").penalty(7, 0) == 0 and parse("per-minute:3").penalty(7, 3600) == 7  # never above the score


@pytest.mark.parametrize("rule", sorted(RULES))
def test_a_late_notebook_loses_what_the_rule_says(course, tmp_path, rule):
    from grader.course.folder import gradebook

    need_program("unshare")
    late_by, penalty = RULES[rule]
    r = snakekit("release", A, "--course", course, "--due", DUE_TEXT, "--late-penalty", rule)
    assert r.returncode == 0, r.stderr
    assert f"{A}: due 2026-03-02 23:59 CET (2026-03-02 22:59 UTC), in the gradebook" in r.stdout
    with gradebook(course) as gb:
        assert gb.find_assignment(A).duedate == DUE_UTC.replace(tzinfo=None)
    dl = tmp_path / "submissions.zip"
    with zipfile.ZipFile(dl, "w") as z:
        z.writestr(f"smithalice_101_5001_{A}.ipynb", good_notebook(course, "alice"))
        z.writestr(f"jonesbob_LATE_102_5002_{A}.ipynb", good_notebook(course, "bob"))
    bob_at = DUE_UTC + late_by
    (tmp_path / "times.csv").write_text("canvas_id,submitted_at\n"
                                        f"101,{DUE_UTC - dt.timedelta(hours=1):%Y-%m-%d %H:%M:%S}\n"
                                        f"102,{bob_at:%Y-%m-%d %H:%M:%S}\n")
    r = snakekit("collect", A, "--course", course, "--from", dl, "--times", tmp_path / "times.csv")
    assert r.returncode == 0, r.stdout + r.stderr
    r = snakekit("grade", A, "--course", course, "--references", REFERENCES, "--jobs", "2", "--timeout", "120")
    assert r.returncode == 0, r.stderr[-3000:]
    want = f"{FULL - penalty:g}"
    with open(course / f"grades-{A}.csv", newline="") as f:
        rows = {row["student"]: row for row in csv.DictReader(f)}
    assert (rows["bob"]["raw_score"], rows["bob"]["late_penalty"], rows["bob"]["score"]) == (
        f"{FULL:g}", f"{penalty:g}", want)
    assert (rows["alice"]["late_penalty"], rows["alice"]["score"]) == ("0", f"{FULL:g}")
    with gradebook(course) as gb:
        sub = gb.find_submission(A, "bob")
        assert (sub.total_seconds_late, sub.late_submission_penalty) == (late_by.total_seconds(), pytest.approx(penalty))
    r = snakekit("export", "--course", course, "--lms", "canvas")
    assert r.returncode == 0, r.stderr
    lines = list(csv.reader(io.StringIO((course / "grades-canvas.csv").read_text())))
    assert lines[2:] == [["Alice Smith", "101", "", "as1", "A", f"{FULL:g}", f"{FULL:g}"],
                         ["Bob Jones", "102", "", "bj2", "A", want, want]]


def test_exchange_releases_the_student_version_for_nbgraders_fetch(course, tmp_path):
    exchange = tmp_path / "exchange"
    exchange.mkdir()
    r = snakekit("release", A, "--course", course, "--exchange", exchange)
    assert r.returncode == 0, r.stdout + r.stderr
    from grader.course.folder import course_id

    outbound = exchange / course_id(course) / "outbound" / A / f"{A}.ipynb"
    assert outbound.read_bytes() == (course / "release" / A / f"{A}.ipynb").read_bytes()
    assert f"{A}: released to the exchange" in r.stdout


def test_a_second_release_keeps_the_other_assignments_rules(course):
    from grader.course.folder import config
    from grader.commands.release import with_rules

    text = with_rules((course / "nbgrader_config.py").read_text(), {"other_lesson": "per-day:5"})
    (course / "nbgrader_config.py").write_text(text)
    r = snakekit("release", A, "--course", course, "--due", "2026-03-02 12:00", "--late-penalty", "zero")
    assert r.returncode == 0, r.stderr
    assert dict(config(course).LatePenalty.rules) == {"other_lesson": "per-day:5", A: "zero"}
    assert (course / "nbgrader_config.py").read_text().count("c.AssignLatePenalties.plugin_class") == 1


BAD = [
    (["--due", "2026-13-01"], "is not a time"),
    (["--due", "next friday"], "is not a time"),
    (["--due", "2026-03-02 23:59 Mars/Base"], "'Mars/Base' is not a time zone"),
    (["--due", "2026-03-02 23:59", "--timezone", "Nowhere"], "--timezone 'Nowhere' is not a time zone"),
    (["--late-penalty", "per-hour:x"], "is not a rule; give one of per-hour:1, per-day:10%, zero or none"),
    (["--late-penalty", "10%"], "is not a rule"),
    (["--late-penalty", "per-fortnight:1"], "no unit 'fortnight'"),
    (["--late-penalty", "per-day:120%"], "at most 100 %"),
    (["--late-penalty", "per-day:-1"], "above 0"),
    (["--late-penalty", "per-day:nan"], "above 0"),
    (["--late-penalty", "per-day:0"], "above 0"),
    (["--late-penalty", "per-day:1"], "has no due date for --late-penalty to count from; give --due TIME too"),
    (["--exchange", "no-such-folder"], "--exchange no-such-folder is not a folder"),
]


@pytest.mark.parametrize("args,says", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_a_bad_value_is_refused_in_one_line_and_nothing_is_written(course, args, says, capsys):
    before = tree(course)
    one_line_error(run(capsys, "release", A, "--course", course, *args), says)
    assert tree(course) == before


def test_an_unknown_assignment_names_the_courses(course, capsys):
    one_line_error(run(capsys, "release", "06_coded_swep", "--course", course),
                   "no assignment '06_coded_swep'", "the course has: t1_sweep")


def test_a_config_with_its_own_late_plugin_is_not_overwritten(course, capsys):
    with open(course / "nbgrader_config.py", "a") as f:
        f.write("c.AssignLatePenalties.plugin_class = 'late.PerHour'\n")
    (course / "late.py").write_text("from nbgrader.plugins import BasePlugin\n\n\nclass PerHour(BasePlugin):\n    pass\n")
    before = tree(course)
    one_line_error(run(capsys, "release", A, "--course", course, "--due", "2026-03-02 12:00", "--late-penalty", "zero"),
                   "sets its own late-penalty plug-in", "remove that line")
    assert tree(course) == before
