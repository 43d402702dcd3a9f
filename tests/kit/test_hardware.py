"""The hardware backend (DynamixelSnake over the real dynamixel-sdk), against the bus emulator."""

import math
import time

import numpy as np
import pytest

import snakekit
from snakekit import CommunicationError, HardwareError, LimitError
from snakekit.emulator import BusEmulator, Faults, make_emulated_robot
from snakekit.emulator.motion import ProfileMotion
from tests.conftest import need, once_goals_arrive

sdk = need("dynamixel_sdk")
from snakekit import hardware as hw  # noqa: E402

IDS = (1, 2, 3, 4, 5)
LO, HI = 1025, 3071  # +-1.57 rad in ticks, rounded inwards


@pytest.fixture
def robot():
    # no Bus Watchdog keep-alive here: these tests count the packets on the bus
    r = make_emulated_robot(motion="profile", boot_time=0.02, watchdog=0)
    yield r
    r.close()


def torques(bus):
    return [bus.servo(i).memory.get("Torque Enable") for i in IDS]


def goal_ticks_on_the_bus(bus):
    return [w.value for w in bus.writes(116, 4)]


# --- units --------------------------------------------------------------------------------------------

def test_ticks_and_radians():
    assert hw.radians_to_ticks([0.0, math.pi / 2, -math.pi / 2]).tolist() == [2048, 3072, 1024]
    assert np.allclose(hw.ticks_to_radians([2048, 3072, 0]), [0.0, math.pi / 2, -math.pi])
    assert hw.position_limit_ticks() == (LO, HI)
    assert hw.ticks_to_radians(HI) <= 1.57 < hw.ticks_to_radians(HI + 1)
    assert hw.to_signed(0xFFFFFFFF, 4) == -1 and hw.to_signed(0x8000, 2) == -32768
    assert float(hw.load_to_torque(1000)) == pytest.approx(2.5)


class _Holding(ProfileMotion):
    """Profile motion with a fixed joint torque, to check the Present Load conversion."""

    def state(self, t):
        pos, vel, _ = super().state(t)
        return pos, vel, np.array([-1.0, 0.5, 0.0, 2.5, -3.0])


def test_read_converts_ticks_velocity_and_load():
    q0 = np.array([0.3, -0.2, 0.0, 1.0, -1.5])
    bus = BusEmulator(motion=_Holding(q0), q0=q0).start()
    with hw.DynamixelSnake(bus.port) as robot:
        robot._release.append(bus.stop)
        time.sleep(0.1)  # torque-on moved each joint the fraction of a tick to its goal
        s = robot.read()
    ticks = np.rint(2048 + q0 * 4096 / (2 * np.pi))
    assert np.allclose(s.positions, (ticks - 2048) * 2 * np.pi / 4096)
    assert np.allclose(s.velocities, 0.0)
    # Present Load in 0.1 % of 2.5 N m, saturating at 100 %
    assert np.allclose(s.efforts, [-1.0, 0.5, 0.0, 2.5, -2.5])


# --- start-up -----------------------------------------------------------------------------------------

def test_start_up_configures_every_servo(robot):
    bus = robot.emulator
    for i in IDS:
        m = bus.servo(i).memory
        assert m.get("Return Delay Time") == 0
        assert (m.get("Min Position Limit"), m.get("Max Position Limit")) == (LO, HI)
        assert m.get("Profile Velocity") == hw.driver.KIT_PROFILE_VELOCITY
        assert m.get("Profile Acceleration") == snakekit.profile_planner.DEFAULT_PROFILE_ACCELERATION
        assert m.get("Torque Enable") == 1
        assert m.get("Goal Position") == 2048


def test_start_up_order_ping_torque_off_eeprom_goal_torque_on(robot):
    record = robot.emulator.received()
    for i in IDS:
        mine = [r.packet for r in record if r.packet.id == i]
        steps = []
        for pk in mine:
            if pk.name == "PING":
                steps.append("ping")
            elif pk.name == "WRITE":
                address, value = pk.params[0], int.from_bytes(pk.params[2:], "little")
                steps.append({64: f"torque {value}", 116: "goal", 9: "eeprom", 11: "eeprom", 48: "eeprom",
                              52: "eeprom"}.get(address, "ram"))
        assert steps[0] == "ping"
        assert steps.index("torque 0") < steps.index("eeprom")
        assert steps.index("goal") < steps.index("torque 1")
        assert steps.count("torque 1") == 1


