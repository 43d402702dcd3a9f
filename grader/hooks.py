"""What an optional part of the grader adds to a batch, without the core importing it.

The arm's lab (:mod:`grader.arm`) keeps each student's Task 2 trajectory at the lab's case and
writes its result into the feedback pages. The core (:mod:`grader.batch`,
:mod:`grader.scoring.verdict`) calls these hooks; the commands layer (:mod:`grader.commands.grade`)
hands it the arm's (:data:`grader.arm.keep.HOOKS`). A batch made without them grades the same.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


def _same(draw, course: Path):
    return draw


def _nothing(*args) -> None:
    return None


@dataclass(frozen=True)
class BatchHooks:
    """Three calls a batch makes on its way.

    Attributes:
        cases: ``(draw, course) -> draw``: the batch's hidden cases (a :class:`grader.scoring.cases.Draw`),
            with any case the extension needs added.
        graded: ``(course, assignment, student, work, draw)``: after a submission is graded, with its
            sandbox folder ``work`` (its hand-in files).
        pages: ``(course, assignment, student)``: after the student's feedback pages are written.
    """

    cases: Callable = _same
    graded: Callable = _nothing
    pages: Callable = _nothing


NO_HOOKS = BatchHooks()
