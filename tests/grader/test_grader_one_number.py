"""One number everywhere: the page, the class CSV, ``snakekit export`` and formgrader agree.

A class of three (alice on time, bob late, carol with one slip) is collected from a Canvas
download and graded once; each test works on its own copy. Random sequences of what a TA does
(grade the class, ``grade --student``, a score, extra credit or comment saved in formgrader, a due
date moved so a late penalty changes, ``return``, ``export``) are run on it, and after every step
each student's score and each exercise's points are the same on the feedback page, in the
CSV, in both exports and in the gradebook, and equal what the steps
taken make of the first grading: nothing changed that no step touched. The numbers expected are
worked here from the steps (a score set by hand replaces the grader's, extra credit adds to it,
the course's late rule is applied at grading and whenever a score or comment is saved, capped at the
score; a resubmission is graded on its own, the earlier attempt's hand-set scores not carried over and
the TA told). Every sequence runs under each late rule of :data:`RULES`: points per started hour, and a
percentage of the score per started day, which must follow a score set by hand at once.
formgrader's running server is asked too, once, for a late and an on-time student: every one of its
answers that shows a score, and its Manage Students page in headless Chromium, give the score after
the late penalty and say the penalty.
"""

from __future__ import annotations

import csv
import datetime as dt
import inspect
import io
import json
import math
import random
import re
import shutil
import statistics
import urllib.request
import zipfile
from pathlib import Path
from types import SimpleNamespace

import nbformat
import pytest

from conftest import need, need_program
from grader_helpers import ASSIGNMENT, GOOD, REFERENCES, box_title, good_notebook, make_course, snakekit, use_safe_grading
from test_grader_week import notebook_bytes

A = ASSIGNMENT
REPO = Path(__file__).resolve().parents[2]
DUE = dt.datetime(2026, 3, 2, 22, 59)  # UTC, as the gradebook keeps it
#: When each student handed in (canvas id, time); bob 2 h 30 min late: 3 started hours, 3 points at 1 per hour.
HANDED_IN = {"alice": (101, DUE - dt.timedelta(hours=1)), "bob": (102, DUE + dt.timedelta(hours=2, minutes=30)),
             "carol": (103, DUE - dt.timedelta(minutes=10))}
SLIP = {"ex1_tool_xy": GOOD["ex1_tool_xy"].replace("np.cos(phi)", "np.sin(phi)")}
STUDENTS = sorted(HANDED_IN)


def grade(course, *extra):
    r = snakekit("grade", A, "--course", course, "--references", REFERENCES, "--jobs", "2", "--timeout", "120", *extra)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


#: The late rules every sequence runs under: points per started hour, and a share of the score per started day.
RULES = ["per-hour:1", "per-day:10%"]


def late_penalty(rule: str, score: float, seconds_late: float) -> float:
    """What ``rule`` takes off a notebook that scored ``score``, ``seconds_late`` after the due date (at most the
    score), worked here from the rule's words."""
    if seconds_late <= 0:
        return 0.0
    per, amount = rule.split(":")
    started = math.ceil(seconds_late / {"per-hour": 3600, "per-day": 86400}[per])
    each = score * float(amount[:-1]) / 100 if amount.endswith("%") else float(amount)
    return min(score, round(started * each, 6))


@pytest.fixture(scope="module")
def classes(tmp_path_factory):
    """The class under each rule of :data:`RULES`, graded once (made when first asked for)."""
    made = {}

    def of(rule):
        if rule not in made:
            made[rule] = graded_under(tmp_path_factory, rule) if rule == RULES[0] else \
                ruled_again(of(RULES[0]), tmp_path_factory.mktemp("one-number"), rule)
        return made[rule]
    return of


def ruled_again(course, tmp, rule):
    """A copy of the graded class under another late rule, its penalties set as grading sets them (nbgrader's
    ``AssignLatePenalties`` with the course's plug-in) and its pages and CSV written again: the class as
    graded under ``rule``, without grading it once more."""
    from grader.commands.release import with_rules
    from grader.course.gradebook import late_penalties
    from grader.feedback.scores import refresh

    shutil.copytree(course, tmp / "course")
    course = tmp / "course"
    (course / "nbgrader_config.py").write_text(with_rules((course / "nbgrader_config.py").read_text(), {A: rule}))
    for s in STUDENTS:
        late_penalties(course, A, s)
    refresh(course, A)
    return course


