"""A one-line progress report for runs that take a while (a real-time sweep takes 50 s).

>>> import io
>>> out = io.StringIO()
>>> bar = TextProgress(50.0, "Task 2 on the emulator", stream=out, every=0.0)
>>> bar.update(12.5); bar.close()
>>> print(out.getvalue().replace("\\r", "|"))
|Task 2 on the emulator:  12.5 / 50.0 s robot time (25 %)|Task 2 on the emulator:  50.0 / 50.0 s robot time (100 %)
<BLANKLINE>
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

#: runs paced by the wall clock and longer than this [s] report their progress by default
LONG_RUN = 3.0


def _in_kernel() -> bool:
    shell = sys.modules.get("IPython.core.interactiveshell")
    return bool(shell and shell.InteractiveShell.initialized())


class TextProgress:
    """Rewrites one line (with a carriage return) at most every ``every`` seconds.

    Args:
        total: the length of the run [s of robot time].
        label: what is running.
        stream: where to write (default: standard output in a notebook, where standard
            error would look like an error; standard error elsewhere, so the progress line
            stays out of a command's output).
        every: least time between two updates [s of wall time].
    """

    def __init__(self, total: float, label: str, *, stream: TextIO | None = None, every: float = 1.0):
        self.total = max(float(total), 1e-9)
        self.label = label
        self.stream = stream or (sys.stdout if _in_kernel() else sys.stderr)
        self.every = every
        self._last = -float("inf")
        self._done = 0.0

    def update(self, done: float) -> None:
        """``done`` [s] of the run are over; redraw if ``every`` has passed."""
        self._done = done
        now = time.perf_counter()
        if now - self._last >= self.every:
            self._last = now
            self._draw()

    def _draw(self) -> None:
        pct = 100 * min(self._done / self.total, 1.0)
        self.stream.write(f"\r{self.label}: {self._done:5.1f} / {self.total:.1f} s robot time ({pct:.0f} %)")
        self.stream.flush()

    def close(self, *, complete: bool = True) -> None:
        """Finish the line, showing the end if the run ``complete``d (else where it stopped)."""
        if complete:
            self._done = self.total
        self._draw()
        self.stream.write("\n")
        self.stream.flush()
