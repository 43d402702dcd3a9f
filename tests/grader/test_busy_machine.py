"""A lesson whose test cells run the arm's bus emulator runs in real time: when a clock stopped its sandbox, or
a reply of the emulated bus came late, on a machine busier than its cores, the TA's line says the load may be
the cause and to grade again on a quiet machine. The load is simulated (a monkeypatched reading)."""

from __future__ import annotations

import os
import re
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from grader.course.assignment import Assignment, TestCell
from grader.feedback.notebook import for_student
from grader.scoring.verdict import Verdicts, busy_machine, real_time
from grader.scoring.wording import title
from tests.conftest import need

ROOT = Path(__file__).resolve().parents[2]
LESSONS = sorted(p.name for p in (ROOT / "course" / "source").iterdir() if (p / f"{p.name}.ipynb").exists())
NOTE = "the grading machine's load was 7.9 on 2 cores"


def assignment(name: str, sources: dict) -> Assignment:
    tests = {gid: TestCell(gid, name, 2.0, src, "code") for gid, src in sources.items()}
    return Assignment(name, [name], tests, {}, 2.0 * len(tests))


def lesson(name: str) -> Assignment:
    nb = need("nbformat").read(ROOT / "course" / "source" / name / f"{name}.ipynb", as_version=4)
    return assignment(name, {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells
                             if c.metadata.get("nbgrader", {}).get("grade")})


@pytest.mark.parametrize("name", LESSONS)
def test_only_the_lesson_on_the_emulated_bus_counts_as_real_time(name):
    assert real_time(lesson(name)) == (name == "07_real_robot")


@pytest.fixture
def load(monkeypatch):
    """Set the machine's last-minute load average on 2 cores."""
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    return lambda value: monkeypatch.setattr(os, "getloadavg", lambda: (value, value / 2, value / 4))


def collect(tmp_path, a, *, runs=1, timed_out=False, error=None):
    """What the grader tells the TA of a submission whose notebook ran one cell (which raised ``error``, if
    given) and handed nothing in."""
    nbformat = need("nbformat")
    v = Verdicts(tmp_path, a, tmp_path, timeout=120.0, cell_timeout=40.0, memory=1 << 30)
    work = tmp_path / "work"
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("recover(arm)", execution_count=1)])
    if error:
        nb.cells[0].outputs = [nbformat.v4.new_output("error", ename=error, evalue="no reply", traceback=[])]
    out = work / "course" / "autograded" / "bob" / a.name
    out.mkdir(parents=True)
    nbformat.write(nb, out / f"{a.name}.ipynb")
    outcome = SimpleNamespace(timed_out=timed_out, returncode=0)
    return v.collect(work, "bob", {}, {}, [], outcome, time.monotonic(), runs=runs).detail


@pytest.mark.parametrize("how", ["stopped", "late reply", "late reply again"])
def test_a_real_time_lesson_stopped_by_the_clock_on_a_busy_machine_tells_the_ta_the_load(tmp_path, load, how):
    """The graded run itself shows a busy machine's marks (stopped by the clock twice, or a cell stopped on a fault of
    the arm's bus): the TA's line names the cell and the load, and says to grade again on a quiet machine. The
    student's page says what happened, never the TA's note."""
    load(7.9)
    a = lesson("07_real_robot")
    kwargs = {"stopped": dict(runs=2, timed_out=True), "late reply": dict(error="CommunicationError"),
              "late reply again": dict(error="BusWatchdogError", runs=2)}[how]
    detail = collect(tmp_path, a, **kwargs)
    assert NOTE in detail and "grade it again on a quiet machine" in detail, detail
    if how.startswith("late reply"):
        said = f"cell 1 raised {kwargs['error']}: no reply in " + ("the second run too" if kwargs.get("runs") else
                                                                     "the run graded")
        assert said in detail, detail
    shown = for_student(detail)
    assert "load" not in shown and "--student" not in shown and shown == detail.split("; the grading machine's")[0] \
        .replace(": no reply", ""), shown  # the fault by its type: its message is the TA's
    # the page's head, as build writes it: the score, then what happened, without the TA's note
    from grader.feedback.notebook import build
    from grader.scoring.verdict import SubmissionResult

    nbformat = need("nbformat")
    status = "timeout" if how == "stopped" else "graded"
    page = build(nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell("recover(arm)")]), student="bob",
                 assignment=a.name, result=SubmissionResult("bob", a.name, 1.0, 8.0, status, detail), test_sources={})
    head = page.cells[0].source
    assert shown in head and "grading machine's load" not in head and "--student" not in head, head


