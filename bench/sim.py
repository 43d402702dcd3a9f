"""Task 2 (the coded sweep) on the simulator: speed, overhead, CPU and memory.

Run ``python bench/sim.py --fast-only`` to skip the 50 s real-time run.

Fast mode: robot time over wall time (target >= 200x real time), and our whole run() against
bare MuJoCo stepping of the same model through the same motion, in the same process
(target <= 1.3x). Medians of 5 runs.

Real-time mode: the process's average CPU (percent of one core) and peak RSS while Task 2
runs paced to the wall clock (targets <= 5 % and <= 200 MB), measured with psutil, next to
the study's figures for the ROS set-ups.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import snakekit  # noqa: E402  (first: it sets MUJOCO_GL for this system before MuJoCo loads)

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from _common import Sampler, add_json_argument, table, write_json  # noqa: E402
from snakekit.profile_planner import ProfilePlanner  # noqa: E402
from snakekit.sim import SimRobot  # noqa: E402

REPEAT = 5


def bare_reference(trajectory, steps: int, dt: float) -> np.ndarray:
    """The servo reference's velocity for every step, computed ahead (outside the timed loop).

    The reference at step i is the profile there before the goals due at that step; the
    control of step i moves it to the reference at step i+1.
    """
    planner = ProfilePlanner(np.zeros(5))
    pos = np.empty((steps + 1, 5))
    g = 0
    for i in range(steps + 1):
        t = i * dt
        pos[i] = planner.at(t)[0]
        while g < len(trajectory) and trajectory.times[g] <= t + 1e-9:
            planner.set_goal(t, trajectory.positions[g])
            g += 1
    return np.diff(pos, axis=0) / dt


def fast_mode():
    sweep = snakekit.side_sweep()
    robot = SimRobot()
    m, dt = robot.model, robot.dt
    robot.close()
    steps = int(round((sweep.duration + 0.5) / dt))
    vel = bare_reference(sweep, steps, dt)
    ours, bare, still, final = [], [], [], None
    for _ in range(REPEAT):
        with SimRobot() as robot:
            t0 = time.perf_counter()
            run = robot.run(sweep)
            ours.append(time.perf_counter() - t0)
        d = mujoco.MjData(m)
        t0 = time.perf_counter()
        for i in range(steps):  # the least a loop driving the same motion must do
            d.ctrl[:] = vel[i]
            mujoco.mj_step(m, d)
        bare.append(time.perf_counter() - t0)
        final = np.abs(d.qpos - run.measured.positions[-1]).max()
        d = mujoco.MjData(m)
        t0 = time.perf_counter()
        mujoco.mj_step(m, d, nstep=steps)  # one call, arm standing still
        still.append(time.perf_counter() - t0)
    return run.robot_time, statistics.median(ours), statistics.median(bare), statistics.median(still), final


CHILD = r"""
import json, resource, threading, time
import psutil, snakekit
me = psutil.Process()
peak = [me.memory_info().rss]
stop = threading.Event()
def watch():
    while not stop.wait(0.05):
        peak[0] = max(peak[0], me.memory_info().rss)