def test_eeprom_is_written_only_where_it_differs():
    bus = BusEmulator(motion="profile").start()
    try:
        with hw.DynamixelSnake(bus.port):
            pass
        bus.clear_record()
        with hw.DynamixelSnake(bus.port):
            pass
        eeprom_writes = [w for a in (9, 11) for w in bus.writes(a, 1)] + bus.writes(48, 4) + bus.writes(52, 4)
        assert eeprom_writes == []
    finally:
        bus.stop()


def test_a_missing_servo_is_named_with_the_port():
    bus = BusEmulator(motion="profile", faults=Faults(missing=(3,))).start()
    try:
        with pytest.raises(CommunicationError, match=rf"no servo answered at id 3 on {bus.port} "
                                                     r"\(ping timed out, \d+ tries\); check the cable and power, or the id"):
            hw.DynamixelSnake(bus.port, retries=1)
    finally:
        bus.stop()


def test_a_servo_of_another_model_is_refused():
    bus = BusEmulator(motion="profile").start()
    bus.servo(4).memory.set("Model Number", 1060)
    try:
        with pytest.raises(hw.ServoMismatchError, match=rf"servo 4 on {bus.port} is model number 1060"):
            hw.DynamixelSnake(bus.port)
        assert torques(bus) == [0] * 5
    finally:
        bus.stop()


def test_a_servo_with_an_alert_at_start_up_is_refused_or_rebooted():
    bus = BusEmulator(motion="profile", boot_time=0.02).start()
    bus.inject_overload(2)
    try:
        with pytest.raises(HardwareError, match="servo 2 .* overload .* reboot_faulted=True"):
            hw.DynamixelSnake(bus.port)
        with hw.DynamixelSnake(bus.port, reboot_faulted=True) as robot:
            assert robot.hardware_error_status(2) == []
            assert torques(bus) == [1] * 5
    finally:
        bus.stop()


def test_bad_port_and_baud_rate_say_what_to_do():
    with pytest.raises(snakekit.BackendError, match="could not open the servo bus at /nonexistent/tty"):
        hw.DynamixelSnake("/nonexistent/tty")
    bus = BusEmulator(motion="profile").start()
    try:
        with pytest.raises(snakekit.BackendError, match="123 baud is not a rate"):
            hw.DynamixelSnake(bus.port, baudrate=123)
    finally:
        bus.stop()


def test_make_robot_maps_the_backends():
    with snakekit.make_robot("emulator", motion="profile") as robot:
        assert isinstance(robot, hw.DynamixelSnake) and robot.backend == "emulator"
        bus = robot.emulator
        assert robot.ping(1) == hw.ServoInfo(1, 30, bus.servo(1).memory.get("Firmware Version"))
    assert bus.closed and not bus._thread.is_alive()


# --- the control cycle ----------------------------------------------------------------------------------

def test_one_sync_write_and_one_sync_read_a_cycle(robot):
    bus = robot.emulator
    robot.command(np.full(5, 0.1))  # the first command reads where the arm is: its path is checked from there
    time.sleep(0.02)
    bus.clear_record()
    for _ in range(10):
        robot.read()
        robot.command(np.full(5, 0.1))
    time.sleep(0.02)  # a SyncWrite has no reply: let the emulator take the last one
    names = [r.name for r in bus.received()]
    assert names == ["SYNC_READ", "SYNC_WRITE"] * 10
    sync_read = bus.received("SYNC_READ")[0].packet.params
    assert sync_read == bytes((126, 0, 10, 0)) + bytes(IDS)   # load, velocity, position as one block
    assert goal_ticks_on_the_bus(bus) == [round(2048 + 0.1 * 4096 / (2 * np.pi))] * 50


def test_out_of_limit_goal_never_reaches_the_bus(robot):
    bus = robot.emulator
    bus.clear_record()
    with pytest.raises(LimitError):
        robot.command([0, 0, 1.6, 0, 0])
    with pytest.raises(LimitError):
        robot.run(snakekit.Trajectory([0, 1], [[0] * 5, [0, 0, 0, 0, 2.0]]))
    assert bus.writes(116, 4) == []
    assert torques(bus) == [1] * 5  # a refused command leaves the arm as it was
    robot._send(np.array([3.0, -3.0, 1.57, -1.57, 0.0]))  # past the software check: clamped at the wire
    time.sleep(0.02)
    assert goal_ticks_on_the_bus(bus) == [HI, LO, HI, LO, 2048]