@pytest.fixture(scope="module")
def graded(classes):
    return classes(RULES[0])


def graded_under(tmp_path_factory, rule):
    """The class collected from a Canvas download (with its times), due at DUE, late penalty ``rule``,
    graded once."""
    from grader.commands.release import with_rules
    from grader.course.folder import gradebook

    need_program("unshare")
    tmp = tmp_path_factory.mktemp("one-number")
    course = make_course(tmp)
    (course / "nbgrader_config.py").write_text(with_rules((course / "nbgrader_config.py").read_text(), {A: rule}))
    with gradebook(course) as gb:
        gb.update_or_create_assignment(A, duedate=DUE)
    (course / "roster.csv").write_text("student,name,canvas_id\n" + "".join(
        f"{s},{s.title()} Doe,{cid}\n" for s, (cid, _) in HANDED_IN.items()))
    with zipfile.ZipFile(tmp / "download.zip", "w") as z:
        for s, (cid, _) in HANDED_IN.items():
            z.writestr(f"doe{s}_{cid}_{5000 + cid}_{A}.ipynb", notebook_bytes(course, SLIP if s == "carol" else None))
    (tmp / "times.csv").write_text("canvas_id,submitted_at\n" + "".join(
        f"{cid},{at:%Y-%m-%d %H:%M:%S}\n" for cid, at in HANDED_IN.values()))
    r = snakekit("collect", A, "--course", course, "--from", tmp / "download.zip", "--times", tmp / "times.csv")
    assert r.returncode == 0, r.stdout + r.stderr
    grade(course)
    return course


@pytest.fixture
def course(graded, tmp_path):
    shutil.copytree(graded, tmp_path / "course")
    return tmp_path / "course"


# --- what each place says ----------------------------------------------------------------------


def in_gradebook(course) -> dict:
    """Per student: (score after the late penalty, {grade id: points}, {grade id: the grader's points}), as
    nbgrader's gradebook holds them."""
    from grader.course.folder import gradebook

    out = {}
    with gradebook(course) as gb:
        for sub in gb.find_assignment(A).submissions:
            grades = {g.name: g for nb in sub.notebooks for g in nb.grades}
            out[sub.student.id] = (round(sub.score - (sub.late_submission_penalty or 0.0), 4),
                                   {k: round(g.score, 4) for k, g in grades.items()},
                                   {k: g.auto_score for k, g in grades.items()})
    return out


def on_page(course, student) -> tuple[float, dict[str, float], str]:
    """The score and each exercise's points as the student's page shows them, and the page's text."""
    text = (course / "feedback" / student / A / f"{A}.html").read_text()
    total = re.search(r"Score: <strong>([-\d.e+]+) / 7</strong>", text)
    # the score table's rows, each exercise named as its lesson names it, read back to its test cell's id
    names = {box_title(course / "source" / A / f"{A}.ipynb", gid): gid
             for gid in ("ex1_tool_xy_test", "ex2_sweep_test", "ex3_peak_speed_test")}
    rows = re.findall(r"<td>([^<]+)</td>\s*<td>([-\d.e+]+) / \d+</td>", text)
    return float(total.group(1)), {names[name]: float(x) for name, x in rows if name in names}, text


def exported(course, tmp, lms=None) -> dict[str, float]:
    from grader.lms.export import export_main

    out = tmp / f"export-{lms or 'plain'}.csv"
    assert export_main(["--course", str(course), "-o", str(out), *(["--lms", lms] if lms else [])], io.StringIO()) == 0
    rows = list(csv.reader(io.StringIO(out.read_text())))
    if lms == "canvas":  # Student (the roster's name), ID, SIS User ID, SIS Login ID, Section, t1_sweep, Final Points
        by_id = {str(cid): s for s, (cid, _) in HANDED_IN.items()}
        return {by_id[r[1]]: float(r[5]) for r in rows[2:]}
    return {r[0]: float(r[1]) for r in rows[1:]}


def in_csv(course) -> dict[str, dict]:
    with open(course / f"grades-{A}.csv", newline="") as f:
        return {r["student"]: r for r in csv.DictReader(f)}


