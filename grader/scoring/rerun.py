"""An exercise built on earlier ones, graded once more with the lesson's own earlier parts.

6.3's sweep is built from the student's 6.1 and 6.2, 3.3's loop from their 3.2: a slip there
would cost the later exercise in full, though what it adds may be right. The cases module names
these dependencies (``DEPENDS``: a test cell's grade id -> the answer cells it builds on). When
a dependent exercise scored less than full and one of its dependencies did too, the grader runs
the submission once more in its sandbox, at the same cases, with those answer cells replaced by
the instructor's (from the source notebook), and scores the dependent exercise from that run;
the exercise keeps the better of the two. The second run's outputs are never shown (the
instructor's code ran in its kernel): only its hand-in of the dependent exercise is read, and
the feedback says in one line which parts were replaced and what that scored.

A test cell the notebook's clock stopped before it had run (earlier cells, each stopped at the
cell limit by a part's endless loop, used up the notebook's time) is run again the same way,
whatever it builds on, with every other part that lost points replaced: a loop costs only its part.
"""

from __future__ import annotations

import dataclasses
import re

import nbformat

from grader.markup import without_solution_markers
from grader.scoring.score import ExerciseScore
from grader.scoring.wording import points

__all__ = ["needed", "with_answers", "better"]

def exercise(grade_id: str) -> str:
    """'ex06_3_task2_test' -> '6.3' (the exercise a cell belongs to; the grade id if it names none).

    >>> exercise("ex06_1_sweep_times"), exercise("ex03_3_ik_loop_test"), exercise("odd")
    ('6.1', '3.3', 'odd')
    """
    m = re.match(r"ex0*(\d+)_(\d+)_", grade_id)
    return f"{m.group(1)}.{m.group(2)}" if m else grade_id


def _grade_id(cell) -> str | None:
    return cell.get("metadata", {}).get("nbgrader", {}).get("grade_id")


def needed(depends: dict, scores: dict, written: dict, unreached=frozenset()) -> dict[str, list[str]]:
    """The test cells worth a second run, each with the answer cells to replace.

    ``scores``: test cell grade id -> :class:`ExerciseScore` of the first run; ``written``: answer
    cell grade id -> whether the student changed it from the release (an exercise left
    unwritten has nothing to grade, whatever it builds on). A dependency is replaced when a
    test cell of its exercise scored less than full. A written dependent exercise that handed in
    nothing (``missing``: its test cell was stopped, as when a part loops endlessly) is run again too.

    ``unreached``: the test cells the notebook's clock stopped before they ran to their end (the
    cell it stopped in and every test cell after it: earlier cells, a part's endless loop among
    them, used up the notebook's time). Each that scored less than full is run again, with every
    other exercise's answer that scored less than full replaced, so that a part that loops costs
    only itself. An exercise whose test cell the second run reads is never replaced in it.
    """
    def lost(cell):
        return any(s.score < s.max_score for g, s in scores.items() if exercise(g) == exercise(cell))

    out = {}
    for gid in [*depends, *sorted(set(unreached) - set(depends))]:
        sc = scores.get(gid)
        if sc is None or sc.status not in ("scored", "missing") or sc.score >= sc.max_score:
            continue
        own = [c for c in written if exercise(c) == exercise(gid)]
        if own and not any(written[c] for c in own):
            continue
        parts = sorted(c for c in written if c not in own and lost(c)) if gid in unreached else \
            [c for c in depends[gid] if lost(c)]
        if parts or gid in unreached:
            out[gid] = parts
    read = {exercise(g) for g in out}
    return {g: [c for c in parts if exercise(c) not in read] for g, parts in out.items()}


def with_answers(nbs: dict, source: dict, cells: set) -> dict:
    """The submitted notebooks (name -> notebook) with the answer ``cells`` replaced by the
    instructor's solution from ``source`` (name -> the source notebook)."""
    theirs = {}
    for nb in source.values():
        for c in nb.cells:
            if _grade_id(c) in cells:
                theirs[_grade_id(c)] = without_solution_markers(c.source)
    out = {}
    for name, nb in nbs.items():
        nb = nbformat.from_dict(nb)
        for c in nb.cells:
            if _grade_id(c) in theirs:
                c.source = theirs[_grade_id(c)]
        out[name] = nb
    return out


#: How :func:`better` starts the message of an exercise graded with the lesson's own parts.
OWN = re.compile(r"graded with the lesson's own (.+?) in place of yours: .*?\(with yours: ([\d.]+), the run below\)")


def rows_note(message: str) -> str:
    """What a page says above the rows of checks of an exercise graded with the lesson's own parts: the rows
    are the run with the student's own (the points come from the other run), "" for any other exercise.

    >>> rows_note("graded with the lesson's own 6.1 in place of yours: 7 of 7 (with yours: 3.98, the run below). x")
    "The rows below describe the run with your own 6.1 (it scored 3.98); the points above come from the run with the lesson's own 6.1."
    """
    m = OWN.match(message)
    if not m:
        return ""
    parts, mine = m.groups()
    return (f"The rows below describe the run with your own {parts} (it scored {mine}); the points above come from "
            f"the run with the lesson's own {parts}.")


def better(first: ExerciseScore, second: ExerciseScore | None, replaced: list[str]) -> ExerciseScore:
    """The better of the two runs' scores of one exercise. The second run's checks and curves
    are never shown (they came from a kernel that held the instructor's code): only its score,
    in one line before the first run's message."""
    if second is None or second.score <= first.score:
        return first
    parts = sorted({exercise(c) for c in replaced})
    names = " and ".join(parts)
    line = (f"graded with the lesson's own {names} in place of yours: {points(second.score)} of {second.max_score:g} "
            f"(with yours: {points(first.score)}, the run below)." if parts else
            f"graded in a run of its own, as your notebook's time ran out before this cell had run: "
            f"{points(second.score)} of {second.max_score:g} (in your notebook's run: {points(first.score)}, the run below).")
    return dataclasses.replace(first, score=second.score, message=f"{line} {first.message}")
