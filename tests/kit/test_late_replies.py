"""Only what the servos said: late, dropped and corrupted replies are never read as the arm's state,
and nothing the driver sends is made from a reading it could not verify.

Every reading is compared with the emulator's own true state over the time the request was on
the bus, and every goal the emulator received with the path the test asked for.
"""

import math
import multiprocessing
import re
import time

import numpy as np
import pytest

import snakekit
from snakekit.emulator import BusEmulator, Faults, make_emulated_robot
from snakekit.emulator.motion import ProfileMotion
from tests.conftest import need

sdk = need("dynamixel_sdk")
from snakekit import hardware as hw  # noqa: E402

pytestmark = pytest.mark.filterwarnings("ignore:the kit wrote its EEPROM settings")

TICK = 2 * math.pi / 4096
PATH_LO, PATH_HI = 0.0, 0.3  # the joint angles the test commands [rad]


def true_range(bus, t_a, t_b, samples=40):
    """The lowest and highest true joint angles of the emulated arm between ``t_a`` and ``t_b``
    (emulator clock [s])."""
    qs = np.array([bus.motion.state(t)[0] for t in np.linspace(t_a, t_b, samples)])
    return qs.min(axis=0), qs.max(axis=0)


def drive_and_read(robot, n, gap):
    """Command a slow back-and-forth inside [PATH_LO, PATH_HI] and read after each goal.

    A Bus Watchdog stop is counted with the communication errors: with packets dropped on
    purpose, a few in a row (or the process held up on a loaded machine) leave the servos
    hearing nothing for the watchdog's period, and they stop, as on the real arm; a student
    turns the torque on again. More than two such stops in a run fail the test: the keep-alive
    is not doing its work.

    Returns (wrong readings, communication errors and watchdog stops, readings checked)."""
    bus = robot.emulator
    wrong, errors, checked, stops = [], 0, 0, []
    for k in range(n):
        q = np.full(5, PATH_LO + (PATH_HI - PATH_LO) * 0.5 * (1 - math.cos(2 * math.pi * k / 20)))
        try:
            robot.command(q)
            t_a = bus.now()
            s = robot.read()
            t_b = bus.now()
        except snakekit.BackendError as e:  # CommunicationError is one
            if not isinstance(e, snakekit.CommunicationError):
                if "Bus Watchdog stopped" not in str(e):
                    raise
                stops.append(k)
                assert len(stops) <= 2, f"the Bus Watchdog stopped the arm at goals {stops} of {n}"
            errors += 1
            for _ in range(5):  # the error stopped the arm; a student starts again until torque is on
                try:
                    robot.torque_on()
                    break
                except snakekit.CommunicationError:  # torque stays off: the next command would be refused
                    errors += 1
            continue
        lo, hi = true_range(bus, t_a - 1e-3, t_b)
        off = np.maximum(lo - s.positions, s.positions - hi)
        if off.max() > 2 * TICK or np.abs(s.velocities).max() > 2.0:
            wrong.append((k, s.positions.round(4).tolist(), s.velocities.round(3).tolist()))
        checked += 1
        time.sleep(gap)  # longer than a quarter of the watchdog: the keep-alive reads in between
    return wrong, errors, checked


def goals_off_the_path(bus):
    """Goal Position writes outside [PATH_LO, PATH_HI] (the start-up's goal = present = home aside)."""
    lo, hi = hw.radians_to_ticks(PATH_LO) - 2, hw.radians_to_ticks(PATH_HI) + 2
    return [(round(w.time, 3), w.id, w.value) for w in bus.writes(116, 4) if not lo <= w.value <= hi]


@pytest.mark.parametrize("faults", [
    Faults(delay=0.3, delay_time=0.1, seed=5),
    Faults(delay=0.15, delay_time=0.06, seed=11),
    Faults(corrupt=0.08, seed=3),
    Faults(drop=0.1, seed=4),
    Faults(drop=0.05, corrupt=0.05, delay=0.1, delay_time=0.08, seed=8),
], ids=lambda f: f.describe())
def test_no_reading_differs_from_the_arms_true_state(faults):
    robot = make_emulated_robot(motion="profile", on_close="hold", watchdog=0.5)
    bus = robot.emulator
    try:
        bus.faults = faults
        wrong, errors, checked = drive_and_read(robot, 40, gap=0.13)
        robot.close()
        assert wrong == [], f"readings that were not the arm's state: {wrong[:3]}"
        assert checked >= 30, f"only {checked} of 40 reads answered ({errors} communication errors)"
        assert goals_off_the_path(bus) == []
    finally:
        robot.close()


def test_late_status_packets_are_drained_and_counted():
    robot = make_emulated_robot(motion="profile", watchdog=0.5)
    try:
        robot.emulator.faults = Faults(delay=0.3, delay_time=0.1, seed=5)
        wrong, _, _ = drive_and_read(robot, 30, gap=0.13)
        assert wrong == []
        assert robot.bus.stray_bytes > 0  # the late replies arrived, and were thrown away
        # learnt from them: 100 ms late, plus what a loaded machine adds; the quiet wait follows
        assert 0.09 <= robot.bus.lateness <= 0.4
        assert robot.bus.quiet_time >= 1.25 * 0.09
    finally:
        robot.close()


