"""The MX-28(2.0) as the driver sees it: control-table addresses, units and conversions.

Servo ticks exist only in :mod:`snakekit.hardware` (and, independently, in the bus
emulator): 2048 ticks = 0 rad, 4096 ticks a turn. Every conversion the driver makes goes
through the functions here, which are doctested.

The addresses come from the ROBOTIS e-manual (MX-28, Protocol 2.0). The bus emulator keeps
its own table (:mod:`snakekit.emulator.control_table`), written separately on purpose, so
that the emulator is a real test of these numbers.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from ..model import SPEC, SnakeSpec

TICKS_PER_TURN = 4096
CENTER_TICK = 2048  # = 0 rad
TICKS_PER_RAD = TICKS_PER_TURN / (2 * math.pi)
VELOCITY_UNIT = 0.229 * 2 * math.pi / 60  # rad/s per Present Velocity unit (0.229 rev/min)
LOAD_UNIT = 0.001  # Present Load counts 0.1 % of the stall torque

# Control-table addresses (EEPROM below 64, RAM from 64).
FIRMWARE_VERSION = 6
RETURN_DELAY_TIME, DRIVE_MODE, OPERATING_MODE, HOMING_OFFSET = 9, 10, 11, 20
PWM_LIMIT, VELOCITY_LIMIT, MAX_POSITION_LIMIT, MIN_POSITION_LIMIT = 36, 44, 48, 52
TORQUE_ENABLE, STATUS_RETURN_LEVEL, HARDWARE_ERROR_STATUS, BUS_WATCHDOG = 64, 68, 70, 98
WATCHDOG_UNIT = 0.02  # s per Bus Watchdog unit
PROFILE_ACCELERATION, PROFILE_VELOCITY, GOAL_POSITION = 108, 112, 116
PRESENT_LOAD, PRESENT_POSITION = 126, 132
STATE_BLOCK = (PRESENT_LOAD, 10)  # Present Load (2), Velocity (4), Position (4): one SyncRead
_STATE = struct.Struct("<hii")  # that block, signed little-endian
NO_LOAD_SPEED = 5.76  # rad/s: the MX-28's 55 rev/min at 12 V, unloaded
#: the largest Present Velocity a true reading holds: the no-load speed and half again
MAX_PRESENT_VELOCITY = math.ceil(1.5 * NO_LOAD_SPEED / VELOCITY_UNIT)
MAX_PRESENT_LOAD = 1000  # 0.1 % units: 100 % of the stall torque
POSITION_MODE = 3  # Operating Mode value
FULL_PWM = 885  # PWM Limit's factory value: the whole supply voltage (the MX-28 has no current limit)

HARDWARE_ERROR_BITS = {0: "input voltage", 2: "overheating", 3: "motor encoder",
                       4: "electrical shock", 5: "overload"}
PACKET_ERRORS = {1: "result fail", 2: "instruction error", 3: "CRC error", 4: "data range error",
                 5: "data length error", 6: "data limit error", 7: "access error"}


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


def velocity_to_radians_per_second(units) -> np.ndarray:
    """Present Velocity (0.229 rev/min units, signed) to joint rates [rad/s].

    >>> velocity_to_radians_per_second([62, -1]).round(4).tolist()
    [1.4868, -0.024]
    """
    return np.asarray(units, dtype=float) * VELOCITY_UNIT


def to_signed(value: int, size: int) -> int:
    """Two's complement: the SDK returns every register unsigned.

    >>> to_signed(0xFFFFFFFF, 4), to_signed(0xFC18, 2)
    (-1, -1000)
    """
    bits = 8 * size
    return value - (1 << bits) if value >> (bits - 1) & 1 else value


def load_to_torque(load, spec: SnakeSpec = SPEC) -> np.ndarray:
    """Present Load (0.1 % of the stall torque, signed) to joint torque [N m].

    >>> float(load_to_torque(-400))      # 40 % of the MX-28's 2.5 N m
    -1.0
    """
    return np.asarray(load, dtype=float) * (LOAD_UNIT * spec.servo.stall_torque)


def decode_state(raw: bytes) -> tuple[int, int, int]:
    """One servo's :data:`STATE_BLOCK` bytes to signed (load, velocity, position) register values.

    >>> decode_state(bytes([0x18, 0xFC, 0xFF, 0xFF, 0xFF, 0xFF, 0x00, 0x08, 0, 0]))
    (-1000, -1, 2048)
    """
    return _STATE.unpack(raw)


def implausible_state(raw: bytes) -> str | None:
    """Why one servo's :data:`STATE_BLOCK` cannot be a true reading, or None when it can be.

    In position mode Present Position stays within one turn (0..4095), no joint turns faster
    than the servo's no-load speed (:data:`MAX_PRESENT_VELOCITY`, with a margin), and Present
    Load counts at most 100 % of the stall torque. A value beyond these is a corrupt or
    misread packet, never the arm's state.

    >>> implausible_state(bytes([0, 0, 0, 0, 0, 0, 0x00, 0x08, 0, 0])) is None
    True
    >>> implausible_state(bytes([0, 0, 0x3B, 0x02, 0, 0, 0x00, 0x08, 0, 0]))
    'Present Velocity 571 (13.7 rad/s; the MX-28 turns at most 5.8 rad/s)'
    """
    load, velocity, position = decode_state(raw)
    if not 0 <= position < TICKS_PER_TURN:
        return f"Present Position {position} (outside the one turn of position mode, 0..{TICKS_PER_TURN - 1})"
    if abs(velocity) > MAX_PRESENT_VELOCITY:
        return (f"Present Velocity {velocity} ({abs(velocity) * VELOCITY_UNIT:.1f} rad/s; the MX-28 turns at most "
                f"{NO_LOAD_SPEED:.1f} rad/s)")
    if abs(load) > MAX_PRESENT_LOAD:
        return f"Present Load {load} (beyond {MAX_PRESENT_LOAD}, 100 % of the stall torque)"
    return None


def position_bytes(tick: int) -> list[int]:
    """A 4-byte position register value, little-endian, as the SDK's write calls take it.

    >>> position_bytes(2048), position_bytes(3071)
    ([0, 8, 0, 0], [255, 11, 0, 0])
    """
    return list(int(tick).to_bytes(4, "little", signed=True))


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


def velocity_limit_units(spec: SnakeSpec = SPEC) -> int:
    """The joint speed limit as Velocity Limit / Profile Velocity units (0.229 rev/min), rounded down.

    >>> velocity_limit_units()                 # 1.5 rad/s
    62
    """
    return math.floor(spec.velocity_limit / VELOCITY_UNIT + 1e-9)
