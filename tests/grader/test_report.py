"""``snakekit report``: the teacher's view of the lesson 06 class of ``tests/grader/class_submissions/``.

The class is graded once (``graded_classes`` of tests/conftest.py, shared with test_class_grades.py);
each test works on a copy of the graded course. The report's numbers are checked against nbgrader's
Gradebook read here on its own, its screen against submissions made for it (a classmate's cells copied
with every name changed; two right answers written apart in the lesson's style; a copied trajectory),
and its page in headless Chromium with every request refused.
"""

from __future__ import annotations

import csv
import shutil
import subprocess
import sys
from itertools import combinations
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from class_submissions import Student, hand_in  # noqa: E402
from class_submissions import lesson06  # noqa: E402
from conftest import copy_course, need, need_program, without_data  # noqa: E402

REPO = HERE.parents[1]
LESSON = lesson06.LESSON
#: the group of test_class_grades.py's lesson 06 tests: under `make test` these run where the class is graded
pytestmark = pytest.mark.xdist_group(f"tests/grader/test_class_grades.py:graded={LESSON}")
TIMEOUT = 600   # a bound for a hang of one `snakekit report` of a class of 40 (about 10 s on a quiet machine)

# ---- submissions made for the screen -----------------------------------------------------------------
# lin writes 6.1 and 6.2 her own way; kai hands in those cells with every name, comment and blank changed
LIN = {
    lesson06.T1: '''\
def sweep_times(points, rate):
    stamps = np.zeros(points)
    for index in range(1, points):
        stamps[index] = stamps[index - 1] + 1.0 / rate   # one period more each goal
    return stamps
''',
    lesson06.T2: '''\
def sweep_positions(times, sweeps, amplitude):
    horizon = float(times[len(times) - 1])
    column = [amplitude * np.sin(2.0 * np.pi * sweeps * (tk / horizon)) for tk in times]
    column[len(column) - 1] = 0.0
    grid = np.empty((len(times), 5))
    for j in range(5):
        grid[:, j] = column
    return grid
''',
    lesson06.T3: '''\
def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    stamps = sweep_times(points, rate)
    grid = sweep_positions(stamps, sweeps, amplitude)
    plan = snakekit.Trajectory(stamps, grid)
    plan.check_limits()
    return plan
''',
}
KAI = {
    lesson06.T1: '''\
def sweep_times(points, rate):
    t = np.zeros(points)

    for k in range(1, points):
        t[k] = t[k - 1] + 1.0 / rate
    return t
''',
    lesson06.T2: '''\
def sweep_positions(times, sweeps, amplitude):
    # the sine over the whole sweep
    T = float(times[len(times) - 1])
    q = [amplitude * np.sin(2.0 * np.pi * sweeps * (s / T)) for s in times]
    q[len(q) - 1] = 0.0
    out = np.empty((len(times), 5))
    for joint in range(5):
        out[:, joint] = q
    return out
''',
    lesson06.T3: lesson06.TASK_A,   # 6.3 as much of the class writes it: no evidence either way
}
# two right answers written apart, each as the lesson writes its code (numpy, whole arrays at once)
MEI = {
    lesson06.T1: "def sweep_times(points, rate):\n    return np.arange(points, dtype=float) / rate\n",
    lesson06.T2: '''\
def sweep_positions(times, sweeps, amplitude):
    t = np.asarray(times, dtype=float)
    q = amplitude * np.sin(2 * np.pi * sweeps * t / t[-1])
    q[-1] = 0.0
    return np.tile(q[:, None], (1, 5))
''',
    lesson06.T3: '''\
def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    t = sweep_times(points, rate)
    return snakekit.Trajectory(t, sweep_positions(t, sweeps, amplitude)).check_limits()
''',
}
NED = {
    lesson06.T1: "def sweep_times(points, rate):\n    dt = 1.0 / rate\n    return dt * np.arange(points)\n",
    lesson06.T2: '''\
def sweep_positions(times, sweeps, amplitude):
    times = np.asarray(times, dtype=float)
    phase = 2 * np.pi * sweeps * times / times[-1]
    angle = amplitude * np.sin(phase)
    angle[-1] = 0
    return np.column_stack([angle] * 5)
''',
    lesson06.T3: '''\
def task2_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    times = sweep_times(points, rate)
    goals = sweep_positions(times, sweeps, amplitude)
    trajectory = snakekit.Trajectory(times, goals)
    trajectory.check_limits()
    return trajectory
''',
}
MADE = [Student(name, "made for the screen", answers, "") for name, answers in
        (("lin", LIN), ("kai", KAI), ("mei", MEI), ("ned", NED))]