def _emulator_process(conn, faults):
    """A bus emulator in a process of its own (as `snakekit emulator` runs): its port out, then,
    when asked, every servo's torque and goal and every goal written."""
    bus = BusEmulator(motion="profile").start()
    conn.send(bus.port)
    conn.recv()  # the robot has started
    bus.faults = faults
    conn.recv()
    conn.send(([(bus.servo(i).memory.get("Torque Enable"), bus.servo(i).memory.get("Goal Position"))
                for i in bus.ids], [w.value for w in bus.writes(116, 4)]))
    bus.stop()


def test_close_with_hold_under_late_replies_never_sends_a_far_goal():
    """The issue's case: the arm at rest at 0, 30 % of replies 100 ms late (the emulator in its
    own process), readings between the keep-alive's; close(hold) had sent every joint to
    -1.57 rad from a misread state."""
    ctx = multiprocessing.get_context("fork")
    for seed in (5, 6):
        here, there = ctx.Pipe()
        proc = ctx.Process(target=_emulator_process, args=(there, Faults(delay=0.3, delay_time=0.1, seed=seed)))
        proc.start()
        try:
            robot = hw.DynamixelSnake(here.recv(), on_close="hold")
            here.send("faults on")
            for _ in range(40):
                try:
                    robot.read()
                except snakekit.CommunicationError:
                    robot.torque_on()
                time.sleep(0.13)
            robot.close()
            here.send("report")
            servos, goals = here.recv()
            for i, (torque, goal) in enumerate(servos, start=1):
                assert torque == 0 or abs(goal - 2048) <= 2, f"servo {i}: goal {goal} with torque on"
            assert [g for g in goals if abs(g - 2048) > 2] == []
        finally:
            proc.join(timeout=10)
            proc.kill()


def test_hold_says_which_servos_hold_and_which_went_limp():
    robot = make_emulated_robot(motion="profile", on_close="hold", watchdog=0)
    bus = robot.emulator
    try:
        robot.move_to(np.full(5, 0.2), duration=0.4)
        bus.faults = Faults(missing=(3,))
        message = robot.stop()
        assert "servo(s) 1, 2, 4, 5 hold where they are" in message
        assert "servo(s) 3 could not be read reliably" in message
        for i in (1, 2, 4, 5):
            m = bus.servo(i).memory
            assert m.get("Torque Enable") == 1 and m.get("Goal Position") == m.get("Present Position")
    finally:
        bus.faults = Faults()
        robot.close()


class _Racing(ProfileMotion):
    """A servo that reports joint 2 turning at 20 rad/s: no MX-28 does."""

    def state(self, t):
        pos, vel, eff = super().state(t)
        vel[1] = 20.0
        return pos, vel, eff


def test_a_reading_no_servo_can_give_is_a_communication_error_naming_servo_and_value():
    bus = BusEmulator(motion=_Racing(np.zeros(5))).start()
    try:
        robot = hw.DynamixelSnake(bus.port, watchdog=0, retries=1)
        robot._release.append(bus.stop)
        with pytest.raises(snakekit.CommunicationError) as e:
            robot.read()
        assert "servo 2" in str(e.value)
        assert "Present Velocity 834 (20.0 rad/s; the MX-28 turns at most 5.8 rad/s)" in str(e.value)
        robot.close()
    finally:
        bus.stop()


@pytest.mark.parametrize("later", ["timed out", "corrupt"])
def test_a_reading_no_servo_can_give_is_named_when_a_later_try_fails_otherwise(later):
    """The first try reads joint 2 at 20 rad/s; the next tries time out (the answer came late on a
    busy computer) or come back corrupt. The message still names the reading: it is what tells the
    student the line or the servo lies, where "did not answer" sends them to the power."""
    import dynamixel_sdk as sdk

    bus = BusEmulator(motion=_Racing(np.zeros(5))).start()
    try:
        robot = hw.DynamixelSnake(bus.port, watchdog=0, retries=2)
        robot._release.append(bus.stop)
        reader = robot._reader
        other = {"timed out": sdk.COMM_RX_TIMEOUT, "corrupt": sdk.COMM_RX_CORRUPT}[later]
        tries = iter([reader.exchange, lambda: (other, None), lambda: (other, None)])
        reader.exchange = lambda: next(tries)()
        with pytest.raises(snakekit.CommunicationError) as e:
            robot.read()
        assert "servo 2" in str(e.value) and "3 tries" in str(e.value)
        assert "Present Velocity 834 (20.0 rad/s; the MX-28 turns at most 5.8 rad/s)" in str(e.value)
        assert next(tries, None) is None  # all three tries were made
        reader.exchange = lambda: (sdk.COMM_RX_TIMEOUT, None)
        with pytest.raises(snakekit.CommunicationError) as e:  # a new read forgets the old refusal
            robot.read()
        assert "did not answer" in str(e.value) and "Present Velocity" not in str(e.value)
    finally:
        bus.stop()


