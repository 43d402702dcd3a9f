"""Helpers shared by the benchmarks: medians of repeated timings, and a plain table."""

from __future__ import annotations

import statistics
import time
import urllib.request


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


# --- results as data, and CPU / memory sampled over time ----------------------------------

SAMPLE_PERIOD = 0.5  # [s] between two samples of CPU and memory (the study's plots)


def add_json_argument(parser) -> None:
    """``--json PATH``: also write the results as JSON there (``bench/run.py`` reads them)."""
    parser.add_argument("--json", metavar="PATH", help="write the results as JSON to PATH")


def write_json(path, data) -> None:
    import json
    from pathlib import Path

    if path:
        Path(path).write_text(json.dumps(data, indent=1, default=float))


def spread(values) -> dict:
    """Median, min, max and count of repeated measurements."""
    values = [float(v) for v in values]
    return {"median": statistics.median(values), "min": min(values), "max": max(values), "n": len(values),
            "values": values}


class Sampler:
    """Samples CPU and memory of a group of processes every ``period`` seconds, in a thread.

    ``processes`` is a callable returning the psutil processes to count now (so a group
    whose members come and go, such as a container's processes, is followed). Each sample
    is (t [s], CPU [% of one core] over the last period, RSS [MB], PSS [MB]), summed over the
    group. CPU counts user + system time of every member (children that ended are lost).
    """

    def __init__(self, processes, period: float = SAMPLE_PERIOD):
        import threading

        self.processes = processes
        self.period = period
        self.samples: list[tuple[float, float, float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._cpu: dict[int, float] = {}

    def _read(self):
        import psutil

        cpu = rss = pss = 0.0
        seen = {}
        for p in self.processes():
            try:
                with p.oneshot():
                    t = p.cpu_times()
                    seen[p.pid] = t.user + t.system
                    rss += p.memory_info().rss
                    try:
                        pss += p.memory_full_info().pss
                    except (psutil.AccessDenied, AttributeError):
                        pss += p.memory_info().rss
            except psutil.NoSuchProcess:
                continue
        for pid, c in seen.items():
            cpu += c - self._cpu.get(pid, c if self._started else 0.0)
        self._cpu = seen
        return cpu, rss / 1e6, pss / 1e6, len(seen)

    def start(self) -> "Sampler":
        self._started = False
        self._read()  # the CPU times so far: the first period counts from here
        self._started = True
        self._peak = 0.0
        self._t0 = self._last = time.perf_counter()
        self._thread.start()
        return self

    def _loop(self) -> None:
        import psutil

        tick = self.period / 5  # the peak RSS is watched more often than the series is sampled
        while not self._stop.wait(tick):
            if time.perf_counter() - self._last >= self.period - tick / 2:
                self._take()
                continue
            rss = 0
            for p in self.processes():
                try:
                    rss += p.memory_info().rss
                except psutil.NoSuchProcess:
                    pass
            self._peak = max(self._peak, rss / 1e6)

    def _take(self) -> None:
        cpu, rss, pss, count = self._read()
        now = time.perf_counter()
        if not count:  # the processes have ended: nothing to sample
            return
        self.samples.append((now - self._t0, 100 * cpu / max(now - self._last, 1e-6), rss, pss))
        self._last = now

    def stop(self) -> dict:
        """Stop; return the series and the summary (average CPU over the whole time, peak RSS)."""
        self._stop.set()
        self._thread.join()
        self._take()
        wall = self.samples[-1][0]
        total_cpu = sum(s[1] * (s[0] - (self.samples[i - 1][0] if i else 0.0)) for i, s in enumerate(self.samples))
        return {"t": [s[0] for s in self.samples], "cpu": [s[1] for s in self.samples],
                "rss": [s[2] for s in self.samples], "pss": [s[3] for s in self.samples],
                "cpu_avg": total_cpu / max(wall, 1e-6),
                "rss_peak": max(self._peak, max(s[2] for s in self.samples)),
                "pss_peak": max(s[3] for s in self.samples), "wall": wall}


def wait_for_lab(port: int, token: str, t0: float, timeout: float, *, gone=lambda: None,
                 poll: float = 0.05) -> float:
    """Seconds since ``t0`` until JupyterLab on ``port`` serves /lab with ``token`` (as a browser
    has it). ``gone()`` returns why the server can no longer come up (it exited), or None."""
    while time.perf_counter() - t0 < timeout:
        why = gone()
        if why:
            raise RuntimeError(why)
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/lab?token={token}", timeout=2) as r:
                if r.status == 200 and b"jupyter-config-data" in r.read():
                    return time.perf_counter() - t0
        except OSError:
            pass
        time.sleep(poll)
    raise RuntimeError(f"JupyterLab was not ready within {timeout:g} s")
