"""`make bench`: every benchmark under bench/, one after the other, into bench/RESULTS.md and plots.

Each benchmark is a script that runs alone and, given ``--json PATH``, writes its results
there; this runner starts each in turn (a progress line says which, and about how long is
left), then writes ``bench/RESULTS.md`` and the PNG plots next to it from those results.

    .venv/bin/python bench/run.py [--only sim,interactive] [--submissions 30]

A benchmark that misses one of its targets still gives its figures (marked MISSED in the
results); one that fails to give figures is reported as failed, and the exit code is 1.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))

from snakekit.host import choose_mujoco_gl  # noqa: E402

#: the study's published figures: Windows host, ROS Melodic, RViz/Gazebo GUI - other hardware
STUDY = [
    # set-up, start to a working shell, image size, Task 1 CPU, Task 2 CPU, RAM
    ("VM (VMware, Ubuntu desktop)", "34 s", "14.4 GB", "7.67 %", "27.93 %", "384-450 MB"),
    ("Docker, one container", "2 s (+15 s engine start)", "~4 GB", "20.67 %", "14.00 %", "217-242 MB"),
    ("Docker, several containers", "2 s (+15 s engine start)", "~4 GB", "15.35 %", "15.54 %", "235-236 MB"),
]
#: the issue's targets for this kit's own set-ups
TARGETS = {"task1_cpu": 5.0, "task1_rss": 200.0, "task2_cpu": 3.0, "lab_s": 3.0}


@dataclass
class Step:
    name: str
    what: str
    args: list[str]
    estimate: float  # [s] on two shared cores, for the progress line
    result: dict | None = None
    code: int | None = None
    seconds: float = 0.0
    log: str = ""
    extra: dict = field(default_factory=dict)


def steps(submissions: int) -> list[Step]:
    return [
        Step("kinematics", "FK, Jacobian, IK vs bare Pinocchio", ["kinematics.py"], 15),
        Step("bus", "control cycle vs the bare Dynamixel SDK", ["bus.py"], 25),
        Step("bridge", "control cycle through snakekit bridge vs the direct port; the USB latency timer",
             ["bridge.py"], 40),
        Step("sim", "Task 2: fast vs bare MuJoCo, and in real time", ["sim.py"], 85),
        Step("collision", "self-collision check: a pose, Task 2's path, Task 2 with contacts", ["collision.py"], 15),
        Step("interactive", "Task 1 through the control panel and viewer", ["interactive.py", "--repeats", "3"], 60),
        Step("setups", "time to a lesson kernel and to JupyterLab; install size", ["setups.py", "--repeats", "3"], 40),
        Step("viewer_proxy", "the 3D view through Jupyter's port (jupyter-server-proxy) vs its own port",
             ["viewer_proxy.py"], 45),
        Step("optimisations", "this round's changes, before and after", ["before_after.py"], 130),
        Step("grading", f"{submissions} submissions: snakekit grade vs nbgrader vs bare",
             ["run.py", "--grading-step", str(submissions)], 30 + 7 * submissions),
        Step("container", "the container and compose set-ups (starts the private Docker engine if needed)",
             ["container.py"], 330),
        Step("ros", "the study's multi-container ROS set-up (compose's ros profile, RViz through noVNC): "
             "Tasks 1 and 2, start, image size (the private Docker engine)", ["ros.py", "--repeats", "3"], 480),
        Step("memory", "memory per user: the single-user server idle, with a lesson kernel, with the 3D view; "
             "users per 24 GB node", ["memory.py", "--repeats", "3"], 150),
        Step("hub", "the class's JupyterHub: spawns, the hub and proxy under 50 users, grading 20 "
             "(the private Docker engine)", ["hub.py"], 600),
    ]


# --- running ----------------------------------------------------------------------------------

class Progress:
    """One line on standard error: which benchmark, how long it has run, about how long is left."""

    def __init__(self, plan: list[Step]):
        self.plan = plan
        self.index = 0
        self.started = time.perf_counter()
        self.step_started = self.started
        self.tty = sys.stderr.isatty()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def left(self) -> float:
        current = self.plan[self.index]
        in_step = time.perf_counter() - self.step_started
        rest = sum(s.estimate for s in self.plan[self.index + 1:])
        return max(current.estimate - in_step, 5.0 if in_step > current.estimate else 0.0) + rest

    def line(self) -> str:
        s = self.plan[self.index]
        return (f"bench [{self.index + 1}/{len(self.plan)}] {s.name}: {s.what} - "
                f"{fmt(time.perf_counter() - self.step_started)} so far, about {fmt(self.left())} left in all")

    def begin(self, index: int) -> None:
        self.index = index
        self.step_started = time.perf_counter()
        if not self.tty:
            print(self.line(), file=sys.stderr, flush=True)

    def _loop(self) -> None:
        while not self._stop.wait(1.0):
            if self.tty:
                sys.stderr.write("\r\033[K" + self.line())
                sys.stderr.flush()

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        if self.tty:
            sys.stderr.write("\r\033[K")
        print(f"bench: done in {fmt(time.perf_counter() - self.started)}", file=sys.stderr, flush=True)


def fmt(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60}:{seconds % 60:02d}"


def run_step(step: Step, tmp: Path) -> None:
    out = tmp / f"{step.name}.json"
    t0 = time.perf_counter()
    env = {**os.environ, "MPLBACKEND": "Agg"}
    choose_mujoco_gl(env)
    proc = subprocess.run([sys.executable, str(HERE / step.args[0]), *step.args[1:], "--json", str(out)],
                          cwd=REPO, capture_output=True, text=True, env=env)
    step.seconds = time.perf_counter() - t0
    step.code = proc.returncode
    step.log = (proc.stdout + ("\n" + proc.stderr if proc.returncode not in (0, 1) else "")).strip()
    if out.exists():
        step.result = json.loads(out.read_text())


# --- grading: bench/grading.py's own measurements, with its results kept as data ----------

def grading_step(submissions: int, json_path: str) -> int:
    """``bench/grading.py``'s ways of grading, timed by its own functions, as JSON.

    Bare serial execution (no target of its own) is left to ``bench/grading.py`` alone, to keep
    ``make bench`` within its time.
    """
    import grading
    from _common import write_json

    os.environ.setdefault("MPLBACKEND", "Agg")
    jobs = os.cpu_count() or 1
    times = {}
    for key, fn in (("snakekit", lambda c: grading.time_snakekit(c, jobs)), ("nbgrader", grading.time_nbgrader),
                    ("bareN", lambda c: grading.time_bare(c, jobs))):
        with tempfile.TemporaryDirectory(prefix="snakekit-bench-") as tmp:
            course = grading.fresh_course(Path(tmp), submissions)
            times[key] = fn(course)
        print(f"{key}: {times[key]:.1f} s for {submissions} submissions", flush=True)
    speedup = times["nbgrader"] / times["snakekit"]
    data = {"submissions": submissions, "jobs": jobs, "lesson": grading.LESSON, "seconds": times,
            "speedup_vs_nbgrader": speedup, "vs_bare_parallel": times["snakekit"] / times["bareN"]}
    write_json(json_path, data)
    return 0 if speedup >= 2 and data["vs_bare_parallel"] <= 1.5 else 1


# --- the machine ----------------------------------------------------------------------------

def machine() -> dict:
    import psutil

    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cores": os.cpu_count(), "cpu": cpu, "memory_gb": psutil.virtual_memory().total / 2**30,
            "load": os.getloadavg(), "python": platform.python_version(), "system": platform.platform(),
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}


# --- plots ------------------------------------------------------------------------------------

def plots(results: dict, out: Path) -> list[tuple[str, str]]:
    """Figures like the study's 4-1 to 4-4: CPU and RSS over time in Tasks 1 and 2, a line a set-up."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    made = []
    for task, title in (("task1", "Task 1 (interactive: three goal changes)"),
                        ("task2", "Task 2 (coded sweep, 500 points at 10 Hz, in real time)")):
        lines = series_of(results, task)
        for key, label, unit in (("cpu", "CPU", "% of one core"), ("rss", "memory (RSS)", "MB")):
            fig, ax = plt.subplots(figsize=(7.5, 3.6), dpi=110)
            for i, (name, s, style) in enumerate(lines):
                if not (s and s.get("t")):
                    continue
                color = f"C{i}"
                if key == "cpu":
                    # CPU time comes in 10 ms ticks: one 0.5 s sample is a multiple of 2 %. The
                    # samples are dots; the line is their mean over 2 s.
                    ax.plot(s["t"], s[key], ".", color=color, alpha=0.45, ms=5)
                    ax.plot(s["t"], moving_mean(s[key], 4), style, color=color, lw=1.8,
                            label=f"{name} (mean over 2 s; dots: 0.5 s samples)")
                else:
                    ax.plot(s["t"], s[key], style, color=color, label=name, lw=1.6, marker=".", ms=4)
            if key == "cpu":
                limit = TARGETS[f"{task}_cpu"]
            else:
                limit = TARGETS["task1_rss"] if task == "task1" else None
            if limit is not None:
                ax.axhline(limit, color="0.5", ls=":", lw=1, label=f"target {limit:g} {unit.split()[0]}")
            ax.set_xlabel("time since the task started [s]")
            ax.set_ylabel(f"{label} [{unit}]")
            ax.set_title(f"{title}: {label}", fontsize=10)
            ax.set_ylim(bottom=0)
            ax.set_xlim(left=0)
            ax.grid(alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=8, loc="best")
            fig.tight_layout()
            name = f"{task}_{key}.png"
            fig.savefig(out / name)
            plt.close(fig)
            made.append((name, f"{title}: {label}"))
    ros = results.get("ros") or {}
    if ros.get("task1"):
        made.append(ros_plot(results, out, plt))
    return made


