"""Stopping the arm: what ``on_close`` asks for, saying only what the servos confirmed.

:meth:`StopMixin.stop` is what the driver calls on ``close()``, after an exception in a run,
after Ctrl-C and when the bus fails: torque off, read back from every servo, or hold the
pose by a goal that can never be far from where each servo is. It never raises: the bus may
be failing while it runs.
"""

from __future__ import annotations

import time

from .bus import sdk
from .registers import GOAL_POSITION, PRESENT_POSITION, TICKS_PER_RAD, TORQUE_ENABLE, to_signed


class StopMixin:
    """The driver's stop: torque off (``on_close="torque_off"``) or hold (``"hold"``)."""

    def stop(self) -> str:
        """Stop the arm now, as ``on_close`` says; never raises (the bus may be failing).

        Returns what was done, in words, saying only what the servos confirmed.
        """
        self._planner = None  # the servos' references start again where they stop
        with self.bus.hold():
            self.port.is_using = False  # an exception may have left the SDK's flag set
            try:
                if self.on_close == "hold":
                    return self._hold_safely()
                still_on = self._torque_off_safely()
            except Exception:  # a closed or broken port: nothing more can be sent
                still_on = list(self.ids)
        if not still_on:
            return "The arm was stopped: torque off, read back from every servo."
        return (f"Torque off was sent, but servo(s) {', '.join(map(str, still_on))} did not confirm it: "
                "they may still have torque on. Switch the arm's power off before touching it.")

    def _torque_off_safely(self, ids=None) -> list[int]:
        """Torque off (broadcast, or to each of ``ids``) and read it back; the ids that did not confirm it.

        A servo that read back torque off once has confirmed it (nothing here turns it on again): the
        next tries send torque off to, and read back, only the servos that have not, so a read that
        fails after a confirmation (a reply held up on a busy computer) does not count against it.
        """
        ph, port = self.bus.ph, self.port
        ids = list(self.ids if ids is None else ids)
        confirmed: set[int] = set()
        for _ in range(self.retries + 1):
            left = [i for i in ids if i not in confirmed]
            try:
                port.clearPort()
                for target in ([sdk.BROADCAST_ID] if left == list(self.ids) else left):
                    ph.write1ByteTxOnly(port, target, TORQUE_ENABLE, 0)
                    port.is_using = False
            except Exception:
                pass
            port.is_using = False
            for i in left:
                value, result, _ = ph.read1ByteTxRx(port, i, TORQUE_ENABLE)
                port.is_using = False
                if result == sdk.COMM_SUCCESS and value == 0:
                    confirmed.add(i)
            if len(confirmed) == len(ids):
                break
        still_on = [i for i in ids if i not in confirmed]
        self.torque_enabled = bool(still_on) or len(ids) < len(self.ids)
        return still_on

    def _hold_safely(self) -> str:
        """Hold each servo where it is, by a goal that cannot be far from it; torque off where in doubt.

        A servo's goal becomes its present position only when two READs of it, each the checked
        answer to its own request, agree within what the joint can move between them, inside
        the joint's limits; the goal is then written with an answered WRITE. A servo that fails
        any of this is not sent a goal at all: its torque is turned off (and read back), so no
        goal is ever made from a reading that was not verified.
        """
        held, limp = [], []
        for i in self.ids:
            (held if self._hold_servo(i) else limp).append(i)
        parts = []
        if held:
            parts.append(f"servo(s) {', '.join(map(str, held))} hold where they are (goal = present position, "
                         "read twice and written with an answer)")
        if limp:
            still_on = self._torque_off_safely(limp)
            off = [i for i in limp if i not in still_on]
            if off:
                parts.append(f"servo(s) {', '.join(map(str, off))} could not be read reliably, so their torque was "
                             "turned off instead (read back)")
            if still_on:
                parts.append(f"servo(s) {', '.join(map(str, still_on))} could not be read reliably and did not "
                             "confirm torque off: they may still move to their last goal. Switch the arm's power "
                             "off before touching it")
        return "The arm was stopped: " + "; ".join(parts) + "."

    def _hold_servo(self, servo_id: int) -> bool:
        """Goal = present position of one servo, from two verified READs that agree; False if not done."""
        lo, hi = self.tick_limits
        tries = min(self.retries, 1)
        readings = []
        for _ in range(2):
            t = time.perf_counter()
            result, value, error = self.bus.read(servo_id, PRESENT_POSITION, 4, tries=tries)
            if result != sdk.COMM_SUCCESS or error & 0x7F:
                return False
            readings.append((t, to_signed(value, 4)))
        (t1, a), (t2, b) = readings
        reach = (self.spec.velocity_limit * 1.5 * (t2 - t1 + 0.01)) * TICKS_PER_RAD + 2  # ticks it can move
        if not (lo <= b <= hi) or abs(b - a) > reach:
            return False
        result, error = self.bus.write(servo_id, GOAL_POSITION, 4, b, tries=tries)
        return result == sdk.COMM_SUCCESS and not error & 0x7F

