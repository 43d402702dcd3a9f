"""The ``snakekit`` command.

    snakekit sweep [--backend sim] [--realtime] [--out run.npz|run.mcap|run.bag] [--plot sweep.png]
    snakekit ros [--backend sim] [--rate 50]   (the arm as a ROS 1 node: /joint_states, goals on /arm/command)
    snakekit emulator [...]          (an emulated MX-28 bus on a pseudo-terminal or a TCP port)
    snakekit bridge PORT [--listen HOST:PORT]   (serve the arm's serial port over TCP)
    snakekit generate [--check]      (the URDF and MJCF from the robot spec)
    snakekit check LESSON.ipynb      (run a lesson's exercise checks: one row per exercise)
    snakekit progress [FOLDER]       (your exercises passed and points across the lessons, and what is next)
    snakekit start [...]             (check this system, then JupyterLab on the lessons: `make lab`)
    snakekit release ASSIGNMENT [--due TIME] [--late-penalty RULE]  (nbgrader's release, due date, penalty)
    snakekit release ASSIGNMENT --solutions  (after the due date: the worked solution, for the students)
    snakekit collect ASSIGNMENT --from DOWNLOAD  (an LMS's download into the course; grader/README.md)
    snakekit grade ASSIGNMENT [...]  (grade a class's submissions; see grader/README.md)
    snakekit return ASSIGNMENT       (the feedback pages back: hub exchange or an LMS zip)
    snakekit export [--lms canvas|moodle]  (one row per student, for the LMS's grade import)

Exit codes: 0 success, 1 the robot or a file failed (or a limit was not held), 2 bad
arguments, 130 interrupted by Ctrl-C, 143 stopped by SIGTERM (both close the robot first).
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import gc
import os
import signal
import sys
import threading
import time
from pathlib import Path

from .errors import SnakekitError
from .robot import BACKENDS

PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def _writable(path: Path, suffixes: tuple[str, ...], what: str) -> str | None:
    """Why ``path`` can't be written as ``what``, or None if it can."""
    from .validate import writable_file

    if path.suffix.lower() not in suffixes:
        return f"{what} {path} must end in {' or '.join(suffixes)}"
    try:
        writable_file(path, what)  # really opened for writing: permission bits don't tell all
    except SnakekitError as e:
        return str(e)
    return None


def _save_run(run, path: Path, out) -> bool:
    """Save ``run`` to ``path``; if that fails now (full disk, the folder went away...), save
    it in the working folder or the temporary folder instead, and say where. True if saved
    where asked."""
    import tempfile

    try:
        run.save(path)
        print(f"saved run:          {path}", file=out)
        return True
    except SnakekitError as e:
        print(f"snakekit sweep: {e}", file=sys.stderr)
    name = f"snakekit-run-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}{path.suffix}"
    for folder in (Path.cwd(), Path(tempfile.gettempdir())):
        try:
            run.save(folder / name)
        except SnakekitError:
            continue
        print(f"snakekit sweep: the run was saved to {folder / name} instead; move it where you want it",
              file=sys.stderr)
        return False
    print("snakekit sweep: the run could not be saved anywhere; nothing else was written", file=sys.stderr)
    return False


def _save_interrupted(run, goals: int, path: Path, out) -> None:
    """Save the part of an interrupted sweep that ran (``run``, or None if nothing did) to
    ``path``, and say so; a second Ctrl-C while it is written is ignored."""
    if run is None:
        print(f"snakekit sweep: nothing had run yet, so nothing was saved to {path}", file=sys.stderr)
        return
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if in_main else None
    try:
        if _save_run(run, path, out):
            print(f"snakekit sweep: the partial run ({len(run.commanded)} of {goals} goals, "
                  f"{run.robot_time:.1f} s recorded) was saved to {path}", file=sys.stderr)
    finally:
        if in_main:
            signal.signal(signal.SIGINT, previous)