def ros_plot(results: dict, out: Path, plt) -> tuple[str, str]:
    """The ROS stack's CPU and memory over Tasks 1 and 2 (its four containers summed, from their
    cgroups), beside the kit's compose services for scale."""
    ros = results["ros"]
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), dpi=110)
    compose = (results.get("container") or {}).get("compose") or {}
    for row, (task, title) in enumerate((("task1", "Task 1 (three goal changes)"),
                                         ("task2", "Task 2 (the sweep, 500 points at 10 Hz)"))):
        lines = [("ROS stack: roscore, arm, robot_state_publisher, RViz + noVNC (cgroups)", ros[task]["series"], "C3")]
        if compose.get(f"{task}_series"):
            lines.append(("snakekit, compose services (the lesson's processes)", compose[f"{task}_series"], "C2"))
        for col, (key, label) in enumerate((("cpu", "CPU [% of one core]"), ("rss", "memory [MB]"))):
            ax = axes[row][col]
            for name, s, color in lines:
                if key == "cpu":
                    ax.plot(s["t"], s["cpu"], ".", color=color, alpha=0.35, ms=4)
                    ax.plot(s["t"], moving_mean(s["cpu"], 4), "-", color=color, lw=1.6, label=name)
                else:
                    ax.plot(s["t"], s["rss"], "-", color=color, lw=1.6, marker=".", ms=3, label=name)
            ax.set_title(f"{title}: {label.split(' [')[0]}", fontsize=9)
            ax.set_xlabel("time since the task started [s]", fontsize=8)
            ax.set_ylabel(label, fontsize=8)
            ax.set_ylim(bottom=0)
            ax.set_xlim(left=0)
            ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(out / "ros_tasks.png")
    plt.close(fig)
    return "ros_tasks.png", ("The multi-container ROS set-up in Tasks 1 and 2 (CPU: mean over 2 s, dots: 0.5 s samples; "
                             "memory: working set), beside the kit's compose services")


