"""Dynamixel Protocol 2.0 framing: CRC, byte stuffing, instruction and status packets.

Pure functions over ``bytes``, written from the protocol description (not from the SDK), so
the tests can check the SDK and the emulator against an independent implementation.

>>> ping(1).hex(" ")
'ff ff fd 00 01 03 00 01 19 4e'
>>> ping(0xFE)[-2:].hex(" ")
'31 42'
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import PacketError

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
MAX_ID = 0xFC
STATUS = 0x55

PING, READ, WRITE, REG_WRITE, ACTION, FACTORY_RESET, REBOOT = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08
SYNC_READ, SYNC_WRITE, BULK_READ, BULK_WRITE = 0x82, 0x83, 0x92, 0x93
INSTRUCTION_NAMES = {
    PING: "PING", READ: "READ", WRITE: "WRITE", REG_WRITE: "REG_WRITE", ACTION: "ACTION",
    FACTORY_RESET: "FACTORY_RESET", REBOOT: "REBOOT", SYNC_READ: "SYNC_READ",
    SYNC_WRITE: "SYNC_WRITE", BULK_READ: "BULK_READ", BULK_WRITE: "BULK_WRITE",
}

# Low 7 bits of a status packet's error byte; bit 7 is the hardware alert.
RESULT_FAIL, INSTRUCTION_ERROR, CRC_ERROR, DATA_RANGE_ERROR = 1, 2, 3, 4
DATA_LENGTH_ERROR, DATA_LIMIT_ERROR, ACCESS_ERROR = 5, 6, 7
ALERT = 0x80
ERROR_NAMES = {
    RESULT_FAIL: "result fail", INSTRUCTION_ERROR: "instruction error", CRC_ERROR: "CRC error",
    DATA_RANGE_ERROR: "data range error", DATA_LENGTH_ERROR: "data length error",
    DATA_LIMIT_ERROR: "data limit error", ACCESS_ERROR: "access error",
}


def _crc_table() -> list[int]:
    table = []
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return table


_CRC_TABLE = _crc_table()


def crc16(data: bytes, crc: int = 0) -> int:
    """CRC-16/BUYPASS (poly 0x8005, init 0, no reflection, no final xor) of ``data``.

    >>> hex(crc16(b"123456789"))
    '0xfee8'
    """
    table = _CRC_TABLE
    for b in data:
        crc = ((crc << 8) ^ table[((crc >> 8) ^ b) & 0xFF]) & 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` in ``body`` (the bytes from INST to the last param).

    The two bytes before the body (the length) never end in ``FF FF`` for packets this
    small, so the search starts inside the body.

    >>> stuff(bytes.fromhex("03 14 00 ff ff fd ff")).hex(" ")
    '03 14 00 ff ff fd fd ff'
    """
    if b"\xff\xff\xfd" not in body:
        return bytes(body)
    return bytes(body).replace(b"\xff\xff\xfd", b"\xff\xff\xfd\xfd")


def unstuff(body: bytes) -> bytes:
    """Undo :func:`stuff`: drop the ``FD`` that follows each ``FF FF FD``."""
    if b"\xff\xff\xfd\xfd" not in body:
        return bytes(body)
    return bytes(body).replace(b"\xff\xff\xfd\xfd", b"\xff\xff\xfd")


def frame(servo_id: int, body: bytes) -> bytes:
    """A complete packet: header, id, length, stuffed ``body`` (INST or 0x55 ERR, params), CRC."""
    body = stuff(body)
    head = HEADER + bytes((servo_id, (len(body) + 2) & 0xFF, (len(body) + 2) >> 8))
    crc = crc16(body, crc16(head))
    return head + body + bytes((crc & 0xFF, crc >> 8))


def instruction(servo_id: int, inst: int, params: bytes = b"") -> bytes:
    """An instruction packet."""
    return frame(servo_id, bytes((inst,)) + bytes(params))


def status(servo_id: int, error: int = 0, params: bytes = b"") -> bytes:
    """A status packet (instruction 0x55) with error byte ``error``."""
    return frame(servo_id, bytes((STATUS, error)) + bytes(params))