def _backend_options(args) -> dict | None:
    """The options of ``args.backend`` from the command line: the hardware's port (or
    $SNAKEKIT_PORT); None, said in one line, when it needs one that was not given."""
    if args.backend != "hardware":
        return {}
    port = args.port or os.environ.get("SNAKEKIT_PORT")
    if not port:
        print(f"snakekit {args.command}: --backend hardware needs --port (e.g. --port /dev/ttyUSB0, or "
              "socket://HOST:7800 through snakekit bridge) or SNAKEKIT_PORT set", file=sys.stderr)
        return None
    return {"port": port}


def _sweep(args, out) -> int:
    from .collision import check_path
    from .profile_planner import ReferencePath
    from .robot import make_robot
    from .trajectory import side_sweep

    problems = []
    if args.out:
        problems.append(_writable(Path(args.out), (".npz", ".mcap", ".bag"), "run file"))
    if args.plot:
        problems.append(_writable(Path(args.plot), PLOT_SUFFIXES, "plot"))
    problems = [p for p in problems if p]
    if problems:
        for p in problems:
            print(f"snakekit sweep: {p}", file=sys.stderr)
        return 2
    options = _backend_options(args)
    if options is None:
        return 2
    if args.backend == "sim":
        options["realtime"] = args.realtime
    trajectory = side_sweep()
    check_path(trajectory.times, trajectory.positions,  # before a robot is made (every run checks again)
               path=ReferencePath.from_rest(trajectory.times, trajectory.positions))
    print(f"Task 2: {len(trajectory)} goals at 10 Hz, 50 side-to-side sweeps, on the {args.backend} backend"
          + (" in real time" if args.realtime or args.backend != "sim" else ""), file=out, flush=True)
    wall0 = time.perf_counter()
    robot = None
    try:
        with make_robot(args.backend, **options) as robot:
            run = robot.run(trajectory)
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM: the robot is closed; what ran is kept, then main says so
        if args.out:
            _save_interrupted(robot and robot.interrupted_run, len(trajectory), Path(args.out), out)
        raise
    saved = _save_run(run, Path(args.out), out) if args.out else True  # first: a finished run is kept
    print(run.summary(), file=out)
    if args.plot:
        from .plots import plot_run

        try:
            plot_run(run).savefig(args.plot, dpi=110)
            print(f"saved plot:         {args.plot}", file=out)
        except OSError as e:
            print(f"snakekit sweep: cannot write plot {args.plot}: {e.strerror or e}", file=sys.stderr)
            saved = False
    print(f"total wall time:    {time.perf_counter() - wall0:.2f} s", file=out)
    return 0 if run.limits_held() and saved else 1


def _ros(args, out) -> int:
    from .ros import serve

    options = _backend_options(args)
    if options is None:
        return 2
    serve(args.backend, rate=args.rate, topic=args.topic, out=out, **options)
    return 0


def _generate(args, out) -> int:
    from . import model

    return model.main(["--check"] if args.check else [])


def _check(args, out) -> int:
    from .errors import FileFormatError
    from .notebook_check import check_notebook

    from .validate import excerpt

    path = Path(args.notebook)
    try:
        is_file = path.is_file()
    except OSError as e:  # a name longer than the system allows...
        print(f"snakekit check: {excerpt(path)} can't be opened: {e.strerror or e}", file=sys.stderr)
        return 2
    if path.suffix != ".ipynb" or not is_file:
        print(f"snakekit check: {excerpt(path)} is not a notebook file (give a lesson, e.g. "
              "notebooks/03_inverse_kinematics.ipynb)", file=sys.stderr)
        return 2
    try:
        return check_notebook(path, out=out, timeout=args.timeout)
    except FileFormatError as e:
        print(f"snakekit check: {e}", file=sys.stderr)
        return 2


def _progress(args, out) -> int:
    from .lesson_progress import progress_report

    return progress_report(args.folder, out=out)


