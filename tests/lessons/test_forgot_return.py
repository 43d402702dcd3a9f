"""A forgotten ``return`` is named as such, for every exercise of the course, in the notebook's own
check and in the grader's feedback: "task1 returned None ...: did you forget `return`?".

Each lesson is handed in by a few students whose answers are the instructor's with every
``return`` of some exercises taken out (the value computed, then a bare ``return``: a path that
ends without one). An exercise and the exercises whose functions it calls are never taken out
in the same notebook, so each exercise meets the slip in its own function. ``snakekit grade``
grades them; the graded notebook's check cells hold what the notebook itself says (the same
kernel, the same checks), the feedback page what the grader says.
"""

from __future__ import annotations

import ast
import html
import re
from pathlib import Path

import pytest

from tests.conftest import need, need_program
from tests.grader.grader_helpers import box_title

REPO = Path(__file__).resolve().parents[2]
LESSONS = sorted(p.name for p in (REPO / "course" / "source").iterdir() if (p / f"{p.name}.ipynb").exists())
ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _meta(cell) -> dict:
    return cell.get("metadata", {}).get("nbgrader", {})


def exercises(lesson: str) -> list[dict]:
    """Per exercise: its answer cell's grade id, its test cell's, its function's name, and the
    other exercises' functions its answer calls."""
    nbformat = need("nbformat")
    nb = nbformat.read(REPO / "course" / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    tests = {_meta(c)["grade_id"]: c.source for c in nb.cells if _meta(c).get("grade")}
    out = []
    for c in nb.cells:
        m = _meta(c)
        if not m.get("solution") or f"{m['grade_id']}_test" not in tests:
            continue
        test = tests[f"{m['grade_id']}_test"]
        name = re.search(r"checks\.Exercise\(\"[\d.]+\", \"(\w+)\"", test).group(1)
        used = {n.id for n in ast.walk(ast.parse(c.source)) if isinstance(n, ast.Name)}
        out.append(dict(answer=m["grade_id"], test=f"{m['grade_id']}_test", name=name, source=c.source, used=used))
    names = {e["name"] for e in out}
    for e in out:
        e["calls"] = (e["used"] & names) - {e["name"]}
    return out


def returnless_source(source: str) -> str:
    """``source`` with every ``return VALUE`` turned into ``_ = VALUE`` and a bare ``return``."""
    return re.sub(r"^(\s*)return (.+)$", r"\1_ = \2\n\1return", source, flags=re.M)


def groups(found: list[dict]) -> list[list[dict]]:
    """The exercises in groups that hold no exercise together with one whose function it calls."""
    out: list[list[dict]] = []
    for e in found:
        for group in out:
            if not any(o["name"] in e["calls"] or e["name"] in o["calls"] for o in group):
                group.append(e)
                break
        else:
            out.append([e])
    return out


CASES = [(lesson, e["test"], e["name"]) for lesson in LESSONS for e in exercises(lesson)]


def test_the_slip_is_made_in_every_exercise_and_leaves_a_function_that_returns_none():
    assert len(CASES) >= 25
    for lesson in LESSONS:
        for e in exercises(lesson):
            changed = returnless_source(e["source"])
            assert changed != e["source"] and "return\n" in changed + "\n", (lesson, e["name"])
            assert not re.search(r"^\s*return \S", changed, flags=re.M), changed
            compile(changed, e["answer"], "exec")


def returnless(lesson: str) -> tuple[dict, dict]:
    """The lesson's slips as students: (student -> answers typed in, every other answer the instructor's;
    test grade id -> the student who made the slip in that exercise)."""
    students, who = {}, {}
    for k, group in enumerate(groups(exercises(lesson))):
        students[f"slip{k}"] = {e["answer"]: returnless_source(e["source"]) for e in group}
        who.update({e["test"]: f"slip{k}" for e in group})
    return students, who


@pytest.fixture(scope="module")
def graded(graded_slips):
    """lesson -> (course folder, test grade id -> the student who made the slip in that exercise): the lesson's
    slips graded in the batch of its known mistakes (tests/conftest.py's ``graded_slips``) when a test first
    asks for them."""
    need_program("unshare")
    need("nbformat")
    return lambda lesson: (graded_slips(lesson), returnless(lesson)[1])


def graded_message(course: Path, student: str, lesson: str, gid: str) -> str:
    """What the feedback page says for ``gid``: the text after "Grader: <exercise>: x / y points"."""
    page = (course / "feedback" / student / lesson / f"{lesson}.html").read_text()
    text = html.unescape(re.sub(r"<[^>]+>", " ", page))
    text = " ".join(text.split())
    at = text.index(f"Grader: {box_title(course / 'source' / lesson / f'{lesson}.ipynb', gid)}:")
    return text[at:at + 1500]


def local_message(course: Path, student: str, lesson: str, gid: str) -> str:
    """What the notebook's own check cell said, run in the grader's kernel."""
    nbformat = need("nbformat")
    nb = nbformat.read(course / "autograded" / student / lesson / f"{lesson}.ipynb", as_version=4)
    cell = next(c for c in nb.cells if _meta(c).get("grade_id") == gid)
    errors = [o for o in cell.outputs if o.output_type == "error"]
    return " ".join(ANSI.sub("", f"{errors[0].ename}: {errors[0].evalue}").split()) if errors else "(passed)"


# a lesson's slips go to one worker under `make test`, with its known mistakes (tests/conftest.py's graded_slips)
@pytest.mark.parametrize("lesson, gid, name", [pytest.param(*case, marks=pytest.mark.xdist_group(f"slips{case[0][:2]}"),
                                                            id="-".join(case)) for case in CASES])
def test_a_forgotten_return_is_named_locally_and_graded(graded, lesson, gid, name):
    course, who = graded(lesson)
    said = local_message(course, who[gid], lesson, gid)
    assert f"{name} returned None" in said and "did you forget `return`?" in said, said
    told = graded_message(course, who[gid], lesson, gid)
    assert f"{name} returned None" in told and "did you forget `return`?" in told, told