def moving_mean(values, n: int) -> list[float]:
    out = []
    for i in range(len(values)):
        window = values[max(0, i - n + 1): i + 1]
        out.append(sum(window) / len(window))
    return out


def series_of(results: dict, task: str) -> list[tuple[str, dict | None, str]]:
    """(label, series, line style) for each set-up measured in ``task``."""
    out = []
    if task == "task1":
        r = results.get("interactive")
        out.append(("local venv: kernel (serving the view)", r and r.get("series"), "-"))
        before = results.get("optimisations", {}).get("task1", {}).get("before_series")
        if before:
            out.append(("local venv before this round's changes", before, "--"))
    else:
        r = results.get("sim")
        out.append(("local venv: kernel", r and r.get("series"), "-"))
    for setup in ("container", "compose"):
        c = (results.get("container") or {}).get(setup) or {}
        s = c.get(f"{task}_series")
        if s:
            out.append((f"{setup}: same processes", s, "-"))
    return out


# --- RESULTS.md -------------------------------------------------------------------------------

def med(d, key="median"):
    return None if d is None else d.get(key) if isinstance(d, dict) else d


def num(x, f="{:.2f}", unit=""):
    return "-" if x is None else f.format(x) + unit


def write_results(plan: list[Step], results: dict, info: dict, figures, out: Path, total: float) -> None:
    L = []
    add = L.append
    add("# snakekit benchmarks")
    add("")
    add(f"Written by `make bench` (bench/run.py) on {info['date']}, in {fmt(total)} (min:s). "
        "Each benchmark also runs alone (`.venv/bin/python bench/<name>.py`).")
    add("")
    load = info["load"]
    add(f"**Machine:** {info['cores']} cores ({info['cpu'] or 'CPU model unknown'}), "
        f"{info['memory_gb']:.1f} GB memory, {info['system']}, Python {info['python']}. "
        f"Load average before the run: {load[0]:.2f} (1 min), {load[1]:.2f} (5 min).")
    if info.get("shared") or load[0] > 0.5:
        add("**Shared machine:** other work ran on this machine during the run (see the load "
            "averages), so the times and CPU figures are noisier and likely higher than on an idle one.")
    add("")

    # --- the study's table
    inter, sim, setups = results.get("interactive"), results.get("sim"), results.get("setups")
    cont = results.get("container") or {}
    add("## The study's table, for this kit")
    add("")
    add("This kit's set-ups, measured here; medians of the repeats (spread in the methodology below). "
        "CPU is percent of one core averaged over the task; RAM is the peak resident memory (RSS) "
        "summed over the processes counted (see *What each figure includes*).")
    add("")
    add("| set-up | time to a working lesson kernel | time to JupyterLab ready | install / image size "
        "| Task 1 CPU | Task 1 peak RAM | Task 2 CPU | Task 2 peak RAM |")
    add("|---|---|---|---|---|---|---|---|")
    t2 = sim and sim.get("series")
    add("| snakekit, local venv (`make lab`) | "
        f"{num(med(setups and setups.get('kernel_s')), unit=' s')} | {num(med(setups and setups.get('lab_s')), unit=' s')} | "
        f"{num(setups and setups.get('install_bytes') / 1e9, unit=' GB')} (.venv) | "
        f"{num(med(inter and inter.get('cpu')), unit=' %')} | {num(med(inter and inter.get('rss')), '{:.0f}', ' MB')} | "
        f"{num(t2 and t2.get('cpu_avg'), unit=' %')} | {num(t2 and t2.get('rss_peak'), '{:.0f}', ' MB')} |")
    for key, label in (("container", "snakekit, one container (`docker run`)"),
                       ("compose", "snakekit, compose services (`docker compose up lab`)")):
        c = cont.get(key)
        if not c or c.get("not_measured"):
            why = (c or {}).get("not_measured") or cont.get("not_measured") or "not measured"
            add(f"| {label} | {why} | | | | | | |")
        else:
            add(f"| {label} | {num(med(c.get('kernel_s')), unit=' s')} | {num(med(c.get('lab_s')), unit=' s')} | "
                f"{num(c.get('image_bytes') and c['image_bytes'] / 1e9, unit=' GB')} (image) | "
                f"{num(med(c.get('task1_cpu')), unit=' %')} | {num(med(c.get('task1_rss')), '{:.0f}', ' MB')} | "
                f"{num(c.get('task2_cpu'), unit=' %')} | {num(c.get('task2_rss'), '{:.0f}', ' MB')} |")
    add("")
    add("The study's published figures, **taken on other hardware** (a Windows host; ROS Melodic "
        "with the RViz/Gazebo GUI; RAM as one range for both tasks). They are beside ours for "
        "scale, not as a measurement on this machine:")
    add("")
    add("| study set-up (other hardware) | start to a working shell | image size | Task 1 CPU | Task 2 CPU | RAM |")
    add("|---|---|---|---|---|---|")
    for row in STUDY:
        add("| " + " | ".join(row) + " |")
    add("")
    ros_rows(results.get("ros"), add, info)

    # --- targets
    add("### Targets for this kit's own set-ups (the local venv here)")
    add("")
    add("| figure | measured (median) | target | |")
    add("|---|---|---|---|")
    checks = [
        ("Task 1 CPU (kernel, serving the view)", med(inter and inter.get("cpu")), TARGETS["task1_cpu"], " %", "{:.2f}"),
        ("Task 1 peak RAM (RSS, kernel, serving the view)", med(inter and inter.get("rss")), TARGETS["task1_rss"], " MB", "{:.0f}"),
        ("Task 2 CPU in real time (kernel)", t2 and t2.get("cpu_avg"), TARGETS["task2_cpu"], " %"),
        ("`make lab` to JupyterLab ready", med(setups and setups.get("lab_s")), TARGETS["lab_s"], " s"),
    ]
    for name, value, limit, unit, *f in checks:
        ok = "-" if value is None else ("met" if value <= limit else "MISSED")
        add(f"| {name} | {num(value, *(f or ['{:.2f}']), unit=unit)} | <= {limit:g}{unit} | {ok} |")
    if inter and inter.get("pss"):
        add("")
        add(f"Task 1 peak RAM with each shared page counted once (PSS, closer to what a container's "
            f"memory counter reports): {med(inter['pss']):.0f} MB. PSS splits a page among every process "
            "that maps it, other programs on the machine included, so it moves with what else runs.")
    add("")

    # --- plots
    add("## CPU and memory over time (like the study's figures 4-1 to 4-4)")
    add("")
    add("Sampled every 0.5 s with psutil from the task's start; one line per set-up measured. "
        "The dotted line is the target."
        + (" The ROS set-up's plot (the last) is sampled from its containers' cgroups, every 0.5 s too."
           if any(name == "ros_tasks.png" for name, _ in figures) else ""))
    add("")
    for name, title in figures:
        add(f"![{title}]({name})")
        add("")

    # --- ratios
    add("## Ratios against peers and limits, measured side by side in one run")
    add("")
    add("| comparison | snakekit | peer / limit | ratio | target |")
    add("|---|---|---|---|---|")
    s = sim
    if s:
        add(f"| Task 2 as fast as possible: `SimRobot.run` vs a bare `mj_step` loop of the same motion | "
            f"{s['ours_s'] * 1000:.0f} ms | {s['bare_s'] * 1000:.0f} ms | {s['overhead']:.2f}x | <= 1.3x |")
        add(f"| ... vs one bare `mj_step(nstep=...)` call, arm still (the floor) | {s['ours_s'] * 1000:.0f} ms | "
            f"{s['still_s'] * 1000:.0f} ms | {s['ours_s'] / s['still_s']:.2f}x | - |")
        add(f"| ... real-time factor | {s['speed']:.0f}x real time | - | - | >= 200x |")
    g = results.get("grading")
    if g:
        n = g["submissions"]
        sec = g["seconds"]
        add(f"| grading {n} submissions: `snakekit grade --jobs {g['jobs']}` vs plain serial `nbgrader autograde` | "
            f"{sec['snakekit']:.1f} s | {sec['nbgrader']:.1f} s | {g['speedup_vs_nbgrader']:.2f}x faster | "
            f"{'>= 2x faster' if n >= 60 else '>= 2x faster at 60 submissions (`bench/grading.py`); here the batch start (~1.5 s) weighs more'} |")
        add(f"| ... vs bare nbclient execution, {g['jobs']} processes (the bound) | {sec['snakekit']:.1f} s | "
            f"{sec['bareN']:.1f} s | {g['vs_bare_parallel']:.2f}x | <= 1.5x |")
        if "bare1" in sec:
            add(f"| ... vs bare nbclient execution, serial | {sec['snakekit']:.1f} s | {sec['bare1']:.1f} s | "
                f"{sec['snakekit'] / sec['bare1']:.2f}x | - |")
    b = results.get("bus")
    if b:
        add(f"| bus control cycle (SyncRead + SyncWrite, 5 servos, emulated): `DynamixelSnake` vs bare dynamixel-sdk | "
            f"{med(b['ours_hz']):.0f} Hz | {med(b['bare_hz']):.0f} Hz | {b['ratio']:.2f} | >= 0.80 |")
    vp = results.get("viewer_proxy")
    if vp:
        u, pg = vp["update_ms"], vp["page_ms"]
        add(f"| 3D view update, `viewer.show(q)` to the page's websocket: through Jupyter's port (jupyter-server-proxy) "
            f"vs the viewer's own port (p95 {u['proxied']['p95']:.1f} / {u['direct']['p95']:.1f} ms) | "
            f"{u['proxied']['median']:.2f} ms | {u['direct']['median']:.2f} ms | {vp['update_ratio']:.2f} | - |")
        add(f"| 3D view page + script (0.85 MB) loaded through Jupyter's port vs the viewer's own port | "
            f"{pg['proxied']['median']:.1f} ms | {pg['direct']['median']:.1f} ms | {vp['page_ratio']:.2f} | - |")
        m = vp["server_rss_mb"]
        add(f"| Jupyter server memory with jupyter-server-proxy vs without (just started; {m['with_proxy']:.0f} MB "
            f"once it served the view) | {m['with_proxy_idle']:.0f} MB | {m['without_proxy']:.0f} MB | "
            f"{m['with_proxy_idle'] / m['without_proxy']:.2f} | - |")
    br = results.get("bridge")
    if br:
        for r in br["bridge"]:
            timer = f"USB latency timer {r['latency_ms']} ms" if r["latency_ms"] else "answering at once"
            add(f"| bus control cycle through `snakekit bridge` vs the direct port (emulated, {timer}) | "
                f"{med(r['bridge_hz']):.0f} Hz | {med(r['direct_hz']):.0f} Hz | {r['ratio']:.2f} | >= 0.80 |")
        lat = br["latency_hz"]
        add(f"| bus control cycle with the USB latency timer at 1 ms vs 16 ms (emulated FTDI chip) | "
            f"{med(lat['1']):.0f} Hz | {med(lat['16']):.0f} Hz | {med(lat['1']) / med(lat['16']):.1f}x | "
            "16 ms: <= 62.5 Hz |")
    k = results.get("kinematics")
    if k:
        for c in k["calls"]:
            add(f"| `snakekit.{c['call']}` vs the bare Pinocchio call | {c['ours_us']:.2f} us | {c['bare_us']:.2f} us | "
                f"{c['ratio']:.2f}x | {c['target']} |")
        add(f"| `snakekit.inverse_kinematics`, {k['ik_targets']} random reachable targets | median {k['ik_median_us']:.0f} us, "
            f"95th percentile {k['ik_p95_us']:.0f} us, {100 * k['ik_success']:.1f} % solved | - | - | < 1000 us, >= 99 % |")
    c = results.get("collision")
    if c:
        add(f"| self-collision: `snakekit.clearance(q)`, one pose (closest pair of non-neighbouring links) | "
            f"{c['pose_us']:.1f} us | {c['pose_bare_us']:.1f} us (bare `pinocchio.computeDistances`) | "
            f"{c['pose_us'] / c['pose_bare_us']:.2f}x | <= 20 us |")
        add(f"| ... Task 2's 500 goals, path between goals included ({c['sweep_poses']} poses computed) | "
            f"{c['sweep_ms']:.2f} ms | - | - | <= 10 ms |")
        add(f"| ... Task 2 fast (`SimRobot.run`, check and contacts) vs a bare `mj_step` loop, same model | "
            f"{c['task2_ours_s'] * 1000:.0f} ms | {c['task2_bare_s'] * 1000:.0f} ms | {c['task2_overhead']:.3f}x | <= 1.05x |")
        add(f"| ... the bare loop with the links' contacts vs without | {c['task2_bare_s'] * 1000:.0f} ms | "
            f"{c['task2_bare_no_contacts_s'] * 1000:.0f} ms | {c['contacts_cost']:.3f}x | - |")
    add("")

    # --- optimisations
    o = results.get("optimisations")
    if o and o.get("not_measured"):
        add("## This round's changes, before and after")
        add("")
        add(f"{o['not_measured']} (the 'before' is commit `{o['before_rev']}`).")
        add("")
    elif o:
        add("## This round's changes, each measured before and after in one run")
        add("")
        add(f"Before = the library at commit `{o['before_rev']}`"
            + (f"; the first change alone = the library at commit `{o['mid_rev']}`" if o.get("mid_rev") else "")
            + (f"; the first two = at commit `{o['thread_rev']}`" if o.get("thread_rev") else "")
            + "; after = this tree. They alternate within the run (same machine, same moment), with the same "
            "benchmark code; medians of the repeats.")
        add("")
        add("| change | figure | before | after | effect |")
        add("|---|---|---|---|---|")
        for row in o["rows"]:
            add(f"| {row['change']} | {row['figure']} | {row['before']} | {row['after']} | {row['effect']} |")
        add("")

    # --- memory per user (a hub's single-user server)
    mem = results.get("memory") or {}
    if mem.get("view"):
        add("## Memory per user on a hub")
        add("")
        add(f"One student's server (the image's `start-lab`, one container each), its memory cgroup as a hub's "
            f"limit counts it; medians of {len(mem['runs'])} runs (bench/memory.py). Working set: usage less "
            "inactive file pages (what `docker stats` shows and Kubernetes evicts by).")
        add("")
        add("| point | usage (MiB) | working set (MiB) | peak (MiB) |")
        add("|---|---|---|---|")
        for point, label in (("idle", "idle"), ("kernel", "lesson 00's kernel, its first cell run"),
                             ("view", "and the lesson and its 3D view open in headless Chromium")):
            r = mem[point]
            add(f"| {label} | {r['usage']:.0f} | {r['working_set']:.0f} | {r['peak']:.0f} |")
        add("")
        add(f"Users per {mem['node_gb']} GB node with a kernel and the 3D view each, at their peak "
            f"({mem['node_reserved_gb']} GB kept for the node): **{mem['users_per_node']}** (target: at least 80).")
        add("")
    elif mem.get("not_measured"):
        add(f"## Memory per user on a hub\n\n{mem['not_measured']}\n")
    # --- the class's JupyterHub
    h = results.get("hub")
    if h:
        add("## The class's JupyterHub (docker/hub/, 20 students on a single-node swarm)")
        add("")
        if h.get("not_measured"):
            add(f"Not measured: {h['not_measured']}.")
        else:
            add("| what | figure | target |")
            add("|---|---|---|")
            add(f"| spawn to ready, warm (a student's server stopped and started again; median of 3) | "
                f"{h['spawn_warm_median_s']} s | <= 5 s |")
            add(f"| spawn to ready, the first server after the hub starts (a new volume) | {h['spawn_first_s']} s | |")
            add(f"| 20 students' servers, five started at a time: each, median | {h['spawn_20_median_s']} s | |")
            add(f"| the hub's API under 50 clients: p50 / p95 | {h['hub_p50_ms']} / {h['hub_p95_ms']} ms | |")
            add(f"| a student's server through the proxy under 50 clients: p50 / p95 | "
                f"{h['proxy_p50_ms']} / {h['proxy_p95_ms']} ms | |")
            add(f"| requests served under that load | {h['requests_per_s']} /s | |")
            add(f"| the hub's container (hub, proxy, exchange, culler): idle / peak under load | "
                f"{h['hub_mem_idle_mib']} / {h['hub_mem_peak_mib']} MiB | |")
            add(f"| grading the 20 collected submissions (`snakekit grade --jobs 2`, grader container) | "
                f"{h['grade_20_s']} s | |")
        add("")

    # --- methodology
    add("## Methodology")
    add("")
    gl = choose_mujoco_gl(dict(os.environ))
    add(f"- **Machine:** {info['cores']} cores, {info['memory_gb']:.1f} GB memory (above). No GPU, no display "
        f"(MuJoCo is imported with MUJOCO_GL={gl or 'unset: its default'}).")
    add("- **Repetitions:** every figure is the median of its repeats; the spread (min-max) is given here.")
    if inter:
        add(f"  - Task 1: {inter['cpu']['n']} repeats, each in a fresh process; CPU {spread_text(inter['cpu'], ' %')}, "
            f"peak RSS {spread_text(inter['rss'], ' MB', '{:.0f}')}, task length {spread_text(inter['wall'], ' s', '{:.1f}')}.")
    if setups:
        add(f"  - Time to a working lesson kernel: {spread_text(setups['kernel_s'], ' s')}; "
            f"time to JupyterLab ready: {spread_text(setups['lab_s'], ' s')} ({setups['lab_s']['n']} repeats, interleaved).")
    if sim:
        add(f"  - Task 2 as fast as possible: medians of {sim['repeats']} runs; Task 2 in real time: one run of "
            f"{sim['realtime']['wall']:.1f} s (its CPU averages 100 samples).")
    ros = results.get("ros")
    if ros and ros.get("task1"):
        add(f"  - ROS set-up (bench/ros.py): {ros['repeats']} starts (down between) and {ros['repeats']} runs of "
            f"each task on the last; start to the arm's node answering {spread_text(ros['start_arm_s'], ' s', '{:.1f}')} "
            f"(noVNC's page answering {spread_text(ros['start_novnc_s'], ' s', '{:.1f}')}); Task 1 CPU "
            f"{spread_text(ros['task1']['cpu'], ' %')}, peak RAM {spread_text(ros['task1']['ram'], ' MB', '{:.0f}')}, "
            f"length {spread_text(ros['task1']['wall'], ' s', '{:.1f}')}; Task 2 CPU {spread_text(ros['task2']['cpu'], ' %')}, "
            f"peak RAM {spread_text(ros['task2']['ram'], ' MB', '{:.0f}')}, length {spread_text(ros['task2']['wall'], ' s', '{:.1f}')}.")
    if b:
        add(f"  - Bus: {b['repeats']} interleaved measurements of {b['seconds']:g} s each; snakekit "
            f"{spread_text(b['ours_hz'], ' Hz', '{:.0f}')}, bare SDK {spread_text(b['bare_hz'], ' Hz', '{:.0f}')}.")
    if g:
        add(f"  - Grading: one round of each method on the same {g['submissions']} generated submissions "
            "(good ones, hidden-test failures, stubs, an import error, a kernel that exits, a file that is not JSON).")
    add("  - Kinematics: medians of 7 rounds of 20,000 calls; IK over 1,000 random reachable targets.")
    add("- **What each figure includes:**")
    add("  - *Task 1* runs in a fresh Python process that plays the lesson kernel (the simulated arm in real "
        "time, the meshcat viewer, the control panel; it sets three tool targets and executes each through the "
        "panel's own callbacks, then waits 0.5 s); headless Chromium shows the viewer page, so the server really "
        "streams the scene. CPU and RAM count **the kernel process**, which serves the view from a thread (the "
        "viewer's server was a second process before this round: the before-and-after rows count both); "
        "Chromium is not counted (the study did not count its host's browser either). The kernel-like process "
        "does not include ipykernel itself, which a real JupyterLab kernel adds.")
    add("  - *Task 2* runs `robot.run(snakekit.side_sweep())` on the simulator paced to the wall clock "
        "(500 goals at 10 Hz, 50 sweeps, back home), in a fresh process; CPU and RAM count **that process** "
        "(no viewer), from the start of the run to its end.")
    add("  - CPU is user + system time over wall time, in percent of one core (100 % = one core busy), as "
        "the study reports it. RAM is resident memory (RSS) summed over the processes counted (where two "
        "are counted, pages they share, like the Python runtime, are counted twice; PSS counts them once). The kernel "
        "counts CPU time in 10 ms ticks, so a single 0.5 s sample is a multiple of 2 %; the averages "
        "(the table) divide the whole task's CPU time by its length and are not quantised that way.")
    add("  - *Time to a working lesson kernel*: from asking jupyter_client for the lessons' kernel to the end of "
        "lesson 00's first cell (imports, the simulated arm, the viewer and its server, the workspace drawn).")
    add("  - *Time to JupyterLab ready*: from running `make lab` (which checks the environment first) to the "
        "server answering `/lab` with the JupyterLab page (token given, as the printed URL has it).")
    add("  - *Install size*: the disk space of `.venv` (all the Python packages). System packages that "
        "tools/setup installs for the test suite (Chromium, debootstrap, docker.io) are not counted.")
    eng = cont.get("engine")
    add("  - *Containers*: a Docker engine already running (DOCKER_HOST, or the default socket) with the image "
        "`snakekit-lab:latest`; otherwise, as root with Debian's docker.io installed, the private engine of "
        "docker/engine.sh (the one docker/test.sh uses: its own data root and socket, no iptables, no "
        "forwarding, no default bridge), the image built from this tree with BuildKit (cached layers "
        "reused), and afterwards the engine stopped and the host's iptables, ip_forward, bridge settings, "
        "links and mounts checked and restored. The same Task 1 and Task 2 workers run inside the container, "
        "counting the same processes (Task 1 without a browser on the viewer: the image has none). "
        "*Time to JupyterLab ready* is from `docker run -d` / `docker compose up -d --no-build lab` to `/lab` "
        "answering on the published port; *time to a working lesson kernel* is measured inside the running "
        "container; *image size* is `docker image inspect`'s."
        + (f" In this run the private engine answered {eng['engine_start_s']:.1f} s after it was started, and the "
           f"image was {'built in ' + format(eng['build_s'], '.0f') + ' s (' + ('cold' if eng['cold'] else 'warm engine cache') + ')' if eng['built'] else 'reused'}; "
           "neither is in the table's times." if eng else ""))
    if ros and ros.get("task1"):
        add("  - *The ROS set-up* (bench/ros.py): `docker compose --profile ros up -d rviz` (the ROS services, "
            "not the lab) on a running engine or the private one of docker/engine.sh, images cached. *Start to a working shell*: "
            "from `up` to the arm's node saying it is up (`snakekit ros: the sim arm is node ...` in its log; the "
            "master healthy before it); noVNC's page answering is given beside it. Each container's CPU time "
            f"(cgroup {ros['cgroup']}: `cpuacct.usage`, v2 `cpu.stat`) and memory (usage less inactive file "
            "pages, as `docker stats`) are read on the host every 0.5 s (the memory's peak every 0.1 s) and summed "
            "over roscore, arm, state-publisher and rviz; the node that sends the goals runs in the arm's "
            "container (`docker compose exec`) and is counted; the headless Chromium on noVNC runs on the host "
            "and is not. RViz draws in software GL (Mesa, no GPU), at most 15 frames a second (docker/ros/arm.rviz).")
    add("- **The study's figures** are the study's published ones: other hardware, other software (ROS, RViz, Gazebo, "
        "a desktop in a VM); they frame ours, they are not measured here.")
    add("")

    # --- what ran
    add("## Benchmarks in this run")
    add("")
    add("| benchmark | what | time | result |")
    add("|---|---|---|---|")
    for s in plan:
        state = ("figures given, targets met" if s.code == 0 else "figures given, a target MISSED" if s.result
                 else f"FAILED (exit code {s.code})")
        if s.name in ("container", "memory", "ros") and s.result and s.result.get("not_measured"):
            state = s.result["not_measured"]
        add(f"| {s.name} | {s.what} | {fmt(s.seconds)} | {state} |")
    add("")
    out.write_text("\n".join(L))


