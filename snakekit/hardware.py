"""The real arm: five MX-28(2.0) servos on one Dynamixel bus, through the unmodified dynamixel-sdk.

>>> import snakekit
>>> with snakekit.make_robot("hardware", port="/dev/ttyUSB0") as robot:   # doctest: +SKIP
...     robot.home()

Servo ticks exist only in this module (2048 ticks = 0 rad, 4096 ticks a turn). What the
driver does, in order (the "good driver" habits of the Dynamixel e-manual and of
well-kept drivers):

1. ping every id and check the model number (30 = MX-28 Protocol 2.0);
2. refuse to start on a servo with a hardware error (or reboot it, if asked);
3. torque off, then write the EEPROM only where it differs: Return Delay Time 0, position
   mode, Min/Max Position Limit from the joint limits;
4. write the RAM settings: Profile Acceleration and Velocity;
5. goal = present position, then torque on.

Each control cycle is one SyncWrite of the five goals and one SyncRead of Present Load,
Velocity and Position (addresses 126..135, one block). Lost or corrupt packets are retried
a bounded number of times; then the arm is stopped and :class:`CommunicationError` raised.
A status packet with the alert bit makes the driver read Hardware Error Status (70), stop
the arm and raise :class:`HardwareError` naming the servo and the fault.

On :meth:`close`, on an exception inside :meth:`run` and on Ctrl-C the arm is stopped as
configured by ``on_close``: ``"torque_off"`` (limp) or ``"hold"`` (stay where it is).
"""

from __future__ import annotations

import math
import select
import struct
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from .errors import BackendError, CommunicationError, HardwareError, LimitError
from .model import SPEC, SnakeSpec
from .robot import JointState, Robot
from .servo import DEFAULT_PROFILE_ACCELERATION, DEFAULT_PROFILE_VELOCITY

try:
    import dynamixel_sdk as sdk
except ImportError as e:  # pragma: no cover - the kit's environment has it
    raise BackendError("the hardware backend needs dynamixel-sdk: pip install dynamixel-sdk") from e

MX28_MODEL_NUMBER = 30
TICKS_PER_TURN = 4096
CENTER_TICK = 2048
TICKS_PER_RAD = TICKS_PER_TURN / (2 * math.pi)
VELOCITY_UNIT = 0.229 * 2 * math.pi / 60  # rad/s per Present Velocity unit
LOAD_UNIT = 0.001  # Present Load is in 0.1 % of the stall torque
STALL_TORQUE = 2.5  # N m

# Control table addresses (MX-28 Protocol 2.0).
RETURN_DELAY_TIME, OPERATING_MODE, MAX_POSITION_LIMIT, MIN_POSITION_LIMIT = 9, 11, 48, 52
TORQUE_ENABLE, STATUS_RETURN_LEVEL, HARDWARE_ERROR_STATUS = 64, 68, 70
PROFILE_ACCELERATION, PROFILE_VELOCITY, GOAL_POSITION = 108, 112, 116
PRESENT_LOAD, PRESENT_POSITION = 126, 132
STATE_BLOCK = (126, 10)  # Present Load (2), Velocity (4), Position (4)
_STATE = struct.Struct("<hii")  # the block, signed little-endian
POSITION_MODE = 3

HARDWARE_ERROR_BITS = {0: "input voltage", 2: "overheating", 3: "motor encoder",
                       4: "electrical shock", 5: "overload"}
PACKET_ERRORS = {1: "result fail", 2: "instruction error", 3: "CRC error", 4: "data range error",
                 5: "data length error", 6: "data limit error", 7: "access error"}
COMM_RESULTS = {
    sdk.COMM_PORT_BUSY: "port busy", sdk.COMM_TX_FAIL: "could not send the packet",
    sdk.COMM_RX_FAIL: "no status packet", sdk.COMM_TX_ERROR: "malformed instruction packet",
    sdk.COMM_RX_WAITING: "status packet incomplete", sdk.COMM_RX_TIMEOUT: "timed out",
    sdk.COMM_RX_CORRUPT: "corrupt status packet", sdk.COMM_NOT_AVAILABLE: "not available",
}
ON_CLOSE = ("torque_off", "hold")


class ServoMismatchError(BackendError):
    """A servo answered, but is not an MX-28 (Protocol 2.0)."""