# --- the TA's steps, and what each makes of the numbers ----------------------------------------


class Class:
    """What the numbers must be: the first grading's points, and what every step since changed."""

    def __init__(self, course, rule=RULES[0]):
        self.rule = rule
        first = in_gradebook(course)
        self.auto = {s: first[s][2] for s in first}
        self.max = {"ex1_tool_xy_test": 2, "ex2_sweep_test": 4, "ex3_peak_speed_test": 1}
        self.manual = {s: {} for s in first}
        self.extra = {s: {} for s in first}
        self.comments = {s: {} for s in first}
        self.due = DUE
        self.penalty = {s: 0.0 for s in first}
        for s in first:
            self.graded(s)

    def points(self, s) -> dict[str, float]:
        return {g: round((self.manual[s].get(g) if self.manual[s].get(g) is not None else a) + (self.extra[s].get(g)
                         or 0.0), 4) for g, a in self.auto[s].items()}

    def graded(self, s):
        """nbgrader's late penalty as grading (or a score saved) sets it: the rule's, at most the score."""
        late = (HANDED_IN[s][1] - self.due).total_seconds()
        self.penalty[s] = late_penalty(self.rule, sum(self.points(s).values()), late)

    def resubmitted(self, s):
        """A corrected notebook graded on its own: full marks, nothing set by hand carried over (comments stay)."""
        dropped = {g: (self.manual[s].get(g), self.extra[s].get(g)) for g in self.max
                   if self.manual[s].get(g) is not None or self.extra[s].get(g)}
        self.auto[s] = {g: float(m) for g, m in self.max.items()}
        self.manual[s], self.extra[s] = {}, {}
        self.graded(s)
        return dropped

    def score(self, s) -> float:
        return round(sum(self.points(s).values()) - self.penalty[s], 4)


def formgrader(course):
    """formgrader's handlers that save a score and a comment (nbgrader's own code for them, without the web
    server around it), with what the course's config adds to them."""
    from nbgrader.server_extensions.formgrader import apihandlers

    from grader.commands.nbgrader_plugins import saved_in_formgrader
    from grader.course.folder import gradebook

    class Request:
        def __init__(self, body):
            self.body, self.coursedir = body, SimpleNamespace(root=str(course))

        def get_json_body(self):
            return self.body

        def write(self, _):
            pass

    handlers = SimpleNamespace(**{name: type(name, (Request,), {"put": inspect.unwrap(getattr(apihandlers, name).put)})
                                  for name in ("GradeHandler", "CommentHandler")})
    saved_in_formgrader(handlers)

    def save(kind, student, cell, body):
        with gradebook(course) as gb:
            find = gb.find_grade if kind == "GradeHandler" else gb.find_comment
            handler = getattr(handlers, kind)(body)
            handler.gradebook = gb
            handler.put(find(cell, A, A, student).id)
    return save


def step(name, course, tmp, rng, model):
    s = rng.choice(STUDENTS)
    if name == "grade":
        grade(course)
        for x in STUDENTS:
            model.graded(x)
    elif name == "grade --student":
        grade(course, "--student", s)
        model.graded(s)
    elif name == "hand-set score":
        gid = rng.choice(sorted(model.max))
        manual = rng.choice([None, 0.0, rng.randint(0, 2 * model.max[gid]) / 2])
        extra = rng.choice([None, None, 0.5, 1.0])
        formgrader(course)("GradeHandler", s, gid, {"manual_score": manual, "extra_credit": extra})
        model.manual[s][gid], model.extra[s][gid] = manual, extra
        model.graded(s)  # the penalty follows the score just saved
    elif name == "comment":
        cell = rng.choice(["ex1_tool_xy", "ex2_sweep"])
        text = rng.choice([None, f"See the note {rng.randint(1, 99)} in the lesson."])
        formgrader(course)("CommentHandler", s, cell, {"manual_comment": text})
        model.comments[s][cell] = text
        model.graded(s)
    elif name == "resubmit":  # a corrected notebook collected (its time kept), then graded on its own
        resubmit(course, s)
        said = grade(course, "--student", s).stdout
        dropped = model.resubmitted(s)
        row = in_csv(course)[s]
        assert row["status"] == ("hand-set score not carried over" if dropped else "graded"), row
        for g, (manual, extra) in dropped.items():  # the TA is told who, which cell and the old value
            old = " and ".join(([f"score {manual:g}"] if manual is not None else [])
                               + ([f"extra credit {extra:+g}"] if extra else []))
            assert f"{g} ({old})" in row["detail"], row
            assert re.search(rf"^{s} .*{re.escape(f'{g} ({old})')}", said, re.MULTILINE), said
    elif name == "late penalty":  # the due date moved (formgrader's Manage Assignments): the next grading applies it
        from grader.course.folder import gradebook

        model.due = DUE + dt.timedelta(hours=rng.choice([-4, -2, 1, 2]))
        with gradebook(course) as gb:
            gb.update_or_create_assignment(A, duedate=model.due)
    elif name == "return":
        from grader.commands.nbgrader_plugins import return_main

        assert return_main([A, "--course", str(course), "-o", str(tmp / "feedback.zip")], io.StringIO()) == 0
    elif name == "export":
        exported(course, tmp, "canvas")


