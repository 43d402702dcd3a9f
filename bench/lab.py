"""Jobs per hour of ``snakekit lab`` for lesson 06's Task 2 on the emulated arm, in real time.

Run as ``python bench/lab.py [--jobs 3] [--calibration-runs 2]``. The arm is the bus emulator
behind the real driver (``make_robot("emulator")``, in this process, paced by the wall clock
like the arm); the trajectory is the full Task 2 (500 goals at 10 Hz, 50 sweeps, 0.2 rad: 49.9 s
of goals and 0.5 s of settling). Each job is timed in the lab's own steps
(:mod:`grader.arm.session`): the gate (limits, self-collision, duration, the 50 s simulator run
against the reference's), the arm (home, the run, home again) and the write-up (the grade, the
result folder with its plot, the gradebook). The arm is opened once, as in a session.

Jobs per hour = 3600 / the median job's seconds. A session also calibrates once: the last
column extrapolates to a session of 30 jobs, ``30 x 3600 / (calibration + 30 x s/job)``. A run in
which this computer stalled (a goal more than ``stall_delay`` late) is run again by a session;
here it is counted and printed, and its time is a job's time like any other.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

import snakekit  # noqa: E402
from bench._common import table  # noqa: E402
from grader.arm import gate  # noqa: E402
from grader.arm import session as lab  # noqa: E402
from grader.arm.jobs import load_handin, settings  # noqa: E402

A = "06_coded_sweep"
TARGET = 50.0  # jobs per hour


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--jobs", type=int, default=3, help="how many Task 2 jobs to run (default 3: about 3.5 min)")
    p.add_argument("--calibration-runs", type=int, default=2, help="runs of the reference (default 2)")
    args = p.parse_args(argv)
    rows, stalls, example = [], 0, None
    with tempfile.TemporaryDirectory(prefix="snakekit-bench-lab-") as tmp:
        course = Path(tmp) / "course"
        (course / "source" / A).mkdir(parents=True)
        task2 = snakekit.side_sweep()
        path = course / "handin.npz"
        np.savez(path, times=task2.times, positions=task2.positions)
        s = settings(course, A)
        with snakekit.make_robot("emulator") as robot:
            t0 = time.perf_counter()
            runs = []
            for _ in range(args.calibration_runs):
                run, info = lab.run_on_arm(robot, s.reference_trajectory())
                runs.append(run)
                stalls += info["largest_goal_delay_s"] > s.stall_delay
            ref_t = np.arange(int(round((task2.duration + 0.5) * lab.RECORD_RATE)) + 1) / lab.RECORD_RATE
            stack = np.stack([gate.resampled(lab.on_plan(r, task2), r.measured.positions, ref_t) for r in runs])
            ref_q = stack.mean(axis=0)
            spread = np.abs(stack[:, None] - stack[None, :]).max(axis=(0, 1, 2))
            cal = {"runs": args.calibration_runs, "bands_rad": np.maximum(s.band_factor * spread, s.band_floor).tolist()}
            calibration = time.perf_counter() - t0
            for k in range(args.jobs):
                student = f"student{k:02d}"
                t0 = time.perf_counter()
                checked = gate.check(load_handin(path), s)
                assert not checked.reason, checked.reason
                t1 = time.perf_counter()
                run, info = lab.run_on_arm(robot, checked.trajectory)
                t2 = time.perf_counter()
                stalls += info["largest_goal_delay_s"] > s.stall_delay
                result = lab.grade(run, checked.trajectory, cal, ref_t, ref_q, s)
                lab.write_result(course, s, student, run, checked.trajectory, checked, info, result, (ref_t, ref_q))
                lab.record_grade(course, s, student, result["points"])
                t3 = time.perf_counter()
                rows.append((t1 - t0, t2 - t1, t3 - t2, t3 - t0))
                example = example or result
    med = [statistics.median(r[i] for r in rows) for i in range(4)]
    per_hour = 3600 / med[3]
    session30 = 30 * 3600 / (calibration + 30 * med[3])
    print(table([[args.jobs, f"{med[0]:.2f}", f"{med[1]:.1f}", f"{med[2]:.2f}", f"{med[3]:.1f}", f"{per_hour:.1f}",
                  f"{session30:.1f}", f"{calibration:.1f}"]],
                ["jobs", "gate [s]", "arm: home, run, home [s]", "write-up [s]", "job [s]", "jobs/h",
                 "jobs/h, 30-job session", f"calibration x{args.calibration_runs} [s]"]))
    print(f"medians of {args.jobs} jobs; Task 2's run is {task2.duration + 0.5:.1f} s of it. Target {TARGET:g} jobs/h: "
          f"{per_hour / TARGET:.2f}x (jobs), {session30 / TARGET:.2f}x (a 30-job session with its calibration). "
          f"Runs this computer stalled in (a session would run them again): {stalls} of "
          f"{args.jobs + args.calibration_runs}")
    print(f"one student's result: {example['points']:g}/{example['max_points']:g}: {example['message']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
