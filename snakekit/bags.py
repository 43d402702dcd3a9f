"""A run as ROS bags: ``.mcap`` (ROS 2, rosbag2's MCAP storage) and ``.bag`` (ROS 1).

No ROS install is needed: the bags are written and read with ``rosbags``, pure Python. They open
in ``ros2 bag``, ``rosbag``, RViz (played back), Foxglove and Lichtblick. The topics:

| topic | type | what |
|---|---|---|
| ``/joint_states`` | ``sensor_msgs/JointState`` | the measured positions, velocities and efforts, one message per sample |
| ``/joint_trajectory`` | ``trajectory_msgs/JointTrajectory`` | the goals as sent, one message (``time_from_start`` from the first goal) |
| ``/tf`` | ``tf2_msgs/TFMessage`` | each link's frame in its parent's, one message per sample |
| ``/tf_static`` | ``tf2_msgs/TFMessage`` | the tool's frame in link5's (latched) |
| ``/robot_description`` | ``std_msgs/String`` | the URDF (latched; transient local in ROS 2) |
| ``/snakekit/run`` | ``std_msgs/String`` | the run's backend, wall time and real-time flag (JSON) |

Times are the robot's clock, in nanoseconds, from 1 s after the epoch (:data:`ORIGIN_NS`, kept in
``/snakekit/run``): ROS 1 takes a time of 0 as unset, and Debian's ``rosbag`` would play neither a
run's first sample nor its latched topics.
:meth:`snakekit.Run.save` and :meth:`snakekit.Run.load` use this module by the file's suffix.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import shutil
import tempfile
from struct import error as struct_error
from pathlib import Path

import numpy as np

from .errors import ConfigurationError, FileFormatError, InputTypeError
from .model import SPEC
from .trajectory import Trajectory
from .validate import write_failed
from .validate.files import readable_file

#: The suffixes of the bags a run is saved to, and the ROS each is for.
SUFFIXES = {".mcap": "ROS 2 (rosbag2, MCAP storage)", ".bag": "ROS 1"}

JOINT_STATES, TRAJECTORY, TF, TF_STATIC = "/joint_states", "/joint_trajectory", "/tf", "/tf_static"
DESCRIPTION, RUN_INFO = "/robot_description", "/snakekit/run"
_STRING, _JOINT_STATE = "std_msgs/msg/String", "sensor_msgs/msg/JointState"
_TRAJECTORY, _TF_MESSAGE = "trajectory_msgs/msg/JointTrajectory", "tf2_msgs/msg/TFMessage"
_FIX = "save runs with Run.save (.npz, .mcap or .bag)"


#: the ROS time [ns] of the robot clock's t = 0 s: 1 s after the epoch, since ROS 1 takes a time of 0
#: as unset (``rosbag`` loads no message stamped 0)
ORIGIN_NS = 1_000_000_000


def _ns(t) -> np.ndarray:
    """Robot times [s] as ROS times [ns] (rounded to the nanosecond, from :data:`ORIGIN_NS`)."""
    return np.rint(np.asarray(t, dtype=float) * 1e9).astype(np.int64) + ORIGIN_NS


@functools.lru_cache(maxsize=None)
def _typestore(ros: int):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if ros == 2:
        return get_typestore(Stores.ROS2_HUMBLE)
    ts = get_typestore(Stores.ROS1_NOETIC)  # its store lacks tf2_msgs: the message as Noetic defines it
    ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", _TF_MESSAGE))
    return ts


def _header(ts, ns: int, frame: str, seq: int, ros: int):
    sec, nsec = divmod(int(ns), 1_000_000_000)
    stamp = ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
    Header = ts.types["std_msgs/msg/Header"]
    return Header(seq=seq, stamp=stamp, frame_id=frame) if ros == 1 else Header(stamp=stamp, frame_id=frame)


def _transform(ts, ns: int, names: tuple[str, str], T: np.ndarray, q: np.ndarray, seq: int, ros: int):
    types = ts.types
    x, y, z, w = (float(v) for v in q)
    return types["geometry_msgs/msg/TransformStamped"](
        header=_header(ts, ns, names[0], seq, ros), child_frame_id=names[1],
        transform=types["geometry_msgs/msg/Transform"](
            translation=types["geometry_msgs/msg/Vector3"](x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
            rotation=types["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)))


def quaternions(R: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(x, y, z, w)``, ``w >= 0``, of rotation matrices ``R`` (..., 3, 3), by
    Shepperd's method: each from the largest of its four squares, never dividing by a small one."""
    R = np.asarray(R, dtype=float)
    t = np.trace(R, axis1=-2, axis2=-1)
    d = np.diagonal(R, axis1=-2, axis2=-1)
    squares = np.stack([1 + t, 1 + 2 * d[..., 0] - t, 1 + 2 * d[..., 1] - t, 1 + 2 * d[..., 2] - t], -1)
    k = np.argmax(squares, -1)[..., None]
    r = np.sqrt(np.take_along_axis(squares, k, -1))[..., 0]
    skew = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    sym = np.stack([R[..., 0, 1] + R[..., 1, 0], R[..., 0, 2] + R[..., 2, 0], R[..., 1, 2] + R[..., 2, 1]], -1)
    x, y, z = skew[..., 0], skew[..., 1], skew[..., 2]
    xy, xz, yz = sym[..., 0], sym[..., 1], sym[..., 2]
    rr = r * r
    q = np.select([k == 0, k == 1, k == 2],
                  [np.stack([x, y, z, rr], -1), np.stack([rr, xy, xz, x], -1), np.stack([xy, rr, yz, y], -1)],
                  np.stack([xz, yz, rr, z], -1)) / (2 * r)[..., None]
    return np.where(q[..., 3:] < 0, -q, q)


