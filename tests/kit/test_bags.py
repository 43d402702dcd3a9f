"""A run as ROS bags: ``Run.save`` writes ``.mcap`` (ROS 2, rosbag2's MCAP storage) and ``.bag``
(ROS 1), read back by readers that share no code with the writer (``mcap`` + ``mcap_ros2``'s
decoder for the MCAP file, Debian's ``python3-rosbag`` in the system's Python for the ROS 1
file), each compared with the run's arrays, and with the arm's planar geometry for ``/tf``.
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

import snakekit
from snakekit.bags import ORIGIN_NS, quaternions
from snakekit.model import SPEC, urdf
from snakekit.run import Run
from tests.conftest import IN_CI, need, need_program

NS = 1e-9  # the bags keep times in whole nanoseconds


@pytest.fixture(scope="module")
def run():
    """A short sweep on the simulator: every joint moves, the measured run at 100 Hz."""
    with snakekit.make_robot("sim") as robot:
        return robot.run(snakekit.side_sweep(points=30, rate=10.0, sweeps=2, amplitude=0.3))


@pytest.fixture(scope="module")
def saved(run, tmp_path_factory):
    d = tmp_path_factory.mktemp("bags")
    return {suffix: run.save(d / f"run{suffix}") for suffix in (".npz", ".mcap", ".bag")}


def planar_tool(q):
    """The tool point (x, y) from the arm's geometry alone: 71 mm links, the tool 47.5 mm past joint 5."""
    angles = np.cumsum(q)
    lengths = [SPEC.link_length] * (SPEC.n_joints - 1) + [SPEC.tool_offset]
    return np.array([np.sum(lengths * np.cos(angles)), np.sum(lengths * np.sin(angles))])


def homogeneous(translation, rotation):
    x, y, z, w = rotation
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, translation
    return T


def check_against_run(run, got):
    """The topics as a reader decoded them (plain lists and floats) against the run's arrays."""
    names = [f"joint{i + 1}" for i in range(SPEC.n_joints)]
    states = got["/joint_states"]
    assert len(states) == len(run.measured.times)
    assert all(s["name"] == names for s in states)
    origin = ORIGIN_NS * 1e-9  # the run's t = 0 s: ROS 1 takes a time of 0 as unset
    assert origin > 0 and all(s["stamp"] > 0 for s in states)
    assert np.allclose(np.array([s["stamp"] for s in states]) - origin, run.measured.times, rtol=0, atol=NS)
    assert np.array_equal([s["position"] for s in states], run.measured.positions)
    assert np.array_equal([s["velocity"] for s in states], run.measured.velocities)
    assert np.array_equal([s["effort"] for s in states], run.efforts)
    (traj,) = got["/joint_trajectory"]
    assert traj["joint_names"] == names
    assert np.allclose(traj["stamp"] - origin + np.array(traj["time_from_start"]), run.commanded.times, rtol=0,
                       atol=2 * NS)
    assert np.array_equal(traj["positions"], run.commanded.positions)
    (description,) = got["/robot_description"]
    assert description == urdf(SPEC)
    info = json.loads(got["/snakekit/run"][0])
    assert (info["backend"], info["wall_time"], info["realtime"]) == (run.backend, run.wall_time, run.realtime)
    # /tf: base_link -> link1 -> ... -> link5 at every sample, /tf_static: link5 -> tool; composed,
    # the tool point the arm's geometry gives
    (static,) = got["/tf_static"]
    assert [(t["parent"], t["child"]) for t in static] == [("link5", "tool")]
    chain = [("base_link", "link1")] + [(f"link{i}", f"link{i + 1}") for i in range(1, SPEC.n_joints)]
    tfs = got["/tf"]
    assert len(tfs) == len(run.measured.times)
    for k in range(0, len(tfs), 7):
        assert [(t["parent"], t["child"]) for t in tfs[k]] == chain
        assert all(abs(t["stamp"] - origin - run.measured.times[k]) <= NS for t in tfs[k])
        T = np.eye(4)
        for t in tfs[k] + static:
            assert abs(np.linalg.norm(t["rotation"]) - 1) < 1e-12
            T = T @ homogeneous(t["translation"], t["rotation"])
        assert np.allclose(T[:2, 3], planar_tool(run.measured.positions[k]), rtol=0, atol=1e-12)


