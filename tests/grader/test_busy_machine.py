"""A lesson whose test cells run the arm's bus emulator runs in real time: when a clock stopped its sandbox, or
a reply of the emulated bus came late, on a machine busier than its cores, the TA's line says the load may be
the cause and to grade again on a quiet machine. The load is simulated (a monkeypatched reading)."""

from __future__ import annotations

import os
import time
from pathlib import Path
from types import SimpleNamespace

import pytest

from grader.course.assignment import Assignment, TestCell
from grader.feedback.notebook import for_student
from grader.scoring.verdict import Verdicts, busy_machine, real_time
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
    assert "load" not in shown and "--student" not in shown and shown == detail.split("; the grading machine's")[0]
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
    assert note and for_student(detail) == before


@pytest.mark.parametrize("name, value", [("07_real_robot", 1.5), ("06_coded_sweep", 7.9)])
def test_no_load_note_on_a_quiet_machine_or_for_a_lesson_that_does_not_run_in_real_time(tmp_path, load, name, value):
    load(value)
    detail = collect(tmp_path, lesson(name), runs=2)
    assert detail.startswith("graded on its second run") and "load" not in detail, detail
