"""Loading a big trajectory .csv: snakekit's Trajectory.load next to numpy.loadtxt and the old
per-value path (csv module, one float() per value), side by side in one run.

The file is what Trajectory.save writes for 176,000 points with velocities (time, q1..q5,
qd1..qd5): about 36 MB of text, 15.5 MB as numbers. Each loader runs in a fresh process
(so the peak memory of one does not hide another's), ``--repeat`` times, interleaved; the
figures are medians. Peak memory is how far the process's resident set rose above where
it was when the load began (Linux: the peak is reset through /proc/self/clear_refs, then
read as VmHWM).

Targets: Trajectory.load within 1.5x the time of a bare numpy.loadtxt, and a peak of at
most 4x the numbers themselves.

    .venv/bin/python bench/csv_load.py [--points 176000] [--repeat 5]
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table  # noqa: E402

LOADERS = ("snakekit Trajectory.load", "numpy.loadtxt", "old path (csv + float per value)")


def old_read_csv(path: Path, n: int = 5) -> dict:
    """snakekit's CSV reader before it was vectorised (kept here to compare against)."""
    text = path.read_text()
    rows = list(csv.reader(io.StringIO(text)))
    width = len(rows[0])
    data = []
    for row in rows[1:]:
        if row:
            assert len(row) == width
            data.append([float(x) for x in row])
    a = __import__("numpy").array(data)
    return {"times": a[:, 0], "positions": a[:, 1: n + 1], "velocities": a[:, n + 1:]}


def child(loader: str, path: str) -> None:
    """One measured load, in this (fresh) process; prints JSON."""
    import time

    import numpy as np

    from snakekit.trajectory import Trajectory

    before = reset_peak()
    t0 = time.perf_counter()
    if loader == LOADERS[0]:
        tr = Trajectory.load(path)
        shape = tr.positions.shape
    elif loader == LOADERS[1]:
        a = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        Trajectory(a[:, 0], a[:, 1:6], a[:, 6:])
        shape = a[:, 1:6].shape
    else:
        Trajectory(**old_read_csv(Path(path)))
        shape = None
    seconds = time.perf_counter() - t0
    peak = status_kib("VmHWM") - before
    print(json.dumps({"seconds": seconds, "peak_mb": peak / 1024, "shape": shape}))


def status_kib(field: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    raise SystemExit(f"no {field} in /proc/self/status: this benchmark needs Linux")


def reset_peak() -> int:
    """Reset the process's peak resident set (VmHWM) to the present one; return it [KiB]."""
    Path("/proc/self/clear_refs").write_text("5")
    return status_kib("VmRSS")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=176_000)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(*args.child)
        return 0

    import numpy as np

    from snakekit.trajectory import Trajectory

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "big.csv"
        rng = np.random.default_rng(0)
        t = np.arange(args.points) / 100.0
        q = rng.uniform(-1.5, 1.5, (args.points, 5))
        qd = rng.uniform(-1.5, 1.5, (args.points, 5))
        Trajectory(t, q, qd).save(path)
        size = path.stat().st_size / 1e6
        numbers = args.points * 11 * 8 / 1e6
        print(f"file: {args.points} points, {size:.1f} MB of text, {numbers:.1f} MB as float64; "
              f"medians of {args.repeat} fresh processes per loader")
        results = {name: [] for name in LOADERS}
        for _ in range(args.repeat):
            for name in LOADERS:  # interleaved, so a busy moment hits every loader alike
                out = subprocess.run([sys.executable, __file__, "--child", name, str(path)],
                                     capture_output=True, text=True, check=True).stdout
                results[name].append(json.loads(out.strip().splitlines()[-1]))
    med = {name: (statistics.median(r["seconds"] for r in rs), statistics.median(r["peak_mb"] for r in rs))
           for name, rs in results.items()}
    base_s, base_mb = med[LOADERS[1]]
    rows = [[name, f"{s:.3f}", f"{mb:.0f}", f"{s / base_s:.2f}", f"{mb / numbers:.1f}"]
            for name, (s, mb) in med.items()]
    print(table(rows, ["loader", "time [s]", "peak [MB]", "time / loadtxt", "peak / numbers"]))
    new_s, new_mb = med[LOADERS[0]]
    old_s, old_mb = med[LOADERS[2]]
    print(f"snakekit vs old path: {old_s / new_s:.1f}x faster, {old_mb / max(new_mb, 1e-9):.1f}x less peak memory")
    ok = new_s <= 1.5 * base_s and new_mb <= 4 * numbers
    print(f"targets (time <= 1.5x loadtxt, peak <= 4x numbers): {'ok' if ok else 'MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
