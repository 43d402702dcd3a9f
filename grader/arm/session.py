"""A lab session: calibration, then each queued job through the gate, onto the arm, graded.

The arm is any :class:`snakekit.robot.Robot` of the hardware driver (the real arm, or the bus
emulator behind the same driver). Per job: home, run, home again; the run is recorded
(commanded and measured angles with their times), with the servos' error status, the bus's
retries, the serial port and the kit's version. A fault of the lab (a :class:`BackendError`:
bus, watchdog, a servo that drops out, a lost port) ends the session with the arm stopped by
the driver and the robot closed (torque off); the job is marked ``lab fault`` and runs again at
the next start. It is never the student's grade. At the end of a session the robot is closed:
torque off.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

import snakekit
from snakekit import validate
from snakekit.errors import BackendError, FileFormatError, SnakekitError
from snakekit.model import SPEC
from grader.errors import Stalled

from grader.arm import gate
from grader.arm.feedback import update_pages
from grader.arm.jobs import LabSettings, Queue, handin_path, lab_dir, load_handin, write_atomic
from grader.errors import LabError

RECORD_RATE = 100.0  # [Hz]
#: The widest band a calibration may set [rad]: wider, any sweep would pass (the arm is not repeatable).
MAX_BAND = 1.0
#: How many times a run the lab computer stalled in is run again before it counts as a lab fault.
STALL_TRIES = 5


def _info(robot) -> dict:
    return {"port": getattr(robot, "port_name", None), "backend": robot.backend, "kit_version": snakekit.__version__}


def _servo_errors(robot) -> dict:
    out = {}
    for i in getattr(robot, "ids", ()):
        try:
            errs = robot.hardware_error_status(i)
        except BackendError as e:
            errs = [f"unreadable: {e}"]
        if errs:
            out[str(i)] = errs
    return out


def on_plan(run, trajectory) -> np.ndarray:
    """The run's measured times [s] from the sweep's start, on the sweep's own clock: when the host
    stalled and the driver sent the rest of the goals later (:attr:`snakekit.robot.Robot.late_goal`),
    the delay of the goals about each sample is taken out, so a busy lab computer is not the student's gap."""
    planned = trajectory.times - trajectory.times[0]
    sent = run.commanded.times - trajectory.times[0]
    t = run.measured.times - trajectory.times[0]
    return t - np.interp(t, sent, sent - planned)


def run_on_arm(robot, trajectory, say=lambda what: None):
    """Home, run ``trajectory``, home again; the run and what the bus saw."""
    retried0, shifts0 = getattr(robot, "retried", 0), robot.late_shifts
    say("homing")
    robot.home(progress=False)
    if np.abs(trajectory.positions[0] - robot.read().positions).max() > robot.start_tolerance:
        say("moving to the sweep's start")
        robot.move_to(trajectory.positions[0], progress=False)
    say(f"running the sweep ({trajectory.duration:.0f} s)")
    run = robot.run(trajectory, record_rate=RECORD_RATE, progress=False)
    say("homing again")
    robot.home(progress=False)
    # how much later than planned each goal left after the one before (the shifts add up over a run:
    # harmless on the sweep's own clock; a single long wait is not)
    waits = np.diff(run.commanded.times) - np.diff(trajectory.times)
    return run, {"servo_errors": _servo_errors(robot), "bus_retries": getattr(robot, "retried", 0) - retried0,
                 "late_shifts": robot.late_shifts - shifts0, "largest_goal_delay_s": float(max(waits.max(initial=0.0), 0.0)),
                 **_info(robot)}