def link_transforms(qs, spec=SPEC) -> tuple[list[tuple[str, str]], np.ndarray]:
    """Each link's frame in its parent's, for each row of joint angles ``qs`` (n, n_joints):
    the ``(parent, child)`` names, base_link to link1 first, then link5 to the tool (what
    robot_state_publisher sends), and the transforms ``T_parent_child``, shape (n, n_joints + 1, 4, 4)."""
    from .kinematics import joint_frames

    frames = np.stack([joint_frames(q, spec=spec) for q in np.atleast_2d(qs)])  # T_world_link, (n, links, 4, 4)
    parents = np.concatenate([np.broadcast_to(np.eye(4), (len(frames), 1, 4, 4)), frames[:, :-1]], 1)
    inverse = np.zeros_like(parents)  # a rigid transform's inverse: R^T, -R^T p
    inverse[..., :3, :3] = np.swapaxes(parents[..., :3, :3], -1, -2)
    inverse[..., :3, 3] = -np.einsum("...ji,...j->...i", parents[..., :3, :3], parents[..., :3, 3])
    inverse[..., 3, 3] = 1
    names = ["base_link"] + [f"link{i + 1}" for i in range(spec.n_joints)] + ["tool"]
    return list(zip(names[:-1], names[1:])), inverse @ frames