def test_a_move_arrives(robot):
    run = robot.move_to([0.4, -0.3, 0.2, 0.0, -0.1], duration=0.5)
    assert run.backend == "emulator" and run.limits_held()
    assert np.allclose(robot.read().positions, [0.4, -0.3, 0.2, 0.0, -0.1], atol=0.002)


# --- faults ------------------------------------------------------------------------------------------

def test_a_few_lost_packets_are_retried(robot):
    # Each retry is one more SyncRead on the bus; the bus record counts them independently.
    # (On a very busy machine a late answer can cost a retry of its own, so "at least".)
    bus = robot.emulator
    bus.clear_record()
    before = robot.retried
    bus.faults = Faults(drop=1.0, count=2)
    s = robot.read()
    reads = bus.received("SYNC_READ")
    assert [r.fault for r in reads[:2]] == ["dropped", "dropped"] and np.allclose(s.positions, 0.0)
    assert robot.retried - before == len(reads) - 1 >= 2
    bus.clear_record()
    before = robot.retried
    bus.faults = Faults(corrupt=1.0, count=6)  # the 5 statuses of one SyncRead, the 1st of the next
    robot.read()
    assert robot.retried - before == len(bus.received("SYNC_READ")) - 1 >= 2
    bus.faults = Faults(delay=1.0, count=1, delay_time=0.05)
    robot.read()
    assert torques(bus) == [1] * 5


def test_a_lost_ping_is_retried_and_counted(robot):
    """PING goes through the same retry loop as every other request, and is counted."""
    bus = robot.emulator
    bus.clear_record()
    before = robot.retried
    bus.faults = Faults(drop=1.0, count=2)
    info = robot.ping(3)
    pings = bus.received("PING")
    assert info.model_number == 30 and info.id == 3
    assert [r.fault for r in pings[:2]] == ["dropped", "dropped"]
    assert robot.retried - before == len(pings) - 1 >= 2


def test_a_servo_lost_mid_run_stops_the_arm(robot):
    bus = robot.emulator
    bus.faults = Faults(missing=(3,))
    with pytest.raises(CommunicationError, match=r"servo 3 on .* did not answer the SyncRead") as e:
        robot.move_to(np.full(5, 0.2), duration=0.5)
    assert torques(bus)[:2] + torques(bus)[3:] == [0] * 4  # servo 3 is unplugged: nobody can reach it
    # servo 3 never confirmed torque off: the message must not claim it
    assert "servo(s) 3 did not confirm it: they may still have torque on" in str(e.value)
    assert "read back from every servo" not in str(e.value)


def test_a_dead_bus_mid_run_never_claims_torque_off(robot):
    # every packet lost: the torque-off broadcast too, so the servos keep their torque
    bus = robot.emulator
    move = snakekit.joint_trajectory(np.zeros(5), np.full(5, 0.3), duration=1.0)
    timer = once_goals_arrive(bus, lambda: setattr(bus, "faults", Faults(drop=1.0)))
    with pytest.raises(CommunicationError) as e:
        robot.run(move)
    timer.join()
    assert torques(bus) == [1] * 5  # the servos still hold torque...
    message = str(e.value)
    assert "did not confirm it: they may still have torque on" in message  # ...and the message says so
    assert "servo(s) 1, 2, 3, 4, 5" in message and "torque off, read back" not in message
    assert robot.torque_enabled
    bus.faults = Faults()


def test_a_confirmed_torque_off_is_reported_as_read_back(robot):
    bus = robot.emulator
    with pytest.raises(CommunicationError, match="torque off, read back from every servo"):
        bus.faults = Faults(corrupt=1.0, count=20)  # 4 SyncReads of 5 status packets fail, then the bus is fine
        robot.read()
    assert torques(bus) == [0] * 5 and not robot.torque_enabled


