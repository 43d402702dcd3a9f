"""One emulated MX-28(2.0): its control table, its firmware rules and its link to the motion.

Ticks exist here and in :mod:`snakekit.hardware` only: 2048 ticks = 0 rad, 4096 ticks a turn,
Present Position = motor position + Homing Offset.
"""

from __future__ import annotations

import math
import struct

from . import protocol as p
from ..model import SPEC
from .control_table import (FIELDS, GOAL_POSITION, HARDWARE_ERROR_STATUS, HOMING_OFFSET, REALTIME_TICK,
                            RETURN_DELAY_TIME, STATUS_RETURN_LEVEL, TORQUE_ENABLE, Memory)

TICKS_PER_RAD = 4096 / (2 * math.pi)
NO_LOAD_SPEED = 55 * 2 * math.pi / 60  # rad/s at 12 V: what full PWM (885) reaches unloaded
FULL_PWM = 885
WATCHDOG_UNIT = 0.02  # s per Bus Watchdog unit
POSITION_MODES = (3, 4)  # position, extended position
VELOCITY_MODE, PWM_MODE = 1, 16
GOALS = ("Goal Position", "Goal Velocity", "Goal PWM")
VELOCITY_UNIT = 0.229 * 2 * math.pi / 60  # rad/s per Present Velocity unit
RETURN_DELAY_UNIT = 2e-6  # s per Return Delay Time unit
OVERLOAD = 1 << 5  # Hardware Error Status bit
# Realtime Tick, Moving, Moving Status, Present PWM, Load, Velocity, Position,
# Velocity Trajectory, Position Trajectory: addresses 120..143, one block
_PRESENT = struct.Struct("<HBBhhiiii")
_HOMING_AND_THRESHOLD = struct.Struct("<iI")  # Homing Offset (20) and Moving Threshold (24)
_I32 = struct.Struct("<i")


