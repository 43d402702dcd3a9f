"""This round's memory changes, each measured before and after, side by side in one run.

"Before" is the library (snakekit/) at a commit before a change, taken from git into a
temporary folder and put first on the path; "after" is this tree. Every variant runs with the
same Python environment and the same benchmark code, alternating, so a busy moment of the
machine hits all alike:

* the kernel imports meshcat's scene modules without meshcat's web server (tornado, asyncio,
  ssl): ``--rev`` (before) against ``--mid-rev`` (after), in Task 1's peak RAM;
* the viewer's server runs in a thread of the kernel instead of a second Python process:
  ``--mid-rev`` against ``--thread-rev``, in Task 1's CPU and peak RAM (kernel + server
  process before, kernel alone after, as bench/interactive.py counts them), and in the time
  ``Viewer()`` takes to return;
* a real-time run steps controls computed once for the whole run, paced from its own start
  (before, each goal was planned as it was sent, and a run after an idle spell raced through
  the time that had passed): ``--thread-rev`` against this tree, in Task 1's CPU and length;
* ``Viewer.play`` writes the animation's tracks whole, every link pose's quaternion in one call,
  instead of meshcat's ``set_transform`` per frame and link: ``--play-rev`` against this tree, in
  the CPU time of replaying Task 2's run (what a lesson 06 notebook does, each graded one too).

Run: ``.venv/bin/python bench/before_after.py [--rev C] [--mid-rev C] [--thread-rev C] [--play-rev C] [--repeats 3]
[--only-play] [--json PATH]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
from _common import add_json_argument, spread, write_json  # noqa: E402

#: main before this round's changes to the viewer
BEFORE_REV = "989a46192ec7189aea356c9d6913e93d8058e4f1"
#: main with the kernel-side meshcat import trimmed, the server still a separate process
MID_REV = "23725f5ef16d476070068146032fc3f07444b61c"
#: main with the viewer's server in a thread, before the real-time runs' change
THREAD_REV = "37fa09114e87c0819fd514ae1d6affa41e0508a7"
#: main before Viewer.play wrote the animation's tracks whole
PLAY_REV = "ce1a4df52318c0a541e71839d388928d8f84274b"

VIEWER_START = r"""
import os, sys, time
from snakekit.viewer import Viewer
t0 = time.perf_counter()
v = Viewer()
print(time.perf_counter() - t0)
v.close()
"""

#: CPU time [s] of replaying Task 2's run in the view (the median of 3 plays, after one that warms up)
PLAY = r"""
import statistics, time
import snakekit
from snakekit.viewer import Viewer
with snakekit.make_robot("sim") as robot:
    run = robot.run(snakekit.side_sweep())
with Viewer() as v:
    v.play(run)
    cpu = []
    for _ in range(3):
        t0 = time.process_time()
        v.play(run)
        cpu.append(time.process_time() - t0)
print(statistics.median(cpu))
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