def run_unstalled(robot, trajectory, stall_delay: float, say=lambda what: None):
    """:func:`run_on_arm`, again when the host stalled in the run (late goals change the motion on
    the arm: such a run is neither the reference's nor the student's). Raises :class:`Stalled`."""
    for k in range(STALL_TRIES):
        run, info = run_on_arm(robot, trajectory, say)
        if info["largest_goal_delay_s"] <= stall_delay:
            info["stalled_tries"] = k
            return run, info
        say(f"the computer stalled during the run (a goal {info['largest_goal_delay_s']:.2f} s late): running it again")
    raise Stalled(f"the lab computer stalled in each of {STALL_TRIES} tries of the run (goals sent late); close "
                  "other programs on it")


def calibrate(robot, course: Path, s: LabSettings, runs: int, out=sys.stdout) -> dict:
    """Run the spec's trajectory ``runs`` times; its mean is the reference run, the spread sets the bands."""
    if runs < 2:
        raise LabError(f"--runs {runs}: the spread needs at least 2 runs of the reference (5 is usual)")
    ref = s.reference_trajectory()
    recorded = []
    for k in range(runs):
        print(f"lab calibrate: reference run {k + 1} of {runs} ({ref.duration:.0f} s)", file=out, flush=True)
        run, info = run_unstalled(robot, ref, s.stall_delay,
                                  lambda what: print(f"lab calibrate: {what}", file=out, flush=True))
        recorded.append(run)
    times = np.arange(int(round((ref.duration + 0.5) * RECORD_RATE)) + 1) / RECORD_RATE
    stack = np.stack([gate.resampled(on_plan(r, ref), r.measured.positions, times) for r in recorded])
    mean = stack.mean(axis=0)
    # the arm's repeatability: the most two runs of the same trajectory differ, per joint
    spread = np.abs(stack[:, None] - stack[None, :]).max(axis=(0, 1, 2))
    bands = np.maximum(s.band_factor * spread, s.band_floor)
    if bands.max() > MAX_BAND:
        j = int(np.argmax(bands))
        raise LabError(f"the {runs} runs of the reference differ by up to {np.degrees(spread[j]):.1f} deg at joint "
                       f"{j + 1}: bands of {bands[j]:.2f} rad (more than {MAX_BAND:g}) would pass any sweep; check the "
                       "arm (a loose horn, a slipping servo, the power supply) and calibrate again; nothing was kept")
    d = lab_dir(course, s.assignment)
    d.mkdir(parents=True, exist_ok=True)
    np.savez(d / "reference.npz", times=times, positions=mean, runs=stack)
    cal = {"runs": runs, "spread_rad": spread.tolist(), "bands_rad": bands.tolist(), "band_factor": s.band_factor,
           "band_floor_rad": s.band_floor, "case": s.case, "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           **info}
    write_atomic(d / "calibration.json", json.dumps(cal, indent=1))
    print("lab calibrate: bands " + " ".join(f"j{j + 1} {np.degrees(b):.2f}" for j, b in enumerate(bands))
          + f" deg (the most two of {runs} runs differ, x {s.band_factor:g}, "
          f"at least {np.degrees(s.band_floor):.2f} deg)",
          file=out, flush=True)
    return cal


def load_calibration(course: Path, s: LabSettings):
    d = lab_dir(course, s.assignment)
    if not (d / "calibration.json").is_file() or not (d / "reference.npz").is_file():
        raise LabError(f"the arm is not calibrated for {s.assignment}: run `snakekit lab calibrate {s.assignment}` "
                       "first (it runs the reference several times to set the bands)")
    again = f"run `snakekit lab calibrate {s.assignment}` again"
    try:
        cal = json.loads((d / "calibration.json").read_text(encoding="utf-8"))
        if not isinstance(cal, dict):
            raise ValueError("not a JSON object")
        bands = cal.get("bands_rad")
        if not isinstance(bands, list) or len(bands) != SPEC.n_joints:
            raise ValueError(f"bands_rad is not one band per joint: {str(bands)[:80]}")
        for j, b in enumerate(bands):
            validate.number(b, f"bands_rad[{j}]", "rad", above=0.0, at_most=MAX_BAND)
        validate.check_count(cal.get("runs"), "runs", 2, 1000)
    except (OSError, ValueError, SnakekitError) as e:
        raise LabError(f"{d}/calibration.json is not a calibration the lab can use ({str(e)[:200]}): {again}") from e
    if cal.get("case") != s.case:
        raise LabError(f"{d}/calibration.json was recorded for {cal.get('case')}, not the lab's {s.case}: "
                       f"run `snakekit lab calibrate {s.assignment}` again")
    try:
        ref = load_handin(d / "reference.npz")
        t, q = np.asarray(ref["times"], dtype=float), np.asarray(ref["positions"], dtype=float)
        if t.ndim != 1 or len(t) < 2 or q.shape != (len(t), SPEC.n_joints) or not (
                np.isfinite(t).all() and np.isfinite(q).all() and (np.diff(t) > 0).all()):
            raise ValueError(f"times {t.shape} and positions {q.shape} are not a run of the arm")
    except (KeyError, ValueError) as e:
        raise LabError(f"{d}/reference.npz is not a reference run ({str(e)[:200]}): {again}") from e
    return cal, t, q


def grade(run, trajectory, cal: dict, ref_t, ref_q, s: LabSettings) -> dict:
    """The recorded run against the reference run, joint by joint, within the calibration's bands."""
    per_joint, j, at = gate.gap(on_plan(run, trajectory), run.measured.positions, ref_t, ref_q)
    bands = np.array(cal["bands_rad"])
    inside = bool((per_joint <= bands).all())
    worst = int(np.argmax(per_joint / bands))
    words = (f"Your sweep on the arm stayed within the lab's bands around the reference run: the largest gap was "
             f"{np.degrees(per_joint[worst]):.2f} deg at joint {worst + 1} (band {np.degrees(bands[worst]):.2f} deg, "
             f"from {cal['runs']} runs of the reference)." if inside else
             f"Your sweep on the arm left the lab's bands around the reference run: joint {worst + 1} was "
             f"{np.degrees(per_joint[worst]):.2f} deg away (band {np.degrees(bands[worst]):.2f} deg, from "
             f"{cal['runs']} runs of the reference); the largest gap of all at t = {at:.2f} s.")
    return {"points": s.max_points if inside else 0.0, "max_points": s.max_points, "within_bands": inside,
            "gap_rad": per_joint.tolist(), "bands_rad": bands.tolist(), "worst_time_s": at, "message": words}


def plot(path: Path, run, trajectory, checked, ref_t, ref_q) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = ref_q.shape[1]
    fig, axes = plt.subplots(n, 1, figsize=(9, 1.6 * n), sharex=True)
    t = on_plan(run, trajectory)
    for j, ax in enumerate(axes):
        ax.plot(ref_t, np.degrees(ref_q[:, j]), "k-", lw=1, label="reference run (arm)")
        ax.plot(checked.sim_times, np.degrees(checked.sim_positions[:, j]), "C1--", lw=1,
                label="your sweep (simulator)")
        ax.plot(t, np.degrees(run.measured.positions[:, j]), "C0-", lw=1, label="your sweep (arm)")
        ax.set_ylabel(f"j{j + 1} [deg]")
    axes[0].legend(loc="upper right", fontsize=7, ncol=3)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


def write_result(course: Path, s: LabSettings, student: str, run, trajectory, checked, info, result, ref) -> Path:
    """The job's folder: run.npz (with run.mcap and run.bag, the same run as ROS bags), info.json,
    plot.png, then report.json (last: the folder is complete)."""
    d = lab_dir(course, s.assignment) / "results" / student
    d.mkdir(parents=True, exist_ok=True)
    (d / "report.json").unlink(missing_ok=True)
    np.savez(d / "run.npz", commanded_times=run.commanded.times, commanded_positions=run.commanded.positions,
             measured_times=run.measured.times, measured_positions=run.measured.positions,
             measured_velocities=run.measured.velocities, efforts=run.efforts,
             sim_times=checked.sim_times, sim_positions=checked.sim_positions)
    for bag in ("run.mcap", "run.bag"):  # the run as ROS 2 and ROS 1 bags, for RViz, Foxglove, rosbag
        run.save(d / bag)
    write_atomic(d / "info.json", json.dumps(info, indent=1))
    plot(d / "plot.png", run, trajectory, checked, *ref)
    report = {"student": student, "assignment": s.assignment, "state": "graded", **result}
    write_atomic(d / "report.json", json.dumps(report, indent=1))
    return d


def lab_assignment(s: LabSettings) -> str:
    """The lab grade's own assignment in the gradebook (the course decides whether it counts)."""
    return f"{s.assignment}-lab"


def record_grade(course: Path, s: LabSettings, student: str, points: float) -> None:
    """The lab grade into nbgrader's gradebook as its own assignment ``<a>-lab``: one notebook
    ``lab``, one grade cell ``lab_run`` of ``max_points``, scored like an autograded cell."""
    from nbgrader.api import MissingEntry

    from grader.course.folder import gradebook

    name = lab_assignment(s)
    bin_dir = str(Path(os.path.abspath(sys.executable)).parent)  # a new gradebook runs nbgrader's `alembic`
    if bin_dir not in os.environ.get("PATH", "").split(os.pathsep):
        os.environ["PATH"] = f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}"
    with gradebook(course) as gb:
        a = gb.update_or_create_assignment(name)
        if not a.notebooks:
            gb.add_notebook("lab", name)
            gb.add_grade_cell("lab_run", "lab", name, max_score=s.max_points, cell_type="code")
        gb.update_or_create_student(student)
        try:
            gb.find_submission(name, student)
        except MissingEntry:
            gb.add_submission(name, student)
        grade = gb.find_grade("lab_run", "lab", name, student)
        grade.auto_score = float(points)
        gb.db.commit()


