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
from grader.scoring.verdict import Verdicts, real_time
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


@pytest.mark.parametrize("how", ["second run", "stopped", "late reply"])
def test_a_real_time_lesson_stopped_by_the_clock_on_a_busy_machine_tells_the_ta_the_load(tmp_path, load, how):
    load(7.9)
    a = lesson("07_real_robot")
    kwargs = {"second run": dict(runs=2), "stopped": dict(runs=2, timed_out=True),
              "late reply": dict(error="CommunicationError")}[how]
    detail = collect(tmp_path, a, **kwargs)
    assert NOTE in detail and "grade it again on a quiet machine" in detail, detail
    if how == "second run":
        assert detail.startswith("graded on its second run: the first was stopped by the clock"), detail


@pytest.mark.parametrize("name, value", [("07_real_robot", 1.5), ("06_coded_sweep", 7.9)])
def test_no_load_note_on_a_quiet_machine_or_for_a_lesson_that_does_not_run_in_real_time(tmp_path, load, name, value):
    load(value)
    detail = collect(tmp_path, lesson(name), runs=2)
    assert detail.startswith("graded on its second run") and "load" not in detail, detail
