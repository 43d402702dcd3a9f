"""`snakekit sweep` as a user runs it: summary, saved run, plot, and clear failures."""

import subprocess
import sys
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
    assert "invalid choice: 'gazebo' (choose from 'sim', 'emulator', 'hardware')" in r.stderr


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
            model, result, error = packet.ping(port, dxl_id)
            assert (model, result, error) == (30, sdk.COMM_SUCCESS, 0)
        port.closePort()
    finally:
        proc.send_signal(signal.SIGINT)
        code = proc.wait(timeout=20)
    assert code in (0, 130)


def test_emulator_command_rejects_a_bad_option():
    r = subprocess.run(SNAKEKIT + ["emulator", "--drop", "2"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "drop is a probability in [0, 1], got 2.0" in r.stderr
