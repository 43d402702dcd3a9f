"""snakekit: a Jupyter course kit for a 5-joint planar arm of Dynamixel MX-28 servos.

Before MuJoCo is imported, the kit sets ``MUJOCO_GL`` to what this system supports, unless
the variable is already set: ``egl`` on Linux (offscreen rendering, no display needed);
on macOS and Windows it leaves MuJoCo its own default (:func:`snakekit.host.choose_mujoco_gl`).

Names are loaded on first use: ``import snakekit`` is quick, and ``snakekit.Trajectory``
does not load Pinocchio or MuJoCo (``snakekit.forward_kinematics`` loads Pinocchio).
"""

import importlib as _importlib

from .host import choose_mujoco_gl as _choose_mujoco_gl

_choose_mujoco_gl()

from .errors import (  # noqa: E402
    BackendError, BridgeError, BusWatchdogError, CheckFailed, CollisionError, CommunicationError, ConfigurationError,
    FileFormatError, FileWriteError, HardwareError, InputTypeError, InstructionError, LimitError, MissingDependencyError,
    NotFiniteError, PacketError, PortLostError,
    ServoMismatchError, ShapeError, ShortcutError, SnakekitError, TrajectoryError, UnreachableTargetError, ViewerError,
)
from .model import SPEC, SnakeSpec  # noqa: E402

__version__ = "0.1.0"

# public name -> module that defines it (imported when the name is first used)
_LAZY = {
    **dict.fromkeys(("forward_kinematics", "inverse_kinematics", "jacobian", "joint_frames",
                     "planar_jacobian", "tool_pose_2d", "workspace_points", "workspace_boundary",
                     "closest_reachable_point"), "kinematics"),
    **dict.fromkeys(("clearance", "collides"), "collision"),
    **dict.fromkeys(("Trajectory", "joint_trajectory", "side_sweep"), "trajectory"),
    **dict.fromkeys(("JointState", "Run", "make_robot"), "robot"),
    **dict.fromkeys(("as_configuration", "check_limits"), "validate"),
}

__all__ = [
    "SPEC", "SnakeSpec", *_LAZY,
    "SnakekitError", "ConfigurationError", "InputTypeError", "ShapeError", "NotFiniteError",
    "LimitError", "CollisionError", "UnreachableTargetError", "TrajectoryError", "FileFormatError", "FileWriteError",
    "BackendError", "BridgeError", "BusWatchdogError",
    "CommunicationError", "HardwareError", "PortLostError", "ServoMismatchError", "InstructionError", "ViewerError",
    "MissingDependencyError", "PacketError", "CheckFailed", "ShortcutError",
]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'snakekit' has no attribute '{name}'")
    value = getattr(_importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later lookups skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