def _messages(run, ros: int):
    """``(topic, type, latched, [(ns, message), ...])`` for every topic of a run."""
    from .model import urdf

    ts = _typestore(ros)
    types, spec = ts.types, run.spec
    names = [f"joint{i + 1}" for i in range(spec.n_joints)]
    t_meas = _ns(run.measured.times)
    states, tfs = [], []
    pairs, T = link_transforms(run.measured.positions, spec)
    quats = quaternions(T[..., :3, :3])
    for k, ns in enumerate(t_meas):
        states.append((ns, types[_JOINT_STATE](
            header=_header(ts, ns, "", k, ros), name=names,
            position=np.array(run.measured.positions[k], dtype=np.float64),
            velocity=np.array(run.measured.velocities[k], dtype=np.float64),
            effort=np.array(run.efforts[k], dtype=np.float64))))
        tfs.append((ns, types[_TF_MESSAGE](transforms=[_transform(ts, ns, pair, T[k, j], quats[k, j], k, ros)
                                                         for j, pair in enumerate(pairs[:-1])])))
    t_cmd = _ns(run.commanded.times)
    Point, Duration = types["trajectory_msgs/msg/JointTrajectoryPoint"], types["builtin_interfaces/msg/Duration"]
    empty = np.zeros(0)
    points = [Point(positions=np.array(q, dtype=np.float64), velocities=empty, accelerations=empty, effort=empty,
                    time_from_start=Duration(*divmod(int(ns - t_cmd[0]), 1_000_000_000)))
              for q, ns in zip(run.commanded.positions, t_cmd)]
    trajectory = types[_TRAJECTORY](header=_header(ts, t_cmd[0], "base_link", 0, ros), joint_names=names,
                                    points=points)
    first = int(min(t_meas[0], t_cmd[0]))
    info = json.dumps({"backend": run.backend, "wall_time": run.wall_time, "realtime": run.realtime,
                       "time_origin_ns": ORIGIN_NS, "format": "snakekit run 2"})
    return [
        (DESCRIPTION, _STRING, True, [(first, types[_STRING](data=urdf(spec)))]),
        (RUN_INFO, _STRING, True, [(first, types[_STRING](data=info))]),
        (TF_STATIC, _TF_MESSAGE, True, [(first, types[_TF_MESSAGE](
            transforms=[_transform(ts, first, pairs[-1], T[0, -1], quats[0, -1], 0, ros)]))]),
        (TRAJECTORY, _TRAJECTORY, False, [(int(t_cmd[0]), trajectory)]),
        (JOINT_STATES, _JOINT_STATE, False, states),
        (TF, _TF_MESSAGE, False, tfs),
    ]


def _latched_qos():
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    never = QosTime(0, 0)
    return [Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL, never, never,
                QosLiveliness.AUTOMATIC, never, False)]


def write(run, path: Path) -> Path:
    """Write ``run`` to ``path`` (``.mcap`` or ``.bag``): the whole file or none of it."""
    return _write_topics(_messages(run, 2 if path.suffix == ".mcap" else 1), path)


def _write_topics(topics, path: Path) -> Path:
    """Write ``(topic, type, latched, [(ns, message), ...])`` to ``path`` (``.mcap``: ROS 2, else ROS 1)."""
    ros = 2 if path.suffix == ".mcap" else 1
    ts = _typestore(ros)
    tmp = Path(tempfile.mkdtemp(prefix=".run-", dir=path.parent))
    try:
        if ros == 2:
            from rosbags.rosbag2 import StoragePlugin, Writer

            bag = Writer(tmp / "bag", version=8, storage_plugin=StoragePlugin.MCAP)
            add = lambda topic, kind, latched: bag.add_connection(  # noqa: E731
                topic, kind, typestore=ts, offered_qos_profiles=_latched_qos() if latched else ())
            serialize = ts.serialize_cdr
        else:
            from rosbags.rosbag1 import Writer

            bag = Writer(tmp / "run.bag")
            add = lambda topic, kind, latched: bag.add_connection(  # noqa: E731
                topic, kind, typestore=ts, callerid="/snakekit", latching=1 if latched else None)
            serialize = ts.serialize_ros1
        with bag:
            for topic, kind, latched, msgs in topics:
                conn = add(topic, kind, latched)
                for ns, msg in msgs:
                    bag.write(conn, int(ns), bytes(serialize(msg, kind)))
        written = next((tmp / "bag").glob("*.mcap")) if ros == 2 else tmp / "run.bag"
        written.replace(path)
    except OSError as e:
        raise write_failed(path, "run file", e) from e
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return path


