"""The bus emulator, driven by the real dynamixel-sdk over its pseudo-terminal."""

import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from snakekit.emulator import BusEmulator, Faults
from snakekit.emulator import protocol as p
from snakekit.profile_planner import ProfilePlanner
from tests.conftest import need, sdk_read

sdk = need("dynamixel_sdk")
serial = need("serial")

IDS = (1, 2, 3, 4, 5)
#: the SDK waits 2 x its LATENCY_TIMER + 2 ms for a reply (34 ms); a busy machine can hold the
#: emulator's thread that long, so the tests give it 200 ms: a bound for a hang (a reply takes
#: well under a millisecond on a quiet machine)
SDK_LATENCY_TIMER = 99


@pytest.fixture(autouse=True)
def patient_sdk(monkeypatch):
    monkeypatch.setattr(sdk.port_handler, "LATENCY_TIMER", SDK_LATENCY_TIMER)


@pytest.fixture
def bus():
    emulator = BusEmulator(motion="profile", boot_time=0.5).start()
    yield emulator
    emulator.stop()


@pytest.fixture
def client(bus):
    port = sdk.PortHandler(bus.port)
    assert port.openPort() and port.setBaudRate(4_000_000)
    yield port, sdk.PacketHandler(2.0)
    port.closePort()


def until(condition, timeout: float = 5.0) -> bool:
    """True once ``condition()`` holds (a packet the emulator's thread has yet to handle on a
    busy machine); False after ``timeout`` [s], a bound for a hang."""
    end = time.perf_counter() + timeout
    while not condition():
        if time.perf_counter() > end:
            return False
        time.sleep(0.005)
    return True


def raw_exchange(bus, packet: bytes, wait: float = 0.3) -> bytes:
    """Send raw bytes with pyserial and return every byte that comes back within ``wait``."""
    with serial.Serial(bus.port, 4_000_000, timeout=0) as s:
        s.reset_input_buffer()
        s.write(packet)
        end, out = time.perf_counter() + wait, b""
        while time.perf_counter() < end:
            out += s.read(256)
        return out


# --- PING ---------------------------------------------------------------------------------------

def test_every_servo_answers_ping_with_model_30(client):
    port, ph = client
    for i in IDS:
        model, result, error = ph.ping(port, i)
        assert (model, result, error) == (30, sdk.COMM_SUCCESS, 0)


def test_broadcast_ping_finds_all_five(client):
    port, ph = client
    found, result = ph.broadcastPing(port)
    assert result == sdk.COMM_SUCCESS
    assert sorted(found) == list(IDS) and all(v[0] == 30 for v in found.values())


def test_ping_reply_is_the_e_manual_packet(bus):
    reply = raw_exchange(bus, p.ping(1))
    # 14 bytes: header, id 1, len 7, 0x55, err 0, model 30 (1E 00), firmware
    fw = bus.servo(1).memory.get("Firmware Version")
    assert reply == p.status(1, 0, bytes((0x1E, 0x00, fw)))
    assert len(reply) == 14


def test_nobody_answers_an_unknown_id(client):
    port, ph = client
    _, result, _ = ph.ping(port, 42)
    assert result == sdk.COMM_RX_TIMEOUT


# --- READ / WRITE and the control table -------------------------------------------------------------

def test_write_then_read_back(client, bus):
    port, ph = client
    assert ph.write1ByteTxRx(port, 2, 65, 1) == (sdk.COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 2, 65) == (1, sdk.COMM_SUCCESS, 0)
    assert bus.servo(2).memory.get("LED") == 1 and bus.servo(1).memory.get("LED") == 0


def test_defaults_of_the_control_table(client):
    port, ph = client
    assert sdk_read(ph, port, 1, 0, 2) == 30          # model number
    assert sdk_read(ph, port, 1, 9, 1) == 250          # return delay 500 us
    assert sdk_read(ph, port, 1, 11, 1) == 3           # position mode
    assert sdk_read(ph, port, 1, 48, 4) == 4095        # max position limit
    assert sdk_read(ph, port, 1, 63, 1) == 52          # shutdown
    assert sdk_read(ph, port, 1, 68, 1) == 2           # status return level
    assert sdk_read(ph, port, 1, 84, 2) == 850         # position P gain
    assert sdk_read(ph, port, 1, 132, 4) == 2048       # at home