@pytest.fixture(scope="module")
def graded06(graded_classes):
    need_program("unshare")
    return graded_classes(LESSON)


@pytest.fixture(scope="module")
def reported(graded06, tmp_path_factory):
    """A copy of the graded lesson 06 course with the submissions made for the screen handed in, a wrong
    trajectory copied (``rio``, from ``copied[0]``) and a right one (``amy``, from ``copied[1]``), and
    ``snakekit report`` run once on it: ``(course, copied)``."""
    from grader.report.standing import standing

    course = tmp_path_factory.mktemp("reported") / "course"
    shutil.copytree(Path(graded06["course"]), course, symlinks=True)
    for student in MADE:
        hand_in(course, LESSON, student)
    kept = sorted(course.glob(f"autograded/*/{LESSON}/lab/*.npz"))
    assert kept, "snakekit grade kept no trajectory for the lab"
    cases = standing(course, LESSON).cases
    wrong = [p for p in kept if any(f < 1 for k, f in cases[(p.parts[-4], p.stem)] if k == "at its defaults")]
    right = [p for p in kept if p not in wrong]
    assert wrong and right
    for copier, original in (("rio", wrong[0]), ("amy", right[0])):
        dest = course / "autograded" / copier / LESSON / "lab" / original.name
        dest.parent.mkdir(parents=True)
        with np.load(original) as z:
            arrays = dict(z)
        arrays["positions"] = arrays["positions"] + 1e-12   # float noise: another machine's last digit
        np.savez(dest, **arrays)
    r = report(course)
    assert r.returncode == 0, r.stderr
    return course, (wrong[0].parts[-4], right[0].parts[-4])


def report(course: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "snakekit.cli", "report", LESSON, "--course", str(course), *args],
                          capture_output=True, text=True, timeout=TIMEOUT, cwd=REPO)