def read(path: Path) -> dict:
    """What a ``.mcap`` or ``.bag`` written by :func:`write` holds, as :class:`snakekit.Run`'s fields
    (``Run.load`` makes the run of them)."""
    from rosbags.highlevel import AnyReader

    readable_file(path, "run file")
    found: dict[str, list] = {}
    try:
        with AnyReader([path], default_typestore=_typestore(2 if path.suffix == ".mcap" else 1)) as bag:
            wanted = [c for c in bag.connections if c.topic in (JOINT_STATES, TRAJECTORY, RUN_INFO)]
            for conn, _, raw in bag.messages(connections=wanted):
                found.setdefault(conn.topic, []).append(bag.deserialize(raw, conn.msgtype))
    except Exception as e:  # rosbags raises its own classes, and struct's and KeyError on damage
        raise FileFormatError(f"{path} is not a readable {SUFFIXES[path.suffix]} bag ({type(e).__name__}: "
                              f"{str(e)[:120]}); {_FIX}") from None
    missing = [t for t in (JOINT_STATES, TRAJECTORY, RUN_INFO) if t not in found]
    if missing:
        raise FileFormatError(f"{path} is not a snakekit run: it has no {', '.join(missing)} topic; {_FIX}")
    states, trajectory = found[JOINT_STATES], found[TRAJECTORY][-1]
    ns = lambda t: t.sec * 1_000_000_000 + t.nanosec  # noqa: E731
    try:
        info = json.loads(found[RUN_INFO][-1].data)
        fields = {"backend": info["backend"], "wall_time": info["wall_time"], "realtime": info["realtime"]}
        origin = int(info.get("time_origin_ns", 0))  # 0 in the first format's bags
    except (ValueError, KeyError, TypeError) as e:
        raise FileFormatError(f"{path} is not a snakekit run: its {RUN_INFO} message is not the run's "
                              f"information ({type(e).__name__}); {_FIX}") from None
    start = ns(trajectory.header.stamp) - origin
    return dict(
        commanded=Trajectory(np.array([(start + ns(p.time_from_start)) * 1e-9 for p in trajectory.points]),
                             np.array([p.positions for p in trajectory.points])),
        measured=Trajectory(np.array([(ns(m.header.stamp) - origin) * 1e-9 for m in states]),
                            np.array([m.position for m in states]), np.array([m.velocity for m in states])),
        efforts=np.array([m.effort for m in states]), **fields)


def ros1_messages():
    """ROS 1 message classes without a ROS install (``rosbags``'s Noetic definitions): a namespace with
    ``JointTrajectory``, ``JointTrajectoryPoint``, ``JointState``, ``Header``, ``Time`` and ``Duration``.
    Their wire format is ROS 1's (:func:`ros1_bytes`), so a message built of them is the one ``rospy``
    sends. A time's fields are named as ``rosbags`` names them for both ROS versions, ``sec`` and
    ``nanosec``; ``Time`` and ``Duration`` also take ROS 1's own names, ``secs`` and ``nsecs`` (rospy's,
    ``rostopic pub``'s), and refuse nanoseconds outside 0 ... 999999999: ROS 1 reads them signed.

    >>> msgs = ros1_messages()
    >>> msgs.Duration(secs=2, nsecs=500000000) == msgs.Duration(sec=2, nanosec=500000000)
    True
    """
    from types import SimpleNamespace

    types = _typestore(1).types
    return SimpleNamespace(JointTrajectory=types[_TRAJECTORY], JointTrajectoryPoint=types[
        "trajectory_msgs/msg/JointTrajectoryPoint"], JointState=types[_JOINT_STATE], Header=types["std_msgs/msg/Header"],
        Time=_time_of(types["builtin_interfaces/msg/Time"]), Duration=_time_of(types["builtin_interfaces/msg/Duration"]))