def viewer_start(env: dict) -> float:
    out = subprocess.run([sys.executable, "-P", "-c", VIEWER_START], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def play_cpu(env: dict) -> float:
    out = subprocess.run([sys.executable, "-P", "-c", PLAY], env=env, capture_output=True, text=True, check=True)
    return float(out.stdout.strip().splitlines()[-1])


def measure_play(args) -> tuple[dict, list]:
    """``Viewer.play`` of Task 2's run at ``--play-rev`` and in this tree, alternating: ({variant: CPU seconds
    of each repeat}, the table's row)."""
    with tempfile.TemporaryDirectory(prefix="snakekit-before-") as tmp:
        export(args.play_rev, Path(tmp))
        envs = {"before": env_with(Path(tmp)), "after": env_with(None)}
        cpu = {k: [] for k in envs}
        for _ in range(args.repeats):
            for k, e in envs.items():
                cpu[k].append(play_cpu(e))
    before, after = statistics.median(cpu["before"]), statistics.median(cpu["after"])
    return cpu, {"change": "`Viewer.play` writes the animation's tracks whole (the poses' quaternions in one call)",
                 "figure": "replaying Task 2's run in the view, CPU time", "before": f"{before:.2f} s",
                 "after": f"{after:.2f} s", "effect": effect(before, after, " s")}


def effect(before: float, after: float, unit: str, f: str = "{:.2f}") -> str:
    change = after - before
    return f"{f.format(change)}{unit} ({100 * change / before:+.0f} %)"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rev", default=BEFORE_REV)
    parser.add_argument("--mid-rev", default=MID_REV)
    parser.add_argument("--thread-rev", default=THREAD_REV)
    parser.add_argument("--play-rev", default=PLAY_REV)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only-play", action="store_true", help="measure the Viewer.play change alone")
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

    play_cpu_s, play_row = measure_play(args)
    if args.only_play:
        print(f"before = {args.play_rev[:10]} (snakekit/), after = this tree; medians of {args.repeats}, alternating")
        print(f"{play_row['change']}: {play_row['figure']} {play_row['before']} -> {play_row['after']}  {play_row['effect']}")
        write_json(args.json, {"before_rev": args.play_rev[:10], "repeats": args.repeats, "rows": [play_row],
                               "play_cpu_s": {k: spread(v) for k, v in play_cpu_s.items()}})
        return 0

    with tempfile.TemporaryDirectory(prefix="snakekit-before-") as tmp:
        old, mid, thread = Path(tmp) / "before", Path(tmp) / "mid", Path(tmp) / "thread"
        try:
            for rev, dest in ((args.rev, old), (args.mid_rev, mid), (args.thread_rev, thread)):
                dest.mkdir()
                export(rev, dest)
        except RuntimeError as e:
            print(f"not measured: {e}")
            write_json(args.json, {"not_measured": str(e), "before_rev": args.rev[:10], "rows": []})
            return 0
        folders = {"before": old, "mid": mid, "thread": thread}
        envs = {**{k: env_with(v) for k, v in folders.items()}, "after": env_with(None)}
        for name, folder in folders.items():  # check that the old libraries are the ones imported
            where = subprocess.run([sys.executable, "-P", "-c", "import snakekit; print(snakekit.__file__)"],
                                   env=envs[name], capture_output=True, text=True, check=True).stdout
            assert where.startswith(str(folder)), where

        start = {k: [] for k in ("mid", "thread")}
        for _ in range(args.repeats):
            for k in start:
                start[k].append(viewer_start(envs[k]))
        task1 = interactive.run_repeats(args.repeats, browser=not args.no_browser, variants={
            k: {"env": e} for k, e in envs.items()})

    for runs in task1.values():
        for r in runs:
            r["cpu_s"] = r["cpu"] * r["wall"] / 100  # CPU seconds over the task
    t1 = {k: {x: statistics.median(r[x] for r in v) for x in ("cpu", "rss", "pss", "wall", "cpu_s")}
          for k, v in task1.items()}
    st = {k: statistics.median(v) for k, v in start.items()}

    def row(change, figure, a, b, key, unit, f):
        return {"change": change, "figure": figure, "before": f"{f.format(t1[a][key])}{unit}",
                "after": f"{f.format(t1[b][key])}{unit}", "effect": effect(t1[a][key], t1[b][key], unit, f)}

    rows = [
        row("kernel imports meshcat without its web server", "Task 1 peak RSS, kernel + server",
            "before", "mid", "rss", " MB", "{:.0f}"),
        row("(the same, seen in Task 1)", "Task 1 peak PSS, kernel + server", "before", "mid", "pss", " MB", "{:.0f}"),
        row("viewer server in a thread of the kernel, not a second process", "Task 1 peak RSS, kernel + server",
            "mid", "thread", "rss", " MB", "{:.0f}"),
        row("(the same, seen in Task 1)", "Task 1 peak PSS, kernel + server", "mid", "thread", "pss", " MB", "{:.0f}"),
        row("(the same, seen in Task 1)", "Task 1 CPU, kernel + server", "mid", "thread", "cpu", " %", "{:.2f}"),
        {"change": "(the same)", "figure": "`Viewer()` to a served scene",
         "before": f"{st['mid']:.2f} s", "after": f"{st['thread']:.2f} s", "effect": effect(st["mid"], st["thread"], " s")},
        row("real-time runs: controls computed once, paced from the run's start", "Task 1 CPU, kernel",
            "thread", "after", "cpu", " %", "{:.2f}"),
        row("(the same: the moves now take their real time)", "Task 1 length (3 moves, 0.5 s pauses)",
            "thread", "after", "wall", " s", "{:.1f}"),
        row("(the same, whatever the length)", "Task 1 CPU time, kernel", "thread", "after", "cpu_s", " s", "{:.3f}"),
        row("all three changes", "Task 1 peak RSS, kernel + server", "before", "after", "rss", " MB", "{:.0f}"),
        row("(the same)", "Task 1 CPU, kernel + server", "before", "after", "cpu", " %", "{:.2f}"),
        {**play_row, "change": play_row["change"] + f" (before: commit `{args.play_rev[:10]}`)"},
    ]
    print(f"before = {args.rev[:10]}, mid = {args.mid_rev[:10]}, thread = {args.thread_rev[:10]} (snakekit/), after = this tree; "
          f"medians of {args.repeats}, alternating")
    for r in rows:
        print(f"{r['change']:62s} {r['figure']:34s} {r['before']:>10s} -> {r['after']:>10s}  {r['effect']}")
    write_json(args.json, {
        "before_rev": args.rev[:10], "mid_rev": args.mid_rev[:10], "thread_rev": args.thread_rev[:10],
        "repeats": args.repeats, "rows": rows, "play_cpu_s": {k: spread(v) for k, v in play_cpu_s.items()},
        "viewer_start_s": {k: spread(v) for k, v in start.items()},
        "task1": {**{k: {x: spread(r[x] for r in v) for x in ("cpu", "rss", "pss", "wall")} for k, v in task1.items()},
                  "before_series": sorted(task1["before"], key=lambda r: r["cpu"])[len(task1["before"]) // 2]["series"]}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
