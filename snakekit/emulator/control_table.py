"""The MX-28(2.0) control table: every field's address, size, access, default and range.

This table is written from the ROBOTIS e-manual independently of the driver's own register
map (:mod:`snakekit.hardware.registers`), on purpose: the emulator is a test of the driver,
and a shared table would let one mistake pass in both.

One :class:`Field` a register; :data:`MX28_TABLE` lists them in address order. A
:class:`Memory` holds one servo's bytes and knows which writes the firmware refuses.
Indirect addresses (168 and up) are not modelled: reading or writing there is an access
error, as it is for any address past the table.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import ConfigurationError

from . import protocol as p

MODEL_NUMBER = 30
FIRMWARE_VERSION = 46
TABLE_SIZE = 147  # bytes 0..146 (Present Temperature is the last field)


@dataclass(frozen=True)
class Field:
    """One control-table register.

    Attributes:
        address: first byte.
        size: bytes (1, 2 or 4), little-endian.
        name: the e-manual's name.
        access: ``"R"`` or ``"RW"``.
        default: value after a factory reset (EEPROM) or a reboot (RAM).
        low, high: the range the firmware accepts for a write (two's complement values
            for signed fields).
        eeprom: True for addresses below 64 (writable only with torque off).
        signed: whether the value is two's complement.
    """

    address: int
    size: int
    name: str
    access: str
    default: int
    low: int = 0
    high: int = 0
    signed: bool = False

    @property
    def eeprom(self) -> bool:
        return self.address < 64

    @property
    def writable(self) -> bool:
        return self.access == "RW"


def _f(address, size, name, access, default, low=0, high=None, signed=False):
    if high is None:
        high = (1 << (8 * size)) - 1
    return Field(address, size, name, access, default, low, high, signed)


MX28_TABLE: tuple[Field, ...] = (
    _f(0, 2, "Model Number", "R", MODEL_NUMBER),
    _f(2, 4, "Model Information", "R", 0),
    _f(6, 1, "Firmware Version", "R", FIRMWARE_VERSION),
    _f(7, 1, "ID", "RW", 1, 0, 252),
    _f(8, 1, "Baud Rate", "RW", 1, 0, 7),
    _f(9, 1, "Return Delay Time", "RW", 250, 0, 254),
    _f(10, 1, "Drive Mode", "RW", 0, 0, 5),
    _f(11, 1, "Operating Mode", "RW", 3, 0, 16),
    _f(12, 1, "Secondary ID", "RW", 255, 0, 255),
    _f(13, 1, "Protocol Type", "RW", 2, 1, 2),
    _f(20, 4, "Homing Offset", "RW", 0, -1044479, 1044479, True),
    _f(24, 4, "Moving Threshold", "RW", 10, 0, 1023),
    _f(31, 1, "Temperature Limit", "RW", 80, 0, 100),
    _f(32, 2, "Max Voltage Limit", "RW", 160, 95, 160),
    _f(34, 2, "Min Voltage Limit", "RW", 95, 95, 160),
    _f(36, 2, "PWM Limit", "RW", 885, 0, 885),
    _f(40, 4, "Acceleration Limit", "RW", 32767, 0, 32767),
    _f(44, 4, "Velocity Limit", "RW", 230, 0, 1023),
    _f(48, 4, "Max Position Limit", "RW", 4095, 0, 4095),
    _f(52, 4, "Min Position Limit", "RW", 0, 0, 4095),
    _f(63, 1, "Shutdown", "RW", 52, 0, 255),
    _f(64, 1, "Torque Enable", "RW", 0, 0, 1),
    _f(65, 1, "LED", "RW", 0, 0, 1),
    _f(68, 1, "Status Return Level", "RW", 2, 0, 2),
    _f(69, 1, "Registered Instruction", "R", 0),
    _f(70, 1, "Hardware Error Status", "R", 0),
    _f(76, 2, "Velocity I Gain", "RW", 1920, 0, 16383),
    _f(78, 2, "Velocity P Gain", "RW", 100, 0, 16383),
    _f(80, 2, "Position D Gain", "RW", 0, 0, 16383),
    _f(82, 2, "Position I Gain", "RW", 0, 0, 16383),
    _f(84, 2, "Position P Gain", "RW", 850, 0, 16383),
    _f(88, 2, "Feedforward 2nd Gain", "RW", 0, 0, 16383),
    _f(90, 2, "Feedforward 1st Gain", "RW", 0, 0, 16383),
    _f(98, 1, "Bus Watchdog", "RW", 0, -1, 127, True),
    _f(100, 2, "Goal PWM", "RW", 0, -885, 885, True),
    _f(104, 4, "Goal Velocity", "RW", 0, -1023, 1023, True),
    _f(108, 4, "Profile Acceleration", "RW", 0, 0, 32767),
    _f(112, 4, "Profile Velocity", "RW", 0, 0, 32767),
    _f(116, 4, "Goal Position", "RW", 0, -1048575, 1048575, True),
    _f(120, 2, "Realtime Tick", "R", 0),
    _f(122, 1, "Moving", "R", 0),
    _f(123, 1, "Moving Status", "R", 0),
    _f(124, 2, "Present PWM", "R", 0, signed=True),
    _f(126, 2, "Present Load", "R", 0, signed=True),
    _f(128, 4, "Present Velocity", "R", 0, signed=True),
    _f(132, 4, "Present Position", "R", 0, signed=True),
    _f(136, 4, "Velocity Trajectory", "R", 0, signed=True),
    _f(140, 4, "Position Trajectory", "R", 0, signed=True),
    _f(144, 2, "Present Input Voltage", "R", 120),
    _f(146, 1, "Present Temperature", "R", 35),
)

FIELDS = {f.name: f for f in MX28_TABLE}
_OWNER: list[Field | None] = [None] * TABLE_SIZE
for _field in MX28_TABLE:
    for _a in range(_field.address, _field.address + _field.size):
        _OWNER[_a] = _field

# Addresses the firmware model reads on every packet, by name (looked up once, here).
MODEL_NUMBER_ADDRESS = FIELDS["Model Number"].address
FIRMWARE_VERSION_ADDRESS = FIELDS["Firmware Version"].address
RETURN_DELAY_TIME = FIELDS["Return Delay Time"].address
HOMING_OFFSET = FIELDS["Homing Offset"].address
TORQUE_ENABLE = FIELDS["Torque Enable"].address
STATUS_RETURN_LEVEL = FIELDS["Status Return Level"].address
HARDWARE_ERROR_STATUS = FIELDS["Hardware Error Status"].address
GOAL_POSITION = FIELDS["Goal Position"].address
REALTIME_TICK = FIELDS["Realtime Tick"].address
HARDWARE_ERROR_BITS = {0: "input voltage", 2: "overheating", 3: "motor encoder",
                       4: "electrical shock", 5: "overload"}
VALID_OPERATING_MODES = (1, 3, 4, 16)


def field_at(address: int) -> Field:
    """The field that starts at ``address`` (``KeyError`` if none does)."""
    f = _OWNER[address] if 0 <= address < TABLE_SIZE else None
    if f is None or f.address != address:
        raise ConfigurationError(f"no MX-28 control-table field starts at address {address}")
    return f


def to_signed(value: int, size: int) -> int:
    """Two's complement of an unsigned ``size``-byte value."""
    bits = 8 * size
    return value - (1 << bits) if value & (1 << (bits - 1)) else value