def test_every_format_loads_back_as_the_run_it_saved(run, saved):
    for suffix, path in saved.items():
        back = Run.load(path)
        assert np.allclose(back.measured.times, run.measured.times, rtol=0, atol=NS), suffix
        assert np.allclose(back.commanded.times, run.commanded.times, rtol=0, atol=2 * NS), suffix
        for a, b in ((back.measured.positions, run.measured.positions), (back.measured.velocities, run.measured.velocities),
                     (back.efforts, run.efforts), (back.commanded.positions, run.commanded.positions)):
            assert np.array_equal(a, b), suffix
        assert (back.backend, back.wall_time, back.realtime) == (run.backend, run.wall_time, run.realtime), suffix
        assert back.summary() == run.summary(), suffix


def decoded_mcap(path):
    """Every message of the MCAP file through ``mcap`` and ``mcap_ros2``'s decoder (no rosbags)."""
    need("mcap_ros2")
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    got, qos, stamp = {}, {}, lambda s: s.sec + s.nanosec * 1e-9
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, m in reader.iter_decoded_messages():
            qos[channel.topic] = channel.metadata.get("offered_qos_profiles", "")
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            if channel.topic == "/joint_states":
                value = {"name": list(m.name), "stamp": stamp(m.header.stamp), "position": list(m.position),
                         "velocity": list(m.velocity), "effort": list(m.effort)}
            elif channel.topic == "/joint_trajectory":
                value = {"joint_names": list(m.joint_names), "stamp": stamp(m.header.stamp),
                         "time_from_start": [stamp(p.time_from_start) for p in m.points],
                         "positions": [list(p.positions) for p in m.points]}
            elif channel.topic in ("/tf", "/tf_static"):
                value = [{"parent": t.header.frame_id, "child": t.child_frame_id, "stamp": stamp(t.header.stamp),
                          "translation": [t.transform.translation.x, t.transform.translation.y, t.transform.translation.z],
                          "rotation": [t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
                                       t.transform.rotation.w]} for t in m.transforms]
            else:
                value = m.data
            got.setdefault(channel.topic, []).append(value)
    return got, qos


def test_the_mcap_file_is_a_ros2_bag_that_an_independent_reader_decodes_to_the_run(run, saved):
    got, qos = decoded_mcap(saved[".mcap"])
    check_against_run(run, got)
    # the description and the static frame are latched: offered as transient local (durability 1)
    for topic in ("/robot_description", "/tf_static", "/snakekit/run"):
        assert "durability: 1" in qos[topic], (topic, qos[topic])
    assert "durability: 1" not in qos["/joint_states"]


ROS1_READER = r"""
import json, sys
import rosbag
out = {}
latched = {}
with rosbag.Bag(sys.argv[1]) as bag:
    for c in bag._get_connections():
        v = c.header.get("latching", "0")
        latched[c.topic] = v.decode() if isinstance(v, bytes) else v
    for topic, m, t in bag.read_messages():
        stamp = lambda s: s.secs + s.nsecs * 1e-9
        if topic == "/joint_states":
            v = {"name": list(m.name), "stamp": stamp(m.header.stamp), "position": list(m.position),
                 "velocity": list(m.velocity), "effort": list(m.effort), "seq": m.header.seq}
        elif topic == "/joint_trajectory":
            v = {"joint_names": list(m.joint_names), "stamp": stamp(m.header.stamp),
                 "time_from_start": [stamp(p.time_from_start) for p in m.points],
                 "positions": [list(p.positions) for p in m.points]}
        elif topic in ("/tf", "/tf_static"):
            v = [{"parent": x.header.frame_id, "child": x.child_frame_id, "stamp": stamp(x.header.stamp),
                  "translation": [x.transform.translation.x, x.transform.translation.y, x.transform.translation.z],
                  "rotation": [x.transform.rotation.x, x.transform.rotation.y, x.transform.rotation.z,
                               x.transform.rotation.w]} for x in m.transforms]
        else:
            v = m.data
        out.setdefault(topic, []).append(v)
    types = {topic: info.msg_type for topic, info in bag.get_type_and_topic_info().topics.items()}
print(json.dumps({"messages": out, "latched": latched, "types": types}))
"""