def test_homing_offset_needing_stuffing_goes_both_ways(client, bus):
    port, ph = client
    params = bytes((20, 0)) + bytes.fromhex("ff ff fd ff")  # -131073: the header pattern in the data
    # stuffed on the way in (built by our framing, sent with pyserial)
    stuffed = p.instruction(2, p.WRITE, params)
    assert b"\xff\xff\xfd\xfd" in stuffed
    assert p.decode(raw_exchange(bus, stuffed)).error == 0
    assert bus.received("WRITE")[-1].packet.params == params
    assert bus.servo(2).memory.get("Homing Offset") == -131073
    # the SDK 4.1.0 drops the result of its own addStuffing and sends the packet unstuffed;
    # the emulator reads by length, so the value arrives either way
    assert ph.write4ByteTxRx(port, 1, 20, (-131073) & 0xFFFFFFFF) == (sdk.COMM_SUCCESS, 0)
    assert bus.received("WRITE")[-1].packet.params == params
    assert bus.servo(1).memory.get("Homing Offset") == -131073
    # stuffed on the way out, unstuffed by the SDK
    reply = raw_exchange(bus, p.instruction(1, p.READ, bytes((20, 0, 4, 0))))
    assert b"\xff\xff\xfd\xfd" in reply
    assert reply == p.status(1, 0, bytes.fromhex("ff ff fd ff"))
    value, result, error = ph.read4ByteTxRx(port, 1, 20)
    assert (result, error) == (sdk.COMM_SUCCESS, 0)
    assert value - (1 << 32) == -131073
    # Present Position = motor position + Homing Offset
    assert sdk_read(ph, port, 1, 132, 4) - (1 << 32) == 2048 - 131073


def test_bad_crc_gets_a_crc_error_status(bus):
    packet = bytearray(p.instruction(3, p.READ, bytes((132, 0, 4, 0))))
    packet[-2] ^= 0x01
    reply = p.decode(raw_exchange(bus, bytes(packet)))
    assert (reply.id, reply.error, reply.params) == (3, p.CRC_ERROR, b"")
    assert not bus.received()[-1].packet.crc_ok


def test_eeprom_write_with_torque_on_is_an_access_error(client, bus):
    port, ph = client
    assert ph.write1ByteTxRx(port, 1, 64, 1) == (sdk.COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, 9, 0) == (sdk.COMM_SUCCESS, p.ACCESS_ERROR)
    assert bus.servo(1).memory.get("Return Delay Time") == 250
    assert ph.write1ByteTxRx(port, 1, 64, 0)[1] == 0
    assert ph.write1ByteTxRx(port, 1, 9, 0) == (sdk.COMM_SUCCESS, 0)


@pytest.mark.parametrize("address, size, value, error", [
    (0, 2, 12, p.ACCESS_ERROR),              # Model Number is read-only
    (14, 1, 0, p.ACCESS_ERROR),              # a gap in the table
    (200, 1, 0, p.ACCESS_ERROR),             # past the table (indirect data not modelled)
    (11, 1, 2, p.DATA_RANGE_ERROR),          # no operating mode 2
    (8, 1, 9, p.DATA_RANGE_ERROR),           # baud rate index 9
    (117, 2, 0, p.DATA_LENGTH_ERROR),        # half of Goal Position
])
def test_bad_writes_are_refused_with_the_right_error(client, bus, address, size, value, error):
    port, ph = client
    write = {1: ph.write1ByteTxRx, 2: ph.write2ByteTxRx}[size]
    before = bytes(bus.servo(4).memory.data)
    assert write(port, 4, address, value) == (sdk.COMM_SUCCESS, error)
    assert bytes(bus.servo(4).memory.data) == before


def test_goal_outside_the_position_limits_is_a_data_limit_error(client, bus):
    port, ph = client
    assert ph.write4ByteTxRx(port, 2, 48, 3071) == (sdk.COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 2, 116, 3072) == (sdk.COMM_SUCCESS, p.DATA_LIMIT_ERROR)
    assert ph.write4ByteTxRx(port, 2, 116, 3071) == (sdk.COMM_SUCCESS, 0)
    assert bus.servo(2).memory.get("Goal Position") == 3071