def _time_of(kind):
    """``kind`` (a Time or a Duration) made of whole seconds and nanoseconds, by ROS 2's names or ROS 1's."""
    what = kind.__msgtype__.rpartition("/")[2]

    def make(sec=None, nanosec=None, *, secs=None, nsecs=None):
        if (sec is not None and secs is not None) or (nanosec is not None and nsecs is not None):
            raise InputTypeError(f"a {what} takes sec and nanosec, or ROS 1's secs and nsecs, not both names for one")
        sec, nanosec = secs if sec is None else sec, nsecs if nanosec is None else nanosec
        if sec is None or nanosec is None:
            raise InputTypeError(f"a {what} needs its whole seconds and nanoseconds: {what}(sec=..., nanosec=...) "
                                 f"(or ROS 1's secs=..., nsecs=...)")
        for name, value in (("seconds", sec), ("nanoseconds", nanosec)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise InputTypeError(f"a {what}'s {name} must be a whole number (int), got {type(value).__name__} "
                                     f"{value!r}: split a time t into divmod(round(t * 1e9), 1000000000)")
        if not 0 <= nanosec <= 999_999_999:
            raise ConfigurationError(f"a {what}'s nanoseconds must be 0 ... 999999999, got {nanosec}: carry whole "
                                     f"seconds into sec (divmod(round(t * 1e9), 1000000000) does), as ROS 1 reads "
                                     "nanoseconds signed")
        return kind(sec=int(sec), nanosec=int(nanosec))

    make.__name__ = make.__qualname__ = what
    return make


def ros1_bytes(message) -> bytes:
    """``message`` (of :func:`ros1_messages`) in ROS 1's wire format; a field of the wrong type raises
    :class:`~snakekit.FileFormatError` naming the message."""
    kind = getattr(message, "__msgtype__", None)
    if not isinstance(kind, str):
        raise FileFormatError(f"expected a ROS message (a class of snakekit.bags.ros1_messages()), got "
                              f"{type(message).__name__}")
    bad = _bad_time(message)
    if bad is not None:
        raise FileFormatError(f"this {kind.replace('/msg/', '/')} cannot be sent: a {bad.__msgtype__.rpartition('/')[2]} "
                              f"has nanoseconds {bad.nanosec}, outside 0 ... 999999999 (ROS 1 would read another "
                              "time): carry whole seconds into sec")
    try:
        return bytes(_typestore(1).serialize_ros1(message, kind))
    except (TypeError, ValueError, AttributeError, KeyError, OverflowError, struct_error) as e:
        raise FileFormatError(f"this {kind.replace('/msg/', '/')} cannot be sent: a field has the wrong type or value "
                              f"({type(e).__name__}: {str(e)[:160]}); float64[] fields take numpy float arrays, "
                              "a Duration's sec and nanosec whole numbers") from None


def _bad_time(value):
    """The first Time or Duration in ``value`` (a message, its fields, their lists) whose nanoseconds are
    outside 0 ... 999999999; None if there is none."""
    if str(getattr(value, "__msgtype__", "")).startswith("builtin_interfaces/"):
        return None if 0 <= value.nanosec <= 999_999_999 else value
    items = [getattr(value, f.name) for f in dataclasses.fields(value)] if dataclasses.is_dataclass(value) else \
        value if isinstance(value, list) else ()
    return next((bad for bad in map(_bad_time, items) if bad is not None), None)


def ros1_message(data: bytes, kind: str):
    """The message of type ``kind`` (``trajectory_msgs/msg/JointTrajectory``) in ROS 1's wire format ``data``."""
    return _typestore(1).deserialize_ros1(data, kind)


def write_joint_states(path: Path, stamps_ns, positions, names, *, description: str | None = None,
                       received_ns=None) -> Path:
    """A bag of ``/joint_states`` alone, as ``rosbag record /joint_states`` writes one: a
    ``sensor_msgs/JointState`` per row of ``positions`` [rad], stamped ``stamps_ns`` [ns, ROS time],
    joints named ``names`` in that order; ``.bag`` (ROS 1) or ``.mcap`` (ROS 2), by the suffix. Each
    message is filed in the bag at ``received_ns`` [ns] (when the recorder got it; default its stamp),
    as a live recording files a message a little after its publisher stamped it. With
    ``description``, a latched ``/robot_description`` message first."""
    path = Path(path)
    ros = 2 if path.suffix == ".mcap" else 1
    ts = _typestore(ros)
    stamps = [int(s) for s in stamps_ns]
    received = stamps if received_ns is None else [int(r) for r in received_ns]
    if len(received) != len(stamps):
        raise ConfigurationError(f"received_ns has {len(received)} times for {len(stamps)} stamps: "
                                 "give one per message")
    states = [(at, ts.types[_JOINT_STATE](header=_header(ts, ns, "", k, ros), name=list(names),
                                          position=np.array(q, dtype=np.float64), velocity=np.zeros(0),
                                          effort=np.zeros(0)))
              for k, (ns, at, q) in enumerate(zip(stamps, received, positions))]
    topics = [(JOINT_STATES, _JOINT_STATE, False, states)]
    if description is not None:
        first = stamps[0] if stamps else ORIGIN_NS
        topics.insert(0, (DESCRIPTION, _STRING, True, [(first, ts.types[_STRING](data=description))]))
    return _write_topics(topics, path)
