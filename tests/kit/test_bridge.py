"""The arm from any host: the driver on pyserial URLs, the TCP emulator, ``snakekit bridge``,
the USB latency timer, and a port that goes away."""

import os
import re
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import snakekit
from snakekit import CommunicationError, PortLostError
from snakekit.emulator import BusEmulator, Faults, make_emulated_robot
from snakekit.emulator import protocol as p
from tests.conftest import need, once_goals_arrive

need("serial")
sdk = need("dynamixel_sdk")
from snakekit import bridge as br  # noqa: E402
from snakekit.hardware import DynamixelSnake, ticks_to_radians  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BRIDGE_FILE = ROOT / "snakekit" / "bridge.py"
TARGET = np.array([0.3, -0.2, 0.1, 0.25, -0.15])


@pytest.fixture
def emulator():
    bus = BusEmulator(motion="profile", boot_time=0.02).start()
    yield bus
    bus.stop()


@pytest.fixture
def bridge(emulator):
    lines = []
    b = br.Bridge(emulator.port, "0", log=lines.append).start()
    b.lines = lines
    yield b
    b.stop()


def quiet_robot(port, **options):
    """The driver on ``port``, without the fresh emulated servos' EEPROM warning."""
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "the kit wrote its EEPROM settings")
        return snakekit.make_robot("hardware", **({} if port is None else {"port": port}), **options)


def last_goal_on_the_bus(bus) -> np.ndarray:
    """The last goal [rad] each servo received, from the emulator's own record."""
    last = {}
    for w in bus.writes(116, 4):
        if not w.dropped:
            last[w.id] = w.value
    return ticks_to_radians([last[i] for i in bus.ids])


def goal_in_message(message: str) -> np.ndarray:
    m = re.search(r"goal \[([-0-9., ]+)\] rad", message)
    assert m, message
    return np.array([float(x) for x in m.group(1).split(",")])


def assert_told_the_last_goal(message: str, bus, socket_between: bool, step: float = 0.0) -> None:
    """The message's goal is the last that reached the servos (the emulator's own record); through
    a socket, the last goal that left the driver, which may have been lost on the way (it says so).
    On the pty itself (``step``: the largest change between two goals of the run), the servos' record
    may end a goal or a few before it: the line was cut while those goals were written into it, before the
    emulator, held up by a loaded machine, had read them (a real adapter pulled out loses them the same way;
    beside stress-ng, two goals were still in the line)."""
    told, arrived = goal_in_message(message), last_goal_on_the_bus(bus)
    if not socket_between:
        # up to three goals on: three steps, plus the record's tick (2 pi / 4096) and the message's 3 decimals
        a_few_on = (np.all(np.abs(told) >= np.abs(arrived) - 1e-3)
                    and np.abs(told - arrived).max() <= 3 * step + 2 * np.pi / 4096 + 1e-3)
        assert np.allclose(told, arrived, atol=1e-3) or a_few_on, (told, arrived, step)
        return
    assert "; it may not have reached the arm)" in message
    assert np.all(np.abs(told) >= np.abs(arrived) - 1e-3) and np.allclose(told, arrived, atol=0.03)  # on the way out


def until(condition, timeout=5.0):
    end = time.perf_counter() + timeout
    while not condition():
        assert time.perf_counter() < end, "timed out"
        time.sleep(0.01)


# --- the driver through the bridge ------------------------------------------------------------------

def test_driver_runs_through_the_bridge_to_the_emulator(emulator, bridge):
    assert bridge.url.startswith("socket://127.0.0.1:")
    with quiet_robot(bridge.url) as robot:
        assert robot.port_name == bridge.url and robot.bus.latency_timer is None  # a socket has no timer
        run = robot.move_to(TARGET, duration=0.6)
        state = robot.read()
        truth = np.array([emulator.servo(i).memory.get("Present Position") for i in emulator.ids])
        assert np.allclose(state.positions, ticks_to_radians(truth), atol=1e-9)  # what the servos hold
        assert np.allclose(state.positions, TARGET, atol=0.002)
        assert run.limits_held()
    assert bridge.served == 1 and bridge.lines[0].startswith("client 127.0.0.1:")
    until(lambda: any(line.endswith(" left") for line in bridge.lines))
    assert [emulator.servo(i).memory.get("Torque Enable") for i in emulator.ids] == [0] * 5  # closed: limp