def rows(course: Path, table: str) -> list[dict]:
    with open(course / f"report-{LESSON}" / f"{table}.csv", newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_the_reports_counts_are_the_gradebooks(reported):
    from nbgrader.api import Gradebook

    course, _ = reported
    full, partial, zero, totals, late = {}, {}, {}, {}, set()
    with Gradebook(f"sqlite:///{course / 'gradebook.db'}") as gb:
        for sub in gb.find_assignment(LESSON).submissions:
            totals[sub.student.id] = float(sub.score) - float(sub.late_submission_penalty or 0)
            if (sub.total_seconds_late or 0) > 0:
                late.add(sub.student.id)
            for nb in sub.notebooks:
                for g in nb.grades:
                    score = float(g.score)
                    for table, hit in ((full, score == g.max_score), (zero, score == 0),
                                       (partial, 0 < score < g.max_score)):
                        table[g.name] = table.get(g.name, 0) + hit
    exercises = {row["grade_id"]: row for row in rows(course, "exercises")}
    assert set(exercises) == set(full) and len(full) == 4
    for gid, row in exercises.items():
        assert (int(row["full"]), int(row["partial"]), int(row["zero"])) == (full[gid], partial[gid], zero[gid]), gid
    got = {row["student"]: float(row["score"]) for row in rows(course, "totals")}
    assert got == pytest.approx(totals) and len(got) == len(lesson06.STUDENTS)
    assert {row["student"] for row in rows(course, "totals") if row["late"] == "True"} == late
    # a failure group's students lost points on its exercise; a student is in one group per exercise
    scored = {}
    with Gradebook(f"sqlite:///{course / 'gradebook.db'}") as gb:
        for sub in gb.find_assignment(LESSON).submissions:
            for nb in sub.notebooks:
                scored.update({(sub.student.id, g.name): (float(g.auto_score or 0), g.max_score) for g in nb.grades})
    seen = set()
    kinds = {(row["exercise"], row["kind"]) for row in rows(course, "failures")}
    # every exercise has a student who did not write it (the class's "abe", "cal", "dot"...), and 6.2 a hint that fired
    assert {e for e, kind in kinds if kind == "not written"} == {row["exercise"] for row in rows(course, "exercises")}
    assert ("6.2 sweep_positions", "hint") in kinds
    for row in rows(course, "failures"):
        students = row["students"].split()
        assert int(row["count"]) == len(students) == len(set(students)) > 0
        assert row["examples"].split(", ") == students[:2]
        gid = f"ex{row['exercise'].split()[0].replace('.', '_').zfill(4)}_{row['exercise'].split()[1]}_test"
        for s in students:
            assert scored[(s, gid)][0] < scored[(s, gid)][1] and (s, gid) not in seen, (s, gid)
            seen.add((s, gid))


def test_a_copy_with_every_name_changed_is_flagged_and_two_answers_written_apart_are_not(reported):
    course, _ = reported
    pairs = {frozenset((row["first"], row["second"])): float(row["similarity"]) for row in rows(course, "alike")}
    assert pairs.get(frozenset(("lin", "kai")), 0) >= 0.8, pairs
    assert frozenset(("mei", "ned")) not in pairs, pairs
    page = (course / f"report-{LESSON}" / "report.html").read_text()
    assert "lin and kai" in page or "kai and lin" in page
    assert "stamps[index - 1] + 1.0 / rate" in page and "t[k - 1] + 1.0 / rate" in page   # side by side


def test_a_copied_wrong_trajectory_is_flagged_and_a_right_one_is_not(reported):
    course, (wrong, right) = reported
    same = {frozenset((row["first"], row["second"])) for row in rows(course, "trajectories")}
    assert frozenset(("rio", wrong)) in same, same
    assert not [p for p in same if "amy" in p or right in p], same


def test_a_report_made_again_is_the_same_and_a_mistake_a_hint_named_is_no_copy(reported, tmp_path):
    """Run again (another process, so another salt of Python's hash), the report is the same byte for
    byte; and no pair is flagged for a trajectory that a mistake a hint named, made by both, explains."""
    course, _ = reported
    again = tmp_path / "again"
    r = report(course, "--out", str(again))
    assert r.returncode == 0, r.stderr
    first = course / f"report-{LESSON}"
    for name in ("alike.csv", "trajectories.csv", "failures.csv", "report.html"):
        assert (again / name).read_bytes() == (first / name).read_bytes(), name
    shared = {frozenset(p) for row in rows(course, "failures") if row["kind"] == "hint"
              for p in combinations(row["students"].split(), 2)}
    flagged = {frozenset((row["first"], row["second"])) for row in rows(course, "trajectories")}
    assert not flagged & shared, flagged & shared


def test_the_page_opens_offline_in_chromium_and_its_plots_are_pictures(reported):
    sync_api = need("playwright.sync_api")
    chromium = need_program("chromium")
    from tests.system.test_browser import CHROMIUM_FLAGS

    course, _ = reported
    page_file = course / f"report-{LESSON}" / "report.html"
    text = page_file.read_text()
    assert "http" not in without_data(text) and str(course) not in text and str(REPO) not in text
    url = page_file.as_uri()
    asked = []
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_FLAGS)
        try:
            context = browser.new_context(offline=True)

            def refuse(route):
                if route.request.url == url or route.request.url.startswith("data:"):
                    return route.continue_()
                asked.append(route.request.url)
                return route.abort()

            context.route("**/*", refuse)
            page = context.new_page()
            page.goto(url)
            images = page.evaluate("() => [...document.images].map(i => [i.src.slice(0, 22), i.naturalWidth])")
            shown = page.evaluate("() => document.body.innerText")
        finally:
            browser.close()
    assert not asked, asked
    assert len(images) >= 3 and all(src == "data:image/png;base64," and width > 100 for src, width in images), images
    assert "Why they fail" in shown and "Too alike to be chance" in shown