def test_broadcast_write_reaches_all_and_gets_no_status(client, bus):
    port, ph = client
    result, _ = ph.write1ByteTxRx(port, sdk.BROADCAST_ID, 65, 1)
    assert result == sdk.COMM_SUCCESS  # the SDK does not wait for a status from broadcast
    assert until(lambda: [bus.servo(i).memory.get("LED") for i in IDS] == [1] * 5)
    assert raw_exchange(bus, p.instruction(p.BROADCAST_ID, p.WRITE, bytes((65, 0, 0)))) == b""


def test_status_return_level_decides_who_answers(client, bus):
    port, ph = client
    assert ph.write1ByteTxRx(port, 5, 68, 1) == (sdk.COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 5, 65, 1)[0] == sdk.COMM_RX_TIMEOUT   # a write: no status now
    assert bus.servo(5).memory.get("LED") == 1                          # ...but it was done
    assert ph.read1ByteTxRx(port, 5, 65) == (1, sdk.COMM_SUCCESS, 0)    # reads still answer
    ph.write1ByteTxOnly(port, 5, 68, 0)
    assert until(lambda: bus.servo(5).memory.get("Status Return Level") == 0)
    assert ph.read1ByteTxRx(port, 5, 65)[1] == sdk.COMM_RX_TIMEOUT
    assert ph.ping(port, 5)[1] == sdk.COMM_SUCCESS                      # ping always answers


def test_unsupported_instruction_is_an_instruction_error(bus):
    reply = p.decode(raw_exchange(bus, p.instruction(2, 0x10, bytes((1, 0x44, 0x58, 0x4C, 0x22)))))
    assert reply.error == p.INSTRUCTION_ERROR
    # Fast Sync Read (0x8A) does not exist on the MX-28: nobody answers
    assert raw_exchange(bus, p.instruction(p.BROADCAST_ID, 0x8A, bytes((132, 0, 4, 0, 1, 2)))) == b""


# --- REG_WRITE / ACTION, REBOOT, FACTORY_RESET ---------------------------------------------------

def test_reg_write_waits_for_action(client, bus):
    port, ph = client
    data = [0x00, 0x09, 0, 0]  # 2304 ticks
    assert ph.regWriteTxRx(port, 3, 116, 4, data) == (sdk.COMM_SUCCESS, 0)
    assert bus.servo(3).memory.get("Goal Position") == 2048  # the firmware starts with goal = present
    assert sdk_read(ph, port, 3, 69, 1) == 1             # Registered Instruction
    assert ph.action(port, sdk.BROADCAST_ID) == sdk.COMM_SUCCESS
    assert until(lambda: bus.servo(3).memory.get("Goal Position") == 2304)
    assert sdk_read(ph, port, 3, 69, 1) == 0


def test_reboot_clears_an_overload_and_ram_only(client, bus):
    port, ph = client
    assert ph.write1ByteTxRx(port, 2, 9, 0)[1] == 0                  # EEPROM survives a reboot
    assert ph.write4ByteTxRx(port, 2, 112, 62)[1] == 0               # RAM does not
    assert ph.write1ByteTxRx(port, 2, 64, 1)[1] == 0
    bus.inject_overload(2)
    model, result, error = ph.ping(port, 2)
    assert result == sdk.COMM_SUCCESS and error & p.ALERT
    assert sdk_read(ph, port, 2, 70, 1) == 0x20                  # overload bit
    assert sdk_read(ph, port, 2, 64, 1) == 0                     # the firmware cut torque
    assert ph.write1ByteTxRx(port, 2, 64, 1)[1] & p.ALERT            # and won't give it back
    assert sdk_read(ph, port, 2, 64, 1) == 0
    assert ph.reboot(port, 2) == (sdk.COMM_SUCCESS, p.ALERT)              # answered before it reboots
    assert ph.ping(port, 2)[1] == sdk.COMM_RX_TIMEOUT                 # still booting (0.5 s)
    assert until(lambda: ph.ping(port, 2)[1] == sdk.COMM_SUCCESS)
    assert ph.read1ByteTxRx(port, 2, 70) == (0, sdk.COMM_SUCCESS, 0)
    assert sdk_read(ph, port, 2, 112, 4) == 0
    assert sdk_read(ph, port, 2, 9, 1) == 0
    assert [r.packet.id for r in bus.received("REBOOT")] == [2]