class InstructionError(BackendError):
    """A servo refused an instruction (the low bits of its status packet's error byte).

    Attributes:
        servo_id: which servo.
        code: the error number (1..7, see :data:`PACKET_ERRORS`).
    """

    def __init__(self, message: str, servo_id: int, code: int):
        self.servo_id, self.code = servo_id, code
        super().__init__(message)


# --- units: ticks exist only here -------------------------------------------------------------

def radians_to_ticks(q) -> np.ndarray:
    """Joint angles [rad] to Goal Position ticks (2048 = 0 rad, 4096 a turn), rounded.

    >>> radians_to_ticks([0.0, math.pi / 2, -math.pi]).tolist()
    [2048, 3072, 0]
    """
    return np.rint(CENTER_TICK + np.asarray(q, dtype=float) * TICKS_PER_RAD).astype(int)


def ticks_to_radians(ticks) -> np.ndarray:
    """Present Position ticks to joint angles [rad].

    >>> ticks_to_radians([2048, 3072]).round(4).tolist()
    [0.0, 1.5708]
    """
    return (np.asarray(ticks, dtype=float) - CENTER_TICK) / TICKS_PER_RAD


def to_signed(value: int, size: int) -> int:
    """Two's complement: the SDK returns every register unsigned.

    >>> to_signed(0xFFFFFFFF, 4), to_signed(0xFC18, 2)
    (-1, -1000)
    """
    bits = 8 * size
    return value - (1 << bits) if value >> (bits - 1) & 1 else value


def load_to_torque(load) -> np.ndarray:
    """Present Load (0.1 % of stall torque, signed) to joint torque [N m].

    >>> float(load_to_torque(-400))
    -1.0
    """
    return np.asarray(load, dtype=float) * LOAD_UNIT * STALL_TORQUE


def decode_hardware_error(bits: int) -> list[str]:
    """Names of the set bits of Hardware Error Status (70).

    >>> decode_hardware_error(0x24)
    ['overheating', 'overload']
    """
    names = [name for b, name in HARDWARE_ERROR_BITS.items() if bits >> b & 1]
    return names or ([f"unknown bits 0x{bits:02X}"] if bits else [])


def position_limit_ticks(spec: SnakeSpec = SPEC) -> tuple[int, int]:
    """The joint limits as Min/Max Position Limit ticks, rounded inwards.

    >>> position_limit_ticks()
    (1025, 3071)
    """
    lo = math.ceil(CENTER_TICK + spec.lower * TICKS_PER_RAD - 1e-9)
    hi = math.floor(CENTER_TICK + spec.upper * TICKS_PER_RAD + 1e-9)
    return max(lo, 0), min(hi, TICKS_PER_TURN - 1)


@dataclass(frozen=True)
class ServoInfo:
    """What a PING returns.

    Attributes:
        id: servo id.
        model_number: control-table address 0 (30 for an MX-28 Protocol 2.0).
        firmware: firmware version (address 6).
    """

    id: int
    model_number: int
    firmware: int


class _Port(sdk.PortHandler):
    """The SDK's port handler, waiting in ``select`` for the first byte instead of spinning.

    The SDK polls the port with a zero timeout until a status packet arrives or its packet
    timeout passes. Polling a moment, then sleeping in ``select`` until a byte arrives,
    gives the same timing without burning a CPU core (and without holding Python's lock
    for long, which an emulator in the same process needs to answer).
    """

    #: how long to poll before sleeping in select [s]: a fast answer is caught without the
    #: cost of a wake-up, a slow one costs no CPU
    spin = 3e-4

    def readPort(self, length):
        ser = self.ser
        data = ser.read(length)  # what the SDK does: a read that never waits
        if data:
            return data
        end = time.perf_counter() + self.spin
        while time.perf_counter() < end:
            data = ser.read(length)
            if data:
                return data
        left = (self.packet_timeout - self.getTimeSinceStart()) / 1000.0  # ms -> s
        if left > 0:
            select.select([ser.fileno()], [], [], min(left, 0.05))
        return ser.read(length)


class _SyncRead(sdk.GroupSyncRead):
    """The SDK's SyncRead, keeping each status packet's error byte (the SDK drops it)."""

    def __init__(self, *args):
        super().__init__(*args)
        self.errors: dict[int, int] = {}
        self.failed_id: int | None = None

    def rxPacket(self):
        self.last_result = False
        self.failed_id = None
        result = sdk.COMM_RX_FAIL
        for dxl_id in self.data_dict:
            self.data_dict[dxl_id], result, self.errors[dxl_id] = self.ph.readRx(self.port, dxl_id, self.data_length)
            if result != sdk.COMM_SUCCESS:
                self.failed_id = dxl_id
                return result
        self.last_result = True
        return result