def test_a_corrupt_bus_raises_communication_error_and_leaves_torque_off(robot):
    bus = robot.emulator
    with pytest.raises(CommunicationError, match="corrupt status packet, 4 tries"):
        bus.faults = Faults(corrupt=1.0)
        robot.read()
    bus.faults = Faults()
    assert torques(bus) == [0] * 5


def test_the_retries_report_a_corrupt_answer_over_a_later_timeout(robot):
    """A try that got a corrupt status packet shows a servo answered on a noisy line; a later try
    that timed out (its answer came late on a busy computer) must not turn the message into "check
    the power or the id". Every try scripted, as the SDK returns them."""
    import dynamixel_sdk as sdk

    def tries(*results):
        it = iter(results)
        return lambda: next(it)

    bus = robot.bus
    T, C, OK = (sdk.COMM_RX_TIMEOUT, None), (sdk.COMM_RX_CORRUPT, None), (sdk.COMM_SUCCESS, 7)
    assert bus.retry(tries(C, T, T, T), tries=3) == C
    assert bus.retry(tries(T, T, C, T), tries=3) == C
    assert bus.retry(tries(T, T, T, T), tries=3) == T
    assert bus.retry(tries(C, T, OK), tries=3) == OK
    before = bus.retried
    assert bus.retry(tries(C, C, C, C), tries=3) == C and bus.retried == before + 3  # 3 sent again


def test_a_syncreads_retries_name_the_servo_that_failed_the_most_tries(robot):
    """Servo 3 unplugged: every try of a SyncRead times out at servo 3, except one whose reply a late byte
    garbled at servo 1. The message must name servo 3, not servo 1. Over every sequence of four failed
    tries at two servos: the servo named is one that failed the most tries, the first such to fail, and
    its result is corrupt when one of its own tries was, else a timeout."""
    import itertools

    import dynamixel_sdk as sdk

    from snakekit.hardware.bus import reported

    T, C = sdk.COMM_RX_TIMEOUT, sdk.COMM_RX_CORRUPT
    bus = robot.bus
    assert bus.retry(iter([(T, 3), (C, 1), (T, 3), (T, 3)]).__next__, tries=3, by_servo=True) == (T, 3)
    for seq in itertools.product([(T, 1), (C, 1), (T, 3), (C, 3)], repeat=4):
        got = reported(list(seq), by_servo=True)   # the rule Bus.retry applies, as above
        fails = {servo: [r for r, s in seq if s == servo] for servo in (1, 3)}
        most = max(len(f) for f in fails.values())
        first = next(s for _, s in seq if len(fails[s]) == most)
        assert got == (C if C in fails[first] else T, first), (seq, got)


def test_noisy_bus_never_carries_a_goal_outside_the_limits(robot):
    bus = robot.emulator
    bus.faults = Faults(drop=0.02, corrupt=0.01, delay=0.01, delay_time=0.04, seed=7)
    target = np.array([1.5, -1.5, 1.5, -1.5, 1.5])
    robot.move_to(target)  # as fast as the velocity limit allows
    bus.faults = Faults()
    goals = goal_ticks_on_the_bus(bus)
    assert len(goals) > 100 and min(goals) >= LO and max(goals) <= HI
    assert any(r.fault for r in bus.received())     # faults really happened
    assert np.allclose(robot.read().positions, target, atol=0.002)


def test_overload_mid_run_raises_hardware_error_then_reboot_recovers(robot):
    bus = robot.emulator
    bus.faults = Faults(overload=(3,), overload_after=0.2)
    with pytest.raises(HardwareError, match=r"servo 3 \(joint 3\) on .* overload \(Hardware Error Status 0x20\)"
                                            r".*robot.reboot\(3\)"):
        robot.move_to(np.full(5, 0.3), duration=1.0)
    assert torques(bus) == [0] * 5 and not robot.torque_enabled
    bus.faults = Faults()
    assert robot.hardware_error_status(3) == ["overload"]
    robot.reboot(3)
    assert robot.hardware_error_status(3) == []
    assert [r.packet.id for r in bus.received("REBOOT")] == [3]   # only the faulted servo
    m = bus.servo(3).memory
    assert m.get("Profile Velocity") == hw.driver.KIT_PROFILE_VELOCITY
    robot.torque_on()
    assert torques(bus) == [1] * 5
    robot.home(duration=1.0)
    assert np.allclose(robot.read().positions, 0.0, atol=0.002)