def agree(course, tmp, model, after: str):
    """Every place gives every student the numbers the steps make; the page says what a teacher set and what
    the late penalty took."""
    book, rows = in_gradebook(course), in_csv(course)
    plain, canvas = exported(course, tmp), exported(course, tmp, "canvas")
    for s in STUDENTS:
        want, points = model.score(s), model.points(s)
        where = f"{s} after {after}"
        assert book[s][2] == model.auto[s], f"{where}: the grader's points changed"
        assert (book[s][0], book[s][1]) == (want, points), where
        total, shown, text = on_page(course, s)
        assert (total, shown) == (want, points), where
        assert (float(rows[s]["score"]), {g: float(rows[s][g]) for g in points}) == (want, points), where
        assert float(rows[s]["late_penalty"]) == round(model.penalty[s], 4), where
        assert plain[s] == want and canvas[s] == want, where
        for g, manual in model.manual[s].items():
            if manual is not None and manual != model.auto[s][g]:
                assert f"set by your teacher (the grader gave {model.auto[s][g]:g})" in text, where
        if model.penalty[s]:
            assert f"the late penalty took {model.penalty[s]:g} point(s) off" in text, where
        for cell, comment in model.comments[s].items():
            assert (f"Comment from your teacher:</strong> {comment}" in text) == bool(comment), where


def resubmit(course, s):
    """``s`` hands in a corrected notebook (the instructor's answers, with a note of their own), at the time
    collected before."""
    nb = nbformat.reads(good_notebook(course, s).decode(), as_version=4)
    nb.cells.append(nbformat.v4.new_markdown_cell(f"Handed in again by {s}."))
    nbformat.write(nb, course / "submitted" / s / A / f"{A}.ipynb")


#: The steps of every sequence, in an order drawn from its seed, with one grading step after the due date moved.
STEPS = ["hand-set score", "hand-set score", "hand-set score", "comment", "late penalty", "return", "export",
         "resubmit"]
GRADING = ["grade", "grade --student"]


def sequence(seed: int) -> list[str]:
    rng = random.Random(seed)
    steps = rng.sample(STEPS, len(STEPS))
    after = steps.index("late penalty") + 1
    steps.insert(rng.randint(after, len(steps)), GRADING[seed])
    return steps


#: (seed, rule) of each sequence: each grading step under points per hour, a percentage with the cheaper one.
SEQUENCES = [(0, RULES[0]), (1, RULES[0]), (1, RULES[1])]


@pytest.mark.parametrize("seed, rule", SEQUENCES)
def test_every_place_shows_the_same_score_after_any_sequence_of_a_tas_steps(classes, tmp_path, seed, rule):
    course = tmp_path / "course"
    shutil.copytree(classes(rule), course)
    rng = random.Random(1000 + seed)  # the students, cells, scores and times the steps take
    model = Class(course, rule)
    agree(course, tmp_path, model, "the first grading")
    taken = []
    for name in sequence(seed):
        step(name, course, tmp_path, rng, model)
        taken.append(name)
        agree(course, tmp_path, model, " > ".join(taken))