def test_the_bag_file_is_a_ros1_bag_that_debians_rosbag_reads_as_the_run(run, saved):
    python = need_program("/usr/bin/python3")  # the system's Python, where Debian's python3-rosbag lives
    r = subprocess.run([python, "-c", ROS1_READER, str(saved[".bag"])], capture_output=True, text=True, timeout=300)
    if r.returncode != 0 and "No module named 'rosbag'" in r.stderr:
        (pytest.fail if IN_CI else pytest.skip)("Debian's python3-rosbag is missing: tools/setup installs it "
                                                "(apt-get install python3-rosbag)")
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout)
    check_against_run(run, out["messages"])
    assert [s["seq"] for s in out["messages"]["/joint_states"]] == list(range(len(run.measured.times)))
    assert out["types"] == {"/joint_states": "sensor_msgs/JointState", "/joint_trajectory": "trajectory_msgs/JointTrajectory",
                            "/tf": "tf2_msgs/TFMessage", "/tf_static": "tf2_msgs/TFMessage",
                            "/robot_description": "std_msgs/String", "/snakekit/run": "std_msgs/String"}
    assert {t for t, v in out["latched"].items() if v == "1"} == {"/robot_description", "/tf_static", "/snakekit/run"}


def test_quaternions_turn_back_into_their_rotations_near_every_branch():
    rng = np.random.default_rng(7)
    v = rng.normal(size=(500, 4))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    rotations = np.stack([homogeneous([0, 0, 0], q)[:3, :3] for q in v])
    # and the half-turns, where three of the four squares vanish
    rotations = np.concatenate([rotations, [np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1]), np.eye(3)]])
    q = quaternions(rotations)
    assert np.allclose(np.linalg.norm(q, axis=1), 1, rtol=0, atol=1e-14) and (q[:, 3] >= 0).all()
    back = np.stack([homogeneous([0, 0, 0], x)[:3, :3] for x in q])
    assert np.allclose(back, rotations, rtol=0, atol=1e-14)


def test_a_damaged_or_foreign_bag_is_a_clear_file_format_error(run, saved, tmp_path):
    cases = {
        "truncated.mcap": saved[".mcap"].read_bytes()[: 4000],
        "truncated.bag": saved[".bag"].read_bytes()[: 4000],
        "npz-renamed.mcap": saved[".npz"].read_bytes(),
        "npz-renamed.bag": saved[".npz"].read_bytes(),
        "empty.bag": b"",
    }
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(snakekit.errors.FileFormatError) as e:
            Run.load(tmp_path / name)
        message = str(e.value)
        assert str(tmp_path / name) in message and "Run.save" in message and len(message) < 400, message
    with pytest.raises(snakekit.errors.FileFormatError, match="missing.mcap does not exist"):
        Run.load(tmp_path / "missing.mcap")
    (tmp_path / "folder.bag").mkdir()
    with pytest.raises(snakekit.errors.FileFormatError, match="folder.bag is a folder, not a file"):
        Run.load(tmp_path / "folder.bag")
    with pytest.raises(snakekit.errors.FileWriteError, match="folder.bag"):
        run.save(tmp_path / "folder.bag")
    # a ROS bag of someone else's: no run's topics
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC)
    with Writer(tmp_path / "other.bag") as bag:
        c = bag.add_connection("/chatter", "std_msgs/msg/String", typestore=ts)
        bag.write(c, 1, bytes(ts.serialize_ros1(ts.types["std_msgs/msg/String"](data="hi"), "std_msgs/msg/String")))
    with pytest.raises(snakekit.errors.FileFormatError,
                       match=r"is not a snakekit run: it has no /joint_states, /joint_trajectory, /snakekit/run topic"):
        Run.load(tmp_path / "other.bag")
    with pytest.raises(snakekit.errors.FileFormatError, match=r"\.npz, \.mcap \(ROS 2\) or \.bag \(ROS 1\), not '\.db3'"):
        run.save(tmp_path / "run.db3")


def test_sweep_out_writes_a_bag_that_loads_as_the_run_it_printed(tmp_path):
    out = tmp_path / "sweep.mcap"
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "sweep", "--out", str(out)], capture_output=True,
                       text=True, timeout=900, env={**os.environ, "MUJOCO_GL": "egl"})
    assert r.returncode == 0, r.stderr[-2000:]
    assert f"saved run:          {out}" in r.stdout
    back = Run.load(out)  # the run it printed the summary of, line for line
    assert len(back.commanded) == 500 and all(line in r.stdout for line in back.summary().splitlines())
    bad = subprocess.run([sys.executable, "-m", "snakekit.cli", "sweep", "--out", str(tmp_path / "run.db3")],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "must end in .npz or .mcap or .bag" in bad.stderr