def test_a_fault_no_reading_saw_is_named_by_the_next_goal_not_taken_for_torque_left_off(robot):
    """A servo that overloads while no reading is taken (between runs, or after a run's last reading on a busy
    computer) turns its torque off itself: the next run raises its HardwareError at the status read before it,
    sending no goal, where it said "torque is off ... call robot.torque_on()" (which does not clear a fault), and
    before a watchdog stop of another servo.
    (Few exchanges on purpose: what follows a reboot is test_overload_mid_run_raises_hardware_error_then_reboot_recovers's.)"""
    bus = robot.emulator
    sent = len(goal_ticks_on_the_bus(bus))
    bus.inject_overload(3)
    bus.servo(2).watchdog_stop(bus.now())   # and a watchdog stop beside it: the fault, which torque_on can't clear, first
    ahead = snakekit.Trajectory(np.array([0.0, 0.3]), np.stack([np.zeros(5), np.full(5, 0.3)]))
    with pytest.raises(HardwareError, match=r"servo 3 \(joint 3\) on .* overload \(Hardware Error Status 0x20\)"
                                            r".*robot.reboot\(3\) and robot.torque_on\(\)"):
        robot.run(ahead)
    assert len(goal_ticks_on_the_bus(bus)) == sent and not robot.torque_enabled
    robot.reboot(3)
    # no fault left: the watchdog's stop is named, and what clears it, as before
    with pytest.raises(snakekit.BackendError, match=r"the Bus Watchdog stopped servo\(s\) 2 .* Call robot.torque_on\(\)"):
        robot.run(ahead)


def test_ctrl_c_inside_the_sdk_leaves_the_port_usable_and_torque_off(robot, monkeypatch):
    bus = robot.emulator
    calls = {"n": 0}
    real = robot.port.readPort

    def interrupted(length):
        calls["n"] += 1
        if calls["n"] == 50:
            raise KeyboardInterrupt
        return real(length)

    monkeypatch.setattr(robot.port, "readPort", interrupted)
    with pytest.raises(KeyboardInterrupt):
        robot.move_to(np.full(5, 0.3), duration=1.0)
    assert robot.port.is_using is False
    assert torques(bus) == [0] * 5
    robot.torque_on()
    assert torques(bus) == [1] * 5


def test_close_turns_torque_off_and_stops_the_emulator():
    robot = make_emulated_robot(motion="profile")
    bus = robot.emulator
    robot.command(np.full(5, 0.1))
    robot.close()
    assert torques(bus) == [0] * 5
    assert bus.closed
    with pytest.raises(snakekit.BackendError, match="closed"):
        robot.read()


def test_close_with_hold_keeps_torque_on_where_it_is():
    bus = BusEmulator(motion="profile").start()
    try:
        robot = hw.DynamixelSnake(bus.port, on_close="hold")
        robot.move_to(np.full(5, 0.2), duration=0.4)
        robot.close()
        assert torques(bus) == [1] * 5
        goals = [bus.servo(i).memory.get("Goal Position") for i in IDS]
        present = [bus.servo(i).memory.get("Present Position") for i in IDS]
        assert goals == present
    finally:
        bus.stop()


def test_options_are_checked():
    with pytest.raises(ValueError, match="on_close must be one of 'torque_off', 'hold'"):
        hw.DynamixelSnake("/dev/null", on_close="sleep")


# --- the study's Task 2, emulated bus vs simulator ----------------------------------------------------------

