"""What the emulated bus keeps of the packets it received (:attr:`BusEmulator.record`), decoded."""

from __future__ import annotations

from dataclasses import dataclass

from . import protocol as p


@dataclass(frozen=True)
class Received:
    """One instruction packet as it reached the bus.

    Attributes:
        time: emulator clock when it was decoded [s].
        packet: the decoded packet.
        fault: the fault injected on it (``"dropped"``, ``"corrupted"``, ``"delayed"``) or "".
    """

    time: float
    packet: p.Packet
    fault: str = ""

    @property
    def name(self) -> str:
        return self.packet.name


@dataclass(frozen=True)
class Write:
    """One value written to a servo register, decoded from the record.

    Attributes:
        time: emulator clock [s].
        id: servo id (254 for a broadcast WRITE).
        value: the value (two's complement decoded for signed registers).
        instruction: which instruction carried it.
        dropped: True if a fault dropped the packet before any servo saw it.
    """

    time: float
    id: int
    value: int
    instruction: str
    dropped: bool
