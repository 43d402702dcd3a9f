"""This round's speed and memory changes, each measured before and after, side by side in one run.

"Before" is the library (snakekit/) and the Makefile at ``--rev`` (the commit before the
changes), taken from git into a temporary folder; "after" is this tree. Both run with the same
Python environment, alternating, so a busy moment of the machine hits both alike:

* the viewer's server process no longer runs meshcat's package __init__ (numpy, IPython,
  PIL and the kernel-side modules it never uses): its resident memory, and Task 1's CPU and
  peak RAM (kernel + server, as bench/interactive.py measures them);
* ``make lab`` starts JupyterLab without rfc3987-syntax's grammar compilation: the time to
  JupyterLab ready;
* the workspace boundary (drawn in Task 1) fills a preallocated array instead of a list of
  ~24,000 small pose arrays: Task 1's peak RAM against ``--boundary-rev``, in the same
  alternating Task 1 run.

Run: ``.venv/bin/python bench/before_after.py [--rev COMMIT] [--repeats 3] [--json PATH]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
from _common import add_json_argument, spread, write_json  # noqa: E402

#: main before this round's changes to the viewer server and the lab target
BEFORE_REV = "73152ed020794eccb8cfcc2b3b685d001d3bd3bc"
#: main before the workspace boundary's in-place fill
BOUNDARY_REV = "92804c2c02388daf02acfaea5f8761146289e480"

SERVER_RSS = r"""
import os, sys, time, psutil
os.environ.setdefault("MUJOCO_GL", "egl")
from snakekit.viewer import Viewer
with Viewer() as v:
    time.sleep(1.0)
    print(psutil.Process(v.server_pid).memory_info().rss)
