"""Jobs per hour of ``snakekit lab`` for lesson 06's Task 2 on the emulated arm, in real time.

Run as ``python bench/lab.py [--jobs 3] [--calibration-runs 2]``. A course in a scratch folder
gets ``--jobs`` graded submissions whose kept trajectory is the full Task 2 (500 goals at 10 Hz,
50 sweeps, 0.2 rad: 49.9 s of goals, 0.5 s of settling); the arm is the bus emulator behind
the real driver (``make_robot("emulator")``, in this process, paced by the wall clock like the
arm). The calibration (``--calibration-runs`` runs of the reference) is timed on its own; then
one session runs every job: the gate (limits, self-collision, duration, the 50 s simulator run
against the reference's), connecting, homing, the run, homing again, the grade, the result
folder (run, info, plot, report) and the gradebook. Jobs per hour = 3600 / (session wall time /
jobs). A lab session of N jobs adds one calibration: the last column extrapolates to a session
of 30 jobs, ``30 / (calibration + 30 x s/job)``, from the figures measured here.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

import snakekit  # noqa: E402
from bench._common import table  # noqa: E402
from grader.lab import session as lab  # noqa: E402
from grader.lab.jobs import Queue, settings  # noqa: E402

A = "06_coded_sweep"
TARGET = 50.0  # jobs per hour


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--jobs", type=int, default=3, help="how many Task 2 jobs to run (default 3: about 3.5 min)")
    p.add_argument("--calibration-runs", type=int, default=2, help="runs of the reference (default 2)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="snakekit-bench-lab-") as tmp:
        course = Path(tmp) / "course"
        (course / "source" / A).mkdir(parents=True)
        task2 = snakekit.side_sweep()
        students = [f"student{k:02d}" for k in range(args.jobs)]
        for st in students:
            d = course / "autograded" / st / A / "lab"
            d.mkdir(parents=True)
            np.savez(d / "ex06_3_task2_test.npz", times=task2.times, positions=task2.positions)
        s = settings(course, A)
        t0 = time.perf_counter()
        with snakekit.make_robot("emulator") as robot:
            lab.calibrate(robot, course, s, args.calibration_runs, out=sys.stderr)
        calibration = time.perf_counter() - t0
        q = Queue.load(course, A)
        for st in students:
            q.add(st)
        t0 = time.perf_counter()
        code = lab.session(lambda: snakekit.make_robot("emulator"), course, s, students, q, out=sys.stderr)
        wall = time.perf_counter() - t0
        q = Queue.load(course, A)
        states = [j["state"] for j in q.jobs]
        stalled = sum(json.loads((course / "lab" / A / "results" / st / "info.json").read_text())["stalled_tries"]
                      for st in students if (course / "lab" / A / "results" / st / "info.json").is_file())
        example = json.loads((course / "lab" / A / "results" / students[0] / "report.json").read_text())
    per_job = wall / args.jobs
    run_time = task2.duration + 0.5
    per_hour = 3600 / per_job
    session30 = 30 * 3600 / (calibration + 30 * per_job)
    print(table([[args.jobs, f"{wall:.1f}", f"{per_job:.1f}", f"{run_time:.1f}", f"{per_job - run_time:.1f}",
                  f"{per_hour:.1f}", f"{session30:.1f}", f"{calibration:.1f}"]],
                ["jobs", "session wall [s]", "s/job", "Task 2 run [s]", "overhead/job [s]", "jobs/h",
                 "jobs/h, 30-job session", f"calibration x{args.calibration_runs} [s]"]))
    print(f"target {TARGET:g} jobs/h: {per_hour / TARGET:.2f}x (session), {session30 / TARGET:.2f}x (30 jobs with "
          f"calibration); states: {', '.join(sorted(set(states)))}; runs repeated after a host stall: {stalled}; "
          f"exit {code}")
    print(f"one student's result: {example['points']:g}/{example['max_points']:g}: {example['message']}")
    return code


if __name__ == "__main__":
    sys.exit(main())
