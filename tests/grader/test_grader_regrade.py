"""A regrade is reproducible: the same attempt always meets the same hidden cases; a new attempt, new ones.

A class graded twice and one student regraded with ``--student`` give identical scores, CSV rows and
pages, byte for byte, though no ``--seed`` is given: each attempt's seed is kept in
``<course>/draws/<a>.json``, and a page shows nothing of the grading machine's timing (a run's summary
printed by the notebook says its wall time in the notebook, not on the page). A
partly right submission (right for half the joint angles) shows it: its score depends on the cases
it meets. A student who hands in again meets a fresh draw, and the others keep theirs.
"""

from __future__ import annotations

import difflib
import json
from pathlib import Path

import pytest

from conftest import need_program
from grader_helpers import ASSIGNMENT, GOOD, REFERENCES, make_course, snakekit, submit

REPO = Path(__file__).resolve().parents[2]
#: right where joint 1 is at or above 0, wrong below: its score is the share of such cases it meets
HALF_RIGHT = GOOD["ex1_tool_xy"].replace("    phi = np.cumsum(q)", "    phi = np.cumsum(q) if q[0] >= 0 else q")
#: a notebook that runs its sweep on the simulator and prints the run's summary, as the lessons do
RUNS = GOOD["ex3_peak_speed"] + ("\nwith snakekit.make_robot('sim') as robot:\n"
                                  "    print(robot.run(my_sweep(200, 10.0, 4, 0.2)).summary())")


def _grade(course, *extra):
    r = snakekit("grade", ASSIGNMENT, "--course", course, "--references", REFERENCES, "--timeout", "120", *extra)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def _state(course):
    csv = (course / f"grades-{ASSIGNMENT}.csv").read_text()
    pages = {p.parent.parent.name: p.read_bytes() for p in (course / "feedback").glob(f"*/{ASSIGNMENT}/*.html")}
    return csv, pages


def _same(now, first):
    """The CSV and every page as they were; a page that changed is shown as its diff."""
    assert now[0] == first[0]
    assert set(now[1]) == set(first[1])
    for s, page in first[1].items():
        if now[1][s] != page:
            diff = difflib.unified_diff(page.decode().splitlines(), now[1][s].decode().splitlines(), lineterm="", n=0)
            pytest.fail(f"{s}'s page changed:\n" + "\n".join(list(diff)[:12])[:3000])


def _seeds(course):
    return {s: v["seed"] for s, v in json.loads((course / "draws" / f"{ASSIGNMENT}.json").read_text()).items()}


@pytest.fixture(scope="module")
def course(tmp_path_factory):
    need_program("unshare")
    course = make_course(tmp_path_factory.mktemp("regrade"))
    submit(course, "good")
    submit(course, "half", {"ex1_tool_xy": HALF_RIGHT})
    submit(course, "slip", {"ex1_tool_xy": GOOD["ex1_tool_xy"].replace("np.cos(phi)", "np.sin(phi)")})
    submit(course, "runs", {"ex3_peak_speed": RUNS})
    return course


def test_a_class_graded_twice_and_one_student_regraded_get_the_same_scores_and_pages(course):
    _grade(course)
    first, seeds = _state(course), _seeds(course)
    assert set(seeds) == {"good", "half", "runs", "slip"} and len(set(seeds.values())) == 1
    assert "robot time:" in first[1]["runs"].decode()  # the summary is on the page
    _grade(course)
    _same(_state(course), first)
    assert _seeds(course) == seeds
    r = _grade(course, "--student", "half", "--student", "half")   # a TA's slip: the name twice
    assert "snakekit grade: half given more than once: graded once" in r.stderr
    assert "graded 1 submission(s)" in r.stdout + r.stderr, r.stdout + r.stderr
    _same(_state(course), first)
    assert _seeds(course) == seeds


def test_a_new_attempt_meets_a_fresh_draw_and_the_others_keep_theirs(course):
    before = _seeds(course)
    submit(course, "half", {"ex1_tool_xy": HALF_RIGHT + "\n# handed in again"})
    r = _grade(course)
    after = _seeds(course)
    assert after["half"] != before["half"]
    assert {s: after[s] for s in ("good", "runs", "slip")} == {s: before[s] for s in ("good", "runs", "slip")}
    assert r.stderr.count("hidden cases drawn with seed") == 2   # the kept seed's batch, then the new attempt's
