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

import threading
import time
import weakref


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
        while not self._stop.wait(self.interval / 2):
            robot = self._robot()
            if robot is None or robot.closed:
                return
            if time.perf_counter() - robot.bus.last_used >= self.interval:
                self.sent += 1
                try:
                    robot._keep_alive()
                except Exception:  # the bus may be failing: the watchdog will stop the arm
                    self.failed += 1
            del robot

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=2)
