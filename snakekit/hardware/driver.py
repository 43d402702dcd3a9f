"""The driver: the arm as a :class:`~snakekit.robot.Robot` on a Dynamixel bus.

What the driver does at start-up, in order (the "good driver" habits of the Dynamixel
e-manual and of well-kept drivers):

1. open the port exclusively (a robot already open on it in this program is closed first);
2. ping every id and check the model number (``spec.servo.model_number``: 30 = MX-28 Protocol 2.0);
3. refuse to start on a servo with a hardware error (or reboot it, if asked); clear a Bus
   Watchdog that stopped a servo after an earlier program lost contact;
4. torque off, then check every EEPROM setting that changes what a tick means or how far a
   joint may go (:mod:`snakekit.hardware.startup`): write the kit's values, or refuse;
5. write the RAM settings: Profile Acceleration and Velocity (within the speed limit);
6. goal = present position, torque on, then arm the Bus Watchdog (:mod:`.keepalive`).

Each control cycle is one SyncWrite of the five goals and one SyncRead of Present Load,
Velocity and Position (addresses 126..135, one block). Lost or corrupt packets are retried
a bounded number of times (:meth:`snakekit.hardware.bus.Bus.retry`); then the arm is
stopped and :class:`~snakekit.errors.CommunicationError` raised. A status packet with the
alert bit makes the driver read Hardware Error Status (70), stop the arm and raise
:class:`~snakekit.errors.HardwareError` naming the servo and the fault. Messages say how
the arm was left only as far as the servos confirmed it.

On :meth:`DynamixelSnake.close`, on an exception inside :meth:`DynamixelSnake.run` and on
Ctrl-C the arm is stopped as configured by ``on_close``: ``"torque_off"`` (limp) or
``"hold"`` (stay where it is).
"""

from __future__ import annotations

import numbers
import os
import time
import warnings
import weakref

import numpy as np
from dataclasses import dataclass

from ..errors import (CommunicationError, ConfigurationError, HardwareError,
                       InstructionError, LimitError, ServoMismatchError)
from ..model import SPEC, SnakeSpec
from ..profile_planner import DEFAULT_PROFILE_ACCELERATION, DEFAULT_PROFILE_VELOCITY, ProfilePlanner
from ..robot import JointState, Robot
from ..bridge import is_url
from .bus import Bus, SyncRead, describe, sdk
from .keepalive import STATUS_BLOCK, KeepAlive, WatchdogMixin
from .lost import last_told
from .registers import (BUS_WATCHDOG, FIRMWARE_VERSION, GOAL_POSITION, HARDWARE_ERROR_STATUS, PACKET_ERRORS,
                        PRESENT_POSITION, PROFILE_ACCELERATION, PROFILE_VELOCITY, STATE_BLOCK,
                        TORQUE_ENABLE, VELOCITY_UNIT, decode_hardware_error, decode_state, implausible_state,
                        load_to_torque, position_bytes, position_limit_ticks, radians_to_ticks, ticks_to_radians,
                        to_signed, velocity_to_radians_per_second)
from .options import ON_CLOSE, check_baudrate, check_options, port_name
from .startup import check_eeprom
from .stopping import StopMixin

KIT_PROFILE_VELOCITY = DEFAULT_PROFILE_VELOCITY  # the simulator's too (profile_planner says why 55)
#: how long [s] each request of the start-up is tried before a servo counts as not answering (its tries are
#: sent again until then): a lab computer that stalls a few tenths of a second while the arm connects (a suite's
#: run beside other work saw a start-up fail on 4 tries in 0.4 s) costs a wait, not a failed start
START_PATIENCE = 1.0
_OPEN: "weakref.WeakValueDictionary[str, DynamixelSnake]" = weakref.WeakValueDictionary()




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


