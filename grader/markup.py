"""nbgrader's markup in a notebook's cells, written once: the solution and hidden-test markers.

The course's instructor notebooks mark a solution with ``### BEGIN SOLUTION`` / ``### END
SOLUTION`` and the tests a student must not see with ``### BEGIN HIDDEN TESTS`` / ``### END
HIDDEN TESTS`` (nbgrader's ``ClearSolutions`` and ``ClearHiddenTests``). The feedback pages
remove hidden tests with :data:`HIDDEN`; the second run of a dependent exercise
(:mod:`grader.scoring.rerun`) strips the solution markers with :data:`SOLUTION_MARKERS`.
"""

from __future__ import annotations

import re

#: A hidden-test region, its marker lines included (any number of ``#``, any case, as nbgrader reads them).
HIDDEN = re.compile(r"^[ \t]*#+[ \t]*BEGIN HIDDEN TESTS.*?^[ \t]*#+[ \t]*END HIDDEN TESTS[^\n]*\n?",
                    re.MULTILINE | re.DOTALL | re.IGNORECASE)
#: The first line of a hidden-test region.
BEGIN_HIDDEN = re.compile(r"^[ \t]*#+[ \t]*BEGIN HIDDEN TESTS", re.IGNORECASE)
#: A solution marker line (``### BEGIN SOLUTION`` or ``### END SOLUTION``).
SOLUTION_MARKERS = re.compile(r"^[ \t]*### (BEGIN|END) SOLUTION[ \t]*\n?", re.M)


def visible_part(source: str) -> str:
    """A test cell's source without its hidden-test region(s) (what the released notebook shows).

    >>> print(visible_part("check(f)\\n### BEGIN HIDDEN TESTS\\nsecret(f)\\n### END HIDDEN TESTS\\n"))
    check(f)
    <BLANKLINE>
    """
    return HIDDEN.sub("", source)


def first_hidden_line(lines: list[str]) -> int:
    """The 1-based number of the first line that opens a hidden-test region (``len(lines) + 1`` if none)."""
    return next((i + 1 for i, line in enumerate(lines) if BEGIN_HIDDEN.match(line)), len(lines) + 1)


def without_solution_markers(source: str) -> str:
    """``source`` without its solution marker lines (the solution itself stays)."""
    return SOLUTION_MARKERS.sub("", source)
