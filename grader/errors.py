"""Every exception the grader raises, all under :class:`snakekit.errors.SnakekitError`.

A command catches these and prints one line (exit 2); nothing here is raised inside the sandbox
(:mod:`grader.sandbox.inside` reports through its exit code and files instead).
"""

from __future__ import annotations

from snakekit.errors import BackendError, ConfigurationError, SnakekitError


class CourseError(SnakekitError, ValueError):
    """A command's arguments name something the course does not have, or a path it must not write."""


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
