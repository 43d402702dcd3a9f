"""One exception tree for snakekit.

Every error says what was wrong, what was expected and what to do. Errors that describe bad
input also derive from the matching built-in (``ValueError``, ``OSError``...), so generic
``except ValueError`` code keeps working.
"""

from __future__ import annotations

import re


class SnakekitError(Exception):
    """Base class of every error snakekit raises on purpose."""


class ConfigurationError(SnakekitError, ValueError):
    """An option or argument has a value the kit can't use (a negative rate, an unknown
    choice, a servo id that is not on the arm...)."""


class InputTypeError(SnakekitError, TypeError):
    """An argument is of the wrong kind (a list where a Trajectory is needed...)."""


class MissingDependencyError(SnakekitError, ImportError):
    """A package the kit needs for this part is not installed; the message names the install step."""


class ShapeError(SnakekitError, ValueError):
    """An array has the wrong shape, e.g. 4 joint angles for a 5-joint arm."""

    def __init__(self, name: str, expected: str, actual: tuple, hint: str = ""):
        self.name, self.expected, self.actual = name, expected, actual
        got = actual if isinstance(actual, str) else f"shape {actual}"  # a str: e.g. ragged rows
        msg = f"{name} must have shape {expected}, got {got}"
        super().__init__(msg + (f". {hint}" if hint else ""))


class NotFiniteError(SnakekitError, ValueError):
    """An array holds NaN or infinity."""


class LimitError(SnakekitError, ValueError):
    """A configuration or trajectory is outside the arm's joint limits.

    Attributes:
        violations: the offending entries (``Violation`` objects for trajectories, or
            ``(joint, value, lower, upper)`` tuples for a single configuration).
    """

    def __init__(self, message: str, violations: list | tuple = ()):
        self.violations = list(violations)
        super().__init__(message)


class UnreachableTargetError(SnakekitError, ValueError):
    """No joint configuration inside the limits puts the tool on the target.

    Attributes:
        target: the requested ``(x, y)`` [m] (and heading [rad] when given).
        closest: the closest tool point the solver found, ``(x, y)`` [m].
        q_closest: the joint angles [rad] that reach ``closest``.
    """

    def __init__(self, message: str, target, closest, q_closest):
        self.target, self.closest, self.q_closest = target, closest, q_closest
        super().__init__(message)


class TrajectoryError(SnakekitError, ValueError):
    """A trajectory is malformed (times not increasing, too few points...)."""


class FileFormatError(SnakekitError, ValueError):
    """A file could not be read as what it claims to be (truncated, wrong columns...)."""


class FileWriteError(SnakekitError, OSError):
    """A file could not be written where asked (the folder is missing, it is a folder, no
    permission, a read-only place...); the message names the path and what to do."""


class PacketError(SnakekitError, ValueError):
    """Bytes that are not one well-formed Dynamixel Protocol 2.0 packet."""


class BackendError(SnakekitError):
    """A robot backend could not be made or used (unknown name, closed robot...)."""


class CommunicationError(BackendError):
    """The servo bus stopped answering, or answered with corrupt packets, too often."""


class PortLostError(BackendError):
    """The servo bus's serial port went away: the USB adapter was unplugged or lost power, the
    bridge serving it stopped, or the emulator behind it was closed. The message says what
    the arm was last told; every later call on the robot raises it again."""


class BusWatchdogError(BackendError):
    """The servos' Bus Watchdog stopped them: they heard no instruction packet for longer than its
    period (the program, or the computer it runs on, stalled), so they hold where they stopped and
    refuse goals until ``robot.torque_on()`` clears it."""


class BridgeError(ConfigurationError):
    """``snakekit bridge`` could not start: the serial port or the address to listen on is not
    usable (missing, in use, a bad ``--listen``); the message says why and what to do."""


class HardwareError(BackendError):
    """A servo reported a hardware alert (overload, overheating, voltage...)."""


class ServoMismatchError(BackendError):
    """A servo answered, but is not the model the arm is built from (MX-28, Protocol 2.0)."""


class InstructionError(BackendError):
    """A servo refused an instruction (the low bits of its status packet's error byte).

    Attributes:
        servo_id: which servo.
        code: the error number (1..7, see ``snakekit.hardware.registers.PACKET_ERRORS``).
    """

    def __init__(self, message: str, servo_id: int, code: int):
        self.servo_id, self.code = servo_id, code
        super().__init__(message)