def test_a_late_students_page_says_the_score_the_export_gives(course, tmp_path):
    total, _, text = on_page(course, "bob")
    assert total == exported(course, tmp_path)["bob"] == exported(course, tmp_path, "canvas")["bob"] == 4
    assert "Handed in late (2 h 30 min after the due date): the late penalty took 3 point(s) off the 7 your " \
           "exercises scored, so your score is 4." in text


@pytest.mark.parametrize("rule", RULES)
def test_a_score_set_by_hand_on_a_late_student_moves_the_penalty_at_once(classes, tmp_path, rule):
    """bob (7 of 7, 2 h 30 min late) gets 0 set by hand on ex1 and ex2: 1 point left. The penalty the rule takes
    off 1 point (at most the score) is on the page, in the CSV, both exports and formgrader's answers at once."""
    course = tmp_path / "course"
    shutil.copytree(classes(rule), course)
    save = formgrader(course)
    for gid in ("ex1_tool_xy_test", "ex2_sweep_test"):
        save("GradeHandler", "bob", gid, {"manual_score": 0.0, "extra_credit": None})
    late = (HANDED_IN["bob"][1] - DUE).total_seconds()
    penalty = late_penalty(rule, 1.0, late)
    want = round(1.0 - penalty, 4)
    assert penalty == {"per-hour:1": 1.0, "per-day:10%": 0.1}[rule]  # capped at the score; 10 % of 1 point
    total, _, text = on_page(course, "bob")
    row = in_csv(course)["bob"]
    assert (total, float(row["score"]), float(row["late_penalty"]), float(row["raw_score"])) == (want, want, penalty, 1)
    assert exported(course, tmp_path)["bob"] == exported(course, tmp_path, "canvas")["bob"] == want
    assert f"the late penalty took {penalty:g} point(s) off the 1 your exercises scored, so your score is {want:g}." \
        in text
    from grader.commands.formgrader_scores import late_penalties
    from grader.course.folder import gradebook

    with gradebook(course) as gb:
        assert late_penalties(gb) == {(A, "bob", A): penalty}  # what formgrader's answers take off


def test_a_resubmission_is_graded_on_its_own_and_the_ta_is_told_of_the_hand_set_score_left_behind(course, tmp_path):
    """carol's slip (ex1: 0 of 2) got 1 point by hand; her corrected notebook scores 7 of 7, not 6, and the TA
    reads who, which cell and the value left behind, in the terminal and the CSV."""
    formgrader(course)("GradeHandler", "carol", "ex1_tool_xy_test", {"manual_score": 1.0, "extra_credit": None})
    assert float(in_csv(course)["carol"]["score"]) == 6
    resubmit(course, "carol")
    said = grade(course, "--student", "carol").stdout
    row = in_csv(course)["carol"]
    total, shown, text = on_page(course, "carol")
    assert (float(row["score"]), total, exported(course, tmp_path)["carol"]) == (7, 7, 7)
    assert shown["ex1_tool_xy_test"] == float(row["ex1_tool_xy_test"]) == 2 and "set by your teacher" not in text
    assert row["status"] == "hand-set score not carried over"
    told = "set by hand on the earlier attempt, not carried over to this new one (graded on its own): " \
           "ex1_tool_xy_test (score 1); set it again in formgrader"
    assert told in row["detail"]
    assert re.search(rf"^carol +7 / 7 +hand-set score not carried over: {re.escape(told)}", said, re.MULTILINE), said
    grade(course, "--student", "carol")  # the same attempt again: nothing more to tell
    assert (in_csv(course)["carol"]["status"], float(in_csv(course)["carol"]["score"])) == ("graded", 7)


def test_after_grade_student_the_page_keeps_the_score_set_by_hand(course, tmp_path):
    formgrader(course)("GradeHandler", "carol", "ex1_tool_xy_test", {"manual_score": 2.0, "extra_credit": None})
    grade(course, "--student", "carol")
    total, shown, text = on_page(course, "carol")
    assert total == float(in_csv(course)["carol"]["score"]) == exported(course, tmp_path)["carol"] == 7
    assert shown["ex1_tool_xy_test"] == float(in_csv(course)["carol"]["ex1_tool_xy_test"]) == 2
    assert "set by your teacher (the grader gave 0)" in text
    assert "Your teacher set the points to 2 (the grader gave 0)." in text


