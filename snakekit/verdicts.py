"""What each exercise's check said in this kernel, for the cells that use the exercise after it.

An exercise built on earlier ones (a composite: 6.3's ``task2_sweep`` uses 6.1's ``sweep_times``) is
judged on what it adds, by one rule, locally and graded: when a part it builds on fails its own check,
the composite's failed check names that part (:func:`composite_note`), and so does a demonstration cell
that stopped while using the composite (:func:`stopped_note`, for ``checks.waiting_for``): the error it
stopped with may advise a fix that does not apply (moving the arm to a sweep's first goal, where the real
slip is 6.1's times starting at 1/rate).
"""

from __future__ import annotations

import re

#: exercise number -> whether its check cell passed, in this kernel (absent: not run yet).
PASSED: dict[str, bool] = {}
#: exercise number -> what its failed check said (its hint, else its message).
CAUSES: dict[str, str] = {}
#: exercise number -> the exercises it builds on, as its check names them (``builds_on``).
BUILDS_ON: dict[str, tuple] = {}


def composite_note(number: str, parts: list) -> str:
    """What a composite's failed check adds when parts it builds on fail their own checks: the one
    rule of the course, the same locally and graded.

    >>> print(composite_note("6.3", ["6.1"]))
    6.3 uses your 6.1, which fails its check: fix 6.1 first; graded, 6.3 is run with the lesson's own 6.1.
    >>> print(composite_note("6.3", ["6.1", "6.2"]))
    6.3 uses your 6.1 and 6.2, which fail their checks: fix them first; graded, 6.3 is run with the lesson's own 6.1 and 6.2.
    """
    names = " and ".join(parts)
    fails, fix = ("fails its check", f"fix {names}") if len(parts) == 1 else ("fail their checks", "fix them")
    return f"{number} uses your {names}, which {fails}: {fix} first; graded, {number} is run with the lesson's own {names}."


#: What :func:`composite_note` writes, as a pattern: a message that holds it is explained by a part's slip, so
#: neither side adds a hint of the composite's own (``Exercise.fail``, ``grader.scoring.verdict.with_local_check``).
NOTE = re.compile(r"\b[\d.]+ uses your [\d. and]+, which fails? (?:its|their) checks?: fix ")


def failing_parts(number: str, builds_on: tuple = ()) -> list:
    """The exercises ``number`` builds on (``builds_on``, else what its check named) whose checks failed."""
    return [n for n in builds_on or BUILDS_ON.get(number, ()) if PASSED.get(n) is False]


def stopped_note(number: str, parts: list, error: BaseException) -> str:
    """Why a cell that uses exercise ``number`` stopped with ``error``, when ``parts`` it builds on fail their
    checks: those parts and what their checks said, and the error's first sentence (not its advice).

    >>> CAUSES["6.1"] = "the times start at 1/rate."
    >>> print(stopped_note("6.3", ["6.1"], ValueError("the sweep starts 0.118 rad away. Move there first.")))
    this cell uses your answer to exercise 6.3, which uses your 6.1, and 6.1 fails its check: the times start at 1/rate. That is why this cell stopped (ValueError: the sweep starts 0.118 rad away). Fix 6.1 first, run its check cell, then this cell again.
    >>> del CAUSES["6.1"]
    """
    names = " and ".join(parts)
    fails, fix = ("fails its check", "its check cell") if len(parts) == 1 else ("fail their checks", "their check cells")
    said = [CAUSES.get(n, "see its check cell").rstrip(".") for n in parts]
    causes = said[0] if len(parts) == 1 else "; ".join(f"{n}: {s}" for n, s in zip(parts, said))
    first = str(error).split(". ")[0].rstrip(".")
    return (f"this cell uses your answer to exercise {number}, which uses your {names}, and {names} {fails}: {causes}. "
            f"That is why this cell stopped ({type(error).__name__}: {first}). Fix {names} first, run {fix}, then "
            "this cell again.")