class ViewerError(SnakekitError, RuntimeError):
    """The 3D viewer's server could not be started, or stopped answering, or is closed."""


def wrap_lines(text: str, width: int) -> list[str]:
    """``text`` in lines of at most ``width`` characters, each line broken at spaces (a longer
    word, such as a file's path, is split); an indented line's continuations keep its indent.

    >>> wrap_lines("tool x is 0.3 m, expected 0.2 m\\n  Hint: metres", 16)
    ['tool x is 0.3 m,', 'expected 0.2 m', '  Hint: metres']
    """
    import textwrap

    out = []
    for line in text.split("\n"):
        indent = line[:len(line) - len(line.lstrip(" "))]
        out += textwrap.wrap(line, width, subsequent_indent=indent, break_on_hyphens=False,
                             drop_whitespace=True) or [""]
    return out


def whole_sentences(text: str, most: int = 2000) -> str:
    """``text`` whole, or, past ``most`` characters, up to the end of its last sentence that fits (a
    message is never cut mid-word): the sentences left out are said to be left out. Text without a
    sentence's end to cut at stays whole.

    >>> whole_sentences("One. Two words here. Three.", 20)
    'One. (the rest of the message left out)'
    >>> whole_sentences("velocity +52.6992 rad/s (limit +1.5000), beyond", 20)
    'velocity +52.6992 rad/s (limit +1.5000), beyond'
    """
    if len(text) <= most:
        return text
    ends = [m.end() for m in re.finditer(r"[.!?](?=\s)", text[:most])]
    return text[:ends[-1]] + " (the rest of the message left out)" if ends else text


class CheckFailed(SnakekitError, AssertionError):
    """A course check failed (:mod:`snakekit.checks`). The message says what, where and by how much.

    Attributes:
        student_frames: the part of a traceback that lies in the student's own code (may be
            empty); shown under the message, never frames of the checks module.
    """

    def __init__(self, message: str, student_frames: str = ""):
        super().__init__(message)
        self.student_frames = student_frames

    def __str__(self) -> str:
        return self.args[0] if self.args else ""

    #: what separates a check's message from its hint (one line, after the message)
    HINT = "\nHint: "

    @classmethod
    def compose(cls, message: str, hint: str = "") -> str:
        """A check's text: the message, then its hint when there is one."""
        return message + (f"{cls.HINT}{hint}" if hint else "")

    @classmethod
    def hint_of(cls, text: str) -> str:
        """The hint of a check's text (what :meth:`compose` wrote), "" when it has none.

        >>> CheckFailed.hint_of(CheckFailed.compose("tool x is 1 m, expected 0.3 m", "millimetres?"))
        'millimetres?'
        """
        return text.partition(cls.HINT)[2].strip()

    #: the widest line of a rendered check message: nbgrader's Validate cuts lines longer than
    #: its ``Validator.width`` (90) less its indent (4) and a "..." (3); wrapped here, at word
    #: boundaries, every line of a message arrives whole
    WIDTH = 80

    def _render_traceback_(self) -> list[str]:
        """What IPython shows instead of a traceback: the message (and the student's frames),
        wrapped to :attr:`WIDTH` columns."""
        red, bold, reset = "\x1b[31m", "\x1b[1m", "\x1b[0m"
        title = "Shortcut" if isinstance(self, ShortcutError) else "Check failed"
        text = f"{title}: {self}"
        if self.student_frames:
            text += "\n\nWhere, in your code:\n" + self.student_frames.rstrip()
        lines = wrap_lines(text, self.WIDTH)
        lines[0] = f"{red}{bold}{title}{reset}" + lines[0][len(title):]
        return lines


class ShortcutError(CheckFailed):
    """A library function was called inside an exercise that asks the student to write it."""


class CollisionError(LimitError):
    """A goal or a path would bring two links that are not neighbours in the chain closer
    than the spec's collision margin (the arm folding onto itself); nothing was sent.

    Attributes:
        time: when on the path [s]: a trajectory's time; for a command, from when it is sent
            (None for a command judged on the straight path from the last goal).
        links: the two bodies (``"base_link"``, ``"link1"``...).
        distance: their distance there [m] (negative: they would overlap by that much).
        q: the joint angles there [rad].
        margin: the least distance allowed [m].
    """

    def __init__(self, message: str, time, links, distance: float, q, margin: float):
        self.time, self.links, self.distance, self.q, self.margin = time, tuple(links), distance, q, margin
        super().__init__(message)
