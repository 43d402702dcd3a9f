"""What the arm was last told, in words, for the error raised when its port goes away.

When the USB adapter is unplugged (or the bridge, or the emulator behind the port, stops),
nothing more can reach the servos: they keep the last goal that left the port, with the
torque they had, until their Bus Watchdog stops them. The message of
:class:`~snakekit.errors.PortLostError` says which goal that was, from the last SyncWrite
that left the port (:attr:`snakekit.hardware.port.Port.last_sync_write`), not from what the
driver meant to send. Through a bridge, a goal that left the port may still have been lost
on the way, and the message says so.
"""

from __future__ import annotations

import time

from ..bridge import is_url
from .registers import GOAL_POSITION, ticks_to_radians, to_signed


def goals_in(packet: bytes) -> dict[int, int] | None:
    """The goal positions [ticks] a SYNC_WRITE packet carries, ``{id: ticks}``; None if it writes another register.

    >>> goals_in(bytes([0xFF, 0xFF, 0xFD, 0, 0xFE, 12, 0, 0x83, 116, 0, 4, 0, 1, 0, 8, 0, 0, 0, 0]))
    {1: 2048}
    """
    address, size = packet[8] | packet[9] << 8, packet[10] | packet[11] << 8
    if address != GOAL_POSITION or size != 4:
        return None
    body = packet[12:-2]
    return {body[i]: to_signed(int.from_bytes(body[i + 1:i + 5], "little"), 4) for i in range(0, len(body) - 4, 5)}


def last_told(robot) -> str:
    """One or two sentences: the last goal that left the port (and when), the torque, and what the servos do now."""
    if robot is None:
        return ""
    sent = robot.port.last_sync_write
    goals = goals_in(sent[1]) if sent is not None else None
    if goals:
        q = ticks_to_radians([goals.get(i, 0) for i in robot.ids])
        ago = time.perf_counter() - sent[0]
        told = (f"The arm was last told, {ago:.2f} s before this was noticed: goal [{', '.join(f'{x:.3f}' for x in q)}] rad "
                f"(joints 1-{len(q)}, goal {robot.goals_sent} of this robot"
                + ("; it may not have reached the arm)" if is_url(robot.port_name) else ")"))
    else:
        told = "The arm was last told no goal since start-up"
    if not robot.torque_enabled:
        return f"{told}, torque off: it is limp."
    if robot.watchdog:
        return (f"{told}, torque on: each servo's Bus Watchdog stops it where it is {robot.watchdog:g} s after "
                "the last packet, torque kept on.")
    return f"{told}, torque on, Bus Watchdog off: the servos go on to that goal and hold it."