def _positive(option: str, unit: str, at_most: float, hint: str, units: str):
    """An option's type: a number above 0 and at most ``at_most`` [``unit``]; anything else is
    a usage error that says so (``units``: the unit's name in words)."""

    def parse(text: str) -> float:
        from .validate import number, quote

        try:
            return number(float(text), option, unit, above=0, at_most=at_most, hint=hint)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e) if option in str(e) else f"not a number of {units}: {quote(text)}")

    return parse


# --timeout: seconds > 0, at most a day (nbclient takes 0 as "no limit")
_seconds = _positive("--timeout", "s", 86400, "It is how long one cell may run (default: 300)", "seconds")
_rate = _positive("--rate", "Hz", 1000, "It is how often /joint_states is published (default: 50)", "Hz")


def _typos(a: str, b: str) -> int:
    """How many typos turn ``a`` into ``b``: letters left out, added, changed, or two side by side swapped (the
    optimal string alignment distance)."""
    d = [[i + j if i * j == 0 else 0 for j in range(len(b) + 1)] for i in range(len(a) + 1)]
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] != b[j - 1]))
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
    return d[len(a)][len(b)]


class OneLineParser(argparse.ArgumentParser):
    """argparse, saying a usage error in one line: what was wrong (a short excerpt of a long
    argument) and where the help is; exit 2."""

    def error(self, message: str):
        import re

        from .validate import excerpt

        # a mistyped command or choice: the typed word cut short, the nearest choice, and all of them (our own words)
        m = re.fullmatch(r"(?s)(argument [^:]+: )?invalid choice: (.*) \(choose from (.*)\)", message)
        if m:
            typed = m.group(2).strip("'")
            choices = [c.strip().strip("'") for c in m.group(3).split(",")]
            close = {c: n for c in choices if (n := _typos(typed, c)) <= max(1, len(c) // 3)}
            near = [c for c, n in close.items() if n == min(close.values())]  # ties: each
            hint = f"; did you mean {' or '.join(near)}?" if near else ""
            self.exit(2, f"{self.prog}: {m.group(1) or ''}invalid choice: '{excerpt(typed, 60)}'"
                         f"{hint} (the choices: {', '.join(choices)}); "
                         f"see {self.prog} --help\n")
        self.exit(2, f"{self.prog}: {excerpt(message, 160)}; see {self.prog} --help\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="snakekit", description="snakekit: the 5-joint MX-28 snake arm kit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    p = sub.add_parser("sweep", help="run the coded sweep (Task 2) and report how it tracked")
    p.add_argument("--backend", default="sim", choices=list(BACKENDS), help="robot backend (default: sim)")
    p.add_argument("--realtime", action="store_true", help="pace the simulator to the wall clock")
    p.add_argument("--port", help="serial port of the arm, or socket://HOST:PORT of a snakekit bridge "
                                  "(hardware backend; default: $SNAKEKIT_PORT)")
    p.add_argument("--out", metavar="RUN.npz", help="save the recorded run: .npz (numpy), .mcap (a ROS 2 bag) "
                   "or .bag (a ROS 1 bag)")
    p.add_argument("--plot", metavar="PLOT.png", help="plot commanded vs measured angles per joint")
    p.set_defaults(func=_sweep)
    p = sub.add_parser("ros", help="the arm as a ROS 1 node: /joint_states, /robot_description, "
                       "trajectory_msgs/JointTrajectory goals through the kit's checks (docs/ros.md)")
    p.add_argument("--backend", default="sim", choices=list(BACKENDS), help="robot backend (default: sim, in real time)")
    p.add_argument("--port", help="serial port of the arm, or socket://HOST:PORT of a snakekit bridge "
                                  "(hardware backend; default: $SNAKEKIT_PORT)")
    p.add_argument("--rate", type=_rate, default=50.0, help="how often /joint_states is published [Hz] (default: 50)")
    p.add_argument("--topic", default="/arm/command", help="the goals' topic (default: /arm/command)")
    p.set_defaults(func=_ros)
    sub.add_parser("emulator", help="emulate the arm's MX-28 bus on a pseudo-terminal "
                                    "(snakekit emulator --help for its options)", add_help=False)
    sub.add_parser("bridge", help="serve the arm's USB serial port over TCP, for a container or another "
                                  "computer (snakekit bridge --help for its options)", add_help=False)
    sub.add_parser("start", help="check this system, then open the lessons in JupyterLab (what `make lab` runs; "
                                 "snakekit start --help for its options)", add_help=False)
    sub.add_parser("release", help="release an assignment with its due date and late penalty "
                                   "(snakekit release --help)", add_help=False)
    sub.add_parser("collect", help="put an LMS's download (Canvas, Moodle, a folder) into the course "
                                   "(snakekit collect --help)", add_help=False)
    sub.add_parser("grade", help="grade a class's submissions of an assignment "
                                 "(snakekit grade --help for its options)", add_help=False)
    sub.add_parser("return", help="return the feedback pages: to the hub's exchange or as an LMS zip "
                                  "(snakekit return --help)", add_help=False)
    sub.add_parser("export", help="grades for Canvas's or Moodle's import (snakekit export --help)", add_help=False)
    sub.add_parser("report", help="the teacher's view of a graded class: where it stands, why it fails, which "
                                  "submissions are too alike (snakekit report --help)", add_help=False)
    p = sub.add_parser("generate", help="write the URDF and MJCF from the robot spec")
    p.add_argument("--check", action="store_true", help="only check that the committed files are current")
    p.set_defaults(func=_generate)
    p = sub.add_parser("progress", help="your exercises passed and points across the lessons (from the saved "
                       "notebooks), and what is next")
    p.add_argument("folder", nargs="?", type=Path, default=None,
                   help="the folder of the lesson notebooks (default: this one if it holds them, else notebooks/)")
    p.set_defaults(func=_progress)
    p = sub.add_parser("check", help="run a lesson's exercise checks: one row per exercise, exit 1 on a failure")
    p.add_argument("notebook", help="the lesson notebook, e.g. notebooks/03_inverse_kinematics.ipynb")
    p.add_argument("--timeout", type=_seconds, default=300.0, help="seconds a cell may run before it is interrupted and fails; the next cells still run (default: 300)")
    p.set_defaults(func=_check)
    return parser


#: Commands another installed package provides (the grader's), by the entry point group they are in.
PLUGIN_GROUP = "snakekit.commands"
PLUGIN_COMMANDS = ("grade", "release", "collect", "return", "export", "lab", "report")


def plugin_command(name: str):
    """The function behind ``snakekit <name>`` from the entry points of :data:`PLUGIN_GROUP`
    (``(argv, out) -> exit code``); the kit itself never imports the package that provides it."""
    from importlib.metadata import entry_points

    found = [ep for ep in entry_points(group=PLUGIN_GROUP) if ep.name == name]
    if not found:
        raise SystemExit(f"snakekit {name}: no installed package provides this command (entry point group "
                         f"'{PLUGIN_GROUP}'); install the kit with its grader: pip install -e . (or make setup)")
    return found[0].load()


def main(argv: list[str] | None = None, out=None) -> int:
    # A command's process ends with numpy, Pinocchio, MuJoCo and (the TA's commands) nbgrader loaded: the
    # collector's last sweep over them costs up to 1 s of CPU at exit and frees nothing the system does not
    # take back. Frozen at exit (gc.freeze), they are left to the system; every exit handler still runs
    # (a temporary folder's cleanup, for one).
    atexit.unregister(gc.freeze)
    atexit.register(gc.freeze)
    out = out or sys.stdout
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["emulator"]:  # the emulator parses its own options (argparse can't pass them on)
        from . import emulator

        return emulator.cli(argv[1:])
    if argv[:1] == ["bridge"]:  # standard library and pyserial only: it also runs as one file
        from .bridge import main as bridge

        return bridge(argv[1:])
    if argv[:1] and argv[0] in PLUGIN_COMMANDS:  # the grader's commands: its own package, its own options
        return _terminated_as_interrupted(argv[0], lambda: plugin_command(argv[0])(argv[1:], out))
    if argv[:1] == ["start"]:  # JupyterLab takes over the process: no signal handlers of ours
        from .start import main as start

        return start(argv[1:], out)
    args = build_parser().parse_args(argv)
    with _sigterm_as_ctrl_c() as terminated:   # the robot is closed on the way out, as for Ctrl-C
        try:
            return args.func(args, out)
        except SnakekitError as e:
            print(f"snakekit {args.command}: {e}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            why = "terminated (SIGTERM)" if terminated else "interrupted"
            print(f"snakekit {args.command}: {why}; the robot was closed", file=sys.stderr)
            return 143 if terminated else 130



@contextlib.contextmanager
def _sigterm_as_ctrl_c():
    """SIGTERM raised as KeyboardInterrupt while inside (in the main thread, where signals can be caught), so a
    command cleans up as on Ctrl-C; yields the list that holds the signal once one came."""
    terminated = []

    def terminate(signum, frame):
        terminated.append(signum)
        raise KeyboardInterrupt

    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, terminate) if in_main else None
    try:
        yield terminated
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, previous)


def _terminated_as_interrupted(name: str, command) -> int:
    """``command()`` (a grader's command) with SIGTERM taken as Ctrl-C: the command stops as it does for Ctrl-C
    (`grade` kills its sandboxes, keeps the students graded before and removes its folders) and exits 143, not
    130. A command that handles SIGTERM itself (`snakekit lab`) sets its own handler over this one."""
    with _sigterm_as_ctrl_c() as terminated:
        try:
            code = command()
        except KeyboardInterrupt:
            if not terminated:   # Ctrl-C in a command that does not stop on it: as before
                raise
            print(f"snakekit {name}: terminated (SIGTERM)", file=sys.stderr)
            return 143
    return 143 if terminated and code == 130 else code


def run(argv: list, *, cwd=None, env: dict | None = None):
    """``snakekit ARGV`` in this process, as ``subprocess.run([... "snakekit", *ARGV], capture_output=True, text=True,
    cwd=cwd, env=env)`` gives it: a ``subprocess.CompletedProcess`` with the exit code and what the command printed.

    For a script or a test that runs many commands: each costs no interpreter's start and imports of its own, and
    a process that grades several batches keeps one warm fork server for them (``grader.sandbox.runner``): about
    4 CPU-s a batch less, the command's process and its server's imports together. The folder, the environment
    and the warning filters are this process's while the command runs, then restored, whatever the command
    changed (call it from one thread at a time); a warning shows at each call, as in a process of its own. Only
    what this process prints is captured (a sandbox's or nbgrader's own processes print to this process's
    stderr), and an error the command does not catch is raised, where its own process would print the
    traceback and exit 1.
    """
    import contextlib
    import io
    import subprocess
    import warnings

    out, err = io.StringIO(), io.StringIO()
    saved = dict(os.environ)
    try:
        # catch_warnings: the filters are restored after, and "once per place" starts afresh, as in a new process
        with contextlib.chdir(cwd or os.getcwd()), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), \
                warnings.catch_warnings():
            if env is not None:
                os.environ.clear()
                os.environ.update(env)
            try:
                code = main([str(a) for a in argv], out)
            except SystemExit as e:   # argparse's usage errors; sys.exit(message)
                code = e.code if isinstance(e.code, int) else 0 if e.code is None else 1
                if not isinstance(e.code, (int, type(None))):
                    print(e.code, file=sys.stderr)
    finally:
        os.environ.clear()
        os.environ.update(saved)
    return subprocess.CompletedProcess(["snakekit", *map(str, argv)], 0 if code is None else code, out.getvalue(),
                                       err.getvalue())


if __name__ == "__main__":
    sys.exit(main())
