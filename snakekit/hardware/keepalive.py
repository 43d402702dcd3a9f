"""The Bus Watchdog's other half: while the robot is open, the bus never stays quiet for long.

Each servo's Bus Watchdog (address 98, 20 ms units) stops it when it hears nothing for longer
than the watchdog period while its torque is on: the joint stops where it is and refuses new
goals until the watchdog is cleared. The driver arms it after torque-on. So that a student
thinking between two cells does not trip it, :class:`KeepAlive` sends one SyncRead of the
servos' status whenever the bus has been idle for a quarter of the period. If the program
dies (``kill -9``, a crashed kernel, a pulled USB cable) the packets stop, and the servos
stop themselves.
"""

from __future__ import annotations

import math
import threading
import time
import weakref

from ..errors import BackendError, BusWatchdogError, PortLostError
from ..host import realtime
from .bus import SILENCE_SHARE, describe, sdk
from .registers import BUS_WATCHDOG, HARDWARE_ERROR_STATUS, TORQUE_ENABLE, WATCHDOG_UNIT, to_signed

STATUS_BLOCK = (TORQUE_ENABLE, BUS_WATCHDOG - TORQUE_ENABLE + 1)  # 64..98: torque, errors, watchdog


class KeepAlive:
    """A daemon thread that calls ``robot._keep_alive()`` when the bus has been idle too long.

    Holds the robot only weakly, so a forgotten robot is still collected (and closed).

    Args:
        robot: the :class:`~snakekit.hardware.DynamixelSnake`.
        period: the watchdog period [s]; the bus is used at least every ``period / 4``.
    """

    def __init__(self, robot, period: float):
        self._robot = weakref.ref(robot)
        self.interval = period / 4
        self._stop = threading.Event()
        #: keep-alive packets sent, and how many of them failed
        self.sent = self.failed = 0
        self._thread = threading.Thread(target=self._loop, name=f"watchdog keep-alive {robot.port_name}",
                                        daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        with realtime():  # a busy computer must not hold it back past the Bus Watchdog
            self._keep_alive()

    def _keep_alive(self) -> None:
        while not self._stop.wait(self.interval / 2):
            robot = self._robot()
            if robot is None or robot.closed:
                return
            if time.perf_counter() - robot.bus.last_used >= self.interval:
                self.sent += 1
                try:
                    robot._keep_alive()
                except PortLostError:  # nothing can reach the arm any more: the next call on it says so
                    self.failed += 1
                    return
                except Exception:  # the bus may be failing: the watchdog will stop the arm
                    self.failed += 1
            del robot

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2)


class WatchdogMixin:
    """The driver's side of the Bus Watchdog: arming it, the status read the keep-alive sends,
    and the check that the servos will take goals (torque on, not stopped by the watchdog)."""

    def _arm_watchdog(self) -> None:
        """Clear any watchdog stop, then set the period (20 ms units) on every servo."""
        units = round(self.watchdog / WATCHDOG_UNIT)
        for i in self.ids:
            self._write(i, BUS_WATCHDOG, 1, 0)
            if units:
                self._write(i, BUS_WATCHDOG, 1, units)
        self._last_status = {i: (self.torque_enabled, units) for i in self.ids}
        # waiting out late bytes must not outlast the watchdog (bus.SILENCE_SHARE of its period)
        self.bus.silence_limit = units * WATCHDOG_UNIT * SILENCE_SHARE if units else math.inf

    def servo_status(self) -> dict[int, tuple[bool, int]]:
        """One SyncRead of every servo's Torque Enable and Bus Watchdog: ``{id: (torque on, watchdog)}``.

        A watchdog of -1 means the servo stopped because it heard nothing for too long.
        """
        self._check_open()
        status = self._status
        result, failed = self.bus.retry(status.exchange, by_servo=True)
        if result != sdk.COMM_SUCCESS:
            self._fail(f"servo {failed} on {self.port_name} did not answer the SyncRead of its "
                       f"status ({describe(result)}, {self._tries()})", result)
        out = {}
        for i in self.ids:
            data = bytes(status.data_dict[i])
            out[i] = (data[0] == 1, to_signed(data[-1], 1))
        self._last_status = out
        return out

    def _keep_alive(self) -> None:
        """What the keep-alive thread sends: a status read (never stops the arm); what it reads
        is kept for :meth:`command` to check without a packet of its own."""
        if not self.closed:
            if self.bus.attempt(self._status.exchange)[0] == sdk.COMM_SUCCESS:
                self._last_status = {i: (self._status.data_dict[i][0] == 1, to_signed(self._status.data_dict[i][-1], 1))
                                     for i in self.ids}

    def _check_after_run(self, run):
        """``run``, unless the watchdog stopped servos midway (the program stalled for longer
        than its period): then a BusWatchdogError that says so, with the run as measured on ``.run``."""
        try:
            self._check_ready()
        except BackendError as e:
            e.args = (f"during the run, {e} The run as measured is kept on this error's .run.",)
            e.run = run
            raise
        return run

    def _check_ready(self, status=None) -> None:
        """Refuse to send goals the servos would ignore: torque off, or stopped by the watchdog. A servo
        whose torque is off because of a fault it reports (an overload the run's last reading came too early
        to see) raises its :class:`~snakekit.errors.HardwareError` first, the arm stopped, as the run would have.

        ``status`` (``{id: (torque on, watchdog)}``) is read from the servos when not given.
        """
        status = self.servo_status() if status is None else status
        stopped = [i for i, (_, w) in status.items() if w < 0]
        off = [i for i, (on, _) in status.items() if not on]
        self.torque_enabled = not off
        for i in off:  # a servo that turned its torque off itself: its fault (first: torque_on does not clear it)
            bits = self._read(i, HARDWARE_ERROR_STATUS, 1, check_alert=False)
            if bits:
                raise self._hardware_error(i, bits)   # the arm is stopped, as for a fault a reading saw
        if stopped:
            raise BusWatchdogError(
                f"the Bus Watchdog stopped servo(s) {', '.join(map(str, stopped))} on {self.port_name}: they "
                f"heard nothing for more than {self.watchdog:g} s, so they hold where they stopped and "
                "refuse goals. Call robot.torque_on() to clear it and go on.")
        if off:
            raise BackendError(
                f"torque is off on servo(s) {', '.join(map(str, off))} on {self.port_name} (read back from the "
                "servos), so they would ignore goals; call robot.torque_on() first")