def ping(servo_id: int) -> bytes:
    """A PING instruction packet."""
    return instruction(servo_id, PING)


@dataclass(frozen=True)
class Packet:
    """One decoded packet (stuffing removed).

    Attributes:
        id: servo id (254 = broadcast).
        instruction: instruction code (0x55 for a status packet).
        params: the parameters (for a status packet: after the error byte).
        error: the error byte of a status packet (0 for instructions).
        crc_ok: whether the CRC matched.
        raw: the packet as it was on the wire.
    """

    id: int
    instruction: int
    params: bytes
    error: int = 0
    crc_ok: bool = True
    raw: bytes = b""

    @property
    def name(self) -> str:
        return "STATUS" if self.instruction == STATUS else INSTRUCTION_NAMES.get(
            self.instruction, f"0x{self.instruction:02X}")


class Parser:
    """Cuts a byte stream into packets; keeps partial packets for the next :meth:`feed`."""

    def __init__(self, max_length: int = 1024):
        self.buffer = bytearray()
        self.max_length = max_length

    def feed(self, data: bytes) -> list[Packet]:
        """Add received bytes; return the complete packets found (CRC checked, unstuffed)."""
        buf = self.buffer
        buf += data
        packets = []
        while True:
            start = buf.find(HEADER)
            if start < 0:
                # keep a possible partial header at the end
                keep = max(len(buf) - 3, 0)
                del buf[:keep]
                return packets
            if start:
                del buf[:start]
            if len(buf) < 7:
                return packets
            length = buf[5] | buf[6] << 8
            if length < 3 or length > self.max_length:
                del buf[:1]  # not a real header
                continue
            total = 7 + length
            if len(buf) < total:
                return packets
            raw = bytes(buf[:total])
            del buf[:total]
            crc_ok = crc16(raw[:-2]) == (raw[-2] | raw[-1] << 8)
            body = unstuff(raw[7:-2])
            if body[0] == STATUS and len(body) >= 2:
                packets.append(Packet(raw[4], STATUS, body[2:], body[1], crc_ok, raw))
            else:
                packets.append(Packet(raw[4], body[0], body[1:], 0, crc_ok, raw))


def decode(raw: bytes) -> Packet:
    """Decode exactly one packet from ``raw``; :class:`~snakekit.errors.PacketError` if it doesn't hold exactly one."""
    packets = Parser().feed(raw)
    if len(packets) != 1:
        raise PacketError(f"expected one packet in {raw.hex(' ')}, found {len(packets)}")
    return packets[0]


def describe_error(error: int) -> str:
    """The error byte in words, e.g. ``'hardware alert, data limit error'``."""
    words = ["hardware alert"] if error & ALERT else []
    low = error & 0x7F
    if low:
        words.append(ERROR_NAMES.get(low, f"unknown error {low}"))
    return ", ".join(words) or "no error"


def u16(b: bytes, i: int) -> int:
    """A little-endian 16-bit value at ``b[i]``."""
    return b[i] | b[i + 1] << 8


def write_blocks(pk: Packet) -> list[tuple[int, int, bytes]]:
    """``(servo id, address, data)`` for every write carried by an instruction packet."""
    b, inst = pk.params, pk.instruction
    if inst in (WRITE, REG_WRITE) and len(b) >= 3:
        return [(pk.id, u16(b, 0), b[2:])]
    if inst == SYNC_WRITE and len(b) >= 4:
        address, length = u16(b, 0), u16(b, 2)
        step = 1 + length
        return [(b[i], address, b[i + 1:i + step]) for i in range(4, len(b) - step + 1, step)]
    if inst == BULK_WRITE:
        out, i = [], 0
        while i + 5 <= len(b):
            servo_id, address, length = b[i], u16(b, i + 1), u16(b, i + 3)
            out.append((servo_id, address, b[i + 5:i + 5 + length]))
            i += 5 + length
        return out
    return []