def test_factory_reset_keeping_id_and_baud(client, bus):
    port, ph = client
    assert ph.write1ByteTxRx(port, 4, 9, 0)[1] == 0
    assert ph.write1ByteTxRx(port, 4, 8, 3)[1] == 0
    assert ph.factoryReset(port, 4, 0x02) == (sdk.COMM_SUCCESS, 0)
    assert until(lambda: ph.ping(port, 4)[1] == sdk.COMM_SUCCESS)
    assert sdk_read(ph, port, 4, 9, 1) == 250
    assert sdk_read(ph, port, 4, 8, 1) == 3
    assert ph.factoryReset(port, 4, 0x01) == (sdk.COMM_SUCCESS, 0)
    assert until(lambda: ph.ping(port, 4)[1] == sdk.COMM_SUCCESS)
    assert sdk_read(ph, port, 4, 8, 1) == 1


# --- SYNC and BULK ----------------------------------------------------------------------------------

def test_sync_write_then_sync_read_of_the_state_block(client, bus):
    port, ph = client
    writer = sdk.GroupSyncWrite(port, ph, 116, 4)
    goals = {i: 2048 + 100 * i for i in IDS}
    for i, g in goals.items():
        assert writer.addParam(i, list(g.to_bytes(4, "little")))
    assert writer.txPacket() == sdk.COMM_SUCCESS
    assert until(lambda: {i: bus.servo(i).memory.get("Goal Position") for i in IDS} == goals)
    reader = sdk.GroupSyncRead(port, ph, 126, 10)
    for i in IDS:
        reader.addParam(i)
    assert reader.txRxPacket() == sdk.COMM_SUCCESS
    for i in IDS:
        assert reader.isAvailable(i, 126, 10)
        assert reader.getData(i, 132, 4) == 2048          # torque off: nobody moved
        assert reader.getData(i, 128, 4) == 0


def test_bulk_read_and_bulk_write_mix_addresses(client, bus):
    port, ph = client
    bw = sdk.GroupBulkWrite(port, ph)
    assert bw.addParam(1, 65, 1, [1])
    assert bw.addParam(3, 112, 4, list((70).to_bytes(4, "little")))
    assert bw.txPacket() == sdk.COMM_SUCCESS
    assert until(lambda: bus.servo(1).memory.get("LED") == 1 and bus.servo(3).memory.get("Profile Velocity") == 70)
    br = sdk.GroupBulkRead(port, ph)
    assert br.addParam(1, 65, 1) and br.addParam(3, 112, 4) and br.addParam(5, 0, 2)
    assert br.txRxPacket() == sdk.COMM_SUCCESS
    assert (br.getData(1, 65, 1), br.getData(3, 112, 4), br.getData(5, 0, 2)) == (1, 70, 30)


def test_sync_read_of_a_negative_velocity_needs_stuffing(client, bus):
    port, ph = client
    bus.servo(2).memory.set("Homing Offset", -(1 << 20) + 3)  # any big negative number
    reply = raw_exchange(bus, p.instruction(2, p.READ, bytes((20, 0, 4, 0))))
    assert p.decode(reply).params == ((-(1 << 20) + 3) & 0xFFFFFFFF).to_bytes(4, "little")


# --- motion -------------------------------------------------------------------------------------------

def test_a_goal_moves_the_servo_along_the_firmware_profile(client, bus):
    port, ph = client
    for addr, value in ((108, 100), (112, 62)):
        assert ph.write4ByteTxRx(port, 1, addr, value)[1] == 0
    assert ph.write4ByteTxRx(port, 1, 116, 2048)[1] == 0
    assert ph.write1ByteTxRx(port, 1, 64, 1)[1] == 0
    assert ph.write4ByteTxRx(port, 1, 116, 2048 + 512)[1] == 0
    t_goal = bus.received("WRITE")[-1].time  # when the servo took the goal
    planner = ProfilePlanner([0.0], 62, 100, t=t_goal)
    planner.set_goal(t_goal, [512 * 2 * np.pi / 4096])
    samples = []
    while bus.now() - t_goal < 0.8:
        before = bus.now()
        ticks, result, _ = ph.read4ByteTxRx(port, 1, 132)
        samples.append((before, bus.now(), ticks))
        time.sleep(0.02)
    to_ticks = 4096 / (2 * np.pi)
    for before, after, ticks in samples:
        # the servo was sampled between the two time stamps; the reference only increases
        low = 2048 + planner.at(before)[0][0] * to_ticks
        high = 2048 + planner.at(after)[0][0] * to_ticks
        assert low - 0.5 <= ticks <= high + 0.5, (before - t_goal, ticks, low, high)
    assert samples[-1][2] == 2048 + 512
    assert sdk_read(ph, port, 1, 122, 1) == 0  # not moving any more


