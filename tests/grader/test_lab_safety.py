"""`snakekit lab`: one session per course and per arm, no setting that switches a check off, and a
bad hand-in refused for its own job only.

The sessions here run the short sweeps of tests/grader/test_arm_lab.py (2.9 s of robot time) on the bus
emulator; the two-session tests start real `snakekit lab` processes.
"""

import io
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

import snakekit
from grader.commands import lab as lab_cli
from grader.arm import lock
from grader.arm import session as lab
from grader.arm.jobs import CASE_NUMBERS, NUMBERS, Queue, settings
from grader.errors import LabError
from grader_helpers import lab_as_a_ta

A = "06_coded_sweep"
CASE = {"points": 30, "rate": 10.0, "sweeps": 2, "amplitude": 0.2}  # 2.9 s, peak 0.87 rad/s
LAB = {"exercise": "ex06_3_task2_test", "case": CASE}  # a lab.json: the lab's exercise at a short case
CMD = [sys.executable, "-m", "snakekit.cli", "lab"]
HANG = 240  # [s] a bound for a hang: a session of two short jobs takes about 30 s on a loaded machine


def make_course(root: Path, students=("alice", "bob")) -> Path:
    course = root / "course"
    (course / "source" / A).mkdir(parents=True)
    (course / "lab" / A).mkdir(parents=True)
    (course / "lab" / A / "lab.json").write_text(json.dumps({**LAB, "stall_delay": 0.03}))
    for st in students:
        hand_in(course, st, snakekit.side_sweep(**CASE))
    return course


def handin_file(course: Path, student: str) -> Path:
    return course / "autograded" / student / A / "lab" / "ex06_3_task2_test.npz"


def hand_in(course: Path, student: str, trajectory=None, raw: bytes | None = None) -> Path:
    path = handin_file(course, student)
    path.parent.mkdir(parents=True, exist_ok=True)
    if raw is None:
        buf = io.BytesIO()
        np.savez(buf, times=trajectory.times, positions=trajectory.positions)
        raw = buf.getvalue()
    path.write_bytes(raw)
    return path


def env(**extra) -> dict:
    return dict(os.environ, MUJOCO_GL="egl", **extra)


def calibrate(course: Path, tries: int = 3) -> None:
    """Calibrate on the emulator, again after a fault of this shared machine (a stall, the watchdog),
    as a TA would."""
    for k in range(tries):
        try:
            with snakekit.make_robot("emulator") as robot:
                lab.calibrate(robot, course, settings(course, A), runs=2)
            return
        except snakekit.BackendError:
            if k == tries - 1:
                raise


# --- settings: every number of lab.json, every bad kind of value -------------------------------

def _range_text(bounds: dict) -> str:
    """The allowed range as the message must state it (independently of the code's wording helper)."""
    def num(v):
        return str(int(v)) if float(v).is_integer() else f"{v:g}"

    lo = bounds.get("at_least", bounds.get("above"))
    if "at_least" in bounds:
        return f"from {num(lo)} to {num(bounds['at_most'])}"
    return f"> {num(lo)} and <= {num(bounds['at_most'])}"


def _bad_values(bounds: dict):
    top = bounds["at_most"]
    return [("nan", float("nan"), "nan"), ("inf", float("inf"), "inf"), ("-inf", float("-inf"), "-inf"),
            ("negative", -1, "-1"), ("zero", 0, "0"), ("above the range", top * 2 + 1, None),
            ("text", "abc", "'abc'"), ("true", True, "True"), ("false", False, "False"), ("null", None, "None"),
            ("a list", [1, 2], "a JSON list")]


CASES = [(key, False, bounds, *bad) for key, bounds in NUMBERS.items() for bad in _bad_values(bounds)] + \
        [(key, True, bounds, *bad) for key, bounds in CASE_NUMBERS.items() for bad in _bad_values(bounds)]


@pytest.fixture(scope="module")
def bare_course(tmp_path_factory):
    course = tmp_path_factory.mktemp("settings") / "course"
    (course / "source" / A).mkdir(parents=True)
    (course / "lab" / A).mkdir(parents=True)
    return course