def test_a_second_run_that_ran_clean_is_a_sound_grade_without_a_note_of_the_load(tmp_path, load):
    """The first run was stopped by the clock, the second ran clean: the TA's line says so, and no more (grading
    again would change nothing)."""
    load(7.9)
    detail = collect(tmp_path, lesson("07_real_robot"), runs=2)
    assert detail == "graded on its second run: the first was stopped by the clock, so it ran once more from the start"


@pytest.mark.parametrize("load_value", [2.1, 7.9, 123.4])
@pytest.mark.parametrize("before", ["", "graded on its second run: the first was stopped by the clock, so it ran once "
                                        "more from the start; cell 3 raised BusWatchdogError: during the run, ...",
                                    "the notebook ran longer than 120 s and was stopped (run twice, ...)"])
def test_the_students_page_never_shows_the_tas_note_of_the_load(before, load_value):
    """Whatever the detail before it, the note busy_machine adds (to grade again with ``--student``) is the TA's:
    the student's page shows the detail without it, and all of the rest."""
    note = busy_machine(load=load_value, cores=2)
    detail = "; ".join(x for x in (before, note) if x)
    assert note and for_student(detail) == before.replace(": during the run, ...", "")


@pytest.mark.parametrize("name, value", [("07_real_robot", 1.5), ("06_coded_sweep", 7.9)])
def test_no_load_note_on_a_quiet_machine_or_for_a_lesson_that_does_not_run_in_real_time(tmp_path, load, name, value):
    load(value)
    detail = collect(tmp_path, lesson(name), runs=2)
    assert detail.startswith("graded on its second run") and "load" not in detail, detail


# --- the student's page: the grader's words, without the TA's (every detail a busy machine leads to) ------------

FAULTS = ("CommunicationError", "PortLostError", "BusWatchdogError")
#: what the kit's faults say, as hard as can be to cut out: the port, a semicolon, brackets, the grader's own words
MESSAGES = ("servo 3 did not answer the SyncRead on /dev/pts/7 (4 tries); check the cable",
            "the Bus Watchdog stopped servo(s) 1, 2 on /dev/pts/12: they heard nothing for more than 0.5 s (the "
            "host stalled). They refuse goals. Call robot.torque_on() to clear it and go on.",
            "the port /dev/ttyUSB0 is gone (unplugged?) in the run, at hidden case 9; and more",
            "x" * 500)


def _details(seed: int, n: int):
    """``n`` details of a lesson-07 run on a busy machine, each made as the grader makes them, with what went in."""
    import random

    from grader.files import fitted
    from grader.scoring.verdict import first_run_fault

    rng = random.Random(seed)
    for _ in range(n):
        error, message = rng.choice(FAULTS), rng.choice(MESSAGES)
        first = rng.choice(["clock", "cell", "handin", None])
        gid = rng.choice(["ex07_2_recover_test", "ex07_3_sweep_on_arm_test"])
        first_run = {"clock": "", None: "",
                     "cell": first_run_fault(f"cell {rng.randint(1, 30)} raised {fitted(error + ': ' + message)}"),
                     "handin": first_run_fault(f"{gid} raised {fitted(error + ': ' + message)} at hidden case "
                                               f"{rng.randint(0, 4)}")}[first]
        yield dict(runs=1 if first is None else 2, first_run=first_run,
                   error=rng.choice([None, (rng.choice(FAULTS), rng.choice(MESSAGES))]),
                   cells=rng.choice([1, 3]), mended={gid: {rng.randint(0, 4): 0.5}} if rng.random() < 0.4 else {},
                   load=rng.choice([1.0, 7.9]), gid=gid)