@pytest.mark.parametrize("case", ["unknown assignment", "not graded yet", "empty class"])
def test_bad_input_gets_one_line_and_exit_2(case, tmp_path):
    course = copy_course(tmp_path / "course")
    if case == "not graded yet":
        hand_in(course, LESSON, MADE[0])
    argv = ["nosuch" if case == "unknown assignment" else LESSON]
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "report", *argv, "--course", str(course)],
                       capture_output=True, text=True, timeout=TIMEOUT, cwd=REPO)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    expected = {"unknown assignment": "no assignment 'nosuch'", "not graded yet": f"snakekit grade {LESSON}",
                "empty class": f"snakekit collect {LESSON}"}[case]
    assert lines[0].startswith("snakekit report: ") and expected in lines[0], lines[0]
    assert not (course / f"report-{LESSON}").exists()


def test_formgrader_serves_the_report_behind_its_login_with_a_menu_entry(reported, tmp_path):
    import urllib.error
    import urllib.request

    from tests.system.test_browser import JupyterLab

    course = tmp_path / "course"
    shutil.copytree(reported[0], course, symlinks=True)
    home = tmp_path / "home"
    home.mkdir()
    server = JupyterLab(course, home)   # in the course folder, as a TA starts it: formgrader reads its config

    class Stay(urllib.request.HTTPRedirectHandler):
        def redirect_request(self, *args):
            return None

    def get(path: str, token: bool = True) -> tuple[int, bytes]:
        req = urllib.request.Request(f"{server.url}/formgrader/{path}",
                                     headers={"Authorization": f"token {server.token}"} if token else {})
        try:
            with urllib.request.build_opener(Stay).open(req, timeout=120) as answer:   # a bound for a hang
                return answer.status, answer.read()
        except urllib.error.HTTPError as e:
            return e.code, e.read()

    try:
        status, listing = get("reports")
        assert status == 200 and f"/formgrader/reports/{LESSON}".encode() in listing, listing[-2000:]
        status, page = get(f"reports/{LESSON}")
        assert (status, page) == (200, (course / f"report-{LESSON}" / "report.html").read_bytes())
        status, students = get("manage_students")
        assert status == 200 and b"/formgrader/reports\">Class reports</a>" in students
        assert get(f"reports/{LESSON}", token=False)[0] in (302, 403)     # formgrader's own login
        assert get("reports/..%2F..%2Fnbgrader_config.py")[0] == 404
        (course / f"report-{LESSON}" / "report.html").unlink()
        status, listing = get("reports")
        assert status == 200 and f"none yet: <code>snakekit report {LESSON}</code>".encode() in listing
        assert get(f"reports/{LESSON}")[0] == 404                          # no report yet: it says how to write one
    finally:
        server.stop()


def test_formgraders_page_rendering_is_wrapped_once_by_each_addition_whatever_the_order():
    """The late-penalty script and the reports' menu entry each wrap formgrader's page rendering once,
    however often and in whichever order the course's config installs them (each server start): a
    second late script would print "(late: -3)" twice beside a score."""
    import nbgrader.server_extensions.formgrader.apihandlers as handlers
    import nbgrader.server_extensions.formgrader.base as base

    from grader.commands import formgrader_report, formgrader_scores

    for install in (formgrader_scores.install, formgrader_report.install, formgrader_scores.install,
                    formgrader_report.install, formgrader_report.install, formgrader_scores.install):
        install(handlers)
    files, render = [], base.BaseHandler.render
    while render is not None:
        files.append(Path(render.__code__.co_filename).name)
        render = getattr(render, "__wrapped__", None)
    assert files.count("formgrader_scores.py") == 1 and files.count("formgrader_report.py") == 1, files