def test_faults_through_the_bridge_are_retried_or_named(emulator, bridge):
    with quiet_robot(bridge.url, watchdog=0) as robot:
        emulator.faults = Faults(drop=0.03, corrupt=0.02, seed=3)
        robot.move_to(TARGET, duration=0.6)
        emulator.faults = Faults()
        assert robot.retried > 0 and any(r.fault for r in emulator.received())
        assert np.allclose(robot.read().positions, TARGET, atol=0.002)
        emulator.faults = Faults(missing=(3,))
        with pytest.raises(CommunicationError, match=r"servo 3 on socket://127\.0\.0\.1:\d+ did not answer"):
            robot.read()
        emulator.faults = Faults()


def test_the_emulator_gone_behind_the_bridge_mid_run_is_a_port_lost_error(emulator, bridge):
    robot = quiet_robot(bridge.url)
    move = snakekit.joint_trajectory(np.zeros(5), TARGET, duration=1.0)
    once_goals_arrive(emulator, emulator.stop)
    with pytest.raises(PortLostError) as e:
        robot.run(move)
    message = str(e.value)
    assert f"the connection to the servo bus at {bridge.url} was lost" in message
    assert_told_the_last_goal(message, emulator, socket_between=True)
    assert "torque on: each servo's Bus Watchdog stops it where it is 0.5 s after the last packet" in message
    assert "start the bridge again" in message
    with pytest.raises(PortLostError, match="was lost"):  # and every later call says the same
        robot.read()
    robot.close()
    until(lambda: bridge.gone)
    assert any(f"the adapter on {emulator.port} is gone" in line and "disconnected" in line for line in bridge.lines)


def test_the_bridge_stopped_mid_run_is_a_port_lost_error(emulator, bridge):
    robot = quiet_robot(bridge.url, on_close="hold")
    move = snakekit.joint_trajectory(np.zeros(5), TARGET, duration=1.0)
    once_goals_arrive(emulator, bridge.stop)
    with pytest.raises(PortLostError) as e:
        robot.run(move)
    assert_told_the_last_goal(str(e.value), emulator, socket_between=True)
    robot.close()  # never raises on a lost port
    assert robot.closed
    # nothing reached the servos after the loss: they hold the last goal, torque on
    assert [emulator.servo(i).memory.get("Torque Enable") for i in emulator.ids] == [1] * 5


def test_the_hardware_backend_finds_its_port_in_snakekit_port(monkeypatch):
    bus = BusEmulator(motion="profile", tcp="0").start()
    try:
        monkeypatch.setenv("SNAKEKIT_PORT", bus.port)
        with quiet_robot(None, watchdog=0) as robot:
            assert robot.port_name == bus.port and robot.read().positions.shape == (5,)
        monkeypatch.delenv("SNAKEKIT_PORT")
        with pytest.raises(snakekit.ConfigurationError, match=r"needs the arm's serial port: .*or SNAKEKIT_PORT set"):
            snakekit.make_robot("hardware")
    finally:
        bus.stop()


def test_the_bridge_refuses_a_second_client(emulator, bridge):
    with quiet_robot(bridge.url, watchdog=0) as robot:
        second = socket.create_connection(bridge.address, timeout=2)
        second.sendall(p.ping(1))
        try:
            assert second.recv(100) == b""  # closed at once, nothing answered
        except ConnectionResetError:
            pass  # closed at once, with the ping unread
        second.close()
        assert robot.read().positions.shape == (5,)  # the first client is not disturbed
        until(lambda: bridge.refused == 1)
        assert any(line.startswith("refused 127.0.0.1:") and "one client at a time" in line for line in bridge.lines)


def test_the_bridge_listens_on_127_0_0_1_unless_told(emulator):
    assert br.parse_listen(None) == ("127.0.0.1", 7800)
    with br.Bridge(emulator.port, "0", log=lambda line: None) as b:
        assert b.address[0] == "127.0.0.1" and b.server.getsockname()[0] == "127.0.0.1"
    with br.Bridge(emulator.port, "0.0.0.0:0", log=lambda line: None) as b:
        assert b.address[0] == "0.0.0.0"
    with pytest.raises(br.BridgeError, match="--listen takes HOST:PORT"):
        br.parse_listen("here:there")