class DynamixelSnake(StopMixin, WatchdogMixin, Robot):
    """The arm on a Dynamixel bus (a U2D2 adapter, or the bus emulator's pseudo-terminal).

    Args:
        port: serial port of the bus adapter, e.g. ``"/dev/ttyUSB0"``, or a pyserial URL such as
            ``"socket://host.docker.internal:7800"`` (a ``snakekit bridge`` on another computer);
            default: the ``SNAKEKIT_PORT`` environment variable (the container's ``hardware`` service sets it).
        baudrate: bus speed [baud] (the servos' Baud Rate register must match).
        ids: servo ids from base to tip (default: ``spec.servo_ids``).
        spec: the arm (limits, number of joints, servo ids, the servo model).
        on_close: ``"torque_off"`` (limp) or ``"hold"`` (keep the present position) when
            closed, after an exception in :meth:`run` and after Ctrl-C.
        profile_velocity: Profile Velocity register (0.229 rev/min units), 1 up to the
            joint speed limit (62 for 1.5 rad/s); default :data:`KIT_PROFILE_VELOCITY`.
        profile_acceleration: Profile Acceleration register (214.577 rev/min^2 units), >= 1.
        retries: how many times a lost or corrupt packet is sent again before giving up.
        torque: turn torque on at the end of the start-up.
        reboot_faulted: reboot a servo that reports a hardware error at start-up
            (otherwise refuse to start).
        fix_eeprom: write the kit's EEPROM settings where a servo differs (with torque off,
            and a warning listing each change); ``False`` refuses to start instead
            (:mod:`snakekit.hardware.startup`).
        watchdog: Bus Watchdog period [s] while the robot is open (0.02..2.54, rounded to
            20 ms; 0 turns it off): a servo that hears nothing for longer stops (0.5 s: a busy laptop's pauses pass).
    """

    backend = "hardware"
    realtime = True
    keeps_bus_time = True

    def __init__(self, port: str | None = None, baudrate: int = 4_000_000, ids=None, *,
                 spec: SnakeSpec = SPEC, on_close: str = "torque_off",
                 profile_velocity: int = KIT_PROFILE_VELOCITY,
                 profile_acceleration: int = DEFAULT_PROFILE_ACCELERATION,
                 retries: int = 3, torque: bool = True, reboot_faulted: bool = False,
                 fix_eeprom: bool = True, watchdog: float = 0.5):
        baudrate = check_baudrate(baudrate)
        super().__init__(spec)
        self.closed = True  # until the port is open: close() has nothing to release
        self._keepalive = None
        self._release: list = []  # extra clean-ups (e.g. stop an emulator) run by close()
        ids, retries, self.profile_velocity, self.profile_acceleration, self.watchdog = check_options(
            spec, ids, on_close, retries, profile_velocity, profile_acceleration, watchdog)
        self.port_name = port_name(port)
        self.baudrate = int(baudrate)
        self.ids = ids
        self.on_close = on_close
        self.tick_limits = position_limit_ticks(spec)
        #: torque as last read back from (or confirmed by) the servos
        self.torque_enabled = False
        #: SyncWrites of goal positions sent, since start-up
        self.goals_sent = 0
        #: EEPROM values written at start-up (:class:`snakekit.hardware.startup.EepromChange`)
        self.eeprom_changes: list = []
        self._t0 = time.perf_counter()
        self._last_positions = None
        self._last_status: dict = {}  # the keep-alive's last status read
        # The servos' profile generators as the kit models them (what the paths are checked on):
        # built from a read when first needed, fed the goals sent since (cheaply, when checked).
        self._planner: ProfilePlanner | None = None
        self._goals_since: list = []

        key = self.port_name if is_url(self.port_name) else os.path.realpath(self.port_name)
        old = _OPEN.get(key)
        if old is not None and not old.closed:
            warnings.warn(f"a robot was already open on {self.port_name}; it was closed first "
                          f"({old.on_close.replace('_', ' ')}), so the new one starts from a known state",
                          UserWarning, stacklevel=2)
            old.close()
        self.bus = Bus(self.port_name, self.baudrate, retries)
        self.bus.port.last_told = lambda me=weakref.ref(self): last_told(me())  # if the port goes away
        self.closed = False
        _OPEN[key] = self
        self._reader = SyncRead(self.port, self.bus.ph, *STATE_BLOCK, check=lambda _, raw: implausible_state(raw))
        self._status = SyncRead(self.port, self.bus.ph, *STATUS_BLOCK)
        self._writer = sdk.GroupSyncWrite(self.port, self.bus.ph, GOAL_POSITION, 4)
        for i in ids:
            self._reader.addParam(i)
            self._status.addParam(i)
            self._writer.addParam(i, [0, 0, 0, 0])
        try:
            self._start(torque, reboot_faulted, fix_eeprom)
        except BaseException:
            self.close()
            raise

    @property
    def port(self):
        """The SDK's port handler."""
        return self.bus.port

    @property
    def retries(self) -> int:
        return self.bus.retries

    @property
    def retried(self) -> int:
        """Packets sent again after a loss or corruption, since start-up."""
        return self.bus.retried

    # --- start-up --------------------------------------------------------------------------

    def _start(self, torque: bool, reboot_faulted: bool, fix_eeprom: bool) -> None:
        self.bus.patience = START_PATIENCE
        try:
            self._start_up(torque, reboot_faulted, fix_eeprom)
        finally:
            self.bus.patience = 0.0
        if self.watchdog:
            self._keepalive = KeepAlive(self, self.watchdog)

    def _start_up(self, torque: bool, reboot_faulted: bool, fix_eeprom: bool) -> None:
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
        tripped = [i for i in self.ids if to_signed(self._read(i, BUS_WATCHDOG, 1), 1) < 0]
        for i in self.ids:
            self._write(i, BUS_WATCHDOG, 1, 0)
        if tripped:
            warnings.warn(f"the Bus Watchdog had stopped servo(s) {', '.join(map(str, tripped))} on "
                          f"{self.port_name} (an earlier program lost contact with the arm); cleared",
                          UserWarning, stacklevel=3)
        self._torque(False)
        self.eeprom_changes = check_eeprom(self._read, self._write, self.ids, self.spec, self.port_name, fix_eeprom)
        for i in self.ids:
            self._apply_ram(i)
        if torque:
            self.torque_on()

    def _check_servo(self, servo_id: int) -> ServoInfo:
        info = self.ping(servo_id)
        expected = self.spec.servo.model_number
        if info.model_number != expected:
            raise ServoMismatchError(
                f"servo {servo_id} on {self.port_name} is model number {info.model_number}, not an "
                f"MX-28 Protocol 2.0 (model {expected}); check the id, or switch the servo "
                "to Protocol 2.0 with Dynamixel Wizard")
        return info

    def _apply_ram(self, servo_id: int) -> None:
        """The RAM settings a reboot erases: profile (torque is handled by the caller)."""
        self._write(servo_id, PROFILE_ACCELERATION, 4, self.profile_acceleration)
        self._write(servo_id, PROFILE_VELOCITY, 4, self.profile_velocity)

    # --- requests ----------------------------------------------------------------------------

    def _fail(self, message: str, result: int):
        hint = ("check the cable and power, or the id" if result == sdk.COMM_RX_TIMEOUT
                else "check the cable, the baud rate and for noise on the bus")
        raise CommunicationError(f"{message}; {hint}. {self.stop()}")

    def _tries(self) -> str:
        return f"{max(self.bus.tries_made, self.retries + 1)} tries"

    def _hardware_error(self, servo_id: int, bits: int) -> HardwareError:
        """The arm stopped, and the error that names ``servo_id``'s fault (Hardware Error Status ``bits``)."""
        stopped = self.stop()
        names = ", ".join(decode_hardware_error(bits)) or "an alert that has cleared"
        return HardwareError(
            f"servo {servo_id} (joint {self.ids.index(servo_id) + 1}) on {self.port_name} reports "
            f"a hardware error: {names} (Hardware Error Status 0x{bits:02X}). The servo turned its "
            f"torque off. {stopped} Remove the cause "
            f"(a blocked joint, heat, the supply), then robot.reboot({servo_id}) and robot.torque_on().")

    def _check_error(self, servo_id: int, error: int, what: str, check_alert: bool = True) -> None:
        if error & 0x80 and check_alert:
            raise self._hardware_error(servo_id, self._read(servo_id, HARDWARE_ERROR_STATUS, 1, check_alert=False))
        code = error & 0x7F
        if code:
            raise InstructionError(
                f"servo {servo_id} on {self.port_name} refused {what}: "
                f"{PACKET_ERRORS.get(code, f'error {code}')}", servo_id, code)

    def _read(self, servo_id: int, address: int, size: int, *, check_alert: bool = True) -> int:
        what = f"a read of address {address}"
        result, value, error = self.bus.read(servo_id, address, size)
        if result != sdk.COMM_SUCCESS:
            self._fail(f"servo {servo_id} on {self.port_name} did not answer {what} "
                       f"({describe(result)}, {self._tries()})", result)
        self._check_error(servo_id, error, what, check_alert)
        return value

    def _write(self, servo_id: int, address: int, size: int, value: int) -> None:
        what = f"a write of {value} to address {address}"
        result, error = self.bus.write(servo_id, address, size, value)
        if result != sdk.COMM_SUCCESS:
            self._fail(f"servo {servo_id} on {self.port_name} did not answer {what} "
                       f"({describe(result)}, {self._tries()})", result)
        self._check_error(servo_id, error, what)

    def ping(self, servo_id: int) -> ServoInfo:
        """Ping one servo: its model number and firmware version.

        Raises:
            CommunicationError: nobody answered at that id (after the retries).
        """
        result, model, _ = self.bus.ping(servo_id)
        if result != sdk.COMM_SUCCESS:
            raise CommunicationError(
                f"no servo answered at id {servo_id} on {self.port_name} (ping "
                f"{describe(result)}, {self._tries()}); check the cable and power, or the id")
        firmware = self._read(servo_id, FIRMWARE_VERSION, 1, check_alert=False)
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
        t_sent = self._now()
        reader.forget()
        result, failed = self.bus.retry(reader.exchange, by_servo=True)
        if result != sdk.COMM_SUCCESS and reader.refused:
            servo, why = reader.refused  # a servo's reading no servo can give, at any try: name it
            self._fail(f"servo {servo} on {self.port_name} reported {why}, which no "
                       f"true reading holds: a corrupt or misread reply ({self._tries()})", result)
        if result != sdk.COMM_SUCCESS:
            self._fail(f"servo {failed} on {self.port_name} did not answer the SyncRead of the "
                       f"joint state ({describe(result)}, {self._tries()})", result)
        t = 0.5 * (t_sent + self._now())  # the servos sampled about half-way through
        values = []
        for i in self.ids:
            error = reader.errors.get(i, 0)
            if error:
                self._check_error(i, error, "the SyncRead of the joint state")
            values.append(decode_state(bytes(reader.data_dict[i])))
        load, vel, ticks = np.array(values, dtype=float).T
        q = ticks_to_radians(ticks)
        self._last_positions = q
        return JointState(t, q, velocity_to_radians_per_second(vel), load_to_torque(load, self.spec))

    def _goal_ticks(self, q) -> list[int]:
        """Goal ticks of joint angles ``q`` [rad], clamped to the position limits in ticks."""
        lo, hi = self.tick_limits
        return np.clip(radians_to_ticks(q), lo, hi).tolist()

    def _load_goals(self, q) -> None:
        for i, tick in zip(self.ids, self._goal_ticks(q)):
            self._writer.changeParam(i, position_bytes(tick))

    def _profiles(self) -> ProfilePlanner:
        now = self._now()
        if self._planner is None:  # the servos at rest where they are (torque just came on)
            self._planner = ProfilePlanner(self.read().positions, self.profile_velocity, self.profile_acceleration, now)
            self._goals_since.clear()
        for t, q in self._goals_since:
            self._planner.set_goal(t, q)
        self._goals_since.clear()
        return self._planner

    def _send(self, q: np.ndarray) -> None:
        """One SyncWrite of the five goals, clamped to the position limits in ticks."""
        self._goals_since.append((self._now(), np.clip(q, self.spec.lower, self.spec.upper)))
        self._load_goals(q)
        writer = self._writer
        result, _ = self.bus.retry(lambda: (writer.txPacket(), None), answered=False)
        if result != sdk.COMM_SUCCESS:
            self._fail(f"the SyncWrite of goal positions could not be sent on {self.port_name} "
                       f"({describe(result)}, {self._tries()})", result)
        self.goals_sent += 1

    def command(self, q) -> None:
        """Send a position goal ``q`` [rad]; on Ctrl-C the arm is stopped (``on_close``).

        Raises :class:`~snakekit.errors.BackendError`, sending nothing, when a servo's torque is
        off or its Bus Watchdog stopped it (the servos would ignore the goal).
        """
        self._check_open()
        quiet = time.perf_counter() - self.bus.last_used
        if self._last_status and not (self.watchdog and quiet > self.watchdog / 2):
            self._check_ready(self._last_status)  # what the keep-alive read, no packet of its own
        else:
            self._check_ready()
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
        self._check_open()
        self._check_ready()
        sent = self.goals_sent
        try:
            run = super().run(trajectory, **options)
        except (LimitError, TypeError, ValueError):
            if self.goals_sent != sent:
                self._stop_once()
            raise
        except BaseException:
            self._stop_once()
            raise
        return self._check_after_run(run)

    def _stop_once(self) -> None:
        """Stop after an exception, unless the arm is closed or its torque is already off."""
        if not self.closed and (self.torque_enabled or self.on_close == "hold"):
            self.stop()

    # --- torque, stop, reboot ------------------------------------------------------------------

    def _torque(self, on: bool) -> None:
        self._planner = None  # each servo's reference starts again where it is
        for i in self.ids:
            self._write(i, TORQUE_ENABLE, 1, int(on))
        self.torque_enabled = on
        self._last_status = {i: (on, 0) for i in self.ids}  # every servo acknowledged the write

    def _hold_here(self, servo_id: int) -> tuple[int, int]:
        """Goal = present position (clamped into the limits), so torque-on doesn't jump.
        Returns (present, goal) ticks: they differ when the joint is outside its limits."""
        self._planner = None  # the servo's reference starts again where it is
        lo, hi = self.tick_limits
        present = to_signed(self._read(servo_id, PRESENT_POSITION, 4), 4)
        goal = min(max(present, lo), hi)
        self._write(servo_id, GOAL_POSITION, 4, goal)
        return present, goal

    def torque_on(self) -> None:
        """Goal = present position on every servo, then torque on (the arm holds still), then
        the Bus Watchdog armed (a stop by the watchdog is cleared).

        A joint found outside its limits (turned there by hand with torque off) gets the nearest
        limit as its goal: torque-on moves it in at the profile speed, with a warning naming
        the joint, where it was and where it goes.
        """
        self._check_open()
        outside = []
        for j, i in enumerate(self.ids):
            self._write(i, BUS_WATCHDOG, 1, 0)  # a stopped servo refuses goals until cleared
            present, goal = self._hold_here(i)
            if present != goal:
                outside.append(f"joint {j + 1} (servo {i}) was at {float(ticks_to_radians(present)):+.2f} rad, "
                               f"goes to {float(ticks_to_radians(goal)):+.2f} rad")
        self._torque(True)
        self._arm_watchdog()
        if outside:
            speed = self.profile_velocity * VELOCITY_UNIT
            warnings.warn("torque on with joints outside their limits (turned there by hand?): "
                          + "; ".join(outside) + f". They move in at the profile speed, {speed:.2f} rad/s.",
                          UserWarning, stacklevel=2)

    def torque_off(self) -> None:
        """Torque off on every servo: the arm goes limp."""
        self._check_open()
        self._torque(False)

    def _reboot(self, servo_id: int, timeout: float = 2.0) -> None:
        result, error = self.bus.reboot(servo_id)
        if result != sdk.COMM_SUCCESS:
            self._fail(f"servo {servo_id} on {self.port_name} did not answer REBOOT "
                       f"({describe(result)}, {self._tries()})", result)
        self._check_error(servo_id, error, "REBOOT", check_alert=False)
        deadline = time.perf_counter() + timeout
        while self.bus.ping_once(servo_id) != sdk.COMM_SUCCESS:
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
        if isinstance(servo_id, bool) or not isinstance(servo_id, numbers.Integral) or servo_id not in self.ids:
            raise ConfigurationError(f"servo {servo_id} is not on this arm; ids: {', '.join(map(str, self.ids))}")
        self._reboot(servo_id)
        self._apply_ram(servo_id)
        if self.torque_enabled:
            self._hold_here(servo_id)
            self._write(servo_id, TORQUE_ENABLE, 1, 1)
            self._arm_watchdog()

    def _shutdown(self) -> None:
        try:
            if self._keepalive is not None:
                self._keepalive.stop()
            if self.bus.is_open:
                if self.on_close == "hold" and self.watchdog:
                    try:  # asked to hold after closing: the watchdog must not stop the arm later
                        for i in self.ids:
                            self.bus.write(i, BUS_WATCHDOG, 1, 0)
                    except Exception:
                        pass
                self.stop()
                self.bus.close()
        finally:
            for release in self._release:
                release()
            self._release.clear()