def ros_rows(ros: dict | None, add, info: dict) -> None:
    """The study's third framework rebuilt on our arm (bench/ros.py): its table and what it counts."""
    if not ros:
        return
    add("### The study's multi-container ROS set-up, rebuilt on our arm and measured here")
    add("")
    if ros.get("not_measured"):
        add(f"compose's `ros` profile: {ros['not_measured']}.")
        add("")
        return
    t1, t2 = ros["task1"], ros["task2"]
    add("Compose's `ros` profile (docs/ros.md): roscore, the arm as a ROS 1 node (`snakekit ros`, the simulator "
        "in real time), robot_state_publisher and RViz on a virtual display served by noVNC, each in its own "
        "container on one network, with headless Chromium connected to noVNC all along (RViz really drawing "
        "and served). CPU and RAM are **the four containers together**, from their cgroups: CPU in percent of "
        f"one core averaged over the task, RAM the peak of their summed memory as `docker stats` counts it "
        f"(usage less inactive file pages). Medians of {ros['repeats']}; spread in the methodology below.")
    m = ros.get("machine")
    if m:
        add("")
        add(f"Measured on {m['date']} on {m['cores']} cores ({m['cpu'] or 'CPU model unknown'}), load average "
            f"{m['load'][0]:.2f} (1 min), {m['load'][1]:.2f} (5 min) before it"
            + (": other work shared the cores, so its CPU figures are likely higher than on an idle machine"
               if m["load"][0] > 0.5 else "") + "."
            + (f" The kit's rows above were measured on {info['date']} on another machine ({info['cpu']})."
               if (m["cpu"], m["date"][:10]) != (info["cpu"], info["date"][:10]) else ""))
    add("")
    add("| set-up | start to a working shell | image size | Task 1 CPU | Task 1 peak RAM | Task 2 CPU | Task 2 peak RAM |")
    add("|---|---|---|---|---|---|---|")
    add(f"| ROS 1 (Debian's), several containers (`docker compose --profile ros up`) | "
        f"{med(ros['start_arm_s']):.1f} s (engine running) | {ros['image_bytes'] / 1e9:.2f} GB (image) | "
        f"{med(t1['cpu']):.2f} % | {med(t1['ram']):.0f} MB | {med(t2['cpu']):.2f} % | {med(t2['ram']):.0f} MB |")
    add("")
    each = lambda t: ", ".join(f"{n} {med(c['cpu']):.1f} %" for n, c in t["by_container"].items())  # noqa: E731
    add(f"By container (CPU, medians): Task 1: {each(t1)}; Task 2: {each(t2)}. "
        f"Task 1 here is three single-point `JointTrajectory` goals sent from a node in the stack, each 2 s "
        "after the arm said the last was done, and 2 s on the last pose (bench/interactive.py's three tool targets, solved by the kit's IK "
        "beforehand): the study dragged a goal in RViz with MoveIt, which Debian's ROS 1 does not have. Task 2 "
        "is `snakekit.side_sweep()` (500 points at 10 Hz, 50 sweeps, back home) as ONE `JointTrajectory` "
        f"on /arm/command. The image is the students' ({ros['lab_image_bytes'] / 1e9:.2f} GB) with Debian's "
        "ROS 1, RViz, Xvfb, x11vnc and noVNC. The study's figures beside it (above) were **taken on other "
        "hardware** and with other software (ROS Melodic, Gazebo, a Windows host).")
    add("")


