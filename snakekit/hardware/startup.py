"""What the driver checks at start-up: every EEPROM setting that changes what a tick means or
how far and how fast a joint may go.

A servo bought new, or set up for another robot, can hold values that make the kit's numbers
wrong without any error: a Homing Offset shifts every reading (the driver would believe a
joint at 0 rad is at 1.5 rad, and drive it past its limit), Drive Mode can reverse the
direction or make Profile Velocity a time, another Operating Mode ignores Goal Position.
The driver reads each of these from every servo, with torque off, and either writes the
kit's value (``fix_eeprom=True``, the default; a warning lists each change) or refuses to
start, naming the servo, the register, the value found and the fix.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

from ..errors import ConfigurationError
from ..model import SnakeSpec
from .registers import (DRIVE_MODE, FULL_PWM, HOMING_OFFSET, MAX_POSITION_LIMIT, MIN_POSITION_LIMIT,
                        OPERATING_MODE, POSITION_MODE, PWM_LIMIT, RETURN_DELAY_TIME, VELOCITY_LIMIT,
                        position_limit_ticks, to_signed, velocity_limit_units)


@dataclass(frozen=True)
class Setting:
    """One EEPROM register the kit depends on.

    Attributes:
        name: the e-manual's name.
        address: control-table address.
        size: bytes.
        signed: two's complement.
        why: what a wrong value does to the arm, for the error message.
    """

    name: str
    address: int
    size: int
    signed: bool
    why: str


RETURN_DELAY = Setting("Return Delay Time", RETURN_DELAY_TIME, 1, False,
                       "each answer waits this many 2 us units; the control loop gets slower")
DRIVE = Setting("Drive Mode", DRIVE_MODE, 1, False,
                "bit 0 reverses the direction, bit 2 makes Profile Velocity a time: the kit's angles and "
                "speeds would be wrong")
MODE = Setting("Operating Mode", OPERATING_MODE, 1, False,
               "only position mode (3) follows Goal Position inside the position limits")
HOMING = Setting("Homing Offset", HOMING_OFFSET, 4, True,
                 "it is added to every position reading: 0 rad would not be the straight pose, and goals "
                 "would drive the joint past its limit")
PWM = Setting("PWM Limit", PWM_LIMIT, 2, False,
              "the MX-28's effort limit (it has no current limit): a lower value makes the joint weaker "
              "than the kit's model")
VELOCITY = Setting("Velocity Limit", VELOCITY_LIMIT, 4, False,
                   "the servo refuses a Profile Velocity above it: the kit sets it to the joint speed limit")
MAX_POSITION = Setting("Max Position Limit", MAX_POSITION_LIMIT, 4, False,
                       "the servo refuses goals above it: the kit sets it to the upper joint limit")
MIN_POSITION = Setting("Min Position Limit", MIN_POSITION_LIMIT, 4, False,
                       "the servo refuses goals below it: the kit sets it to the lower joint limit")


@dataclass(frozen=True)
class EepromChange:
    """One EEPROM value the driver wrote at start-up.

    Attributes:
        servo_id: which servo.
        setting: which register.
        found: the value read from the servo.
        written: the kit's value, written with torque off.
    """

    servo_id: int
    setting: Setting
    found: int
    written: int

    def describe(self) -> str:
        s = self.setting
        return f"servo {self.servo_id}: {s.name} (address {s.address}) was {self.found}, now {self.written}"


def kit_eeprom(spec: SnakeSpec) -> list[tuple[Setting, int]]:
    """The kit's value of every EEPROM setting checked at start-up, in the order they are written.

    >>> from snakekit.model import SPEC
    >>> [(s.name, v) for s, v in kit_eeprom(SPEC)][-3:]
    [('Velocity Limit', 62), ('Max Position Limit', 3071), ('Min Position Limit', 1025)]
    """
    lo, hi = position_limit_ticks(spec)
    return [(RETURN_DELAY, 0), (DRIVE, 0), (MODE, POSITION_MODE), (HOMING, 0), (PWM, FULL_PWM),
            (VELOCITY, velocity_limit_units(spec)), (MAX_POSITION, hi), (MIN_POSITION, lo)]


def check_eeprom(read, write, ids, spec: SnakeSpec, port: str, fix: bool) -> list[EepromChange]:
    """Read every setting of :func:`kit_eeprom` from every servo; write the kit's values or refuse.

    Torque must be off (the servos refuse EEPROM writes otherwise).

    Args:
        read: ``read(servo_id, address, size) -> unsigned value``.
        write: ``write(servo_id, address, size, value)``.
        ids: the servo ids.
        spec: the arm.
        port: the port's name, for messages.
        fix: write the kit's values (True) or raise :class:`ConfigurationError` (False).

    Returns:
        The changes written (empty when every servo was already set up).
    """
    wrong = []
    for i in ids:
        for setting, value in kit_eeprom(spec):
            found = read(i, setting.address, setting.size)
            if setting.signed:
                found = to_signed(found, setting.size)
            if found != value:
                wrong.append(EepromChange(i, setting, found, value))
    if wrong and not fix:
        lines = [f"servo {c.servo_id}: {c.setting.name} (address {c.setting.address}) is {c.found}, the kit "
                 f"needs {c.written}: {c.setting.why}" for c in wrong]
        raise ConfigurationError(
            f"the servos on {port} are not set up for the kit:\n  " + "\n  ".join(lines) +
            "\nFix: make_robot('hardware', port=..., fix_eeprom=True) writes the kit's values (torque off), "
            "or set them with Dynamixel Wizard.")
    for c in wrong:
        write(c.servo_id, c.setting.address, c.setting.size, c.written)
    if wrong:
        warnings.warn(f"the kit wrote its EEPROM settings (torque off) on {port}:\n  "
                      + "\n  ".join(c.describe() for c in wrong), UserWarning, stacklevel=4)
    return wrong
