"""`snakekit sweep` as a user runs it: summary, saved run, plot, and clear failures."""

import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import snakekit
from snakekit.robot import Run

SNAKEKIT = [sys.executable, "-m", "snakekit.cli"]


def sweep(*args, cwd):
    return subprocess.run(SNAKEKIT + ["sweep", *args], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_sweep_prints_a_summary_and_writes_run_and_plot(tmp_path):
    r = sweep("--out", "run.npz", "--plot", "sweep.png", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    for line in ("goals sent:         500 over 49.90 s", "robot time:         50.40 s", "limits held:        yes",
                 "max tracking error: j1", "final distance from home (tool):", "saved plot:         sweep.png"):
        assert line in r.stdout
    # the saved run is the simulator's run, bit for bit (the simulator is deterministic)
    saved = Run.load(tmp_path / "run.npz")
    with snakekit.make_robot("sim") as robot:
        direct = robot.run(snakekit.side_sweep())
    np.testing.assert_array_equal(saved.measured.positions, direct.measured.positions)
    np.testing.assert_array_equal(saved.commanded.positions, snakekit.side_sweep().positions)
    png = (tmp_path / "sweep.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(png[16:20], "big"), int.from_bytes(png[20:24], "big")
    assert width > 1000 and height > 900  # one panel row per joint


def test_unknown_backend_is_a_usage_error(tmp_path):
    r = sweep("--backend", "gazebo", cwd=tmp_path)
    assert r.returncode == 2
    assert "invalid choice: 'gazebo' (the choices: sim, emulator, hardware)" in r.stderr


def test_every_mistyped_command_or_choice_is_named_with_the_nearest_one(capsys):
    """Each choice of the `snakekit` command line (its commands, each command's options with choices), typed with
    one letter dropped or two swapped: one line that names the nearest choice (each, when two are as near) and lists
    them all."""
    import argparse

    from snakekit.cli import build_parser

    def choices(parser, words):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                yield words, None, list(action.choices)
                for name, sub in action.choices.items():
                    yield from choices(sub, [*words, name])
            elif action.choices and action.option_strings:
                yield words, action.option_strings[0], list(action.choices)

    tried = 0
    for words, option, options in choices(build_parser(), []):
        for choice in options:
            for typo in {choice[:-1], choice[1:2] + choice[:1] + choice[2:]} - set(options):
                args = [*words, *([option, typo] if option else [typo])]
                with pytest.raises(SystemExit) as e:   # the parser alone, as `snakekit` runs it first
                    build_parser().parse_args(args)
                err = capsys.readouterr().err
                assert e.value.code == 2 and len(err.splitlines()) == 1, (args, err)
                said = re.search(rf"invalid choice: '{re.escape(typo)}'; did you mean (.+)\? \(the choices: "
                                 rf"{re.escape(', '.join(options))}\)", err)
                assert said and choice in said.group(1).split(" or "), (args, err)
                tried += 1
    assert tried >= 40, tried  # 14 commands and the backends, two typos each


def test_unwritable_output_fails_before_the_run(tmp_path):
    r = sweep("--out", "missing/run.npz", "--plot", "sweep.jpg2", cwd=tmp_path)
    assert r.returncode == 2
    assert "cannot write run file missing/run.npz: folder" in r.stderr
    assert "plot sweep.jpg2 must end in .png or .pdf or .svg" in r.stderr
    assert "Task 2" not in r.stdout  # nothing ran


def test_output_path_that_is_a_folder(tmp_path):
    (tmp_path / "runs.npz").mkdir()
    r = sweep("--out", "runs.npz", cwd=tmp_path)
    assert r.returncode == 2 and "cannot write run file runs.npz: it is a folder" in r.stderr


def test_hardware_without_a_port_says_what_to_add(tmp_path):
    r = sweep("--backend", "hardware", cwd=tmp_path)
    assert r.returncode == 2 and "--backend hardware needs --port" in r.stderr


def test_run_file_that_is_not_a_run(tmp_path):
    p = tmp_path / "x.npz"
    np.savez(p, a=np.zeros(3))
    with pytest.raises(snakekit.FileFormatError, match="is not a snakekit run file"):
        Run.load(p)
    with pytest.raises(snakekit.FileFormatError, match="does not exist"):
        Run.load(tmp_path / "nope.npz")


def test_console_script_is_installed():
    exe = Path(sys.executable).parent / "snakekit"
    r = subprocess.run([str(exe), "--help"], capture_output=True, text=True)
    assert r.returncode == 0 and "sweep" in r.stdout and "emulator" in r.stdout


def _commands() -> list[str]:
    """Every command `snakekit --help` lists, and the plug-in commands it runs (snakekit lab, ...)."""
    from snakekit.cli import PLUGIN_COMMANDS

    r = subprocess.run(SNAKEKIT + ["--help"], capture_output=True, text=True, timeout=60)
    names = re.findall(r"^    (\w+) ", r.stdout, re.M)
    return sorted(set(names) | set(PLUGIN_COMMANDS))


@pytest.mark.parametrize("command", _commands())
def test_every_commands_help_prints_its_usage(command):
    r = subprocess.run(SNAKEKIT + [command, "--help"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.startswith("usage: ") and "Traceback" not in r.stdout + r.stderr, r.stdout[:500] + r.stderr[-500:]
    # the command run in this process (snakekit.cli.run, for scripts and the suite) says the same, and so does
    # its refusal of an option it does not know
    from snakekit.cli import run

    here = run([command, "--help"])
    assert (here.returncode, here.stdout, here.stderr) == (r.returncode, r.stdout, r.stderr)
    bad = [command, "--no-such-option"]
    r, here = subprocess.run(SNAKEKIT + bad, capture_output=True, text=True, timeout=120), run(bad)
    assert r.returncode == 2 and r.stderr.strip() and "Traceback" not in r.stderr, r.stderr[-2000:]
    assert (here.returncode, here.stdout, here.stderr) == (r.returncode, r.stdout, r.stderr)


def test_a_command_run_in_this_process_reads_the_folder_and_environment_given_then_leaves_them(tmp_path):
    """snakekit.cli.run: a relative path is read from ``cwd`` and a variable from ``env``, as a subprocess's would be;
    afterwards this process's folder and environment are as they were, and the command's output is in the result,
    not on this process's stdout."""
    import os

    from snakekit.cli import run

    (tmp_path / "notes.txt").write_text("not a notebook")
    before, environ = os.getcwd(), dict(os.environ)
    env = {**os.environ, "SNAKEKIT_PORT": str(tmp_path / "no-such-port")}
    for argv, kw in ((["check", "notes.txt"], {"cwd": tmp_path}),
                     (["sweep", "--backend", "hardware", "--out", "run.npz"], {"cwd": tmp_path, "env": env})):
        r = subprocess.run(SNAKEKIT + argv, capture_output=True, text=True, timeout=120, **kw)
        here = run(argv, **kw)
        assert r.returncode != 0 and r.stderr, (argv, r.stdout, r.stderr)
        assert (here.returncode, here.stdout, here.stderr) == (r.returncode, r.stdout, r.stderr), argv
        assert os.getcwd() == before and dict(os.environ) == environ
    assert "no-such-port" in here.stderr   # the port the environment named, not "needs --port"


def test_a_commands_process_runs_its_exit_handlers_then_leaves_what_it_loaded_to_the_system(tmp_path):
    """A command ends without the collector's last sweep over the libraries it loaded (gc.freeze at exit;
    about 1 s of CPU for the TA's commands, which load nbgrader), and only after every exit handler ran:
    a temporary folder made while it ran is still removed, and its output is whole."""
    code = ("import atexit, gc, sys, tempfile\n"
            "from snakekit.cli import main\n"
            "atexit.register(lambda: print('frozen at exit:', gc.get_freeze_count() > 0, flush=True))\n"
            "made = tempfile.TemporaryDirectory(dir=sys.argv[1])\n"
            "print('made:', made.name, flush=True)\n"
            "sys.exit(main(['--help']))\n")
    r = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "usage: snakekit" in r.stdout and r.stdout.rstrip().endswith("frozen at exit: True"), r.stdout[-500:]
    assert list(tmp_path.iterdir()) == [], "the temporary folder's cleanup did not run"


def test_a_command_run_in_this_process_leaves_no_trace_of_what_it_changed(tmp_path, monkeypatch):
    """snakekit.cli.run, given no folder or environment: whatever the command changed of them (nbgrader's steps add
    to PATH and change folder) is undone after it, its warning shows at each call as it would in a process of its
    own (not once per process), and a command that returns nothing exits 0."""
    import os
    import warnings

    from snakekit import cli

    def command(argv, out):
        os.environ["PATH"] = f"{tmp_path}{os.pathsep}{os.environ.get('PATH', '')}"
        os.environ["SNAKEKIT_LEFT_BEHIND"] = "1"
        os.chdir(tmp_path)
        warnings.warn("the same warning from the same line", UserWarning)
        print("ran", argv, file=out)

    monkeypatch.setattr(cli, "plugin_command", lambda name: command)
    before, environ = os.getcwd(), dict(os.environ)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("default")   # Python's own: a warning once per place and process
        runs = [cli.run(["grade", "x"]) for _ in range(2)]
    assert [(r.returncode, r.stdout) for r in runs] == [(0, "ran ['x']\n")] * 2
    assert os.getcwd() == before and dict(os.environ) == environ
    assert [str(w.message) for w in seen] == ["the same warning from the same line"] * 2


def test_emulator_command_prints_a_port_the_sdk_can_use():
    import re
    import signal

    from tests.conftest import need

    sdk = need("dynamixel_sdk")
    proc = subprocess.Popen(SNAKEKIT + ["emulator", "--motion", "profile"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        m = re.search(r"(/dev/pts/\d+)", line)
        assert m, f"no port in {line!r}"
        port = sdk.PortHandler(m.group(1))
        assert port.openPort() and port.setBaudRate(4_000_000)
        packet = sdk.PacketHandler(2.0)
        for dxl_id in (1, 2, 3, 4, 5):
            # the SDK waits 34 ms for a reply: on a busy machine the emulator's process may not be
            # scheduled within it, so a ping is sent again (up to 10 s: a bound for a hang)
            deadline = time.monotonic() + 10
            while True:
                model, result, error = packet.ping(port, dxl_id)
                if result != sdk.COMM_RX_TIMEOUT or time.monotonic() > deadline:
                    break
            assert (model, result, error) == (30, sdk.COMM_SUCCESS, 0)
        port.closePort()
    finally:
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=20)
    assert code in (0, 130)


def test_emulator_command_rejects_a_bad_option():
    r = subprocess.run(SNAKEKIT + ["emulator", "--drop", "2"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "Faults.drop must be a finite number from 0 to 1, got 2.0. It is a probability" in r.stderr


# --- `snakekit check`: a lesson's checks from a terminal ------------------------------------

LESSON3 = "03_inverse_kinematics"


def _exercises(nb) -> list[tuple[str, int, str, str]]:
    """(test cell grade id, points, number, name) of each exercise, read from the notebook itself."""
    import re

    rows = []
    for cell in nb.cells:
        meta = cell.metadata.get("nbgrader", {})
        if meta.get("solution") and cell.cell_type == "code":
            number, name = re.search(r'exercise (\d+\.\d+): (\w+)', cell.source).groups() \
                if "NotImplementedError" in cell.source else (None, None)
            rows.append([f"{meta['grade_id']}_test", None, number, name])
    points = {c.metadata["nbgrader"]["grade_id"]: c.metadata["nbgrader"]["points"] for c in nb.cells
              if c.metadata.get("nbgrader", {}).get("grade")}
    return [(gid, points[gid], number, name) for gid, _, number, name in rows]


def check(path, cwd):
    # the console script, as a student types it (snakekit check notebooks/03_inverse_kinematics.ipynb)
    exe = Path(sys.executable).parent / "snakekit"
    return subprocess.run([str(exe), "check", str(path)], cwd=cwd, capture_output=True, text=True, timeout=600)


def _rows(stdout: str) -> dict[str, tuple[int, str, str]]:
    import re

    rows = {}
    for line in stdout.splitlines():
        m = re.match(r"  (ex\d\d_\d+_\w+_test)\s+(\d+) pt  (passed|FAILED)\s*(.*)$", line)
        if m:
            rows[m.group(1)] = (int(m.group(2)), m.group(3), m.group(4))
    return rows


def test_check_reports_each_exercise_of_a_student_lesson(tmp_path):
    """As handed out, every exercise fails with the message the notebook shows."""
    import shutil

    import nbformat

    src = Path(__file__).resolve().parents[2] / "notebooks" / f"{LESSON3}.ipynb"
    shutil.copy(src, tmp_path)
    nb = nbformat.read(src, as_version=4)
    exercises = _exercises(nb)
    assert len(exercises) >= 3
    r = check(f"{LESSON3}.ipynb", cwd=tmp_path)
    assert r.returncode == 1, r.stdout + r.stderr
    rows = _rows(r.stdout)
    assert list(rows) == [gid for gid, *_ in exercises], r.stdout       # one row per exercise, in order
    for gid, points, number, name in exercises:
        # what the student sees under the check cell, after "Check failed: "
        assert rows[gid] == (points, "FAILED", f"exercise {number} {name}: `{name}` is not written yet (it raises "
                             f"NotImplementedError: exercise {number}: {name}). Write it in the answer cell above, "
                             "run that cell, then run this check again."), r.stdout
    total = sum(p for _, p, *_ in exercises)
    assert f"0 of {len(exercises)} exercises passed, 0 of {total} points" in r.stdout
    assert "also failed" not in r.stdout                               # nothing fails outside the checks
    assert nbformat.read(tmp_path / f"{LESSON3}.ipynb", as_version=4) == nb   # the file is not changed


def test_check_shows_by_how_much_a_wrong_answer_is_off(tmp_path):
    """Exercise 3.1 filled correctly except for degrees: its row says what, where and by how much."""
    import re

    import nbformat

    root = Path(__file__).resolve().parents[2]
    student = nbformat.read(root / "notebooks" / f"{LESSON3}.ipynb", as_version=4)
    instructor = nbformat.read(root / "course" / "source" / LESSON3 / f"{LESSON3}.ipynb", as_version=4)
    solutions = {c.metadata["nbgrader"]["grade_id"]: c.source for c in instructor.cells
                 if c.metadata.get("nbgrader", {}).get("solution") and c.cell_type == "code"}
    first, second = [c for c in student.cells if c.metadata.get("nbgrader", {}).get("solution")
                     and c.cell_type == "code"][:2]
    first.source = solutions[first.metadata["nbgrader"]["grade_id"]]    # 3.1: the right answer
    body = solutions[second.metadata["nbgrader"]["grade_id"]]
    body = re.sub(r"(\n\s*)return (.+)", r"\1return np.degrees(\2)", body, count=1)   # 3.2: in degrees
    assert "np.degrees" in body
    second.source = body
    nbformat.write(student, tmp_path / "lesson.ipynb")
    r = check("lesson.ipynb", cwd=tmp_path)
    assert r.returncode == 1, r.stdout + r.stderr
    rows = _rows(r.stdout)
    gids = list(rows)
    assert rows[gids[0]][1] == "passed" and rows[gids[0]][2] == "", r.stdout
    status, message = rows[gids[1]][1:]
    assert status == "FAILED" and message.startswith("exercise 3.2 "), r.stdout
    assert re.search(r" at .* is .*, expected .*: off by [0-9.e+-]+ \w+ .*\(tolerance ", message), message
    assert "Traceback" not in r.stdout
    # the whole message reaches the terminal: its hint on the line under the row, indented
    lines = r.stdout.splitlines()
    row = next(i for i, line in enumerate(lines) if line.lstrip().startswith(gids[1]))
    assert lines[row + 1].strip() == ("Hint: this looks like degrees where radians were asked: use radians "
                                      "(np.radians / np.deg2rad)."), r.stdout
    assert lines[row + 1].startswith(" " * (len(gids[1]) + 4)), r.stdout
    assert "without encryption" not in r.stdout + r.stderr        # no kernel warnings for the student


def test_check_passes_a_filled_lesson(tmp_path):
    """The instructor version (every exercise filled) passes every row and exits 0."""
    import shutil

    root = Path(__file__).resolve().parents[2]
    shutil.copy(root / "course" / "source" / LESSON3 / f"{LESSON3}.ipynb", tmp_path)
    import nbformat

    exercises = _exercises(nbformat.read(tmp_path / f"{LESSON3}.ipynb", as_version=4))
    r = check(f"{LESSON3}.ipynb", cwd=tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    rows = _rows(r.stdout)
    assert rows == {gid: (points, "passed", "") for gid, points, *_ in exercises}, r.stdout
    total = sum(p for _, p, *_ in exercises)
    assert f"{len(exercises)} of {len(exercises)} exercises passed, {total} of {total} points" in r.stdout


def test_check_refuses_what_is_not_a_notebook(tmp_path):
    (tmp_path / "lesson.py").write_text("print('hi')\n")
    r = check("lesson.py", cwd=tmp_path)
    assert r.returncode == 2
    assert "lesson.py is not a notebook file" in r.stderr and "notebooks/03_inverse_kinematics.ipynb" in r.stderr
