"""Protocol 2.0 framing: CRC, byte stuffing and packet parsing agree with the spec and the SDK."""

import random

import pytest

from snakekit.emulator import protocol as p
from tests.conftest import need


def test_crc_known_vectors_from_the_e_manual():
    assert p.ping(1) == bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E")
    assert p.ping(0xFE) == bytes.fromhex("FF FF FD 00 FE 03 00 01 31 42")
    assert p.crc16(b"123456789") == 0xFEE8  # the CRC-16/BUYPASS check value


def test_crc_matches_the_sdk_on_random_packets():
    sdk = need("dynamixel_sdk")
    ph = sdk.PacketHandler(2.0)
    rng = random.Random(4)
    for _ in range(200):
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 60)))
        assert p.crc16(data) == ph.updateCRC(0, list(data), len(data))


def test_homing_offset_write_is_stuffed_like_the_sdk_does():
    sdk = need("dynamixel_sdk")
    ph = sdk.PacketHandler(2.0)
    value = (-131073) & 0xFFFFFFFF  # bytes FF FF FD FF: the header pattern inside the data
    params = bytes((20, 0)) + value.to_bytes(4, "little")
    ours = p.instruction(1, p.WRITE, params)
    txpacket = [0] * 16
    txpacket[4], txpacket[5], txpacket[6], txpacket[7] = 1, len(params) + 3, 0, p.WRITE
    txpacket[8:8 + len(params)] = list(params)
    stuffed = ph.addStuffing(txpacket)
    length = stuffed[5] | stuffed[6] << 8
    body = bytes(stuffed[7:7 + length - 2])
    assert b"\xff\xff\xfd\xfd" in ours and ours[7:-2] == body
    assert ours[5] == length == len(params) + 4  # LEN counts the stuffed byte
    packet = p.decode(ours)
    assert packet.crc_ok and packet.params == params


def test_stuffing_round_trips_on_nasty_payloads():
    for body in (b"\xff\xff\xfd", b"\xff\xff\xfd\xfd", b"\xff\xff\xff\xfd\xff\xff\xfd", b"\x55\x00" + b"\xff" * 4 + b"\xfd"):
        assert p.unstuff(p.stuff(body)) == body
        assert b"\xff\xff\xfd" not in p.stuff(body).replace(b"\xff\xff\xfd\xfd", b"")


def test_status_with_velocity_minus_one_is_stuffed_and_decoded():
    raw = p.status(2, 0, (-1 & 0xFFFFFFFF).to_bytes(4, "little") + b"\xfd")
    assert b"\xff\xff\xff\xff\xfd\xfd" in raw
    pk = p.decode(raw)
    assert (pk.id, pk.instruction, pk.error, pk.crc_ok) == (2, p.STATUS, 0, True)
    assert pk.params == b"\xff\xff\xff\xff\xfd"


def test_parser_finds_packets_split_across_reads_and_skips_garbage():
    stream = b"\x00\x17\xff" + p.ping(1) + p.instruction(3, p.READ, bytes((132, 0, 4, 0)))
    parser = p.Parser()
    got = []
    for i in range(0, len(stream), 3):
        got += parser.feed(stream[i:i + 3])
    assert [(k.id, k.name) for k in got] == [(1, "PING"), (3, "READ")]
    assert got[1].params == bytes((132, 0, 4, 0))


def test_parser_flags_a_bad_crc():
    raw = bytearray(p.ping(1))
    raw[-1] ^= 0xFF
    (pk,) = p.Parser().feed(bytes(raw))
    assert not pk.crc_ok


@pytest.mark.parametrize("error, words", [(0, "no error"), (0x86, "hardware alert, data limit error"),
                                          (0x07, "access error")])
def test_error_byte_in_words(error, words):
    assert p.describe_error(error) == words


@pytest.mark.parametrize("name", ["snakekit.hardware", "snakekit.emulator.protocol", "snakekit.emulator.faults"])
def test_docstring_examples(name):
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.failed == 0 and result.attempted > 0


def test_control_table_fields_do_not_overlap_and_match_the_e_manual():
    from snakekit.emulator.control_table import FIELDS, MX28_TABLE, TABLE_SIZE

    ends = 0
    for f in MX28_TABLE:
        assert f.address >= ends, f"{f.name} overlaps the field before it"
        ends = f.address + f.size
    assert ends == TABLE_SIZE
    expected = {"Model Number": (0, 2, 30), "Return Delay Time": (9, 1, 250), "Homing Offset": (20, 4, 0),
                "Max Position Limit": (48, 4, 4095), "Torque Enable": (64, 1, 0), "Status Return Level": (68, 1, 2),
                "Hardware Error Status": (70, 1, 0), "Position P Gain": (84, 2, 850), "Goal Position": (116, 4, 0),
                "Present Load": (126, 2, 0), "Present Velocity": (128, 4, 0), "Present Position": (132, 4, 0),
                "Present Temperature": (146, 1, 35)}
    for name, (address, size, default) in expected.items():
        f = FIELDS[name]
        assert (f.address, f.size, f.default) == (address, size, default), name
    assert [f.name for f in MX28_TABLE if f.eeprom and f.writable][:3] == ["ID", "Baud Rate", "Return Delay Time"]