# --- faults -------------------------------------------------------------------------------------------

def test_missing_servo_never_answers(client, bus):
    port, ph = client
    bus.faults = Faults(missing=(3,))
    assert ph.ping(port, 3)[1] == sdk.COMM_RX_TIMEOUT
    assert ph.ping(port, 4)[1] == sdk.COMM_SUCCESS
    bus.faults = Faults()
    assert ph.ping(port, 3)[1] == sdk.COMM_SUCCESS


def test_dropped_packets_get_no_answer_and_are_recorded(client, bus):
    port, ph = client
    bus.faults = Faults(drop=1.0, count=2)
    assert ph.ping(port, 1)[1] == sdk.COMM_RX_TIMEOUT
    assert ph.write1ByteTxRx(port, 1, 65, 1)[0] == sdk.COMM_RX_TIMEOUT
    assert bus.servo(1).memory.get("LED") == 0
    assert ph.ping(port, 1)[1] == sdk.COMM_SUCCESS
    assert [r.fault for r in bus.received()[-3:]] == ["dropped", "dropped", ""]


def test_corrupted_status_is_seen_as_corrupt(client, bus):
    port, ph = client
    bus.faults = Faults(corrupt=1.0, count=1)
    assert ph.read4ByteTxRx(port, 1, 132)[1] == sdk.COMM_RX_CORRUPT
    assert ph.read4ByteTxRx(port, 1, 132)[:2] == (2048, sdk.COMM_SUCCESS)


def test_delayed_reply_times_out(client, bus):
    port, ph = client
    bus.faults = Faults(delay=1.0, delay_time=1.0, count=1)
    # the SDK gives up (after 0.2 s) before the reply held back 1 s comes (a reply in time would be a success)
    assert ph.ping(port, 1)[1] == sdk.COMM_RX_TIMEOUT
    assert bus.received()[-1].fault == "delayed"
    time.sleep(1.2)  # the late reply came and went
    port.clearPort()
    assert ph.ping(port, 1)[1] == sdk.COMM_SUCCESS


def test_scheduled_overload_from_faults(client, bus):
    port, ph = client
    bus.faults = Faults(overload=(5,), overload_after=0.5)
    assert ph.ping(port, 5)[2] == 0
    time.sleep(0.6)
    assert ph.ping(port, 5)[2] == p.ALERT
    assert sdk_read(ph, port, 5, 70, 1) == 0x20


def test_faults_refuse_nonsense():
    with pytest.raises(ValueError, match="probability"):
        Faults(drop=1.5)


#: How much slower the fastest ping with the default Return Delay Time (0.5 ms) must be than the fastest with 0.
#: Without the delay emulated the two are alike (within 0.1 ms); with it, a loaded run measured 0.44 ms once (the
#: fastest ping of each side carries its own share of the machine's noise), so the bound is well under 0.5 ms.
SLOWER = 0.0003


