"""Helpers shared by the benchmarks: medians of repeated timings, and a plain table."""

from __future__ import annotations

import statistics
import time


def per_call(fn, *, number: int, repeat: int = 7) -> float:
    """Median over ``repeat`` rounds of the time of one call of ``fn`` [s]."""
    rounds = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        rounds.append((time.perf_counter() - t0) / number)
    return statistics.median(rounds)


def table(rows: list[list], header: list[str]) -> str:
    cells = [header] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    line = lambda r: "  ".join(c.ljust(w) for c, w in zip(r, widths))  # noqa: E731
    return "\n".join([line(cells[0]), line(["-" * w for w in widths])] + [line(r) for r in cells[1:]])