"""


def export(rev: str, dest: Path) -> None:
    """snakekit/ and the Makefile at ``rev`` into ``dest``."""
    archive = subprocess.run(["git", "archive", rev, "snakekit", "Makefile"], cwd=REPO, capture_output=True)
    if archive.returncode != 0:
        raise RuntimeError(f"git archive {rev} failed: {archive.stderr.decode().strip()} "
                           "(a clone without history cannot measure the 'before')")
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive.stdout, check=True)


def env_with(path: Path | None) -> dict:
    env = dict(os.environ)
    if path is not None:  # the old library first on the path
        env["PYTHONPATH"] = str(path) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def server_rss(env: dict) -> float:
    out = subprocess.run([sys.executable, "-P", "-c", SERVER_RSS], env=env, capture_output=True, text=True, check=True)
    return int(out.stdout.strip().splitlines()[-1]) / 1e6


def effect(before: float, after: float, unit: str, f: str = "{:.2f}") -> str:
    change = after - before
    return f"{f.format(change)}{unit} ({100 * change / before:+.0f} %)"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rev", default=BEFORE_REV)
    parser.add_argument("--boundary-rev", default=BOUNDARY_REV)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-browser", action="store_true")
    add_json_argument(parser)
    args = parser.parse_args(argv)

    try:
        return measure_all(args)
    except Exception as e:  # noqa: BLE001 - e.g. the old library no longer runs in today's environment
        why = f"not measured: {type(e).__name__}: {e}"
        print(why)
        write_json(args.json, {"not_measured": why, "before_rev": args.rev[:10], "rows": []})
        return 0


def measure_all(args) -> int:
    import interactive
    import setups

    with tempfile.TemporaryDirectory(prefix="snakekit-before-") as tmp:
        old, old_boundary = Path(tmp) / "round", Path(tmp) / "boundary"
        try:
            for rev, dest in ((args.rev, old), (args.boundary_rev, old_boundary)):
                dest.mkdir()
                export(rev, dest)
        except RuntimeError as e:
            print(f"not measured: {e}")
            write_json(args.json, {"not_measured": str(e), "before_rev": args.rev[:10], "rows": []})
            return 0
        envs = {"before": env_with(old), "after": env_with(None)}
        # check that "before" really imports the old library
        where = subprocess.run([sys.executable, "-P", "-c", "import snakekit; print(snakekit.__file__)"],
                               env=envs["before"], capture_output=True, text=True, check=True).stdout
        assert where.startswith(str(old)), where

        rss = {k: [] for k in envs}
        lab = {k: [] for k in envs}
        commands = {"before": ["make", "-s", "-f", str(old / "Makefile"), "lab"], "after": ["make", "-s", "lab"]}
        for _ in range(args.repeats):
            for k in envs:
                rss[k].append(server_rss(envs[k]))
                port = setups.free_port()
                lab[k].append(setups.time_to_lab(commands[k] + [f"LAB_PORT={port}"], port=port))
        task1 = interactive.run_repeats(args.repeats, browser=not args.no_browser,
                                        variants={**{k: {"env": e} for k, e in envs.items()},
                                                  "boundary_before": {"env": env_with(old_boundary)}})

    m = {k: statistics.median(v) for k, v in rss.items()}
    lm = {k: statistics.median(v) for k, v in lab.items()}
    t1 = {k: {x: statistics.median(r[x] for r in v) for x in ("cpu", "rss", "pss")} for k, v in task1.items()}
    b = t1["boundary_before"]
    rows = [
        {"change": "viewer server without meshcat's package __init__", "figure": "viewer server RSS",
         "before": f"{m['before']:.1f} MB", "after": f"{m['after']:.1f} MB", "effect": effect(m["before"], m["after"], " MB", "{:.1f}")},
        {"change": "(the same, seen in Task 1)", "figure": "Task 1 peak RSS, kernel + server",
         "before": f"{t1['before']['rss']:.0f} MB", "after": f"{t1['after']['rss']:.0f} MB",
         "effect": effect(t1["before"]["rss"], t1["after"]["rss"], " MB", "{:.0f}")},
        {"change": "(the same, seen in Task 1)", "figure": "Task 1 peak PSS, kernel + server",
         "before": f"{t1['before']['pss']:.0f} MB", "after": f"{t1['after']['pss']:.0f} MB",
         "effect": effect(t1["before"]["pss"], t1["after"]["pss"], " MB", "{:.0f}")},
        {"change": "(the same, seen in Task 1)", "figure": "Task 1 CPU, kernel + server",
         "before": f"{t1['before']['cpu']:.2f} %", "after": f"{t1['after']['cpu']:.2f} %",
         "effect": effect(t1["before"]["cpu"], t1["after"]["cpu"], " %")},
        {"change": "workspace boundary filled in place", "figure": "Task 1 peak RSS, kernel + server",
         "before": f"{b['rss']:.0f} MB", "after": f"{t1['after']['rss']:.0f} MB",
         "effect": effect(b["rss"], t1["after"]["rss"], " MB", "{:.0f}")},
        {"change": "(the same, seen in Task 1)", "figure": "Task 1 peak PSS, kernel + server",
         "before": f"{b['pss']:.0f} MB", "after": f"{t1['after']['pss']:.0f} MB",
         "effect": effect(b["pss"], t1["after"]["pss"], " MB", "{:.0f}")},
        {"change": "`make lab` without rfc3987-syntax's import", "figure": "`make lab` to JupyterLab ready",
         "before": f"{lm['before']:.2f} s", "after": f"{lm['after']:.2f} s", "effect": effect(lm["before"], lm["after"], " s")},
    ]
    print(f"before = {args.rev[:10]} (snakekit/ and Makefile; the boundary row: {args.boundary_rev[:10]}), "
          f"after = this tree; medians of {args.repeats}, alternating")
    for r in rows:
        print(f"{r['change']:52s} {r['figure']:34s} {r['before']:>10s} -> {r['after']:>10s}  {r['effect']}")
    middle = lambda runs: sorted(runs, key=lambda r: r["cpu"])[len(runs) // 2]["series"]  # noqa: E731
    write_json(args.json, {
        "before_rev": args.rev[:10], "boundary_rev": args.boundary_rev[:10], "repeats": args.repeats, "rows": rows,
        "server_rss_mb": {k: spread(v) for k, v in rss.items()}, "lab_s": {k: spread(v) for k, v in lab.items()},
        "task1": {"before": {x: spread(r[x] for r in task1["before"]) for x in ("cpu", "rss", "pss")},
                  "after": {x: spread(r[x] for r in task1["after"]) for x in ("cpu", "rss", "pss")},
                  "boundary_before": {x: spread(r[x] for r in task1["boundary_before"]) for x in ("cpu", "rss", "pss")},
                  "before_series": middle(task1["before"])}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
