"""The real arm: five MX-28(2.0) servos on one Dynamixel bus, through the unmodified dynamixel-sdk.

>>> import snakekit
>>> with snakekit.make_robot("hardware", port="/dev/ttyUSB0") as robot:   # doctest: +SKIP
...     robot.home()

Modules, one concept each:

* :mod:`.registers`: control-table addresses, units and the tick conversions (servo ticks
  exist only in this package: 2048 ticks = 0 rad, 4096 a turn);
* :mod:`.bus`: the SDK's port (opened exclusively) and packets, and the one retry loop;
* :mod:`.options`: the driver's options, checked before the port opens;
* :mod:`.startup`: the EEPROM settings checked (and written, or refused) at start-up;
* :mod:`.keepalive`: the Bus Watchdog, armed while the robot is open, and its keep-alive;
* :mod:`.driver`: :class:`DynamixelSnake`, the arm as a :class:`~snakekit.robot.Robot`.
"""

from ..errors import InstructionError, ServoMismatchError
from .driver import ON_CLOSE, DynamixelSnake, ServoInfo
from .registers import (decode_hardware_error, load_to_torque, position_limit_ticks, radians_to_ticks,
                        ticks_to_radians, to_signed, velocity_to_radians_per_second)

__all__ = ["DynamixelSnake", "ServoInfo", "ON_CLOSE", "ServoMismatchError", "InstructionError",
           "radians_to_ticks", "ticks_to_radians", "velocity_to_radians_per_second", "to_signed",
           "load_to_torque", "decode_hardware_error", "position_limit_ticks"]