def test_a_status_from_another_request_is_refused():
    """A 35-byte status block read where a 10-byte one was asked: refused, not cut to 10 bytes."""
    bus = BusEmulator(motion="profile").start()
    try:
        robot = hw.DynamixelSnake(bus.port, watchdog=0)
        robot._release.append(bus.stop)
        ph, port = robot.bus.ph, robot.port
        # a status block of servo 1, answered late, comes when the joint state is asked for
        bus.faults = Faults(delay=1.0, delay_time=0.01, count=1)
        ph.readTx(port, 1, 64, 35)
        port.is_using = False
        data, result, _ = ph.readTxRx(port, 1, 126, 10)
        assert result == sdk.COMM_RX_CORRUPT and data == []
        assert ph.rejected == 1
        robot.close()
    finally:
        bus.stop()


def test_waiting_out_late_bytes_never_outlasts_the_bus_watchdog():
    """One stall of a busy computer taught the bus a lateness of MAX_LATENESS (0.4 s); every wait after a failed
    exchange then held the bus silent 0.5 to 0.67 s, past the servos' 0.5 s Bus Watchdog, which stopped the arm
    (3 stops in 30 goals, where the keep-alive allows none). The bus now stays silent at most 60 % of the period."""
    from snakekit.hardware.bus import MAX_LATENESS, SILENCE_SHARE

    robot = make_emulated_robot(motion="profile", watchdog=0.5)
    try:
        bus = robot.bus
        assert bus.silence_limit == pytest.approx(SILENCE_SHARE * 0.5)
        bus.lateness = MAX_LATENESS   # as after one stall
        assert bus.quiet_time == pytest.approx(SILENCE_SHARE * 0.5)
        robot.emulator.faults = Faults(delay=0.3, delay_time=0.1, seed=5)
        wrong, _, _ = drive_and_read(robot, 30, gap=0.13)   # at most 2 watchdog stops, as before the stall
        assert wrong == []
    finally:
        robot.close()
    off = make_emulated_robot(motion="profile", watchdog=0)
    try:
        assert off.bus.silence_limit == math.inf   # no watchdog: late bytes are waited out in full
        off.bus.lateness = MAX_LATENESS
        assert off.bus.quiet_time == pytest.approx(1.25 * MAX_LATENESS)
    finally:
        off.close()


@pytest.mark.parametrize("lost", [4, 8])
def test_a_start_up_whose_first_packets_are_lost_waits_them_out(lost):
    """The start-up tries each request for START_PATIENCE (1 s), more often than its 4 tries if need be: the
    first ``lost`` instruction packets dropped (as a computer that stalls a few tenths of a second while the
    arm connects) cost a wait, not a failed start (a run of the suite beside other work saw one fail on 4 tries
    in 0.4 s). After the start-up, a request is tried 4 times again."""
    robot = make_emulated_robot(motion="profile", watchdog=0.5, faults=Faults(drop=1.0, count=lost))
    try:
        assert robot.bus.retried >= lost and robot.bus.patience == 0.0
        robot.emulator.faults = Faults(missing=(2,))
        robot.emulator.clear_record()
        # 4 tries, as the message says and the bus received: not tried again until a patience runs out (the
        # time it takes is no measure of that on a busy machine)
        with pytest.raises(snakekit.CommunicationError, match=r"servo 2 .*\(timed out, 4 tries\)"):
            robot._read(2, 11, 1)
        asked = [r for r in robot.emulator.received("READ") if r.packet.id == 2 and r.packet.params[:2] == bytes([11, 0])]
        assert len(asked) == 4, asked   # (address 11: the operating mode this read asks for)
    finally:
        robot.close()


def test_a_servo_missing_at_start_up_is_named_after_the_patience_with_the_tries_made():
    bus = BusEmulator(motion="profile", faults=Faults(missing=(3,))).start()
    try:
        started = time.perf_counter()
        with pytest.raises(snakekit.CommunicationError, match=r"no servo answered at id 3 .*\(ping timed out, (\d+) "
                                                              r"tries\); check the cable and power, or the id") as e:
            hw.DynamixelSnake(bus.port)
        waited = time.perf_counter() - started
        assert hw.driver.START_PATIENCE <= waited < 5 * hw.driver.START_PATIENCE, waited
        made = int(re.search(r"ping timed out, (\d+) tries", str(e.value)).group(1))
        assert made > 4, str(e.value)  # tried for the whole second, more than the 4 tries of a running arm
        assert [s for s in range(1, 6) if bus.servo(s).memory.get("Torque Enable")] == []
    finally:
        bus.stop()