def to_unsigned(value: int, size: int) -> int:
    return value & ((1 << (8 * size)) - 1)


def decode_hardware_error(bits: int) -> list[str]:
    """Names of the set bits of Hardware Error Status (address 70)."""
    return [name for b, name in HARDWARE_ERROR_BITS.items() if bits >> b & 1] or (
        [f"unknown bits 0x{bits:02X}"] if bits else [])


class Memory:
    """The bytes of one servo's control table, with the firmware's write rules."""

    def __init__(self, servo_id: int = 1):
        self.data = bytearray(TABLE_SIZE)
        self.factory_reset()
        self.set("ID", servo_id)

    # --- plain access ---------------------------------------------------------------------

    def get(self, name: str) -> int:
        f = FIELDS[name]
        v = int.from_bytes(self.data[f.address:f.address + f.size], "little")
        return to_signed(v, f.size) if f.signed else v

    def set(self, name: str, value: int) -> None:
        """Store a value without any check (the firmware's own updates)."""
        f = FIELDS[name]
        self.data[f.address:f.address + f.size] = to_unsigned(int(value), f.size).to_bytes(f.size, "little")

    def factory_reset(self, keep: tuple[str, ...] = ()) -> None:
        kept = {name: self.get(name) for name in keep} if any(self.data) else {}
        for f in MX28_TABLE:
            self.set(f.name, f.default)
        for name, value in kept.items():
            self.set(name, value)

    def reset_ram(self) -> None:
        """RAM fields back to their defaults (what a reboot does)."""
        for f in MX28_TABLE:
            if not f.eeprom:
                self.set(f.name, f.default)

    # --- the firmware's checks --------------------------------------------------------------

    def read(self, address: int, length: int) -> tuple[int, bytes]:
        """``(error, data)`` for a READ of ``length`` bytes at ``address``."""
        if length < 1 or address < 0 or address + length > TABLE_SIZE:
            return p.ACCESS_ERROR, b""
        return 0, bytes(self.data[address:address + length])

    def check_write(self, address: int, data: bytes) -> tuple[int, list[tuple[Field, int]]]:
        """Check a WRITE; ``(error, [(field, value), ...])``. Nothing is stored.

        Errors: access (outside the table, a gap, a read-only field, EEPROM with torque on),
        data length (a write that cuts a field), data range (outside the field's range),
        data limit (a goal outside the position, velocity or PWM limits).
        """
        end = address + len(data)
        if not data or address < 0 or end > TABLE_SIZE:
            return p.ACCESS_ERROR, []
        torque_on = self.data[TORQUE_ENABLE] == 1
        values = []
        a = address
        while a < end:
            f = _OWNER[a]
            if f is None or not f.writable:
                return p.ACCESS_ERROR, []
            if f.address != a or a + f.size > end:
                return p.DATA_LENGTH_ERROR, []
            if f.eeprom and torque_on:
                return p.ACCESS_ERROR, []
            v = int.from_bytes(data[a - address:a - address + f.size], "little")
            if f.signed:
                v = to_signed(v, f.size)
            values.append((f, v))
            a += f.size
        for f, v in values:
            if not f.low <= v <= f.high or (f.name == "Operating Mode" and v not in VALID_OPERATING_MODES):
                return p.DATA_RANGE_ERROR, []
        for f, v in values:
            if self._over_limit(f, v, values):
                return p.DATA_LIMIT_ERROR, []
        return 0, values

    def _over_limit(self, f: Field, v: int, values) -> bool:
        pending = {g.name: x for g, x in values}

        def now(name):
            return pending.get(name, self.get(name))

        if f.name == "Goal Position" and now("Operating Mode") == 3:
            return not now("Min Position Limit") <= v <= now("Max Position Limit")
        if f.name == "Goal Velocity":
            return abs(v) > now("Velocity Limit")
        if f.name == "Goal PWM":
            return abs(v) > now("PWM Limit")
        if f.name == "Profile Acceleration":
            return v > now("Acceleration Limit")
        if f.name == "Profile Velocity":
            return v > now("Velocity Limit")
        return False