class EmulatedServo:
    """An MX-28(2.0) on the emulated bus.

    Args:
        servo_id: its id (control-table address 7).
        joint: which joint of the motion source it drives (0-based).
        motion: the shared :class:`~snakekit.emulator.motion.MotionSource`.
        stall_torque: the torque that reads as 100 % Present Load [N m].
    """

    def __init__(self, servo_id: int, joint: int, motion, *, stall_torque: float = SPEC.servo.stall_torque):
        self.memory = Memory(servo_id)
        self.stall_torque = float(stall_torque)
        self.joint = joint
        self.motion = motion
        self.registered: list | None = None  # a REG_WRITE waiting for ACTION
        self.booting_until = -math.inf
        self._sync_profile(0.0)
        self.memory.set("Goal Position", self.rad_to_ticks(self.present_rad(0.0)))  # the firmware starts there

    @property
    def id(self) -> int:
        return self.memory.get("ID")

    @property
    def hardware_error(self) -> int:
        return self.memory.data[HARDWARE_ERROR_STATUS]

    @property
    def status_return_level(self) -> int:
        return self.memory.data[STATUS_RETURN_LEVEL]

    @property
    def return_delay(self) -> float:
        """Return Delay Time [s]."""
        return self.memory.data[RETURN_DELAY_TIME] * RETURN_DELAY_UNIT

    @property
    def mode(self) -> int:
        """Operating Mode (11): 1 velocity, 3 position, 4 extended position, 16 PWM."""
        return self.memory.get("Operating Mode")

    @property
    def watchdog_period(self) -> float:
        """Bus Watchdog period [s] (0 when off or tripped)."""
        return max(self.memory.get("Bus Watchdog"), 0) * WATCHDOG_UNIT

    def error_byte(self, error: int = 0) -> int:
        return error | (p.ALERT if self.hardware_error else 0)

    # --- units ------------------------------------------------------------------------------

    def ticks_to_rad(self, ticks: int) -> float:
        """A Goal/Present Position value to the joint angle [rad] (Homing Offset removed)."""
        return (ticks - self.memory.get("Homing Offset") - 2048) / TICKS_PER_RAD

    def rad_to_ticks(self, q: float) -> int:
        return int(round(2048 + q * TICKS_PER_RAD)) + self.memory.get("Homing Offset")

    # --- present values ---------------------------------------------------------------------

    def refresh(self, t: float, q: float, qd: float, tau: float) -> None:
        """Update the read-only present values (addresses 120..143) from the motion at ``t`` [s]."""
        data = self.memory.data
        homing, threshold = _HOMING_AND_THRESHOLD.unpack_from(data, HOMING_OFFSET)
        position = int(round(2048 + q * TICKS_PER_RAD)) + homing
        vel = int(round(qd / VELOCITY_UNIT))
        load = max(-1000, min(1000, int(round(1000 * tau / self.stall_torque))))
        moving = abs(vel) > threshold
        goal = _I32.unpack_from(data, GOAL_POSITION)[0] if data[TORQUE_ENABLE] else position
        _PRESENT.pack_into(data, REALTIME_TICK, int(t * 1000) % 32768, int(moving), 2 if moving else 1,
                           int(load * 885 / 1000), load, vel, position, vel, goal)

    # --- writes -----------------------------------------------------------------------------

    def write(self, t: float, address: int, data: bytes) -> int:
        """A WRITE (or the write part of SYNC/BULK WRITE, ACTION); returns the error code."""
        error, values = self.memory.check_write(address, data)
        if error:
            return error
        if self.memory.get("Bus Watchdog") < 0 and any(f.name in GOALS for f, _ in values):
            return p.DATA_RANGE_ERROR  # after a watchdog stop the goals are read-only until cleared
        self.apply(t, values)
        return 0

    def apply(self, t: float, values) -> None:
        """Store checked ``(field, value)`` pairs and act on them."""
        m = self.memory
        for f, v in values:
            if f.name == "Torque Enable" and v == 1 and self.hardware_error & m.get("Shutdown"):
                continue  # after a shutdown only REBOOT brings torque back
            was_on = m.data[TORQUE_ENABLE] == 1
            m.set(f.name, v)
            torque = m.data[TORQUE_ENABLE] == 1
            if f.name == "Torque Enable" and v != was_on:
                self._sync_profile(t)
                if v and self.mode in POSITION_MODES:
                    self.motion.set_torque(t, self.joint, True, self.ticks_to_rad(m.get("Goal Position")))
                else:
                    self.motion.set_torque(t, self.joint, bool(v), self.present_rad(t))
                    if v:
                        self._drive(t)
                    else:  # torque off: the firmware sets the goal where the joint is
                        m.set("Goal Position", self.rad_to_ticks(self.present_rad(t)))
            elif f.name == "Goal Position" and self.mode in POSITION_MODES:
                self.motion.set_goal(t, self.joint, self.ticks_to_rad(v))
            elif f.name in ("Goal Velocity", "Goal PWM") and torque:
                self._drive(t)
            elif f.name in ("Profile Velocity", "Profile Acceleration"):
                self._sync_profile(t)

    def present_rad(self, t: float) -> float:
        """Where the joint is at ``t`` [s] [rad]."""
        return float(self.motion.state(t)[0][self.joint])

    def _drive(self, t: float) -> None:
        """Velocity mode (Goal Velocity) and PWM mode (Goal PWM, as a share of the no-load speed)."""
        m = self.memory
        if self.mode == VELOCITY_MODE:
            self.motion.set_velocity(t, self.joint, m.get("Goal Velocity") * VELOCITY_UNIT,
                                     m.get("Profile Acceleration"))
        elif self.mode == PWM_MODE:
            self.motion.set_velocity(t, self.joint, m.get("Goal PWM") / FULL_PWM * NO_LOAD_SPEED, 0)

    def _sync_profile(self, t: float) -> None:
        m = self.memory
        if self.mode in POSITION_MODES:
            self.motion.set_profile(t, self.joint, m.get("Profile Velocity"), m.get("Profile Acceleration"))

    def watchdog_stop(self, t: float) -> None:
        """The Bus Watchdog fired at ``t`` [s]: stop where the joint is (profile 0), goals read-only."""
        m = self.memory
        m.set("Bus Watchdog", -1)
        if m.data[TORQUE_ENABLE]:
            q = self.motion.stop(t, self.joint)
            m.set("Goal Position", self.rad_to_ticks(q))
            m.set("Goal Velocity", 0)

    def register(self, address: int, data: bytes) -> int:
        error, values = self.memory.check_write(address, data)
        if error:
            return error
        self.registered = values
        self.memory.set("Registered Instruction", 1)
        return 0

    def action(self, t: float) -> None:
        if self.registered is not None:
            values, self.registered = self.registered, None
            self.memory.set("Registered Instruction", 0)
            self.apply(t, values)

    # --- faults and resets ------------------------------------------------------------------

    def raise_hardware_error(self, t: float, bits: int) -> None:
        """Set Hardware Error Status bits; a bit in Shutdown (63) turns torque off."""
        m = self.memory
        m.set("Hardware Error Status", self.hardware_error | bits)
        if bits & m.get("Shutdown") and m.data[TORQUE_ENABLE]:
            m.set("Torque Enable", 0)
            self.motion.set_torque(t, self.joint, False, 0.0)
            m.set("Goal Position", self.rad_to_ticks(self.present_rad(t)))

    def reboot(self, t: float, boot_time: float) -> None:
        """RAM back to defaults (torque off, errors cleared); silent for ``boot_time`` [s]."""
        if self.memory.data[TORQUE_ENABLE]:
            self.motion.set_torque(t, self.joint, False, 0.0)
        self.memory.reset_ram()
        self.memory.set("Goal Position", self.rad_to_ticks(self.present_rad(t)))  # the firmware starts there
        self.registered = None
        self._sync_profile(t)
        self.booting_until = t + boot_time

    def factory_reset(self, t: float, option: int, boot_time: float) -> int:
        keep = {0xFF: (), 0x01: ("ID",), 0x02: ("ID", "Baud Rate")}.get(option)
        if keep is None:
            return p.DATA_RANGE_ERROR
        servo_id = self.id
        self.reboot(t, boot_time)
        self.memory.factory_reset(keep)
        self.memory.set("Goal Position", self.rad_to_ticks(self.present_rad(t)))
        if "ID" not in keep:
            self.memory.set("ID", FIELDS["ID"].default)
        else:
            self.memory.set("ID", servo_id)
        return 0
