"""snakekit: a Jupyter course kit for a 5-joint planar arm of Dynamixel MX-28 servos.

The kit sets ``MUJOCO_GL=egl`` (offscreen rendering, no display needed) before MuJoCo is
imported, unless the variable is already set.
"""

import os as _os

_os.environ.setdefault("MUJOCO_GL", "egl")

from .errors import (  # noqa: E402
    BackendError, CommunicationError, FileFormatError, HardwareError, LimitError, NotFiniteError,
    ShapeError, SnakekitError, TrajectoryError, UnreachableTargetError,
)
from .model import SPEC, SnakeSpec  # noqa: E402
from .kinematics import (  # noqa: E402
    forward_kinematics, inverse_kinematics, jacobian, joint_frames, planar_jacobian, tool_pose_2d,
    workspace_points,
)
from .trajectory import Trajectory, joint_trajectory, side_sweep  # noqa: E402
from .robot import JointState, Run, make_robot  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "SPEC", "SnakeSpec", "forward_kinematics", "jacobian", "planar_jacobian", "joint_frames",
    "inverse_kinematics", "tool_pose_2d", "workspace_points", "Trajectory", "joint_trajectory",
    "side_sweep", "JointState", "Run", "make_robot", "SnakekitError", "ShapeError",
    "NotFiniteError", "LimitError", "UnreachableTargetError", "TrajectoryError",
    "FileFormatError", "BackendError", "CommunicationError", "HardwareError",
]