def test_return_delay_is_emulated_when_timing_is_on():
    # Noise on a busy machine only ever adds time, so the fastest of many pings shows the
    # emulated delay: 250 x 2 us = 0.5 ms more with the default Return Delay Time than with 0.
    # A ping the SDK gave up on (the emulator's thread held up past the SDK's 34 ms timeout on a
    # loaded machine) is no timing sample: it is tried again, a few of them at most.
    def fastest_ping(ph, port):
        times, failed = [], []
        while len(times) < 40:
            t = time.perf_counter()
            result = ph.ping(port, 1)[1]
            if result == sdk.COMM_SUCCESS:
                times.append(time.perf_counter() - t)
            else:
                failed.append(result)
                assert len(failed) <= 4, f"{len(failed)} pings failed ({failed}) for {len(times)} answered"
                time.sleep(0.05)
                port.clearPort()
        return min(times)

    def set_delay(ph, port, value):
        for _ in range(3):  # as the pings: a write the SDK gave up on under load is sent again
            if ph.write1ByteTxRx(port, 1, 9, value) == (sdk.COMM_SUCCESS, 0):
                break
            time.sleep(0.05)
            port.clearPort()
        assert sdk_read(ph, port, 1, 9, 1) == value

    # Up to 5 rounds of 40 pings each way, each side's fastest kept: on a loaded machine 40 pings may
    # all carry some noise, and more of them only bring each fastest closer to its true time.
    with BusEmulator(motion="profile", timing=True) as bus:
        port = sdk.PortHandler(bus.port)
        port.openPort()
        port.setBaudRate(1_000_000)
        ph = sdk.PacketHandler(2.0)
        assert sdk_read(ph, port, 1, 9, 1) == 250
        slow = fast = float("inf")
        for _ in range(5):
            set_delay(ph, port, 250)
            slow = min(slow, fastest_ping(ph, port))
            set_delay(ph, port, 0)
            fast = min(fast, fastest_ping(ph, port))
            if SLOWER < slow - fast < 0.002:
                break
        port.closePort()
    assert SLOWER < slow - fast < 0.002, (slow, fast)


def test_a_stall_of_the_emulators_thread_after_a_read_is_not_the_clients_silence(client, bus, monkeypatch):
    """The Bus Watchdog goes by when a packet reached the servos. A machine that holds the emulator's thread up
    after it read the bytes (another thread's long call under load) must not trip it: the client was not quiet,
    only the reading was late. Seen beside stress-ng: lesson 07's instructor run stopped by the watchdog."""
    port, ph = client
    assert ph.write1ByteTxRx(port, 1, 98, 25)[:2] == (sdk.COMM_SUCCESS, 0)    # Bus Watchdog 0.5 s
    assert ph.write1ByteTxRx(port, 1, 64, 1)[:2] == (sdk.COMM_SUCCESS, 0)     # torque on
    feed, calls, held = bus._parser.feed, [], 0.8
    held_at = []

    def late_feed(data):   # the bytes are read; then the thread is held up for longer than the period
        calls.append(1)
        if len(calls) == 10:
            held_at.append(bus.now())
            time.sleep(held)
        return feed(data)

    monkeypatch.setattr(bus._parser, "feed", late_feed)
    end = time.perf_counter() + 2.0
    while time.perf_counter() < end:   # the client: a goal every 50 ms, never quiet for long
        ph.write4ByteTxOnly(port, 1, 116, 2048)
        time.sleep(0.05)
    assert held_at, "the emulator's thread was never held up: the test did not test"
    assert sdk_read(ph, port, 1, 98, 1) == 25, "the Bus Watchdog fired although the client never went quiet"
    # the client's real silence still trips it: nothing for longer than the period
    time.sleep(0.8)
    assert until(lambda: bus.servo(1).memory.get("Bus Watchdog") == -1)


# --- the command line -------------------------------------------------------------------------------

def test_cli_prints_the_port_and_stops_on_ctrl_c():
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys; from snakekit.emulator import cli; sys.exit(cli(sys.argv[1:]))",
         "--motion", "profile", "--missing", "5"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = [proc.stdout.readline() for _ in range(3)]
        line = lines[0]
        m = re.match(r"emulator: 5 MX-28 servos \(ids 1-5\) on (\S+) at 4000000 baud", line)
        assert m, line
        port = sdk.PortHandler(m.group(1))
        assert port.openPort() and port.setBaudRate(4_000_000)
        ph = sdk.PacketHandler(2.0)
        assert ph.ping(port, 1)[:2] == (30, sdk.COMM_SUCCESS)
        assert ph.ping(port, 5)[1] == sdk.COMM_RX_TIMEOUT
        port.closePort()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert lines[1] == "faults: servo(s) 5 missing\n"
    assert "emulator stopped" in out


def test_cli_rejects_bad_options(capsys):
    from snakekit.emulator import cli
    assert cli(["--ids", "1,2"]) == 2
    assert "ids must be 5 distinct" in capsys.readouterr().err


def test_stop_closes_the_pty(bus):
    path = bus.port
    bus.stop()
    assert not bus._thread.is_alive()
    with pytest.raises(OSError):
        os.fstat(bus._line.master)
    assert path
