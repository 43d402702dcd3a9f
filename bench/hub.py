"""The class's JupyterHub (docker/hub/): a class of 25 logging in at once (log-in to a ready
server, each), a student's server's memory with lesson 00 and its 3D view, spawn to ready, the
hub and its proxy under load, and grading the 25 collected submissions from a TA's terminal.

Runs docker/hub/test.sh with SNAKEKIT_HUB_BENCH=1 on the private engine of docker/engine.sh
(root and Debian's docker.io needed; otherwise the figures say "not measured" and why): a cold
start first (the students' and the grader's images taken out of the engine and loaded again
from a gzip'd `docker save`, the bytes a node's pull unpacks; then the first spawn), the week of
25 students of the hub test (all logging in at once; one student's lesson 00 in Chromium, its
server's memory cgroup read after it), then five warm spawns (a student's server stopped and
started again, their volume kept, 27 servers running) and 50 clients on loopback, each sending 40
requests one at a time, alternating the hub's REST API and the student's server through the
proxy. It prints the test's "figure:" lines, the load average, and a table of them.

The cold start takes the images out of the engine, and with them the build's cache of their
last stages: the next `docker compose build` (or test) after it makes those again (20 s here;
the venv's stage stays cached).

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
    "cold_load_s": r"cold: docker load of the two images .*: ([\d.]+) s$",
    "spawn_warm_median_s": r"spawn to ready, warm: median ([\d.]+) s",
    "spawn_warm_all": r"spawn to ready, warm: median [\d.]+ s of ([\d., ]+) \(",
    "login_at_once_n": r"figure: (\d+) students logging in at once",
    "login_at_once_median_s": r"students logging in at once, no server running, log-in to a ready server: "
                              r"median ([\d.]+) s",
    "login_at_once_max_s": r"students logging in at once, no server running, log-in to a ready server: "
                           r"median [\d.]+ s, max ([\d.]+) s",
    "login_at_once_each": r"students logging in at once, no server running, .*; each: (.*)$",
    "login_prestarted_median_s": r"servers started before the lesson, log-in to a ready server: median ([\d.]+) s",
    "login_prestarted_max_s": r"servers started before the lesson, log-in to a ready server: median [\d.]+ s, "
                              r"max ([\d.]+) s",
    "start_all_s": r"every student's server started before the lesson \(five at a time\) in ([\d.]+) s",
    "mem_started_median_mib": r"servers, started and logged in to, each container's peak: median (\d+) MiB",
    "mem_started_max_mib": r"servers, started and logged in to, each container's peak: median \d+ MiB, max (\d+) MiB",
    "mem_lesson_usage_mib": r"3D view open in Chromium: usage (\d+) MiB",
    "mem_lesson_peak_mib": r"3D view open in Chromium: usage \d+ MiB, peak (\d+) MiB",
    "hub_p50_ms": r"under load, the hub's API .*: p50 (\d+) ms",
    "hub_p95_ms": r"under load, the hub's API .*: p50 \d+ ms, p95 (\d+) ms",
    "proxy_p50_ms": r"under load, a server through the proxy .*: p50 (\d+) ms",
    "proxy_p95_ms": r"under load, a server through the proxy .*: p50 \d+ ms, p95 (\d+) ms",
    "requests_per_s": r"requests from \d+ clients in [\d.]+ s \((\d+)/s\)",
    "hub_mem_idle_mib": r"the hub's container .* (\d+) MiB before",
    "hub_mem_peak_mib": r"the hub's container .* peak (\d+) MiB",
    "grade_s": r"grading the \d+ collected submissions .*: ([\d.]+) s",
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
    load_before = os.getloadavg()
    env = dict(os.environ, SNAKEKIT_HUB_BENCH="1", SNAKEKIT_HUB_SUBMITTING="0", PATH=f"{REPO / '.venv/bin'}:{os.environ['PATH']}")
    proc = subprocess.run(["bash", str(REPO / "docker/hub/test.sh")], cwd=REPO, env=env, capture_output=True, text=True)
    out = proc.stdout + proc.stderr
    for line in out.splitlines():
        if line.startswith("figure:"):
            print(line)
    if proc.returncode != 0:
        print("\n".join(line for line in out.splitlines() if line.startswith("hub-test:")), file=sys.stderr)
        print(out[-3000:], file=sys.stderr)
        write_json(args.json, {"not_measured": "docker/hub/test.sh failed"})
        return 1
    result = {}
    for key, pattern in FIGURES.items():
        m = re.search(pattern, out, re.M)
        result[key] = (m.group(1) if key in ("spawn_warm_all", "login_at_once_each") else float(m.group(1))) if m else None
    result["spawn_cold_s"] = (round(result["cold_load_s"] + result["spawn_first_s"], 1)
                              if result["cold_load_s"] is not None and result["spawn_first_s"] is not None else None)
    result["wall_s"] = round(time.monotonic() - t, 1)
    result["load_average_1min"] = [round(load_before[0], 1), round(os.getloadavg()[0], 1)]
    print(f"load average (1 min) before / after the run: {result['load_average_1min'][0]} / {result['load_average_1min'][1]}")
    print()
    print("| what | figure | target |")
    print("|---|---|---|")
    print(f"| spawn to ready, warm (median of 5: {result['spawn_warm_all']}) | {result['spawn_warm_median_s']} s | <= 5 s |")
    print(f"| spawn to ready, cold: the images loaded ({result['cold_load_s']} s), then the first spawn "
          f"({result['spawn_first_s']} s) | {result['spawn_cold_s']} s | |")
    n = int(result["login_at_once_n"] or 0)
    print(f"| {n} students logging in at once, no server running, log-in to a ready server: median / max | "
          f"{result['login_at_once_median_s']} / {result['login_at_once_max_s']} s | <= 30 s each |")
    print(f"| the same, their servers started before the lesson (the teacher started them, five at a time: "
          f"{result['start_all_s']} s): median / max | "
          f"{result['login_prestarted_median_s']} / {result['login_prestarted_max_s']} s | <= 30 s each |")
    print(f"| one student's server with lesson 00 run and its 3D view open (Chromium): usage / peak | "
          f"{result['mem_lesson_usage_mib']} / {result['mem_lesson_peak_mib']} MiB | <= 280 MiB peak |")
    print(f"| {n} students' servers, started and logged in to (no lesson): each container's peak, median / max | "
          f"{result['mem_started_median_mib']} / {result['mem_started_max_mib']} MiB | |")
    print(f"| hub API under 50 clients, p50 / p95 | {result['hub_p50_ms']} / {result['hub_p95_ms']} ms | |")
    print(f"| a server through the proxy under 50 clients, p50 / p95 | {result['proxy_p50_ms']} / {result['proxy_p95_ms']} ms | |")
    print(f"| requests served | {result['requests_per_s']} /s | |")
    print(f"| the hub's container, idle / peak under load | {result['hub_mem_idle_mib']} / {result['hub_mem_peak_mib']} MiB | |")
    print(f"| grading the {n} collected submissions (the TA's `snakekit grade`, the hub's grading service) | "
          f"{result['grade_s']} s | |")
    if result["mem_lesson_peak_mib"]:
        node = int((24e9 - 2.5e9) / 2**20 / result["mem_lesson_peak_mib"])
        print(f"| students per 24 GB node (2.5 GB kept for the system) at that peak | {node} | >= 80 |")
    write_json(args.json, result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