threading.Thread(target=watch, daemon=True).start()
sweep = snakekit.side_sweep()
robot = snakekit.make_robot("sim", realtime=True)
print("start", flush=True)
c0, w0 = me.cpu_times(), time.perf_counter()
run = robot.run(sweep)
c1, w1 = me.cpu_times(), time.perf_counter()
print("done", flush=True)
robot.close()
stop.set()
cpu = (c1.user + c1.system - c0.user - c0.system) / (w1 - w0)
print(json.dumps({"cpu": 100 * cpu, "wall": w1 - w0, "robot": run.robot_time, "peak_rss": peak[0],
                  "maxrss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
"""


def realtime_mode():
    """Task 2 in real time in a fresh process; its CPU and RSS sampled every 0.5 s from here."""
    import psutil

    proc = subprocess.Popen([sys.executable, "-c", CHILD], stdout=subprocess.PIPE, text=True)
    if proc.stdout.readline().strip() != "start":
        raise SystemExit("the real-time Task 2 run did not start")
    me = psutil.Process(proc.pid)
    sampler = Sampler(lambda: [me] if proc.poll() is None else []).start()
    line = proc.stdout.readline().strip()
    series = sampler.stop()  # the run is over (or failed): the sampling ends with it
    out, _ = proc.communicate()
    if line != "done":
        raise SystemExit("the real-time Task 2 run stopped early")
    if proc.returncode != 0:
        raise SystemExit("the real-time Task 2 run failed")
    result = json.loads(out.strip().splitlines()[-1])
    return result, series


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--fast-only", action="store_true", help="skip the 50 s real-time run")
    parser.add_argument("--realtime-only", action="store_true", help="only the real-time run (for a container)")
    add_json_argument(parser)
    args = parser.parse_args(argv)
    if args.realtime_only:
        r, series = realtime_mode()
        print(f"Task 2 in real time: CPU {r['cpu']:.2f} % of one core, peak RSS {r['peak_rss'] / 1e6:.0f} MB, "
              f"{r['wall']:.1f} s")
        write_json(args.json, {"realtime": r, "series": series})
        return 0
    robot_time, ours, bare, still, final = fast_mode()
    speed = robot_time / ours
    overhead = ours / bare
    print(f"Task 2, as fast as possible ({robot_time:.1f} s of robot time, medians of {REPEAT} runs)")
    print(table([
        ["snakekit SimRobot.run(side_sweep())", f"{ours * 1000:.0f} ms", f"{speed:.0f}x", f"{overhead:.2f}x"],
        ["bare mj_step loop, same motion", f"{bare * 1000:.0f} ms", f"{robot_time / bare:.0f}x", "1.00x"],
        ["bare mj_step, one call, arm still", f"{still * 1000:.0f} ms", f"{robot_time / still:.0f}x",
         f"({ours / still:.2f}x)"],
    ], ["", "wall time", "real-time factor", "vs bare loop"]))
    print(f"bare loop ends {final:.1e} rad from our run's final pose (same physics)")
    ok_fast = speed >= 200 and overhead <= 1.3
    print(f"targets: >= 200x real time: {'ok' if speed >= 200 else 'MISSED'}; "
          f"<= 1.3x bare: {'ok' if overhead <= 1.3 else 'MISSED'}\n")
    data = {"robot_time": robot_time, "ours_s": ours, "bare_s": bare, "still_s": still, "speed": speed,
            "overhead": overhead, "final_gap_rad": float(final), "repeats": REPEAT, "ok_fast": bool(ok_fast)}
    if args.fast_only:
        write_json(args.json, data)
        return 0 if ok_fast else 1

    print("Task 2 in real time (one run of ~50 s) ...", flush=True)
    r, series = realtime_mode()
    mb = r["peak_rss"] / 1e6
    print(table([
        ["snakekit sim, real time (this machine)", f"{r['cpu']:.2f} %", f"{mb:.0f} MB", f"{r['wall']:.1f} s"],
        ["study: Docker, one container", "14.00 %", "217-242 MB", "~52 s"],
        ["study: Docker, several containers", "15.54 %", "235-236 MB", "~52 s"],
        ["study: VM", "27.93 %", "384-450 MB", "~52 s"],
    ], ["Task 2", "CPU (% of one core)", "peak RSS", "wall time"]))
    ok_rt = r["cpu"] <= 5 and mb <= 200
    print(f"targets: <= 5 % CPU: {'ok' if r['cpu'] <= 5 else 'MISSED'}; <= 200 MB: {'ok' if mb <= 200 else 'MISSED'}")
    data.update(realtime=r, series=series)
    write_json(args.json, data)
    return 0 if ok_fast and ok_rt else 1


if __name__ == "__main__":
    sys.exit(main())