@pytest.mark.parametrize("case", list(_details(seed=31, n=60)), ids=lambda c: f"{c['runs']}-{bool(c['first_run'])}-"
                         f"{bool(c['error'])}-{c['cells']}-{bool(c['mended'])}-{c['load']}")
def test_a_students_page_says_what_happened_in_the_graders_words_and_never_the_tas(tmp_path, load, case):
    """Any detail a busy machine leads to (a first run stopped by the clock or by a fault of the arm's bus, a cell or
    hidden case that faulted in the graded run, the load): the student's page keeps every part of it in the
    grader's words, names each fault by its type and each exercise as the lesson does, and leaves out what is the
    TA's: the faults' own messages (the grading machine's ports, registers, advice to call robot.torque_on()),
    the test cells' ids and the note of the load."""
    nbformat = need("nbformat")
    load(case["load"])
    a = lesson("07_real_robot")
    v = Verdicts(tmp_path, a, tmp_path, timeout=120.0, cell_timeout=40.0, memory=1 << 30)
    work = tmp_path / "work"
    cells = [nbformat.v4.new_code_cell(f"step({k})", execution_count=k + 1) for k in range(case["cells"])]
    if case["error"]:
        for c in cells:
            c.outputs = [nbformat.v4.new_output("error", ename=case["error"][0], evalue=case["error"][1],
                                                traceback=[])]
    out = work / "course" / "autograded" / "bob" / a.name
    out.mkdir(parents=True)
    nbformat.write(nbformat.v4.new_notebook(cells=cells), out / f"{a.name}.ipynb")
    v.mend(work, case["mended"])
    detail = v.collect(work, "bob", {}, {}, [], SimpleNamespace(timed_out=False, returncode=0), time.monotonic(),
                       runs=case["runs"], first_run=case["first_run"]).detail
    shown = for_student(detail)

    for message in MESSAGES:  # none of a fault's own words, in whole or in part
        for words in (message[:25], "/dev/", "robot.torque_on", "xxxxx"):
            assert words not in shown, (words, shown)
    assert "load" not in shown and "--student" not in shown and "quiet machine" not in shown, shown
    assert not re.search(r"\bex\d+_\d+_", shown), shown
    # every part the grader said is there, in its words, each fault by its type
    said = []
    if case["runs"] == 2:
        said.append("graded on its second run: the first " + ("was stopped by the clock" if not case["first_run"] else
                                                               "had a fault of the arm's bus (") )
        said.append("so it ran once more from the start")
    if case["first_run"]:
        cause = re.search(r"\((.*?) raised (\w+)", case["first_run"])
        said.append(f"{cause[1] if cause[1].startswith('cell') else 'exercise ' + title(case['gid'])} raised "
                    f"{cause[2]}")
    if case["mended"]:
        (k,) = case["mended"][case["gid"]]
        said.append(f"exercise {title(case['gid'])} at hidden case {k} had a fault of the arm's bus in the second "
                    "run too, and took the first run's result there")
    if case["error"]:
        more = " (and 2 more cell(s))" if case["cells"] == 3 else ""
        said.append(f"cell 1 raised {case['error'][0]}{more} in " + ("the second run too" if case["runs"] == 2 else
                                                                     "the run graded"))
    for words in said:
        assert words in shown, (words, shown)
    assert for_student(shown) == shown  # the page's words are the student's already
    assert bool(shown) == bool(said), (detail, shown)
    # both heads a page can have say exactly that: build's, and the gradebook's (the page the student gets)
    from grader.course.gradebook import SubmissionScores
    from grader.feedback import scores
    from grader.feedback.notebook import build
    from grader.scoring.verdict import SubmissionResult

    numbers = SubmissionScores("bob", a.name, 8.0, 5.0, 0.0, 0.0, ())
    heads = [scores.head(numbers, "graded", detail, {}),
             build(nbformat.v4.new_notebook(), student="bob", assignment=a.name, test_sources={},
                   result=SubmissionResult("bob", a.name, 5.0, 8.0, "graded", detail)).cells[0].source]
    for h in heads:
        assert (shown in h if shown else "raised" not in h) and "load" not in h and "/dev/" not in h, h