# --- formgrader's own server --------------------------------------------------------------------


#: formgrader's pages that show a submission's score: the class's, then bob's own.
SCORE_PAGES = ["manage_students", f"manage_submissions/{A}", f"gradebook/{A}/{A}", "manage_students/bob",
               f"manage_students/bob/{A}"]


def formgrader_answers(course, home) -> tuple[dict, dict]:
    """What formgrader's server answers (its API, by path), and the score cells of each of its score pages as
    headless Chromium shows them (sorted)."""
    from tests.system.test_browser import CHROMIUM_FLAGS, JupyterLab

    sync_api = need("playwright.sync_api")
    chromium = need_program("chromium")
    paths = ["students", f"submissions/{A}", f"submission/{A}/bob", f"submitted_notebooks/{A}/{A}",
             f"assignment/{A}", f"notebooks/{A}", *(f"student_submissions/{s}" for s in STUDENTS),
             *(f"student_notebook_submissions/{s}/{A}" for s in STUDENTS)]
    server = JupyterLab(course, home)  # in the course folder, as a TA starts it: formgrader reads its config
    try:
        answers, shown = {}, {}
        for path in paths:
            req = urllib.request.Request(f"{server.url}/formgrader/api/{path}",
                                         headers={"Authorization": f"token {server.token}"})
            with urllib.request.urlopen(req, timeout=120) as r:  # a bound for a hang: a fraction of a second
                answers[path] = json.loads(r.read())
        with sync_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_FLAGS)
            try:
                page = server.browser_context(browser, []).new_page()
                for path in SCORE_PAGES:
                    page.goto(f"{server.url}/formgrader/{path}")
                    page.wait_for_function("() => { const cells = document.querySelectorAll('#main-table td.score');"
                                           " return cells.length && [...cells].every(td => td.textContent); }",
                                           timeout=120_000)
                    shown[path] = sorted(td.strip() for td in page.locator("#main-table td.score").all_inner_texts())
            finally:
                browser.close()
    finally:
        server.stop()
    return answers, shown


def test_formgrader_shows_each_score_after_the_late_penalty_as_the_page_csv_and_export(course, tmp_path):
    use_safe_grading(course, 120)
    home = tmp_path / "home"
    home.mkdir()
    answers, shown = formgrader_answers(course, home)
    rows, plain, canvas = in_csv(course), exported(course, tmp_path), exported(course, tmp_path, "canvas")
    assert (plain["bob"], float(rows["bob"]["late_penalty"]), plain["alice"]) == (4, 3, 7)  # one late, one on time
    by = {path: {r.get("student", r.get("id")): r for r in answers[path]}
          for path in ("students", f"submissions/{A}", f"submitted_notebooks/{A}/{A}")}
    cells = {s: f"{plain[s]:g} / 7" + (f" (late: -{float(rows[s]['late_penalty']):g})" if s == "bob" else "")
             for s in STUDENTS}
    assert cells["bob"] == "4 / 7 (late: -3)"
    for path in SCORE_PAGES:  # what the TA sees
        assert shown[path] == sorted(cells.values() if "bob" not in path else [cells["bob"]]), path
    for s in sorted(STUDENTS, key=lambda s: s != "bob"):  # the late student first
        want, late = float(rows[s]["score"]), float(rows[s]["late_penalty"])
        assert want == plain[s] == canvas[s] == on_page(course, s)[0], s
        given = {"students": by["students"][s], "submissions": by[f"submissions/{A}"][s],
                 "student's assignments": next(r for r in answers[f"student_submissions/{s}"] if r["name"] == A),
                 "student's notebooks": answers[f"student_notebook_submissions/{s}/{A}"][0],
                 "gradebook's submissions": by[f"submitted_notebooks/{A}/{A}"][s]}
        for where, r in given.items():
            assert (r["score"], r.get("late_penalty")) == (want, late), f"{s}, formgrader's {where}: {r}"
    assert answers[f"submission/{A}/bob"]["score"] == plain["bob"]
    mean = statistics.fmean(plain.values())
    assert answers[f"assignment/{A}"]["average_score"] == pytest.approx(mean)
    assert answers[f"notebooks/{A}"][0]["average_score"] == pytest.approx(mean)
