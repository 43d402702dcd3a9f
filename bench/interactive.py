"""Benchmark of the study's Task 1: three goal changes executed from the control panel.

Each repeat starts a fresh Python process that plays the kernel: it makes a real-time
simulated arm, a viewer and a control panel; headless Chromium opens the viewer page (so
the server really streams the scene); then the worker sets three tool targets and executes
each through the panel's callbacks, exactly what the widgets call. Meanwhile this process
samples the worker with psutil (the viewer's server is a thread of it; with an older library,
a separate process, counted too): average CPU over the task (% of one core) and peak RSS.
Chromium is not counted (the study's figures do not include the Windows host's browser
either).

Run: ``.venv/bin/python bench/interactive.py [--repeats 3] [--no-browser]``
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

# The worker plays a lesson kernel, so this module imports nothing at its top but what the
# worker needs: the benchmark's own helpers are imported where they are used, in the
# measuring process only.
sys.path.insert(0, str(Path(__file__).resolve().parent))

TARGETS = [(0.25, 0.10, 0.3), (0.12, 0.22, 1.6), (0.28, -0.08, -0.4)]  # x [m], y [m], heading [rad]
STUDY = [("VM (VMware, Ubuntu desktop)", "7.67", "384-450"),
         ("Docker, one container", "20.67", "217-242"),
         ("Docker, several containers", "15.35", "235-236")]
CHROMIUM_FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run"]


def worker() -> None:
    """The 'kernel': set up, wait for 'go', run Task 1, report."""
    import os

    import snakekit
    from snakekit.viewer import Viewer
    from snakekit.widgets import ControlPanel

    robot = snakekit.make_robot("sim", realtime=True)
    viewer = Viewer()
    viewer.draw_workspace()
    panel = ControlPanel(robot, viewer)
    # the process serving the view: the kernel itself (a thread of it) since the viewer's server
    # moved in; a separate process in the library before that (bench/before_after.py runs both)
    server = getattr(viewer, "server_pid", None) or os.getpid()
    print(f"ready {server} {viewer.url}", flush=True)
    sys.stdin.readline()
    for x, y, heading in TARGETS:
        if panel.set_target(x, y, heading) is None:
            raise SystemExit(f"target ({x}, {y}, {heading}) unreachable: {panel.message}")
        panel.execute()
        time.sleep(0.5)  # a student looks at the result before the next goal
    print("done", flush=True)
    sys.stdin.readline()
    viewer.close()
    robot.close()


def measure(browser, command=None, env=None) -> dict:
    """One repeat: start the worker (``command``, default this file in this Python), run Task 1.

    Counted: the worker and the process serving the view (the same process since the viewer's
    server became a thread of the kernel; two in older libraries).
    """
    import selectors
    import subprocess

    import psutil

    from _common import Sampler

    proc = subprocess.Popen(command or [sys.executable, __file__, "--worker"], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, env=env)
    page = None
    try:
        line = proc.stdout.readline().split()
        if not line or line[0] != "ready":
            raise RuntimeError("the worker did not start")
        group = [psutil.Process(pid) for pid in dict.fromkeys([proc.pid, int(line[1])])]
        processes = lambda: group  # noqa: E731
        if browser is not None:
            page = browser.new_page(viewport={"width": 1000, "height": 700})
            page.goto(line[2])
            page.wait_for_selector("canvas", timeout=30_000)
            time.sleep(1.0)
        sampler = Sampler(processes).start()
        proc.stdin.write("go\n")
        proc.stdin.flush()
        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        while True:
            if sel.select(timeout=0.05):
                if proc.stdout.readline().strip() == "done":
                    break
                raise RuntimeError("the worker stopped early")
        series = sampler.stop()
        proc.stdin.write("quit\n")
        proc.stdin.flush()
        proc.wait(timeout=30)
        return {"cpu": series["cpu_avg"], "rss": series["rss_peak"], "pss": series["pss_peak"],
                "wall": series["wall"], "series": series}
    finally:
        if page is not None:
            page.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def run_repeats(repeats: int, browser: bool = True, variants=None, **kwargs) -> list[dict]:
    """``repeats`` measurements; with ``variants`` ({name: measure kwargs}), that many of each,
    alternating, returned as {name: [results]}."""
    def rounds(chromium):
        if variants is None:
            return [measure(chromium, **kwargs) for _ in range(repeats)]
        out = {name: [] for name in variants}
        for _ in range(repeats):
            for name, extra in variants.items():
                out[name].append(measure(chromium, **kwargs, **extra))
        return out

    if not browser:
        return rounds(None)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path="/usr/bin/chromium", headless=True, args=CHROMIUM_FLAGS)
        try:
            return rounds(chromium)
        finally:
            chromium.close()


def main(argv=None) -> int:
    import argparse
    import statistics

    from _common import add_json_argument, spread, write_json

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-browser", action="store_true", help="do not connect Chromium to the viewer")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    add_json_argument(parser)
    args = parser.parse_args(argv)
    if args.worker:
        worker()
        return 0

    results = run_repeats(args.repeats, browser=not args.no_browser)
    for i, r in enumerate(results, 1):
        print(f"repeat {i}: CPU {r['cpu']:.2f} % of one core, peak RSS {r['rss']:.0f} MB (PSS {r['pss']:.0f} MB), "
              f"task {r['wall']:.1f} s")
    cpu = statistics.median(r["cpu"] for r in results)
    rss = statistics.median(r["rss"] for r in results)
    wall = statistics.median(r["wall"] for r in results)
    viewer = "viewer connected to headless Chromium" if not args.no_browser else "no browser connected"
    print(f"\nTask 1: three goal changes through the control panel, sim in real time, {viewer}")
    print(f"medians of {len(results)} repeats; CPU and RSS of the kernel (which serves the view)\n")
    print(f"| set-up | Task 1 CPU [% of one core] | RAM [MB] |")
    print(f"|---|---|---|")
    print(f"| snakekit (kernel-like Python process serving the view), task {wall:.1f} s | {cpu:.2f} | {rss:.0f} (peak) |")
    for name, c, m in STUDY:
        print(f"| study: {name} | {c} | {m} |")
    spread_of = lambda key: spread(r[key] for r in results)  # noqa: E731
    write_json(args.json, {"cpu": spread_of("cpu"), "rss": spread_of("rss"), "pss": spread_of("pss"),
                           "wall": spread_of("wall"), "browser": not args.no_browser,
                           "series": sorted(results, key=lambda r: r["cpu"])[len(results) // 2]["series"]})
    return 0


if __name__ == "__main__":
    if sys.argv[1:] == ["--worker"]:  # the kernel's part, without the measuring side's imports
        worker()
        sys.exit(0)
    sys.exit(main())