def test_task2_sweep_on_the_emulator_matches_the_simulator():
    """The Task 2 sweep's motion on the emulated bus moves like the sim: 10 of its 50 side-to-side
    sweeps (100 goals at 10 Hz, 10 s in real time, where the task's 500 goals take 50 s to repeat
    the same sweep), each at the task's amplitude and within 1 % of its period and speed.

    Tolerance: each recorded position against the closest the simulator comes within 0.1 s of
    its time stamp: RMS under 0.005 rad (typical: 0.001 at the same time on a quiet machine),
    every one within 0.02 rad (1.1 deg). The simulator gets the goals at the times the driver
    sent them; what differs is the position's 1.5 mrad tick quantisation and the reading time
    stamps: a busy machine can stall the emulator's thread between sampling a position and
    answering, which shifts stamps by tens of ms while the arm moves at up to 1.5 rad/s.
    """
    sweep = snakekit.side_sweep(points=100, sweeps=10)
    # the longest Bus Watchdog (2.54 s): the motion is compared here, and a busy machine can hold
    # this process past the default 0.5 s between two goals (the watchdog has its own tests)
    with snakekit.make_robot("emulator", watchdog=2.54) as robot:
        run = robot.run(sweep)
        bus = robot.emulator
        goals = goal_ticks_on_the_bus(bus)
        run_profile_velocity = robot.profile_velocity
    # The reference: the simulator given the same goals at the times they were actually sent
    # (a busy machine sends some late; that is the bus's timing, not its motion).
    with snakekit.make_robot("sim", profile_velocity=run_profile_velocity) as sim:
        # (no limit check here: a goal sent late makes the step after it look fast on paper)
        sim._check_trajectory = lambda trajectory: None
        reference = sim.run(run.commanded)
    assert run.backend == "emulator" and run.realtime
    # paced by the robot clock: no goal left before its time, so the run lasts at least the sweep
    # (how far a busy machine's late goals stretch it is a figure of bench/, not a test)
    assert len(run.commanded) == 100
    assert (run.commanded.times - sweep.times >= -1e-9).all()
    assert run.wall_time >= sweep.duration and reference.robot_time >= sweep.duration
    assert min(goals) >= LO and max(goals) <= HI
    lower, upper = run.spec.lower, run.spec.upper
    assert ((run.measured.positions >= lower) & (run.measured.positions <= upper)).all()
    # The measured speed is what the servos did: goals sent late make a joint catch up, so it
    # depends on the machine's load, and the simulator given the same goal times shows it too.
    # Compared at the times the servos were read: a loaded machine reads them less often, and its
    # samples can miss the top of a sweep that the simulator's every-step record catches.
    t = run.measured.times
    ref_speed = np.column_stack([np.interp(t, reference.measured.times, reference.measured.velocities[:, j])
                                 for j in range(5)])
    assert np.allclose(run.peak_speeds(), np.abs(ref_speed).max(axis=0), atol=0.05)
    ref = np.column_stack([np.interp(t, reference.measured.times, reference.measured.positions[:, j])
                           for j in range(5)])
    diff = np.abs(run.measured.positions - ref)
    nearest = diff
    for shift in np.arange(-0.1, 0.1001, 0.005):  # the closest the reference comes within +-0.1 s
        shifted = np.column_stack([np.interp(t + shift, reference.measured.times, reference.measured.positions[:, j])
                                   for j in range(5)])
        nearest = np.minimum(nearest, np.abs(run.measured.positions - shifted))
    rms = np.sqrt((nearest ** 2).mean())
    assert rms < 0.005, (rms, np.sqrt((diff ** 2).mean()))
    assert nearest.max() < 0.02, (nearest.max(axis=0), diff.max(axis=0))
    assert np.allclose(run.tracking_error(), reference.tracking_error(), atol=0.02)
    assert run.final_distance_from_home() < 0.002


def test_two_threads_share_the_bus_without_port_busy(robot):
    import threading

    errors = []

    def reader():
        try:
            for _ in range(100):
                robot.read()
        except Exception as e:  # pragma: no cover - the failure being tested for
            errors.append(e)

    bus = robot.emulator
    robot.command(np.full(5, 0.05))  # the first command reads where the arm is: its path is checked from there
    time.sleep(0.02)
    bus.clear_record()
    retried = robot.retried
    threads = [threading.Thread(target=reader) for _ in range(2)]
    for t in threads:
        t.start()
    for _ in range(100):
        robot.command(np.full(5, 0.05))
    for t in threads:
        t.join()
    robot.read()  # answered only after the bus has taken every packet sent before it
    assert errors == []
    # Interleaved packets would reach the bus garbled: every packet arrived whole, and each
    # request was sent once, or again only after a timeout (a busy machine can cause one).
    got = bus.received()
    assert all(r.packet.crc_ok for r in got)
    assert {r.packet.name for r in got} == {"SYNC_READ", "SYNC_WRITE"}
    assert len(bus.received("SYNC_WRITE")) == 100
    assert len(bus.received("SYNC_READ")) == 201 + robot.retried - retried
