"""When the machine held the emulator's serve loop up: real servos have processors of their own,
emulated ones share this computer's.

The serve loop marks each step (:meth:`HoldUps.beat`: before a wait, after it, around a reply
delayed on purpose). Coming back later than due is a hold-up; :meth:`HoldUps.held_up` tells a
driver in the same process (``snakekit.host.HELD_UP``) whether an exchange that failed fell in one.
"""

from __future__ import annotations

import collections
import math
import time

STALL = 0.02  # s: a serve loop later than its wait by more than this was held up by the machine


class HoldUps:
    """The hold-ups of one serve loop, as ``time.perf_counter()`` spans [s]."""

    def __init__(self, keep: int = 1000):
        self.spans: collections.deque[tuple[float, float]] = collections.deque(maxlen=keep)
        self.due = math.inf  # when the serve loop is due back at its next step, unless held up

    def beat(self, allow: float) -> None:
        """The serve loop reached a step: the span since it was due (when it is later than that) is a
        hold-up; it is due back within ``allow`` [s] (a wait, a reply delayed on purpose) and :data:`STALL`."""
        now = time.perf_counter()
        if now > self.due:
            self.spans.append((self.due, now))
        self.due = now + allow + STALL

    def ended(self) -> None:
        """The serve loop ended: it is not held up."""
        self.due = math.inf

    def sleep(self, seconds: float, sleep=time.sleep) -> None:
        """Wait on purpose (a delayed reply, the return delay): not a hold-up."""
        self.beat(seconds)
        sleep(seconds)
        self.beat(0.0)

    def held_up(self, since: float, until: float) -> bool:
        """Whether the machine held the serve loop up between two ``time.perf_counter()`` times [s]: it
        came back from a step later than due in that span, or is overdue now and was due before
        ``until``. A reply the servos owe then may be late for want of the processor, not of a servo:
        the driver does not count such an exchange as a failed try. A reply delayed on purpose
        (``Faults(delay=...)``, the return delay) is not a hold-up."""
        due = self.due
        if time.perf_counter() > due and due < until:
            return True
        return any(start < until and end > since for start, end in list(self.spans))


def precise_sleep(seconds: float) -> None:
    """Sleep ``seconds`` [s], spinning the last 0.2 ms for sub-millisecond precision."""
    end = time.perf_counter() + seconds
    if seconds > 3e-4:
        time.sleep(seconds - 2e-4)
    while time.perf_counter() < end:
        pass
