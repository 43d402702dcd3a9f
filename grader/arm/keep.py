"""What ``snakekit grade`` keeps for the lab: each student's trajectory at the spec's own values.

The hidden cases change every batch. Where the exercise's cases hold the call with no arguments
(lesson 06: ``task2_sweep()``, Task 2 at the function's own defaults, which the spec's values
are), that case is the lab's; otherwise the grader also asks the lab's exercise for the spec's
case (:func:`with_lab_case`: one more case of that grade id, scored like the others against the
instructor's run of it). It keeps what the student's function returned there, as arrays, beside
the autograded notebook (:func:`keep`): ``autograded/<student>/<a>/lab/<grade id>.npz`` with
``times``, ``positions`` (the trajectory) and ``measured_times``, ``measured_positions`` (its
simulator run in the sandbox). The lab reads it with ``allow_pickle=False``; the student's code
never runs outside the sandbox.
"""

from __future__ import annotations

import dataclasses
import io
from pathlib import Path

import numpy as np

from grader.arm.feedback import update_pages
from grader.arm.jobs import handin_path, settings
from grader.errors import NoLab
from grader.hooks import BatchHooks

KEPT = ("times", "positions", "measured_times", "measured_positions")


def lab_case(course: Path, assignment: str):
    """``(settings, the spec's case as a tuple of arguments)``, or None when the lab does not run the assignment.

    Raises:
        LabError: the course's ``lab.json`` has a bad value (grading stops before it starts, saying which).
    """
    try:
        s = settings(course, assignment)
    except NoLab:
        return None
    return s, tuple(s.case.values())


def with_lab_case(batch, course: Path):
    """``batch`` (a :class:`grader.scoring.cases.Draw`) with the spec's case last among the lab exercise's cases."""
    found = lab_case(course, batch.assignment)
    if found is None or found[0].exercise not in batch.cases:
        return batch
    s, case = found
    if () in batch.cases[s.exercise]:
        return batch  # Task 2 itself is a case already: the call with no arguments (kept by keep())
    cases = dict(batch.cases)
    cases[s.exercise] = [c for c in cases[s.exercise] if c != case] + [case]
    return dataclasses.replace(batch, cases=cases)


def keep(course: Path, assignment: str, student: str, results: list | None, batch) -> Path | None:
    """Write the student's result at the spec's case (``results``: the exercise's hand-in, decoded) for the lab.

    Returns the file written, or None (no lab for the assignment, no hand-in, or an error at that case:
    the lab then refuses the job, saying so).
    """
    found = lab_case(course, assignment)
    if found is None:
        return None
    s, case = found
    path = handin_path(course, student, s)
    path.unlink(missing_ok=True)
    cases = batch.cases.get(s.exercise, [])
    if () in cases:  # the student's Task 2 as their function makes it with no arguments
        case = ()
    if results is None or case not in cases:
        return None
    k = cases.index(case)
    r = results[k] if k < len(results) else None
    if not isinstance(r, dict) or not {"times", "positions"} <= set(r):
        return None
    path.parent.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez(buf, **{name: np.asarray(r[name], dtype=float) for name in KEPT if name in r})
    path.write_bytes(buf.getvalue())
    return path


def keep_for_lab(course: Path, assignment: str, student: str, work: Path, batch) -> Path | None:
    """:func:`keep` from a sandbox's folder ``work`` (its hand-in files)."""
    from grader.course.assignment import read_inside
    from grader.scoring.score import read_handin

    found = lab_case(course, assignment)
    if found is None:
        return None
    raw = read_inside(work, f"handin/{found[0].exercise}.npz")
    try:
        results = read_handin(raw) if raw is not None else None
    except ValueError:
        results = None
    return keep(course, assignment, student, results, batch)


#: What a batch does for the lab (:class:`grader.hooks.BatchHooks`): the lab's case among the
#: hidden cases, the trajectory kept at it, and the lab's result in the feedback pages.
HOOKS = BatchHooks(cases=with_lab_case, graded=keep_for_lab, pages=update_pages)
