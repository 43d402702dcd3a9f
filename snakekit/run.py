"""What a robot reads and records: one reading of the arm (:class:`JointState`) and what
happened when a trajectory ran (:class:`Run`, saved to and loaded from ``.npz`` files).

They load without Pinocchio or MuJoCo: the grader and the plots read runs with numpy alone.
:mod:`snakekit.robot` makes them, and names them too.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import CheckFailed, FileFormatError, InputTypeError, NotFiniteError, ShapeError, SnakekitError
from .model import SPEC, SnakeSpec
from .trajectory import Trajectory
from .validate import (as_path, check_length, finite_array, frozen, number, quote, read_npz, real_array,
                       write_failed, writable_file)


@dataclass(frozen=True, eq=False)
class JointState:
    """One reading of the arm.

    Attributes:
        time: robot clock [s] (simulated time for the simulator).
        positions: joint angles [rad].
        velocities: joint rates [rad/s].
        efforts: joint torques [N m] (from Present Load on hardware).
    """

    time: float
    positions: np.ndarray
    velocities: np.ndarray
    efforts: np.ndarray

    def __post_init__(self):
        arrays = (self.positions, self.velocities, self.efforts)
        if (type(self.time) in (float, np.float64) and all(  # a backend's own reading: checked in 2 us, not 40
                type(a) is np.ndarray and a.dtype == np.float64 and a.ndim == 1 and a.shape == arrays[0].shape
                for a in arrays) and np.isfinite(self.time) and np.isfinite(arrays).all()):
            object.__setattr__(self, "time", float(self.time))
            for name, a in zip(("positions", "velocities", "efforts"), arrays):
                object.__setattr__(self, name, frozen(a))
            return
        object.__setattr__(self, "time", number(self.time, "time", "s"))
        for name in ("positions", "velocities", "efforts"):
            a = finite_array(getattr(self, name), name, "(n_joints,)", "Give one value per joint")
            if a.ndim != 1 or a.shape != np.shape(self.positions):
                raise ShapeError(name, "(n_joints,), one value per joint", a.shape)
            object.__setattr__(self, name, frozen(a))


@dataclass(frozen=True, eq=False)
class Run:
    """What happened when a trajectory ran: the goals sent and the motion measured.

    Attributes:
        commanded: the goals as sent, at the robot time they were sent [s].
        measured: the recorded joint positions and velocities (100 Hz or faster).
        efforts: recorded joint torques [N m], one row per measured sample.
        backend: which backend ran it ("sim", "emulator", "hardware").
        wall_time: how long the run took on the wall clock [s].
        realtime: whether the run was paced to the wall clock.
    """

    commanded: Trajectory
    measured: Trajectory
    efforts: np.ndarray
    backend: str
    wall_time: float
    realtime: bool
    spec: SnakeSpec = field(default=SPEC, repr=False)

    def __post_init__(self):
        for name in ("commanded", "measured"):
            if not isinstance(getattr(self, name), Trajectory):
                raise InputTypeError(f"a Run's {name} must be a snakekit.Trajectory, got "
                                     f"{type(getattr(self, name)).__name__}")
        shape = self.measured.positions.shape
        check_length(self.efforts, "efforts")
        efforts = real_array(self.efforts, "efforts", f"{shape} (one row per measured sample)")
        if efforts.shape != shape:
            raise ShapeError("efforts", f"{shape} (one row per measured sample, one column per joint)", efforts.shape)
        if not np.isfinite(efforts).all():
            raise NotFiniteError("efforts hold NaN or infinity; every recorded torque [N m] is finite")
        if not isinstance(self.backend, str):
            raise InputTypeError(f"a Run's backend is a name such as 'sim', got {quote(self.backend)} "
                                 f"({type(self.backend).__name__})")
        if not isinstance(self.realtime, (bool, np.bool_)):
            raise InputTypeError(f"a Run's realtime is True or False, got {quote(self.realtime)} "
                                 f"({type(self.realtime).__name__})")
        object.__setattr__(self, "wall_time", number(self.wall_time, "wall_time", "s", at_least=0))
        object.__setattr__(self, "realtime", bool(self.realtime))
        object.__setattr__(self, "efforts", frozen(efforts))

    @property
    def robot_time(self) -> float:
        """Duration of the recording on the robot clock [s]."""
        return self.measured.duration

    def tracking_error(self) -> np.ndarray:
        """Largest |measured - commanded| per joint [rad], over the commanded time span.

        The commanded goals are interpolated linearly between the times they were sent.
        """
        t = self.measured.times
        inside = (t >= self.commanded.times[0]) & (t <= self.commanded.times[-1])
        ref = self.commanded.sample(t[inside])
        return np.abs(self.measured.positions[inside] - ref).max(axis=0)

    def peak_speeds(self) -> np.ndarray:
        """The largest measured joint speed |velocity| per joint [rad/s] (what the servos did)."""
        return np.abs(self.measured.velocities).max(axis=0)

    def speed_limit_held(self) -> bool:
        """True if no joint was measured faster than the velocity limit."""
        return bool((self.peak_speeds() <= self.spec.velocity_limit).all())

    def limits_held(self) -> bool:
        """True if every commanded goal and every measured position stayed inside the position
        limits, and no measured joint speed went over the velocity limit."""
        s = self.spec
        return bool(((self.commanded.positions >= s.lower) & (self.commanded.positions <= s.upper)).all()
                    and ((self.measured.positions >= s.lower) & (self.measured.positions <= s.upper)).all()
                    and self.speed_limit_held())

    def final_distance_from_home(self) -> float:
        """Tool distance [m] between the last measured pose and the home pose."""
        from .kinematics import forward_kinematics  # Pinocchio only when asked: runs load without it

        a = forward_kinematics(self.measured.positions[-1], spec=self.spec)[:2, 3]
        b = forward_kinematics(self.spec.home, spec=self.spec)[:2, 3]
        return float(np.linalg.norm(a - b))

    def summary(self) -> str:
        """A few lines for a person: times, tracking error per joint, limits, end pose.

        Angles are in degrees (as in the plots), lengths in millimetres.
        """
        err = self.tracking_error()
        lines = [
            f"backend:            {self.backend}{' (real time)' if self.realtime else ' (as fast as possible)'}",
            f"goals sent:         {len(self.commanded)} over {self.commanded.duration:.2f} s",
            f"robot time:         {self.robot_time:.2f} s",
            f"wall time:          {self.wall_time:.2f} s ({self.robot_time / max(self.wall_time, 1e-9):.1f}x real time)",
            "max tracking error: " + "  ".join(f"j{j + 1} {np.degrees(e):.2f} deg" for j, e in enumerate(err)),
            f"limits held:        {'yes' if self.limits_held() else 'NO'}",
            "max measured speed: " + "  ".join(f"j{j + 1} {v:.1f}" for j, v in enumerate(np.degrees(self.peak_speeds())))
            + f" deg/s (limit {np.degrees(self.spec.velocity_limit):.1f}: "
            + f"{'held' if self.speed_limit_held() else 'EXCEEDED'})",
            "final joint angles: " + " ".join(f"{q:+.2f}" for q in np.degrees(self.measured.positions[-1])) + " deg",
            f"final distance from home (tool): {1000 * self.final_distance_from_home():.2f} mm",
        ]
        return "\n".join(lines)

    def save(self, path) -> Path:
        """Write the run to a file; its suffix says which kind.

        - ``.npz``: numpy's arrays (the kit's own; loads with numpy alone);
        - ``.mcap``: a ROS 2 bag (rosbag2's MCAP storage), for ``ros2 bag``, Foxglove, Lichtblick;
        - ``.bag``: a ROS 1 bag, for ``rosbag`` and RViz.

        The bags hold ``/joint_states``, ``/joint_trajectory``, ``/tf``, ``/tf_static`` and
        ``/robot_description`` (:mod:`snakekit.bags` lists them).

        Raises:
            FileFormatError: another suffix.
            FileWriteError: the folder is missing, the path is a folder, or writing failed.
        """
        from . import bags

        path = as_path(path, "run file")
        if path.suffix not in (".npz", *bags.SUFFIXES):
            raise FileFormatError(f"a run is saved as .npz, .mcap (ROS 2) or .bag (ROS 1), not "
                                  f"'{path.suffix}' ({path})")
        writable_file(path, "run file", probe=False)
        if path.suffix in bags.SUFFIXES:
            return bags.write(self, path)
        try:
            np.savez(path, commanded_times=self.commanded.times, commanded_positions=self.commanded.positions,
                     measured_times=self.measured.times, measured_positions=self.measured.positions,
                     measured_velocities=self.measured.velocities, efforts=self.efforts,
                     backend=np.array(self.backend), wall_time=self.wall_time, realtime=self.realtime)
        except OSError as e:
            raise write_failed(path, "run file", e) from e
        return path

    @classmethod
    def load(cls, path) -> "Run":
        """Read a run written by :meth:`save` (``.npz``, ``.mcap`` or ``.bag``).

        Raises:
            FileFormatError: the file is missing, truncated, damaged, or its arrays are not a
                run (a missing array, efforts of another shape than the measured positions...).
        """
        from . import bags

        path = as_path(path, "run file")
        if path.suffix in bags.SUFFIXES:
            try:
                return cls(**bags.read(path))
            except (FileFormatError, CheckFailed):   # a lesson's check (a forbidden reader) speaks for itself
                raise
            except SnakekitError as e:
                raise FileFormatError(f"{path} is not a snakekit run ({e}); save runs with Run.save") from None
        fix = "save runs with Run.save"
        z = read_npz(path, "run file", _RUN_ARRAYS, fix=fix)
        path = Path(path)
        scalars = {}
        for name in ("backend", "wall_time", "realtime"):
            if z[name].shape != ():
                raise FileFormatError(f"{path} is not a snakekit run file: '{name}' holds an array of shape "
                                      f"{z[name].shape}, not one value; {fix}")
            scalars[name] = z[name].item()
        try:
            return cls(Trajectory(z["commanded_times"], z["commanded_positions"]),
                       Trajectory(z["measured_times"], z["measured_positions"], z["measured_velocities"]),
                       z["efforts"], scalars["backend"], scalars["wall_time"], scalars["realtime"])
        except SnakekitError as e:
            raise FileFormatError(f"{path} is not a snakekit run file ({e}); {fix}") from None


#: The arrays of a run file, as :meth:`Run.save` writes them.
_RUN_ARRAYS = ("commanded_times", "commanded_positions", "measured_times", "measured_positions",
               "measured_velocities", "efforts", "backend", "wall_time", "realtime")
