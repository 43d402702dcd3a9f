"""``snakekit lab``: the TA's command (docs/lab.md).

    snakekit lab calibrate ASSIGNMENT [--runs 5] [--course DIR] [--port PORT | --emulator]
    snakekit lab ASSIGNMENT [--course DIR] [--port PORT | --emulator] [--order collected|student] [--student S ...]
                            [--retry S ...]
    snakekit lab ASSIGNMENT --status [--csv FILE]

Exit codes: 0 done; 1 a lab fault stopped the session (the job runs again at the next start);
2 bad arguments, a bad value in lab.json, a course not ready, or the course or the arm in use by
another session (nothing moved); 130/143 Ctrl-C / SIGTERM (arm stopped, queue kept).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from pathlib import Path

from snakekit.errors import SnakekitError

from grader.course.folder import default_course
from grader.errors import CourseError
from grader.files import check_output, one_line
from grader.arm import lock
from grader.arm.jobs import STATES, Queue, graded_students, lab_dir, ordered, settings, write_atomic
from grader.errors import LabError


def parser(calibrating: bool) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="snakekit lab" + (" calibrate" if calibrating else ""),
                                description="Graded runs of the students' trajectories on the arm (docs/lab.md).")
    p.add_argument("assignment")
    p.add_argument("--course", type=Path, default=default_course(),
                   help="the nbgrader course folder (default: the current folder when it holds "
                        "nbgrader_config.py, else course/)")
    arm = p.add_mutually_exclusive_group()
    arm.add_argument("--port", help="the arm's serial port or a bridge's socket:// URL (default: $SNAKEKIT_PORT)")
    arm.add_argument("--emulator", action="store_true", help="the bus emulator instead of the arm")
    if calibrating:
        p.add_argument("--runs", type=int, default=5, help="how many runs of the reference (default 5)")
    else:
        p.add_argument("--order", choices=("collected", "student"), default="collected",
                       help="collected: as collected (default); student: by student id")
        p.add_argument("--student", nargs="+", default=None, help="only these students")
        p.add_argument("--retry", nargs="+", default=[], metavar="STUDENT",
                       help="queue these students' jobs again, whatever their state (a job left for the TA after "
                            "repeated lab faults; a refused one graded again)")
        p.add_argument("--status", action="store_true", help="list the jobs and their states; nothing moves")
        p.add_argument("--csv", type=Path, help="with --status: also write the list here")
    return p


def robot_opener(args):
    """A function opening the arm, and its port (None: the session's own emulator). The check that
    the port is there is made before anything runs."""
    import snakekit

    if args.emulator:
        return (lambda: snakekit.make_robot("emulator")), None
    port = args.port or os.environ.get("SNAKEKIT_PORT")
    if not port:
        raise LabError("no arm named: give --port (e.g. /dev/ttyUSB0, or socket://HOST:7800 for a bridge), set "
                       "SNAKEKIT_PORT, or --emulator")
    if "://" not in port and not Path(port).exists():
        raise LabError(f"the port {port} is not there: is the arm's USB adapter plugged in? (ls /dev/ttyUSB* "
                       "/dev/ttyACM*; docs/hardware.md)")
    return (lambda: snakekit.make_robot("hardware", port=port)), port


def status(course: Path, assignment: str, csv_path: Path | None, out) -> int:
    q = Queue.load(course, assignment)
    if not q.jobs:
        print(f"snakekit lab: no jobs for {assignment} yet (start `snakekit lab {assignment}` first)", file=out)
        return 0
    counts = {s: sum(j["state"] == s for j in q.jobs) for s in STATES}
    width = max(len(j["student"]) for j in q.jobs)
    for j in q.jobs:
        pts = f" {j['points']:g}" if "points" in j and j["state"] == "graded" else ""
        print(f"{j['student']:<{width}}  {j['state']:<9}{pts}  {j['reason']}", file=out)
    print(", ".join(f"{n} {s}" for s, n in counts.items() if n), file=out)
    if csv_path is not None:
        write_atomic(csv_path, q.path.with_name("status.csv").read_bytes())
        print(f"written {csv_path}", file=out)
    return 0


def main(argv=None, out=None) -> int:
    out = out or sys.stdout
    argv = sys.argv[1:] if argv is None else list(argv)
    calibrating = argv[:1] == ["calibrate"]
    args = parser(calibrating).parse_args(argv[1:] if calibrating else argv)
    course = args.course
    terminated = []

    def terminate(signum, frame):
        terminated.append(signum)
        raise KeyboardInterrupt

    in_main = signal.getsignal(signal.SIGTERM) is not None and _main_thread()
    previous = signal.signal(signal.SIGTERM, terminate) if in_main else None
    try:
        if not course.is_dir():
            raise LabError(f"no course folder {course} (give --course DIR)")
        if not calibrating and args.csv is not None:
            if not args.status:
                raise LabError(f"--csv {args.csv} writes the list of --status: give --status with it (without "
                               "--status the command starts a session on the arm); nothing was started")
            check_output(args.csv, course, suffix=".csv", what="--csv", command="snakekit lab")
        s = settings(course, args.assignment)
        if not calibrating and args.status:
            return status(course, args.assignment, args.csv, out)
        opener, port = robot_opener(args)
        with lock.held(course, args.assignment, port):
            return _locked(args, course, s, opener, calibrating, out)
    except (LabError, CourseError) as e:
        print(f"snakekit lab: {one_line(e)}", file=sys.stderr)
        return 2
    except SnakekitError as e:
        again = "Run the same snakekit lab command again: it turns torque on and goes on."
        print(f"snakekit lab: {str(e).replace('Call robot.torque_on() to clear it and go on.', again)}",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        why = "terminated (SIGTERM)" if terminated else "interrupted"
        kept = "nothing of the calibration was kept" if calibrating else "the queue kept"
        print(f"snakekit lab: {why}; the arm was stopped (torque off) and {kept}: start again to go on",
              file=sys.stderr)
        return 143 if terminated else 130
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, previous)


def _locked(args, course: Path, s, opener, calibrating: bool, out) -> int:
    """The session proper, run while it holds the course's and the arm's locks."""
    from grader.arm import session

    if calibrating:
        if args.runs < 2:
            raise LabError(f"--runs {args.runs}: the spread needs at least 2 runs of the reference (5 is usual)")
        robot = opener()
        try:
            session.calibrate(robot, course, s, args.runs, out)
        finally:
            robot.close()
        return 0
    students = graded_students(course, args.assignment)
    if not students:
        raise LabError(f"no graded submissions of {args.assignment} in {course}/autograded: run "
                       f"`snakekit grade {args.assignment}` first")
    if args.student:
        unknown = sorted(set(args.student) - set(students))
        if unknown:
            raise LabError(f"no graded submission of {args.assignment} for {', '.join(unknown)} (graded: "
                           f"{', '.join(students)})")
        students = [st for st in args.student]
    students = ordered(course, args.assignment, students, args.order)
    session.load_calibration(course, s)
    q = Queue.load(course, args.assignment)
    for st in students:
        q.add(st)
    for st in args.retry:
        q.retry(st)
    q.save()
    code = session.session(opener, course, s, students, q, out)
    status(course, args.assignment, None, out)
    print(f"snakekit lab: results in {lab_dir(course, args.assignment)}/results, the list in "
          f"{q.path.with_name('status.csv')}", file=out)
    return code


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


if __name__ == "__main__":
    sys.exit(main())
