"""Every exception the grader raises: its errors, all under :class:`snakekit.errors.SnakekitError`, and
:class:`Interrupted`, Ctrl-C between two students (a :class:`KeyboardInterrupt`, carrying what was done by then).

A command catches these and prints one line (exit 2); nothing here is raised inside the sandbox
(:mod:`grader.sandbox.inside` reports through its exit code and files instead).
"""

from __future__ import annotations

from snakekit.errors import BackendError, ConfigurationError, SnakekitError


class CourseError(SnakekitError, ValueError):
    """A command's arguments name something the course does not have, or a path it must not write."""


class LateRuleError(CourseError):
    """A late-penalty rule that is not one of the forms :func:`grader.commands.late.parse` reads."""


class GradingError(SnakekitError):
    """The batch cannot be graded (no such assignment, no gradebook entry, bad course...)."""


class CasesError(SnakekitError):
    """A cases module is missing, broken, or draws something that cannot be sent."""


class InstructorReferenceError(SnakekitError):
    """A reference (the instructor's run at the hidden cases) is missing, unreadable, stale, or could
    not be recorded."""


class SandboxError(SnakekitError):
    """The sandbox cannot be made on this machine (no namespaces, no unshare...)."""


class Stopped(SnakekitError):
    """A sandbox was killed because the batch was interrupted (:data:`grader.sandbox.namespaces.STOP`)."""


class LabError(ConfigurationError):
    """Bad arguments or a course the arm's lab cannot work on yet (exit 2: nothing moved)."""


class NoLab(LabError):
    """The lab does not run this assignment (unknown, or its hand-in is not a trajectory)."""


class Busy(LabError):
    """Another lab session holds the course or the arm (exit 2: nothing moved)."""


class Stalled(BackendError):
    """The lab computer stalled during every try of a run (the goals went out late): the lab's fault."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C stopped a command between two students. A KeyboardInterrupt, not an error: it stops the command as
    Ctrl-C does, and carries what was done by then, which the command reports (exit 130)."""


class GradeInterrupted(Interrupted):
    """``snakekit grade`` stopped between two students: ``results`` are those written to the gradebook."""

    def __init__(self, results: list):
        super().__init__(f"interrupted after {len(results)} submission(s)")
        self.results = results


class CollectInterrupted(Interrupted):
    """``snakekit collect`` stopped between two students: ``placed`` of ``total`` were placed and listed."""

    def __init__(self, placed: int, total: int):
        super().__init__(f"{placed} of {total}")
        self.placed, self.total = placed, total


class ReturnInterrupted(Interrupted):
    """``snakekit return`` stopped between two students: ``released`` to the exchange, ``zips`` written whole."""

    def __init__(self, released: int, zips: list | None = None):
        super().__init__(f"{released} released")
        self.released, self.zips = released, list(zips or [])