class DynamixelSnake(Robot):
    """The arm on a Dynamixel bus (a U2D2 adapter, or the bus emulator's pseudo-terminal).

    Args:
        port: serial port of the bus adapter, e.g. ``"/dev/ttyUSB0"``.
        baudrate: bus speed [baud] (the servos' Baud Rate register must match).
        ids: servo ids from base to tip.
        spec: the arm (limits, number of joints).
        on_close: ``"torque_off"`` (limp) or ``"hold"`` (keep the present position) when
            closed, after an exception in :meth:`run` and after Ctrl-C.
        profile_velocity: Profile Velocity register (0.229 rev/min units).
        profile_acceleration: Profile Acceleration register (214.577 rev/min^2 units).
        retries: how many times a lost or corrupt packet is sent again before giving up.
        torque: turn torque on at the end of the start-up.
        reboot_faulted: reboot a servo that reports a hardware error at start-up
            (otherwise refuse to start).
    """

    backend = "hardware"
    realtime = True

    def __init__(self, port: str, baudrate: int = 4_000_000, ids=(1, 2, 3, 4, 5), *,
                 spec: SnakeSpec = SPEC, on_close: str = "torque_off",
                 profile_velocity: int = DEFAULT_PROFILE_VELOCITY,
                 profile_acceleration: int = DEFAULT_PROFILE_ACCELERATION,
                 retries: int = 3, torque: bool = True, reboot_faulted: bool = False):
        super().__init__(spec)
        self.closed = True  # until the port is open: close() has nothing to release
        ids = tuple(int(i) for i in ids)
        if len(ids) != spec.n_joints or len(set(ids)) != len(ids):
            raise ValueError(f"ids must be {spec.n_joints} distinct servo ids, one a joint, got {ids}")
        if on_close not in ON_CLOSE:
            raise ValueError(f"on_close must be one of {', '.join(map(repr, ON_CLOSE))}, got {on_close!r}")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self.port_name = str(port)
        self.baudrate = int(baudrate)
        self.ids = ids
        self.on_close = on_close
        self.profile_velocity = int(profile_velocity)
        self.profile_acceleration = int(profile_acceleration)
        self.retries = int(retries)
        self.tick_limits = position_limit_ticks(spec)
        self.torque_enabled = False
        #: packets sent again after a loss or corruption, since start-up
        self.retried = 0
        #: SyncWrites of goal positions sent, since start-up
        self.goals_sent = 0
        self._lock = threading.RLock()
        self._release: list = []  # extra clean-ups (e.g. stop an emulator) run by close()
        self._t0 = time.perf_counter()
        self._last_positions = None

        self.port = _Port(self.port_name)
        self.ph = sdk.PacketHandler(2.0)
        try:
            opened = self.port.openPort()
        except Exception as e:  # pyserial raises SerialException (an OSError) for a bad path
            raise BackendError(f"could not open the servo bus at {self.port_name}: {e}; check the port "
                               "name, that the adapter is plugged in, and that you may use it "
                               "(the 'dialout' group)") from e
        if not opened or not self.port.setBaudRate(self.baudrate):
            if self.port.is_open:
                self.port.closePort()
            raise BackendError(f"{self.baudrate} baud is not a rate the Dynamixel SDK supports on "
                               f"{self.port_name}; use 57600, 1000000, 2000000, 3000000 or 4000000")
        self.closed = False
        self._reader = _SyncRead(self.port, self.ph, *STATE_BLOCK)
        self._writer = sdk.GroupSyncWrite(self.port, self.ph, GOAL_POSITION, 4)
        for i in ids:
            self._reader.addParam(i)
            self._writer.addParam(i, [0, 0, 0, 0])
        try:
            self._start(torque, reboot_faulted)
        except BaseException:
            self.close()
            raise

    # --- start-up --------------------------------------------------------------------------

    def _start(self, torque: bool, reboot_faulted: bool) -> None:
        self.servos = [self._check_servo(i) for i in self.ids]
        for i in self.ids:
            bits = self._read(i, HARDWARE_ERROR_STATUS, 1, check_alert=False)
            if bits:
                if not reboot_faulted:
                    raise HardwareError(
                        f"servo {i} on {self.port_name} reports a hardware error at start-up: "
                        f"{', '.join(decode_hardware_error(bits))} (Hardware Error Status 0x{bits:02X}); "
                        "remove the cause (load, heat, supply), then power-cycle the arm or pass "
                        "reboot_faulted=True")
                self._reboot(i)
        self._torque(False)
        lo, hi = self.tick_limits
        for i in self.ids:
            self._write_if_different(i, RETURN_DELAY_TIME, 1, 0)
            self._write_if_different(i, OPERATING_MODE, 1, POSITION_MODE)
            self._write_if_different(i, MIN_POSITION_LIMIT, 4, lo)
            self._write_if_different(i, MAX_POSITION_LIMIT, 4, hi)
            self._apply_ram(i)
        if torque:
            self.torque_on()

    def _check_servo(self, servo_id: int) -> ServoInfo:
        info = self.ping(servo_id)
        if info.model_number != MX28_MODEL_NUMBER:
            raise ServoMismatchError(
                f"servo {servo_id} on {self.port_name} is model number {info.model_number}, not an "
                f"MX-28 Protocol 2.0 (model {MX28_MODEL_NUMBER}); check the id, or switch the servo "
                "to Protocol 2.0 with Dynamixel Wizard")
        return info

    def _apply_ram(self, servo_id: int) -> None:
        """The RAM settings a reboot erases: profile (torque is handled by the caller)."""
        self._write(servo_id, PROFILE_ACCELERATION, 4, self.profile_acceleration)
        self._write(servo_id, PROFILE_VELOCITY, 4, self.profile_velocity)

    def _write_if_different(self, servo_id, address, size, value) -> None:
        if self._read(servo_id, address, size) != value:
            self._write(servo_id, address, size, value)

    # --- bus access ------------------------------------------------------------------------

    @contextmanager
    def _bus(self):
        """Hold the bus; after any exception (Ctrl-C included) the SDK's port flag is reset."""
        with self._lock:
            try:
                yield
            finally:
                self.port.is_using = False

    def _request(self, servo_id: int, what: str, call, *, check_alert: bool = True):
        """One request/answer with retries. ``call()`` returns ``(value, result, error)``."""
        result = sdk.COMM_SUCCESS
        for attempt in range(self.retries + 1):
            with self._bus():
                value, result, error = call()
            if result == sdk.COMM_SUCCESS:
                self._check_error(servo_id, error, what, check_alert)
                return value
            if attempt < self.retries:
                self.retried += 1
        self._fail(f"servo {servo_id} on {self.port_name} did not answer {what} "
                   f"({COMM_RESULTS.get(result, result)}, {self.retries + 1} tries)",
                   result)

    def _fail(self, message: str, result: int):
        hint = ("check the cable and power, or the id" if result == sdk.COMM_RX_TIMEOUT
                else "check the cable, the baud rate and for noise on the bus")
        self.stop()
        raise CommunicationError(f"{message}; {hint}. The arm was stopped ({self._stop_words()}).")

    def _stop_words(self) -> str:
        return "torque off" if self.on_close == "torque_off" else "holding position"

    def _check_error(self, servo_id: int, error: int, what: str, check_alert: bool = True) -> None:
        if error & 0x80 and check_alert:
            bits = self._read(servo_id, HARDWARE_ERROR_STATUS, 1, check_alert=False)
            self.stop()
            names = ", ".join(decode_hardware_error(bits)) or "an alert that has cleared"
            raise HardwareError(
                f"servo {servo_id} (joint {self.ids.index(servo_id) + 1}) on {self.port_name} reports "
                f"a hardware error: {names} (Hardware Error Status 0x{bits:02X}). The servo turned its "
                f"torque off and the arm was stopped ({self._stop_words()}). Remove the cause "
                f"(a blocked joint, heat, the supply), then robot.reboot({servo_id}) and robot.torque_on().")
        code = error & 0x7F
        if code:
            raise InstructionError(
                f"servo {servo_id} on {self.port_name} refused {what}: "
                f"{PACKET_ERRORS.get(code, f'error {code}')}", servo_id, code)

    def _read(self, servo_id: int, address: int, size: int, *, check_alert: bool = True) -> int:
        fn = {1: self.ph.read1ByteTxRx, 2: self.ph.read2ByteTxRx, 4: self.ph.read4ByteTxRx}[size]
        return self._request(servo_id, f"a read of address {address}",
                             lambda: fn(self.port, servo_id, address), check_alert=check_alert)

    def _write(self, servo_id: int, address: int, size: int, value: int) -> None:
        fn = {1: self.ph.write1ByteTxRx, 2: self.ph.write2ByteTxRx, 4: self.ph.write4ByteTxRx}[size]
        value = value & ((1 << 8 * size) - 1)
        self._request(servo_id, f"a write of {value} to address {address}",
                      lambda: (None, *fn(self.port, servo_id, address, value)))

    def ping(self, servo_id: int) -> ServoInfo:
        """Ping one servo: its model number and firmware version.

        Raises:
            CommunicationError: nobody answered at that id (after the retries).
        """
        result = sdk.COMM_SUCCESS
        for attempt in range(self.retries + 1):
            with self._bus():
                model, result, error = self.ph.ping(self.port, servo_id)
            if result == sdk.COMM_SUCCESS:
                break
        else:
            raise CommunicationError(
                f"no servo answered at id {servo_id} on {self.port_name} (ping "
                f"{COMM_RESULTS.get(result, result)}); check the cable and power, or the id")
        firmware = self._read(servo_id, 6, 1, check_alert=False)
        return ServoInfo(servo_id, model, firmware)

    def hardware_error_status(self, servo_id: int) -> list[str]:
        """The faults a servo reports (Hardware Error Status, address 70), in words."""
        return decode_hardware_error(self._read(servo_id, HARDWARE_ERROR_STATUS, 1, check_alert=False))

    # --- the robot interface -----------------------------------------------------------------

    def _now(self) -> float:
        return time.perf_counter() - self._t0

    def _advance(self, t: float) -> None:
        delay = t - self._now()
        if delay > 0:
            time.sleep(delay)

    def read(self) -> JointState:
        """One SyncRead of Present Load, Velocity and Position: the present joint state."""
        self._check_open()
        reader = self._reader
        result = sdk.COMM_SUCCESS
        t_sent = 0.0
        for attempt in range(self.retries + 1):
            t_sent = self._now()
            with self._bus():
                result = reader.txRxPacket()
            if result == sdk.COMM_SUCCESS and all(reader.isAvailable(i, *STATE_BLOCK) for i in self.ids):
                break
            if attempt < self.retries:
                self.retried += 1
        else:
            who = reader.failed_id
            self._fail(f"servo {who} on {self.port_name} did not answer the SyncRead of the joint "
                       f"state ({COMM_RESULTS.get(result, result)}, {self.retries + 1} tries)", result)
        t = 0.5 * (t_sent + self._now())  # the servos sampled about half-way through
        values = []
        for i in self.ids:
            error = reader.errors.get(i, 0)
            if error:
                self._check_error(i, error, "the SyncRead of the joint state")
            values.append(_STATE.unpack(bytes(reader.data_dict[i])))  # two's complement
        load, vel, ticks = np.array(values, dtype=float).T
        q = (ticks - CENTER_TICK) / TICKS_PER_RAD
        self._last_positions = q
        return JointState(t, q, vel * VELOCITY_UNIT, load * (LOAD_UNIT * STALL_TORQUE))

    def _send(self, q: np.ndarray) -> None:
        """One SyncWrite of the five goals, clamped to the position limits in ticks."""
        lo, hi = self.tick_limits
        writer = self._writer
        for i, x in zip(self.ids, q.tolist()):  # plain floats: faster than numpy for five values
            tick = min(max(round(CENTER_TICK + x * TICKS_PER_RAD), lo), hi)
            writer.changeParam(i, [tick & 0xFF, tick >> 8 & 0xFF, tick >> 16 & 0xFF, tick >> 24 & 0xFF])
        result = sdk.COMM_SUCCESS
        for attempt in range(self.retries + 1):
            with self._bus():
                result = writer.txPacket()
            if result == sdk.COMM_SUCCESS:
                self.goals_sent += 1
                return
            if attempt < self.retries:
                self.retried += 1
        self._fail(f"the SyncWrite of goal positions could not be sent on {self.port_name} "
                   f"({COMM_RESULTS.get(result, result)})", result)

    def command(self, q) -> None:
        """Send a position goal ``q`` [rad]; on Ctrl-C the arm is stopped (``on_close``)."""
        try:
            super().command(q)
        except (KeyboardInterrupt, SystemExit):
            self._stop_once()
            raise

    def run(self, trajectory, **options):
        """:meth:`Robot.run`, stopping the arm (``on_close``) on any exception or Ctrl-C.

        A trajectory refused by the checks (limits, start pose, type) never moved the arm: it
        is left as it is, torque on.
        """
        sent = self.goals_sent
        try:
            return super().run(trajectory, **options)
        except (LimitError, TypeError, ValueError):
            if self.goals_sent != sent:
                self._stop_once()
            raise
        except BaseException:
            self._stop_once()
            raise

    def _stop_once(self) -> None:
        """Stop after an exception, unless the arm is closed or its torque is already off."""
        if not self.closed and (self.torque_enabled or self.on_close == "hold"):
            self.stop()

    # --- torque, stop, reboot ------------------------------------------------------------------

    def _torque(self, on: bool) -> None:
        for i in self.ids:
            self._write(i, TORQUE_ENABLE, 1, int(on))
        self.torque_enabled = on

    def _hold_here(self, servo_id: int) -> None:
        """Goal = present position (clamped into the limits), so torque-on doesn't jump."""
        lo, hi = self.tick_limits
        present = to_signed(self._read(servo_id, PRESENT_POSITION, 4), 4)
        self._write(servo_id, GOAL_POSITION, 4, min(max(present, lo), hi))

    def torque_on(self) -> None:
        """Goal = present position on every servo, then torque on (the arm holds still)."""
        self._check_open()
        for i in self.ids:
            self._hold_here(i)
        self._torque(True)

    def torque_off(self) -> None:
        """Torque off on every servo: the arm goes limp."""
        self._check_open()
        self._torque(False)

    def stop(self) -> None:
        """Stop the arm now, as ``on_close`` says; never raises (the bus may be failing)."""
        with self._lock:
            self.port.is_using = False
            try:
                if self.on_close == "hold":
                    self._hold_safely()
                else:
                    self._torque_off_safely()
            except Exception:  # a closed or broken port: nothing more can be sent
                pass
            finally:
                self.port.is_using = False

    def _torque_off_safely(self) -> None:
        for attempt in range(self.retries + 1):
            try:
                self.port.clearPort()
                self.ph.write1ByteTxOnly(self.port, sdk.BROADCAST_ID, TORQUE_ENABLE, 0)
            except Exception:
                pass
            self.port.is_using = False
            still_on = []
            for i in self.ids:
                value, result, _ = self.ph.read1ByteTxRx(self.port, i, TORQUE_ENABLE)
                self.port.is_using = False
                if result != sdk.COMM_SUCCESS or value != 0:
                    still_on.append(i)
            if not still_on:
                break
        self.torque_enabled = False

    def _hold_safely(self) -> None:
        q = self._last_positions
        if q is None:
            return
        lo, hi = self.tick_limits
        ticks = np.clip(radians_to_ticks(q), lo, hi)
        for i, tick in zip(self.ids, ticks.tolist()):
            self._writer.changeParam(i, list(int(tick).to_bytes(4, "little")))
        try:
            self._writer.txPacket()
        except Exception:
            pass
        self.port.is_using = False

    def _reboot(self, servo_id: int, timeout: float = 2.0) -> None:
        self._request(servo_id, "REBOOT", lambda: (None, *self.ph.reboot(self.port, servo_id)), check_alert=False)
        deadline = time.perf_counter() + timeout
        while True:
            with self._bus():
                _, result, _ = self.ph.ping(self.port, servo_id)
            if result == sdk.COMM_SUCCESS:
                return
            if time.perf_counter() > deadline:
                raise CommunicationError(f"servo {servo_id} on {self.port_name} did not come back "
                                         f"within {timeout:g} s of a reboot; check its power")
            time.sleep(0.01)

    def reboot(self, servo_id: int) -> None:
        """Reboot one servo (clears its hardware error) and re-apply its RAM settings.

        The other servos are not touched. The rebooted servo gets its profile back, its goal
        set to where it is, and torque on if the arm's torque is on.
        """
        self._check_open()
        if servo_id not in self.ids:
            raise ValueError(f"servo {servo_id} is not on this arm; ids: {', '.join(map(str, self.ids))}")
        self._reboot(servo_id)
        self._apply_ram(servo_id)
        if self.torque_enabled:
            self._hold_here(servo_id)
            self._write(servo_id, TORQUE_ENABLE, 1, 1)

    def _shutdown(self) -> None:
        try:
            if self.port.is_open:
                self.stop()
                self.port.closePort()
        finally:
            for release in self._release:
                release()
            self._release.clear()