def spread_text(d: dict, unit: str, f: str = "{:.2f}") -> str:
    return f"median {f.format(d['median'])}{unit} (min {f.format(d['min'])}, max {f.format(d['max'])})"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", help="comma-separated benchmarks to run (default: all)")
    parser.add_argument("--submissions", type=int, default=30, help="submissions graded in the grading benchmark")
    parser.add_argument("--out", default=str(HERE), help="folder for RESULTS.md and the plots")
    parser.add_argument("--shared", action="store_true", help="say in RESULTS.md that the machine was shared")
    parser.add_argument("--grading-step", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--json", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.grading_step is not None:
        return grading_step(args.grading_step, args.json)

    plan = steps(args.submissions)
    if args.only:
        wanted = set(args.only.split(","))
        unknown = wanted - {s.name for s in plan}
        if unknown:
            parser.error(f"no benchmark named {', '.join(sorted(unknown))}; choose from {', '.join(s.name for s in plan)}")
        plan = [s for s in plan if s.name in wanted]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    info = machine()
    info["shared"] = args.shared
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="snakekit-bench-") as tmp, Progress(plan) as progress:
        for i, step in enumerate(plan):
            progress.begin(i)
            run_step(step, Path(tmp))
            step.estimate = step.seconds
            if step.result is None:
                print(f"\nbench: {step.name} FAILED (exit code {step.code}); its output ends:\n"
                      + "\n".join(step.log.splitlines()[-25:]), file=sys.stderr, flush=True)
    total = time.perf_counter() - t0
    results = {s.name: s.result for s in plan if s.result is not None}
    # figures of a partial run (--only) are merged with the last full run's data
    data_path = out / "results.json"
    if args.only and data_path.exists():
        results = {**json.loads(data_path.read_text()).get("results", {}), **results}
    data_path.write_text(json.dumps({"machine": info, "results": results}, indent=1))
    figures = plots(results, out)
    write_results(plan, results, info, figures, out / "RESULTS.md", total)
    for s in plan:
        print(f"{s.name:14s} {fmt(s.seconds):>6s}  {'ok' if s.code == 0 else 'target missed' if s.result else 'FAILED'}")
    print(f"wrote {out / 'RESULTS.md'} and {len(figures)} plots")
    return 0 if all(s.result is not None for s in plan) else 1


if __name__ == "__main__":
    sys.exit(main())
