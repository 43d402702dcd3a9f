"""The class's JupyterHub (docker/hub/): spawn to ready, the hub and its proxy under load, and
grading the 20 collected submissions.

Runs docker/hub/test.sh with SNAKEKIT_HUB_BENCH=1 on the private engine of docker/engine.sh
(root and Debian's docker.io needed; otherwise the figures say "not measured" and why): the
week of 20 students of the hub test, then three warm spawns (a student's server stopped and
started again, their volume kept) and 50 clients on loopback, each sending 40 requests one at
a time, alternating the hub's REST API and the student's server through the proxy. It prints
the test's "figure:" lines and a table of them.

Run: ``.venv/bin/python bench/hub.py [--json PATH]``
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
from _common import add_json_argument, write_json  # noqa: E402

FIGURES = {
    "spawn_first_s": r"spawn to ready, first server .*: ([\d.]+) s",
    "spawn_warm_median_s": r"spawn to ready, warm: median ([\d.]+) s",
    "spawn_20_median_s": r"students' servers ready in [\d.]+ s \(each: median ([\d.]+) s",
    "hub_p50_ms": r"under load, the hub's API .*: p50 (\d+) ms",
    "hub_p95_ms": r"under load, the hub's API .*: p50 \d+ ms, p95 (\d+) ms",
    "proxy_p50_ms": r"under load, a server through the proxy .*: p50 (\d+) ms",
    "proxy_p95_ms": r"under load, a server through the proxy .*: p50 \d+ ms, p95 (\d+) ms",
    "requests_per_s": r"requests from \d+ clients in [\d.]+ s \((\d+)/s\)",
    "hub_mem_idle_mib": r"the hub's container .* (\d+) MiB before",
    "hub_mem_peak_mib": r"the hub's container .* peak (\d+) MiB",
    "grade_20_s": r"grading the 20 collected submissions .*: ([\d.]+) s",
}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_json_argument(p)
    args = p.parse_args(argv)
    if os.geteuid() != 0 or not shutil.which("dockerd"):
        result = {"not_measured": "needs root and Debian's docker.io (the private engine of docker/engine.sh)"}
        print(f"hub: not measured: {result['not_measured']}")
        write_json(args.json, result)
        return 0
    t = time.monotonic()
    env = dict(os.environ, SNAKEKIT_HUB_BENCH="1", PATH=f"{REPO / '.venv/bin'}:{os.environ['PATH']}")
    proc = subprocess.run(["bash", str(REPO / "docker/hub/test.sh")], cwd=REPO, env=env, capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    for line in out.splitlines():
        if line.startswith("figure:"):
            print(line)
    if proc.returncode != 0:
        print(out[-3000:], file=sys.stderr)
        write_json(args.json, {"not_measured": "docker/hub/test.sh failed"})
        return 1
    result = {}
    for key, pattern in FIGURES.items():
        m = re.search(pattern, out)
        result[key] = float(m.group(1)) if m else None
    result["wall_s"] = round(time.monotonic() - t, 1)
    print()
    print("| what | figure | target |")
    print("|---|---|---|")
    print(f"| spawn to ready, warm (median of 3) | {result['spawn_warm_median_s']} s | <= 5 s |")
    print(f"| spawn to ready, first server after the hub starts (new volume) | {result['spawn_first_s']} s | |")
    print(f"| 20 students' servers, five started at a time: each (median) | {result['spawn_20_median_s']} s | |")
    print(f"| hub API under 50 clients, p50 / p95 | {result['hub_p50_ms']} / {result['hub_p95_ms']} ms | |")
    print(f"| a server through the proxy under 50 clients, p50 / p95 | {result['proxy_p50_ms']} / {result['proxy_p95_ms']} ms | |")
    print(f"| requests served | {result['requests_per_s']} /s | |")
    print(f"| the hub's container, idle / peak under load | {result['hub_mem_idle_mib']} / {result['hub_mem_peak_mib']} MiB | |")
    print(f"| grading the 20 collected submissions | {result['grade_20_s']} s | |")
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