class Pace:
    """``lab: job 3 of 10 (bob): running the sweep (52 s); about 7 min left at this pace`` on stderr."""

    def __init__(self, total: int, estimate: float, stream=None):
        self.total, self.estimate, self.done, self.t0 = total, estimate, 0, time.monotonic()
        self.jobs = total  # as numbered; ``total`` drops the refused ones (they take no arm time)
        self.stream = stream if stream is not None else sys.stderr
        self.n, self.student = 0, ""

    def left(self) -> float:
        per = (time.monotonic() - self.t0) / self.done if self.done else self.estimate
        return per * (self.total - self.done)

    def say(self, what: str) -> None:
        m = self.left() / 60
        print(f"lab: job {self.n} of {self.jobs} ({self.student}): {what}; about {m:.0f} min left at this pace",
              file=self.stream, flush=True)


def session(open_robot, course: Path, s: LabSettings, students: list[str], queue: Queue, out=sys.stdout,
            stream=None) -> int:
    """Run the queue's runnable jobs of ``students`` in order. Returns the exit code (0: all ran;
    1: a lab fault stopped the session)."""
    cal, ref_t, ref_q = load_calibration(course, s)
    todo = [queue.job(st) for st in students if queue.runnable(queue.job(st))]
    pace = Pace(len(todo), 2 * s.reference_trajectory().duration + 15, stream)
    robot = None
    try:
        passed = []  # every job through the gate first: nothing heavy runs while the arm is open and idle
        for n, job in enumerate(todo, 1):
            pace.n, pace.student = n, job["student"]
            pace.say("checking the sweep in the simulator")
            path = handin_path(course, job["student"], s)
            if not path.is_file():
                checked = gate.Checked("no sweep at the task's values was kept when this submission was graded: "
                                       f"grade it again (snakekit grade {s.assignment} --student {job['student']})")
            else:
                try:
                    checked = gate.check(load_handin(path), s)
                except FileFormatError as e:
                    checked = gate.Checked(f"{e}: grade it again (snakekit grade {s.assignment} --student "
                                           f"{job['student']}) to keep your sweep anew")
                except SnakekitError as e:  # this hand-in only: the session goes on with the others
                    checked = gate.Checked(f"your sweep could not be checked: {str(e).splitlines()[0][:300]}")
            if checked.reason:
                queue.set(job, "refused", checked.reason)
                update_pages(course, s.assignment, job["student"])
                print(f"lab: {job['student']}: refused: {checked.reason}", file=out, flush=True)
                pace.total -= 1
            else:
                passed.append((n, job, checked))
        pace.t0 = time.monotonic()
        ran = []  # run on the arm; written up once the arm is closed (a plot drawn while the arm idles
        code = 0  # would keep the bus quiet long enough, on a busy computer, for the servos' watchdog)
        stopped = faulted = None
        try:
            for n, job, checked in passed:
                pace.n, pace.student = n, job["student"]
                queue.set(job, "running", "", attempts=job["attempts"] + 1)
                if robot is None:
                    pace.say("connecting to the arm")
                    robot = open_robot()
                try:
                    run, info = run_unstalled(robot, checked.trajectory, s.stall_delay, pace.say)
                except BackendError as e:
                    faulted = fault(queue, job, s, e)
                    print(f"lab: {job['student']}: lab fault: {e}\nlab: the arm was stopped and the session ended; "
                          f"check the arm and its cable, then start `snakekit lab {s.assignment}` again", file=out,
                          flush=True)
                    if job.get("held"):
                        print(f"lab: {job['student']}'s job faulted {job['faults']} times in a row: it is left for you "
                              f"(`snakekit lab {s.assignment} --retry {job['student']}` runs it again)", file=out,
                              flush=True)
                    code = 1
                    break
                ran.append((job, checked, run, info))
                pace.done += 1
        except KeyboardInterrupt as e:  # Ctrl-C / SIGTERM: the runs already made are still written up
            stopped = e
        close(robot, out)
        robot = None
        if faulted is not None:
            update_pages(course, s.assignment, faulted["student"])
        for job, checked, run, info in ran:
            result = grade(run, checked.trajectory, cal, ref_t, ref_q, s)
            info.update(student=job["student"], sim_gap_rad=checked.sim_gap, calibration=cal)
            write_result(course, s, job["student"], run, checked.trajectory, checked, info, result, (ref_t, ref_q))
            record_grade(course, s, job["student"], result["points"])
            queue.set(job, "graded", result["message"], points=result["points"], faults=0)
            update_pages(course, s.assignment, job["student"])
            print(f"lab: {job['student']}: {result['points']:g}/{result['max_points']:g}: {result['message']}",
                  file=out, flush=True)
        if stopped is not None:
            raise stopped
        return code
    except BaseException:
        for job in todo:
            if job["state"] == "running":
                queue.set(job, "queued", "interrupted by the TA; runs again at the next start")
        raise
    finally:
        close(robot, out)


def fault(queue: Queue, job: dict, s: LabSettings, error: BackendError) -> dict:
    """Mark ``job`` a fault of the lab; after ``s.max_faults`` of them in a row it is left for the TA."""
    first = str(error).split(". ")[0]
    faults = job.get("faults", 0) + 1
    if faults < s.max_faults:
        queue.set(job, "lab fault", f"the lab's fault, not yours: {first}; it runs again at the next start",
                  faults=faults)
    else:
        queue.set(job, "lab fault", f"left for the TA: the lab's fault, not yours, in each of {faults} tries "
                  f"(the last: {first}); it runs again once the TA has checked the arm", faults=faults, held=True)
    return job


def close(robot, out) -> None:
    """Torque off (the driver's ``on_close``), at the end of the arm's part of a session."""
    if robot is not None:
        try:
            robot.close()
        except BackendError as e:  # the port is gone: the driver said what the arm was left doing
            print(f"lab: closing the arm: {e}", file=out, flush=True)
