"""The graded feedback says what the notebook's own check says: for every known mistake of every lesson,
the hint its visible check gives is the hint its graded feedback gives, and no other.

The known mistakes are those the lessons' checks name (tests/lessons/test_no_solution.py's ``MISTAKES``:
a wrong answer as a student writes it, and the words its visible check must show). Each is typed into the
lesson's student notebook, every other answer the instructor's, and a lesson's mistakes are graded in one
batch by ``snakekit grade`` (:func:`grader.course.fairness.grade_students`, as the fairness test grades its
variants). One notebook holds one mistake of each of several exercises when none of them calls another
(tests/lessons/test_forgot_return.py's groups), so a lesson's batch has as many notebooks as its exercise
with the most mistakes. The graded notebook's check cell holds what the notebook itself said (the same
kernel, the same checks); the grader's verdict on that exercise is what the feedback page shows.
"""

from __future__ import annotations

import html
import re

import pytest

from grader.course import fairness
from grader.feedback.notebook import recorded
from grader.scoring.verdict import LOCAL
from snakekit.errors import CheckFailed
from tests.conftest import need, need_program
from tests.grader.grader_helpers import box_title
from tests.lessons.test_forgot_return import exercises, groups
from tests.lessons.test_no_solution import MISTAKES

CASES = [(lesson, k) for lesson in sorted(MISTAKES) for k in range(len(MISTAKES[lesson]))]


def packed(lesson: str) -> tuple[dict, dict]:
    """The lesson's mistakes as students: (student -> answers typed in, mistake index -> its student).
    A student holds at most one mistake per exercise, and only of exercises that call none of the others."""
    found = {e["test"]: e for e in exercises(lesson)}
    students, who = {}, {}
    for n, group in enumerate(groups(list(found.values()))):
        tests = {e["test"] for e in group}
        for test in sorted(tests):
            mine = [k for k, (gid, *_) in enumerate(MISTAKES[lesson]) if gid == test]
            for i, k in enumerate(mine):
                name = f"group{n}_{i}"
                students.setdefault(name, {})[found[test]["answer"]] = MISTAKES[lesson][k][1]
                who[k] = name
    return students, who


@pytest.fixture(scope="module")
def graded(graded_slips):
    """lesson -> (course folder, mistake index -> its student): the lesson's mistakes graded in one batch (with its
    forgotten returns: tests/conftest.py's ``graded_slips``) when a test first asks for them."""
    need_program("unshare")
    need("nbformat")
    return lambda lesson: (graded_slips(lesson), packed(lesson)[1])


def said_and_graded(course, lesson: str, student: str, gid: str) -> tuple[str, object, str]:
    """What the notebook's check cell said in the graded run, the grader's verdict on that exercise (as the
    TA's graded notebook keeps it), and the verdict's text on the student's feedback page."""
    nbformat = need("nbformat")
    nb = nbformat.read(course / "autograded" / student / lesson / f"{lesson}.ipynb", as_version=4)
    cell = next(c for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") == gid)
    errors = [o for o in cell.outputs if o.output_type == "error"]
    verdict = next(e for e in recorded(nb)[4] if e.grade_id == gid)
    page = (course / "feedback" / student / lesson / f"{lesson}.html").read_text()
    at = page.index(f"Grader: {box_title(course / 'source' / lesson / f'{lesson}.ipynb', gid)}:")
    shown = html.unescape(re.sub(r"<[^>]+>", " ", page[at:page.index("</div>", at)]))
    return (str(errors[0].evalue) if errors else ""), verdict, " ".join(shown.split())


def test_every_lesson_has_known_mistakes_each_in_a_notebook_with_no_mistake_in_a_function_it_calls():
    assert {lesson for lesson, _ in CASES} == set(fairness.lessons())
    for lesson in fairness.lessons():
        students, who = packed(lesson)
        assert sorted(who) == list(range(len(MISTAKES[lesson])))
        calls = {e["answer"]: e["calls"] | {o["name"] for o in exercises(lesson) if e["name"] in o["calls"]}
                 for e in exercises(lesson)}
        names = {e["answer"]: e["name"] for e in exercises(lesson)}
        for answers in students.values():
            assert not any(names[a] in calls[b] for a in answers for b in answers), (lesson, sorted(answers))


# ids "lessonNN-k", not the lesson's name: lesson 07's name marks a test serial, and this one need not be. Under
# `make test` a lesson's mistakes go to one worker (its batch graded once, with the lesson's forgotten returns of
# tests/lessons/test_forgot_return.py) and the lessons to several.
@pytest.mark.parametrize("lesson, k", [pytest.param(lesson, k, marks=pytest.mark.xdist_group(f"slips{lesson[:2]}"),
                                                    id=f"lesson{lesson[:2]}-{k}") for lesson, k in CASES])
def test_a_mistake_the_notebooks_check_names_gets_the_same_hint_graded(graded, lesson, k):
    course, who = graded(lesson)
    gid, wrong, words, *anywhere = MISTAKES[lesson][k]
    said, verdict, page = said_and_graded(course, lesson, who[k], gid)
    message, hint = (" ".join(part.split()) for part in (said.partition(CheckFailed.HINT)[0], CheckFailed.hint_of(said)))
    # the notebook's own check names the mistake, in the graded run as when the student runs it
    assert words in (message + " " + hint if anywhere else hint), \
        f"{gid}: the answer\n{wrong}\nshould be told {words!r}; its check said {said!r}"
    assert verdict.score < verdict.max_score, f"{gid}: the mistake its check names earned full points graded"
    graded = " ".join(verdict.message.split())
    # the grader says what the check said: its message (the visible case it fails at) and its hint
    assert re.sub(r"^exercise [\w.]+ \w+: ", "", message) in graded and hint in graded and words in graded, \
        f"{gid}: the check said {said!r}; graded: {graded!r}"
    # the page says all of it, each detail once: a check's words in its row (a box with rows of checks) or in the
    # message above, and the notebook's check's words and hint
    parts = [" ".join(c.message.split()) for c in verdict.checks if not c.passed] + \
        [re.sub(r"^exercise [\w.]+ \w+: ", "", message), hint]
    missing = [p for p in parts if p and page.count(p) != 1]
    assert not missing, f"{gid}: the page shows {page!r}, where {missing[0]!r} should be once"
    if hint:   # ...and no hint of its own that names another mistake
        others = [h for h in " ".join([graded, *(c.message for c in verdict.checks)]).split("Hint: ")[1:]
                  if not h.startswith(hint)]
        assert others == [], f"{gid}: the check's hint is {hint!r}; graded also: {others}"
