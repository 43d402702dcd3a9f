"""A Dynamixel Protocol 2.0 bus of emulated MX-28 servos, on a pseudo-terminal.

Any serial client (the dynamixel-sdk, Dynamixel Wizard through a pty bridge, the kit's own
:class:`snakekit.hardware.DynamixelSnake`) can open :attr:`BusEmulator.port` and talk to
five MX-28(2.0) servos that hold a full control table, follow the firmware's rules, move
like the simulated arm and fail on demand (:class:`Faults`).

>>> import snakekit
>>> with snakekit.make_robot("emulator") as robot:
...     run = robot.move_to([0.3, 0, 0, 0, 0], duration=0.5)
...     print(round(float(robot.read().positions[0]), 2))
0.3

Modules: :mod:`.protocol` (framing), :mod:`.control_table` (registers),
:mod:`.servo` (one servo's firmware), :mod:`.motion` (how the servos move),
:mod:`.faults`, :mod:`.bus` (the pty and the packet loop), :mod:`.record` (what it
keeps of the packets), :mod:`.cli`.
"""

from __future__ import annotations

from .bus import BusEmulator
from .cli import cli
from .faults import Faults
from .motion import MujocoMotion, ProfileMotion
from .record import Received, Write

__all__ = ["BusEmulator", "Faults", "Received", "Write", "MujocoMotion", "ProfileMotion", "cli",
           "make_emulated_robot"]


def make_emulated_robot(*, motion: str = "mujoco", faults: Faults | None = None, q0=None,
                        timing: bool = False, boot_time: float = 0.05, baudrate: int = 4_000_000,
                        ids=None, tcp: str | None = None, latency_timer: int = 0, **robot_options):
    """A :class:`~snakekit.hardware.DynamixelSnake` connected to an emulated bus in a thread.

    The bus emulator is started first, on its own pseudo-terminal; closing the robot stops
    it. The emulator is at ``robot.emulator`` (to inject faults or read its record).

    Args:
        motion: ``"mujoco"`` (default: the simulated arm) or ``"profile"``.
        faults: faults to inject from the start (default none).
        q0: initial joint angles of the emulated arm [rad].
        timing: emulate the return delay and wire time of each status packet.
        boot_time: how long a rebooted servo stays silent [s].
        baudrate: bus speed [baud].
        ids: servo ids, base to tip (default: the spec's).
        tcp: serve the bus on this TCP address (``HOST:PORT``; ``"0"``: a free port on
            127.0.0.1) instead of a pseudo-terminal; the robot opens ``socket://HOST:PORT``.
        latency_timer: model the USB adapter's latency timer [ms] (0: answer at once).
        **robot_options: keyword options of :class:`~snakekit.hardware.DynamixelSnake`
            (``on_close``, ``retries``, ``profile_velocity``...).
    """
    import warnings

    from ..hardware import DynamixelSnake
    from ..validate import options_of

    options_of(DynamixelSnake, robot_options, "the 'emulator' backend", given=("port", "baudrate", "ids"),
               also=("motion", "faults", "q0", "timing", "boot_time", "baudrate", "ids"))
    bus = BusEmulator(ids=ids, motion=motion, q0=q0, timing=timing, boot_time=boot_time,
                      baudrate=baudrate, faults=faults or Faults(), tcp=tcp, latency_timer=latency_timer).start()
    try:
        with warnings.catch_warnings():  # fresh emulated servos: the kit's EEPROM values are always
            warnings.filterwarnings("ignore", "the kit wrote its EEPROM settings")  # written (robot.eeprom_changes)
            robot = DynamixelSnake(bus.port, baudrate, ids, **robot_options)
    except BaseException:
        bus.stop()
        raise
    robot.backend = "emulator"
    robot.emulator = bus
    robot._release.append(bus.stop)
    return robot