@pytest.mark.parametrize("key, in_case, bounds, kind, value, shown", CASES,
                         ids=[f"{'case.' if c[1] else ''}{c[0]}-{c[3]}" for c in CASES])
def test_every_number_of_lab_json_refuses_a_bad_value_naming_file_key_value_and_range(
        bare_course, key, in_case, bounds, kind, value, shown, capsys):
    lab_json = bare_course / "lab" / A / "lab.json"
    fields = {**LAB, "case": {**CASE, key: value}} if in_case else {**LAB, key: value}
    lab_json.write_text(json.dumps(fields))  # NaN and Infinity as Python's json writes (and reads) them
    name = f'"case.{key}"' if in_case else f'"{key}"'
    with pytest.raises(LabError) as e:
        settings(bare_course, A)
    message = str(e.value)
    assert message.startswith(f"{lab_json}: {name} must be ")
    assert _range_text(bounds) in message
    assert f"got {shown if shown is not None else repr(value)}" in message
    # the command: exit 2, one line, before anything moves (no queue, no lock taken)
    assert lab_cli.main([A, "--course", str(bare_course), "--emulator"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err
    assert not (bare_course / "lab" / A / "queue.json").exists()
    assert not (bare_course / "lab" / ".session.lock").exists()


@pytest.mark.parametrize("key", NUMBERS)
def test_each_end_of_a_setting_s_range_is_accepted(bare_course, key):
    bounds = NUMBERS[key]
    ends = [bounds.get("at_least"), bounds["at_most"]]
    for v in [e for e in ends if e is not None]:
        (bare_course / "lab" / A / "lab.json").write_text(json.dumps({**LAB, key: v}))
        assert getattr(settings(bare_course, A), key) == v


def test_grading_stops_before_it_starts_on_a_bad_lab_json_and_goes_on_without_one(bare_course):
    """The grader keeps the hand-ins for the lab as lab.json says: a bad value is said, not passed over."""
    from types import SimpleNamespace

    from grader.arm.keep import with_lab_case

    batch = SimpleNamespace(assignment=A, cases={})
    (bare_course / "lab" / A / "lab.json").write_text(json.dumps({**LAB, "max_duration_ratio": "abc"}))
    with pytest.raises(LabError, match=r'lab.json: "max_duration_ratio" must be a finite number from 1 to 4, '
                                       r"got 'abc' \(str\)"):
        with_lab_case(batch, bare_course)
    (bare_course / "lab" / A / "lab.json").unlink()
    assert with_lab_case(batch, bare_course) is batch  # no lab.json: the assignment has no lab
    assert with_lab_case(SimpleNamespace(assignment="07_other", cases={}), bare_course).assignment == "07_other"


def test_sim_tolerance_nan_no_longer_lets_a_sweep_of_40_sweeps_onto_the_arm(bare_course):
    """The probe's case: NaN compared false with every gap, so the simulator gate passed everything."""
    from grader.arm import gate

    (bare_course / "lab" / A / "lab.json").write_text('{"sim_tolerance": NaN, "exercise": "ex06_3_task2_test", '
                                                      '"case": {"points": 30, "rate": 10.0, "sweeps": 2, '
                                                      '"amplitude": 0.2}}')
    with pytest.raises(LabError, match=r'"sim_tolerance" must be a finite number > 0 and <= 0.5 \[rad\], got nan'):
        settings(bare_course, A)
    (bare_course / "lab" / A / "lab.json").write_text(json.dumps(LAB))
    off = snakekit.side_sweep(**{**CASE, "sweeps": 1, "amplitude": 0.3})
    checked = gate.check({"times": off.times, "positions": off.positions}, settings(bare_course, A))
    assert "on the simulator your sweep is" in checked.reason


@pytest.mark.parametrize("text, says", [
    ('{"exercise": "ex06_3_task2_test", "case": [1, 2]}', '"case" must be a JSON object of points, rate, sweeps, '
                                                           'amplitude'),
    ('{"exercise": "ex06_3_task2_test", "case": {"points": 30, "rate": 10.0, "sweeps": 2}}',
     '"case" must hold exactly points, rate, sweeps, amplitude; missing amplitude'),
    ('{"exercise": 7, "case": {"points": 30, "rate": 10.0, "sweeps": 2, "amplitude": 0.2}}',
     '"exercise" must be a grade id (text), got 7'),
    ('[1, 2]', "must hold one JSON object of fields"),
    ('{"exercise": "ex06_3_task2_test", "case": {"points": 30, "rate": 10.0, "sweeps": 2, "amplitude": 1.5}}',
     "is not a sweep the arm may run"),
    ('{"exercise": "ex06_3_task2_test", "case": {"points": 30, "rate": 0.01, "sweeps": 2, "amplitude": 0.2}}',
     "is not a sweep the arm may run: its duration is 2900 s"),
])
def test_a_lab_json_that_is_not_the_lab_s_settings_is_refused(bare_course, text, says):
    (bare_course / "lab" / A / "lab.json").write_text(text)
    with pytest.raises(LabError, match=re.escape(says)):
        settings(bare_course, A)


def test_the_course_names_the_lab_s_exercise_and_the_spec_s_own_case():
    """course/lab/06_coded_sweep/lab.json (the course's, not the grader's): Task 2's test cell, at the
    sweep ``snakekit.side_sweep()`` makes with no arguments (what Task 2 asks for)."""
    import inspect

    import nbformat

    course = Path(__file__).resolve().parents[2] / "course"
    s = settings(course, A)
    spec_case = {k: p.default for k, p in inspect.signature(snakekit.side_sweep).parameters.items() if k != "spec"}
    assert (s.exercise, s.case) == ("ex06_3_task2_test", spec_case)
    source = nbformat.read(course / "source" / A / f"{A}.ipynb", as_version=4)
    graded = {c.metadata.get("nbgrader", {}).get("grade_id") for c in source.cells
              if c.metadata.get("nbgrader", {}).get("grade")}
    assert s.exercise in graded


def test_an_assignment_without_the_lab_s_exercise_has_no_lab_and_is_told_where_to_name_it(tmp_path):
    from grader.errors import NoLab

    course = tmp_path / "course"
    (course / "source" / A).mkdir(parents=True)
    lab_json = course / "lab" / A / "lab.json"
    for text in (None, json.dumps({"case": CASE}), json.dumps({"exercise": "ex06_3_task2_test"})):
        if text is not None:
            lab_json.parent.mkdir(parents=True, exist_ok=True)
            lab_json.write_text(text)
        with pytest.raises(NoLab) as e:
            settings(course, A)
        assert str(e.value).startswith(f"{A} has no exercise the lab runs (its hand-in is not a trajectory); "
                                       f"name one in {lab_json} as {{\"exercise\": GRADE_ID, \"case\": ")


# --- the files the lab writes and reads back --------------------------------------------------

@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    course = make_course(tmp_path_factory.mktemp("lab"))
    calibrate(course)
    return course


@pytest.mark.parametrize("change, says", [
    (lambda c: {**c, "bands_rad": [float("nan")] * 5}, "bands_rad[0] must be a finite number > 0"),
    (lambda c: {**c, "bands_rad": [-0.01] * 5}, "bands_rad[0] must be a finite number > 0"),
    (lambda c: {**c, "bands_rad": [0.01] * 4}, "bands_rad is not one band per joint"),
    (lambda c: {**c, "runs": True}, "runs must be a whole number from 2 to 1000, got True"),
    (lambda c: [c], "not a JSON object"),
])
def test_a_calibration_file_that_would_change_the_grade_is_refused(calibrated, tmp_path, change, says):
    import shutil

    course = tmp_path / "course"
    shutil.copytree(calibrated, course)
    path = course / "lab" / A / "calibration.json"
    path.write_text(json.dumps(change(json.loads(path.read_text()))))
    with pytest.raises(LabError, match=re.escape(says) + ".*snakekit lab calibrate 06_coded_sweep` again"):
        lab.load_calibration(course, settings(course, A))


def test_two_copies_of_the_queue_never_write_each_other_s_jobs_away(tmp_path):
    """The probe's case: the second session's job vanished, written over by the first's stale copy."""
    course = make_course(tmp_path)
    first, second = Queue.load(course, A), Queue.load(course, A)  # both read the empty queue
    first.set(first.add("alice"), "queued")
    second.set(second.add("bob"), "running", attempts=1)
    first.set(first.job("alice"), "graded", "ok", points=1.0)
    on_disk = json.loads((course / "lab" / A / "queue.json").read_text())["jobs"]
    assert sorted(j["student"] for j in on_disk) == ["alice", "bob"]
    assert {j["student"]: j["state"] for j in on_disk} == {"alice": "graded", "bob": "running"}
    assert first.job("bob")["state"] == "running"  # the first copy took up the second's job
    assert not list((course / "lab" / A).glob(".queue.json.*"))  # no temporary file left behind


def test_a_queue_file_that_is_not_the_lab_s_is_refused(tmp_path):
    course = make_course(tmp_path)
    (course / "lab" / A / "queue.json").write_text('{"jobs": [{"student": "alice", "state": "flying"}]}')
    with pytest.raises(LabError, match="is not the lab's queue .*move it away"):
        Queue.load(course, A)


# --- bad hand-ins: refused for their own job, the session goes on -------------------------------

def _good_bytes() -> bytes:
    buf = io.BytesIO()
    tr = snakekit.side_sweep(**CASE)
    np.savez(buf, times=tr.times, positions=tr.positions)
    return buf.getvalue()


def _flipped() -> bytes:
    raw = bytearray(_good_bytes())
    raw[len(raw) // 3] ^= 0xFF  # inside the first array's data: its CRC no longer matches
    return bytes(raw)


def _bomb() -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("times.npy", b"\0" * (80 * 2**20))
    return buf.getvalue()


def _pickled() -> bytes:
    buf = io.BytesIO()
    np.savez(buf, times=np.array([object()], dtype=object), positions=np.zeros((2, 5)))
    return buf.getvalue()


BAD_HANDINS = {  # student: (the file's bytes, what the reason says)
    "carl": (_good_bytes()[:700], "your hand-in file cannot be read as arrays of numbers"),
    "dora": (_flipped(), "your hand-in file cannot be read as arrays of numbers"),
    "emil": (None, "your sweep is not a trajectory the arm can take: positions must have shape (30, 5)"),
    "fay": (_bomb(), "your hand-in unpacks to 80 MB, more than the 64 MB a sweep can take"),
    "gus": (_pickled(), "your hand-in file cannot be read as arrays of numbers"),
}


def test_a_session_with_bad_hand_ins_among_good_ones_runs_the_good_ones(calibrated, tmp_path):
    import shutil

    import nbformat

    from grader.feedback.exporter import write_html

    course = tmp_path / "course"
    shutil.copytree(calibrated, course)
    for st, (raw, _) in BAD_HANDINS.items():
        if raw is None:  # wrong-shaped: four joints
            tr = snakekit.side_sweep(**CASE)
            handin_file(course, st).parent.mkdir(parents=True)
            np.savez(handin_file(course, st), times=tr.times, positions=tr.positions[:, :4])
        else:
            hand_in(course, st, raw=raw)
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell(f"# Feedback: {A}")])
    nb.cells[0]["id"] = "cell-0"
    write_html(nb, course / "feedback" / "carl" / A / f"{A}.html")
    students = ["carl", "alice", "dora", "emil", "bob", "fay", "gus"]
    q = Queue.load(course, A)
    for st in students:
        q.add(st)
    q.save()
    s = settings(course, A)
    codes = []
    while len(codes) < 4 and (not codes or codes[-1] == 1):  # a stall of this shared machine is a lab fault
        codes.append(lab.session(lambda: snakekit.make_robot("emulator"), course, s, students,
                                 Queue.load(course, A), out=io.StringIO()))
    assert codes[-1] == 0, codes
    jobs = {j["student"]: j for j in Queue.load(course, A).jobs}
    assert jobs["alice"]["state"] == jobs["bob"]["state"] == "graded"
    assert (course / "lab" / A / "results" / "alice" / "report.json").is_file()
    for st, (_, says) in BAD_HANDINS.items():
        assert jobs[st]["state"] == "refused" and says in jobs[st]["reason"], jobs[st]
        assert not (course / "lab" / A / "results" / st).exists()
    assert f"snakekit grade {A} --student carl" in jobs["carl"]["reason"]
    page = (course / "feedback" / "carl" / A / f"{A}.html").read_text()
    assert "your hand-in file cannot be read as arrays of numbers" in page


# --- one session per course and per arm -------------------------------------------------------

HOLDER = re.compile(r"snakekit lab: (?P<what>.+) is in use by another lab session \(pid (?P<pid>\d+) on "
                    r"(?P<host>\S+), user (?P<user>\S+), since (?P<since>\S+Z), running (?P<a>\S+) of the course "
                    r"(?P<course>\S+) on the arm (?P<arm>.+)\): wait for it to end, or stop it there \(its lock goes "
                    r"with it\)\n")


def _start(argv, **kw):
    return subprocess.Popen(CMD + argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _user() -> str:
    import getpass

    return getpass.getuser()


def test_two_sessions_started_together_on_one_course_one_is_refused_and_the_queue_stays_whole(calibrated, tmp_path):
    import shutil

    course = tmp_path / "course"
    shutil.copytree(calibrated, course)
    argv = [A, "--course", str(course), "--emulator", "--order", "student"]
    procs = [_start(argv, env=env()), _start(argv, env=env())]
    outs = [p.communicate(timeout=HANG) for p in procs]
    codes = sorted(p.returncode for p in procs)
    assert codes in ([0, 2], [1, 2]), outs  # 1: a stall of this shared machine (a lab fault), never a second run
    k = [p.returncode for p in procs].index(2)
    refused, winner = outs[k][1], procs[1 - k]
    m = HOLDER.fullmatch(refused)
    assert m, refused
    assert (m["what"], int(m["pid"]), m["host"], m["user"], m["a"], m["course"], m["arm"]) == (
        f"the course {course}", winner.pid, socket.gethostname(), _user(), A, str(course.resolve()), "the emulator")
    jobs = json.loads((course / "lab" / A / "queue.json").read_text())["jobs"]
    assert sorted(j["student"] for j in jobs) == ["alice", "bob"]  # each job once
    assert all(j["attempts"] <= 1 for j in jobs)  # no job ran twice
    if winner.returncode == 0:
        assert {j["state"] for j in jobs} == {"graded"}


@pytest.fixture
def tcp_arm():
    from snakekit.emulator.bus import BusEmulator

    bus = BusEmulator(motion="profile", tcp="0").start()
    yield bus
    bus.stop()


def test_one_arm_behind_a_bridge_takes_one_session_however_its_url_is_spelled(tmp_path, tcp_arm):
    """Two courses, one arm: socket://localhost:P and socket://127.0.0.1:P are the same arm."""
    port = int(tcp_arm.port.rsplit(":", 1)[1])
    courses = [make_course(tmp_path / "one"), make_course(tmp_path / "two")]
    urls = [f"socket://localhost:{port}", f"socket://127.0.0.1:{port}"]
    e = env(SNAKEKIT_LOCK_DIR=str(tmp_path / "locks"))
    for attempt in range(2):  # the session that took the arm, once more after a fault of this shared machine (a stall)
        procs = [_start(["calibrate", A, "--course", str(c), "--port", u, "--runs", "2"], env=e)
                 for c, u in zip(courses, urls)]
        outs = [p.communicate(timeout=HANG) for p in procs]
        codes = sorted(p.returncode for p in procs)
        if codes != [1, 2] or attempt:
            break
    assert codes == [0, 2], [f"exit {p.returncode}; stdout: {o[-1500:]}; stderr: {err[-1500:]}"
                             for p, (o, err) in zip(procs, outs)]
    k = [p.returncode for p in procs].index(2)
    m = HOLDER.fullmatch(outs[k][1])
    assert m, outs[k][1]
    assert m["what"] == (f"the arm {urls[k]} (socket://127.0.0.1:{port})" if k == 0 else f"the arm {urls[k]}")
    assert int(m["pid"]) == procs[1 - k].pid and m["course"] == str(courses[1 - k].resolve())
    assert m["arm"] == f"socket://127.0.0.1:{port}"
    assert (courses[1 - k] / "lab" / A / "calibration.json").is_file()
    assert not (courses[k] / "lab" / A / "calibration.json").exists()


def test_a_session_killed_with_sigkill_leaves_no_lock(tmp_path, tcp_arm):
    course = make_course(tmp_path)
    e = env(SNAKEKIT_LOCK_DIR=str(tmp_path / "locks"))
    argv = ["calibrate", A, "--course", str(course), "--port", tcp_arm.port, "--runs"]
    p = _start(argv + ["5"], env=e)
    seen = ""
    deadline = time.monotonic() + HANG
    while "reference run 1 of 5" not in seen and time.monotonic() < deadline:
        seen += p.stdout.readline()
    held = _start(argv + ["2"], env=e)  # while it runs: refused
    assert held.wait(timeout=HANG) == 2 and "is in use by another lab session" in held.stderr.read()
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=HANG)
    p.stdout.close()
    p.stderr.close()
    held.stdout.close()
    held.stderr.close()
    r = lab_as_a_ta(*argv, "2", env=e, timeout=HANG)  # again after a stall of this shared machine, as a TA would
    assert r.returncode == 0, r.stderr
    assert json.loads((course / "lab" / A / "calibration.json").read_text())["runs"] == 2


@pytest.mark.parametrize("a, b, same", [
    ("socket://localhost:7800", "socket://127.0.0.1:7800", True),
    ("socket://LOCALHOST:7800", "socket://127.0.0.1:7800", True),
    ("socket://127.0.0.1:7800", "socket://127.0.0.1:7801", False),
    ("socket://localhost:7800", "rfc2217://localhost:7800", False),
])
def test_spellings_of_one_bridge_are_one_arm(a, b, same):
    assert (lock.arm_key(a) == lock.arm_key(b)) is same
    assert (lock.arm_lock_path(a) == lock.arm_lock_path(b)) is same


def test_a_symlink_to_a_serial_port_is_the_same_arm(tmp_path):
    device = tmp_path / "ttyUSB0"
    device.touch()
    (tmp_path / "by-id").mkdir()
    link = tmp_path / "by-id" / "usb-FTDI_USB__-__Serial_Converter-if00-port0"
    link.symlink_to(device)
    assert lock.arm_key(str(link)) == lock.arm_key(str(device)) == str(device.resolve())
    assert lock.arm_key(str(tmp_path / "ttyUSB1")) != lock.arm_key(str(device))


def test_the_arms_locks_are_in_one_folder_for_every_user(monkeypatch):
    monkeypatch.delenv("SNAKEKIT_LOCK_DIR", raising=False)
    where = lock.lock_dir()
    assert where in (Path("/run/lock/snakekit"), Path("/tmp/snakekit-locks"))
    mode = os.stat("/run/lock").st_mode if os.path.isdir("/run/lock") else 0
    assert (where == Path("/run/lock/snakekit")) == bool(mode & 0o002 and mode & 0o1000)


def test_a_calibration_whose_runs_differ_too_much_for_the_bands_to_mean_anything_keeps_nothing(
        bare_course, monkeypatch):
    """Runs 0.2 rad apart at joint 3 (a slipping servo): bands of 10 x 0.2 rad would pass any sweep."""
    from types import SimpleNamespace

    (bare_course / "lab" / A / "lab.json").write_text(json.dumps({**LAB, "band_factor": 10}))
    s = settings(bare_course, A)
    offsets = iter([0.0, 0.2])

    def fake_run(robot, trajectory, stall_delay, say):
        q = trajectory.positions.copy()
        q[:, 2] += next(offsets)
        t = trajectory.times
        return SimpleNamespace(commanded=SimpleNamespace(times=t), measured=SimpleNamespace(times=t, positions=q)), {}

    monkeypatch.setattr(lab, "run_unstalled", fake_run)
    with pytest.raises(LabError, match=r"the 2 runs of the reference differ by up to 11.5 deg at joint 3: bands of "
                                       r"2.00 rad \(more than 1\) would pass any sweep; check the arm"):
        lab.calibrate(None, bare_course, s, runs=2, out=io.StringIO())
    assert not (bare_course / "lab" / A / "calibration.json").exists()
    assert not (bare_course / "lab" / A / "reference.npz").exists()