def test_the_bridge_holds_the_port_exclusively(emulator, bridge):
    with pytest.raises(br.BridgeError, match="another program holds it"):
        br.Bridge(emulator.port, "0", log=lambda line: None)
    with pytest.raises(snakekit.BackendError, match="in use by another program"):
        DynamixelSnake(emulator.port)


def test_the_bridge_file_runs_alone_without_the_kit(emulator, tmp_path):
    """The one file, copied out of the kit, run with numpy, mujoco and pinocchio unimportable."""
    alone = tmp_path / "bridge.py"
    alone.write_text(BRIDGE_FILE.read_text())
    blocker = textwrap.dedent("""
        import runpy, sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in ("numpy", "mujoco", "pinocchio", "snakekit"):
                    raise ImportError(f"{name} is blocked")
        sys.meta_path.insert(0, Block())
        sys.argv = sys.argv[1:]
        runpy.run_path(sys.argv[0], run_name="__main__")
    """)
    proc = subprocess.Popen([sys.executable, "-c", blocker, str(alone), emulator.port, "--listen", "0"],
                            cwd=tmp_path, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()
        m = re.search(r"serving \S+ on 127\.0\.0\.1:(\d+) \(open (socket://127\.0\.0\.1:\d+)\)", line)
        assert m, line + proc.stderr.read() if proc.poll() is not None else line
        with quiet_robot(m.group(2), watchdog=0) as robot:
            robot.command(TARGET)
            until(lambda: np.allclose(robot.read().positions, TARGET, atol=0.002))
        proc.send_signal(signal.SIGTERM)
        rest = proc.communicate(timeout=10)[1]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0
    assert re.search(r"bridge: client 127\.0\.0\.1:\d+ connected\nbridge: client 127\.0\.0\.1:\d+ left\n"
                     r"bridge: stopped \(1 client\(s\) served\)", rest), rest


def test_snakekit_bridge_says_why_it_cannot_start(tmp_path, capsys):
    from snakekit.cli import main

    assert main(["bridge", str(tmp_path / "ttyUSB9")]) == 2
    err = capsys.readouterr().err
    assert f"could not open the serial port {tmp_path / 'ttyUSB9'}" in err and "plugged in" in err
    assert main(["bridge", "/dev/null", "--listen", "nowhere"]) == 2
    assert "--listen takes HOST:PORT" in capsys.readouterr().err


# --- the TCP emulator ---------------------------------------------------------------------------

def test_the_driver_runs_on_the_tcp_emulator_with_faults():
    robot = make_emulated_robot(motion="profile", tcp="0", watchdog=0, boot_time=0.02)
    try:
        bus = robot.emulator
        assert bus.port.startswith("socket://127.0.0.1:") and robot.port_name == bus.port
        bus.faults = Faults(drop=0.03, corrupt=0.02, delay=0.01, delay_time=0.04, seed=11)
        robot.move_to(TARGET, duration=0.6)
        bus.faults = Faults()
        assert robot.retried > 0
        assert np.allclose(robot.read().positions, TARGET, atol=0.002)
        bus.inject_overload(2)
        with pytest.raises(snakekit.HardwareError, match="servo 2 .* overload"):
            robot.read()
        robot.reboot(2)
        robot.torque_on()
        assert np.allclose(robot.read().positions, TARGET, atol=0.002)
    finally:
        robot.close()


def test_the_tcp_emulator_stopped_mid_run_is_a_port_lost_error():
    robot = make_emulated_robot(motion="profile", tcp="0")
    bus = robot.emulator
    once_goals_arrive(bus, bus.stop)
    with pytest.raises(PortLostError) as e:
        robot.run(snakekit.joint_trajectory(np.zeros(5), TARGET, duration=1.0))
    assert "was lost" in str(e.value)
    assert_told_the_last_goal(str(e.value), bus, socket_between=True)
    robot.close()


def test_the_pty_closed_mid_run_is_a_port_lost_error_not_a_serial_exception():
    robot = make_emulated_robot(motion="profile")
    bus = robot.emulator
    once_goals_arrive(bus, bus.stop)
    move = snakekit.joint_trajectory(np.zeros(5), TARGET, duration=1.0)
    with pytest.raises(PortLostError) as e:
        robot.run(move)
    message = str(e.value)
    assert re.match(rf"the servo bus at {bus.port} is gone \(.+\): the USB adapter was unplugged or lost "
                    r"power\. The arm was last told, \d\.\d\d s before this was noticed: goal \[", message), message
    assert_told_the_last_goal(message, bus, socket_between=False, step=np.abs(np.diff(move.positions, axis=0)).max())
    assert isinstance(e.value.__cause__, br.PORT_ERRORS)  # termios.error or SerialException, kept as the cause
    robot.close()


def test_a_port_lost_while_idle_is_noticed_by_the_keep_alive_and_raised_by_the_next_call():
    robot = make_emulated_robot(motion="profile", watchdog=0.2)
    bus = robot.emulator
    robot.command(TARGET)
    time.sleep(0.1)
    bus.stop()
    until(lambda: robot.port.lost is not None)  # the keep-alive found it, and stopped trying
    assert robot._keepalive.failed == 1
    with pytest.raises(PortLostError) as e:
        robot.command(np.zeros(5))
    assert np.allclose(goal_in_message(str(e.value)), TARGET, atol=1e-3)
    assert "Bus Watchdog stops it where it is 0.2 s after the last packet" in str(e.value)
    robot.close()


def test_a_port_lost_while_idle_without_keep_alive_names_the_torque_and_no_goal():
    robot = make_emulated_robot(motion="profile", watchdog=0)
    robot.torque_off()
    robot.emulator.stop()
    with pytest.raises(PortLostError, match="last told no goal since start-up, torque off: it is limp"):
        robot.read()
    robot.close()


# --- the USB latency timer --------------------------------------------------------------------------

def fake_adapter(tmp_path, value=16, name="ttyUSB0"):
    """A fake sysfs tree with one FTDI adapter, and a /dev/serial/by-id style link to its tty."""
    sysfs = tmp_path / "sys"
    timer = sysfs / "bus" / "usb-serial" / "devices" / name / "latency_timer"
    timer.parent.mkdir(parents=True)
    timer.write_text(f"{value}\n")
    dev = tmp_path / "dev"
    (dev / "serial" / "by-id").mkdir(parents=True)
    (dev / name).write_text("")
    link = dev / "serial" / "by-id" / "usb-FTDI_USB__-__Serial_Converter_FT4NQ6XU-if00-port0"
    link.symlink_to(f"../../{name}")
    return sysfs, timer, link


def test_latency_timer_is_read_through_symlinks_and_set_to_1_ms(tmp_path):
    sysfs, timer, link = fake_adapter(tmp_path)
    found = br.check_latency_timer(str(link), sysfs)
    assert (found.device, found.found, found.now, found.error) == ("ttyUSB0", 16, 1, "")
    assert timer.read_text() == "1\n"
    assert found.describe() == "USB latency timer of ttyUSB0: 1 ms (was 16 ms; set by the kit)"
    again = br.check_latency_timer(str(link), sysfs)
    assert (again.found, again.now) == (1, 1)


def test_latency_timer_that_cannot_be_set_warns_once_with_the_udev_rule(tmp_path, monkeypatch):
    import warnings

    sysfs, timer, link = fake_adapter(tmp_path)
    if os.geteuid() == 0:  # root may write anything: refuse as sysfs refuses a user (or a container)
        write = Path.write_text

        def refuse(self, *args, **kwargs):
            if self == timer:
                raise PermissionError(13, "Permission denied", str(self))
            return write(self, *args, **kwargs)

        monkeypatch.setattr(Path, "write_text", refuse)
    else:
        timer.chmod(0o444)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        first = br.check_latency_timer(str(link), sysfs)
        second = br.check_latency_timer(str(link), sysfs)
    assert (first.found, first.now, first.error, second.now) == (16, 16, "Permission denied", 16)
    assert len(caught) == 1 and caught[0].category is UserWarning  # once, for two checks
    message = str(caught[0].message)
    assert message.startswith(f"the USB adapter of {link} (ttyUSB0) has its latency timer at 16 ms")
    assert "could not set it to 1 ms (Permission denied)" in message
    assert f"echo '{br.UDEV_RULE}' | sudo tee /etc/udev/rules.d/99-snakekit-ftdi.rules" in message
    assert "sudo udevadm control --reload-rules" in message
    assert timer.read_text() == "16\n"
    assert br.UDEV_RULE in (ROOT / "tools" / "99-snakekit-ftdi.rules").read_text()
    assert br.UDEV_RULE in (ROOT / "docs" / "hardware.md").read_text()


def test_ports_without_a_latency_timer_are_left_alone(tmp_path, emulator):
    sysfs, timer, _ = fake_adapter(tmp_path)
    assert br.check_latency_timer(emulator.port, sysfs) is None  # a pty
    assert br.check_latency_timer("socket://127.0.0.1:7800", sysfs) is None
    assert br.check_latency_timer("rfc2217://ttyUSB0:7800", sysfs) is None
    assert timer.read_text() == "16\n"


def test_the_driver_sets_its_adapters_latency_timer(tmp_path, monkeypatch, emulator):
    sysfs, timer, _ = fake_adapter(tmp_path, name=os.path.basename(emulator.port))  # the pty stands in for ttyUSB0
    monkeypatch.setattr(br, "SYSFS", str(sysfs))
    robot = quiet_robot(emulator.port, watchdog=0)
    try:
        assert (robot.bus.latency_timer.found, robot.bus.latency_timer.now) == (16, 1)
        assert timer.read_text() == "1\n"
    finally:
        robot.close()


def test_the_latency_timer_holds_each_of_the_drivers_replies_until_it_expires():
    """Every read's reply waits in the modelled chip for its timer (at most one period), so the
    timer sets the cycle: never more than 1 / timer a second. How fast the cycle runs against
    the bare port is a figure of ``bench/bridge.py``, not a test."""
    holds, reads = {}, 100
    for ms in (16, 1):
        robot = make_emulated_robot(motion="profile", latency_timer=ms, watchdog=0)
        try:
            assert f"USB latency timer {ms} ms" in robot.emulator.describe()
            chip = robot.emulator._chip
            chip.holds.clear()
            t0 = time.perf_counter()
            for _ in range(reads):
                robot.read()
                robot.command(np.zeros(5))
            wall = time.perf_counter() - t0
            holds[ms] = list(chip.holds)
            print(f"{ms} ms: {reads} cycles in {wall:.2f} s, {len(holds[ms])} replies held")
        finally:
            robot.close()
        # a reply (the five servos' status packets, under one chip buffer) held for each read, and
        # for each read the driver sent again after a reply that came too late on a busy machine
        assert len(holds[ms]) >= reads, (ms, len(holds[ms]))
        assert all(0 < h <= ms / 1000 + 1e-9 for h in holds[ms]), (ms, min(holds[ms]), max(holds[ms]))
        # each read waits for its own expiry of the timer: a cycle can't be shorter than the timer
        assert wall >= reads * ms / 1000 * 0.98, (ms, wall)
    # at 16 ms the replies wait for longer than the whole 1 ms timer
    assert sum(h > 0.001 for h in holds[16]) > reads / 2, sorted(holds[16])


def test_the_modelled_chip_sends_a_full_buffer_at_once_and_the_rest_when_its_timer_expires():
    bus = BusEmulator(motion="profile", tcp="0", latency_timer=255).start()
    try:
        host, port = bus.port[len("socket://"):].rsplit(":", 1)
        with socket.create_connection((host, int(port)), timeout=2) as s:
            # SYNC_READ of 140 bytes from 5 servos: 5 status packets of 151 bytes = 755 bytes, over one chip buffer
            s.sendall(p.instruction(p.BROADCAST_ID, p.SYNC_READ, bytes([0, 0, 140, 0, 1, 2, 3, 4, 5])))
            sent = time.perf_counter()
            got, times = b"", []
            while len(got) < 755:
                chunk = s.recv(4096)
                assert chunk
                got += chunk
                times.append((len(got), time.perf_counter() - sent))
        first = next(t for n, t in times if n >= 510)
        # 510 bytes at once; the rest a timer's period (255 ms) later
        assert times[-1][1] - first > 0.15, times
        assert [pk.id for pk in p.Parser().feed(got)] == [1, 2, 3, 4, 5]
    finally:
        bus.stop()


def test_emulator_options_for_tcp_and_latency_are_checked():
    with pytest.raises(snakekit.ConfigurationError, match="latency_timer is a whole number of milliseconds, 1..255"):
        BusEmulator(latency_timer=300)
    with pytest.raises(snakekit.ConfigurationError, match="the emulator's TCP address takes HOST:PORT"):
        BusEmulator(tcp="here:there")
    from snakekit.emulator import cli

    assert cli(["--latency-timer", "-1"]) == 2
