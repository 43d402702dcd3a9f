"""What lesson 8 uses of the kit: ROS 1 messages without ROS (``snakekit.bags.ros1_messages``), their
wire format read by Debian's own message classes, bags of ``/joint_states`` alone read back by
Debian's ``rosbag`` and by ``mcap_ros2``, and the live arm (``snakekit.ros.live_arm``: a roscore and
the arm's node of its own) taking a sweep that ``rosbag record`` records and a goal it refuses.
"""

import json
import subprocess
import sys

import numpy as np
import pytest

import snakekit
from snakekit.bags import ros1_bytes, ros1_messages, write_joint_states
from snakekit.errors import FileFormatError
from tests.conftest import need, need_program
from tests.kit.test_bags import ROS1_READER, decoded_mcap

NAMES = ["joint3", "joint1", "joint2", "joint5", "joint4"]  # another publisher's order
STAMPS = 1_700_000_000_000_000_000 + np.arange(7) * 33_333_333  # wall-clock stamps [ns], 30 Hz
POSITIONS = np.random.default_rng(3).uniform(-1.5, 1.5, (7, 5))

# Debian's genpy message class (system Python) decodes the wire format the kit wrote.
GENPY_READER = r"""
import json, sys
from trajectory_msgs.msg import JointTrajectory
m = JointTrajectory().deserialize(open(sys.argv[1], "rb").read())
print(json.dumps({"names": list(m.joint_names), "secs": [p.time_from_start.secs for p in m.points],
                  "nsecs": [p.time_from_start.nsecs for p in m.points], "positions": [list(p.positions) for p in m.points]}))
"""


def system_python(script, *args):
    python = need_program("/usr/bin/python3")  # where Debian's ROS 1 lives
    r = subprocess.run([python, "-c", script, *map(str, args)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return json.loads(r.stdout)


def trajectory_message(times_ns, positions):
    m = ros1_messages()
    empty = np.zeros(0)
    return m.JointTrajectory(
        header=m.Header(seq=0, stamp=m.Time(sec=0, nanosec=0), frame_id=""), joint_names=NAMES,
        points=[m.JointTrajectoryPoint(positions=np.array(q, float), velocities=empty, accelerations=empty, effort=empty,
                                       time_from_start=m.Duration(*divmod(int(t), 1_000_000_000)))
                for t, q in zip(times_ns, positions)])


def test_a_trajectory_built_without_ros_is_the_message_debians_rospy_decodes(tmp_path):
    times = [0, 333_333_333, 1_666_666_667, 12_000_000_001]
    (tmp_path / "goal").write_bytes(ros1_bytes(trajectory_message(times, POSITIONS[:4])))
    got = system_python(GENPY_READER, tmp_path / "goal")
    assert got["names"] == NAMES
    assert [s * 1_000_000_000 + n for s, n in zip(got["secs"], got["nsecs"])] == times
    np.testing.assert_array_equal(got["positions"], POSITIONS[:4])


def test_a_field_of_the_wrong_type_is_named_before_anything_is_sent():
    m = ros1_messages()
    bad = trajectory_message([0], POSITIONS[:1])
    bad.points[0].positions = [0.0] * 5  # a list where ROS's float64[] is asked
    with pytest.raises(FileFormatError, match="cannot be sent.*float64\\[\\] fields take numpy float arrays"):
        ros1_bytes(bad)
    with pytest.raises(snakekit.InputTypeError, match=r"a Duration's seconds must be a whole number \(int\), got float "
                                                     r"0.5: split a time t into divmod\(round\(t \* 1e9\), 1000000000\)"):
        m.Duration(sec=0.5, nanosec=0)    # refused as it is made, before any message holds it


def test_a_joint_states_bag_is_read_back_by_debians_rosbag(tmp_path):
    path = write_joint_states(tmp_path / "states.bag", STAMPS, POSITIONS, NAMES, description="<robot/>")
    got = system_python(ROS1_READER, path)
    assert got["types"] == {"/joint_states": "sensor_msgs/JointState", "/robot_description": "std_msgs/String"}
    assert got["latched"]["/robot_description"] == "1" and got["messages"]["/robot_description"] == ["<robot/>"]
    states = got["messages"]["/joint_states"]
    assert [s["name"] for s in states] == [NAMES] * len(STAMPS)
    assert [s["seq"] for s in states] == list(range(len(STAMPS)))
    np.testing.assert_allclose([s["stamp"] for s in states], STAMPS * 1e-9, rtol=0, atol=1e-6)  # float seconds
    np.testing.assert_array_equal([s["position"] for s in states], POSITIONS)


# Debian's rosbag: each /joint_states message's header stamp and the time the bag filed it under, in whole ns
RECEIVED_READER = r"""
import json, sys
import rosbag
with rosbag.Bag(sys.argv[1]) as bag:
    got = [(m.header.stamp.to_nsec(), t.to_nsec()) for _, m, t in bag.read_messages(topics=["/joint_states"])]
print(json.dumps({"stamps": [s for s, _ in got], "received": [r for _, r in got]}))
"""


def test_a_live_recordings_messages_are_filed_when_received_and_keep_their_stamps(tmp_path):
    received = STAMPS + np.array([3, 11, 4, 9, 15, 2, 7]) * 1_000_000   # 2 to 15 ms after they were stamped
    path = write_joint_states(tmp_path / "live.bag", STAMPS, POSITIONS, NAMES, received_ns=received)
    got = system_python(RECEIVED_READER, path)
    assert got == {"stamps": STAMPS.tolist(), "received": received.tolist()}
    need("mcap_ros2")
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(write_joint_states(tmp_path / "live.mcap", STAMPS, POSITIONS, NAMES, received_ns=received), "rb") as f:
        got = [(m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, message.log_time) for _, _, message, m
               in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(topics=["/joint_states"])]
    assert got == list(zip(STAMPS.tolist(), received.tolist()))


def test_received_times_that_do_not_match_the_stamps_are_refused():
    with pytest.raises(snakekit.ConfigurationError, match="received_ns has 2 times for 7 stamps: give one per message"):
        write_joint_states("unused.bag", STAMPS, POSITIONS, NAMES, received_ns=STAMPS[:2])


def test_a_joint_states_mcap_is_read_back_by_mcap_ros2(tmp_path):
    need("mcap_ros2")
    got, _ = decoded_mcap(write_joint_states(tmp_path / "states.mcap", STAMPS, POSITIONS, NAMES))
    assert set(got) == {"/joint_states"}
    assert [s["name"] for s in got["/joint_states"]] == [NAMES] * len(STAMPS)
    np.testing.assert_array_equal([s["position"] for s in got["/joint_states"]], POSITIONS)


@pytest.fixture
def default_socket_timeout_kept():
    """rospy sets the process's default socket timeout to 60 s when it connects a topic
    (rospy.impl.masterslave), and never sets it back: this test process's later tests would run with it."""
    import socket

    before = socket.getdefaulttimeout()
    yield
    socket.setdefaulttimeout(before)


def test_the_live_arm_runs_a_sweep_rosbag_records_and_refuses_a_goal_beyond_the_limits(tmp_path,
                                                                                        default_socket_timeout_kept):
    need_program("roscore"), need_program("rosbag")
    from rosbags.highlevel import AnyReader
    from snakekit.ros import live_arm

    sweep = snakekit.side_sweep(points=20, rate=10.0, sweeps=2, amplitude=0.2)
    goal = trajectory_message(np.rint(sweep.times * 1e9), sweep.positions)
    goal.joint_names = [f"joint{i}" for i in range(1, 6)]
    with live_arm() as arm:
        with arm.recording(tmp_path / "sweep.bag") as path:
            assert arm.send(goal).startswith("goal done: 20 points")
        over = trajectory_message([3_000_000_000], [[2.0, 0, 0, 0, 0]])
        with pytest.raises(snakekit.TrajectoryError, match="refused the goal; nothing moved.*limit"):
            arm.send(over)
    with AnyReader([path]) as bag:
        assert set(bag.topics) == {"/joint_states"}
        states = [bag.deserialize(raw, c.msgtype) for c, _, raw in bag.messages()]
    q = np.array([s.position for s in states])
    # the sweep swung every joint both ways by most of its 0.2 rad, and came home
    assert (q.max(0) > 0.12).all() and (q.min(0) < -0.12).all(), (q.max(0), q.min(0))
    np.testing.assert_allclose(q[-1], 0.0, atol=0.02)


# A notebook's kernel, as lesson 8 uses the live arm across cells: started without a block, found running again,
# joined by the kernel's own node, stopped; then, with the kernel's node gone with it, no second master.
KERNEL = r"""
import json, os, sys
import snakekit
from snakekit.ros import import_ros, live_arm

arm = live_arm()
again = live_arm() is arm
pids = [p.pid for p in arm._started]
rospy = import_ros()[1]
rospy.init_node("sweep_sender", anonymous=True, disable_signals=True)
joined = os.environ["ROS_MASTER_URI"] == arm.master == rospy.get_master().getUri()[2].rstrip("/")
publishers = dict(arm._state()[0])
arm.stop()
alive = []
for pid in pids:
    try:
        os.killpg(pid, 0)
        alive.append(pid)
    except ProcessLookupError:
        pass
try:
    live_arm()
    second = "started"
except snakekit.ConfigurationError as e:
    second = str(e)
print(json.dumps({"again": again, "joined": joined, "me": rospy.get_name(), "publishers": publishers,
                  "alive": alive, "running": arm.running, "second": second}))
"""


def test_a_live_arm_runs_across_cells_until_stopped_and_a_kernel_that_joined_it_is_told_to_restart(tmp_path):
    need_program("roscore"), need_program("rosbag")
    r = subprocess.run([sys.executable, "-c", KERNEL], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout.strip().splitlines()[-1])
    assert got["again"] and got["joined"] and got["me"].startswith("/sweep_sender_")
    assert got["publishers"]["/joint_states"] == ["/snakekit_arm"] and got["me"] in got["publishers"]["/rosout"]
    assert got["alive"] == [] and got["running"] is False          # roscore and the arm's node are gone
    assert got["second"].startswith("this process already joined the ROS master at http://127.0.0.1:")
    assert got["second"].endswith("restart the kernel to start another live arm")


# rosbag record's shape: a front that exits at Ctrl-C's signal, and a recorder (same process group) that
# renames NAME.active to NAME only once it has closed the bag, a while later on a busy machine.
FAKE_ROSBAG = r"""
import os, signal, sys, time
path = sys.argv[1]
if os.fork() == 0:
    def close(*_):
        time.sleep(float(sys.argv[2]))
        os.rename(path + ".active", path)
        os._exit(0)
    signal.signal(signal.SIGINT, close)
    with open(path + ".part", "w") as f:   # whole before it is seen: the test stops it once .active exists
        f.write("218 messages")
    os.rename(path + ".part", path + ".active")
    while True:
        time.sleep(1)
signal.signal(signal.SIGINT, lambda *_: os._exit(0))
while True:
    time.sleep(1)
"""


def fake_rosbag(path, closing):
    import sys
    import time
    rosbag = subprocess.Popen([sys.executable, "-c", FAKE_ROSBAG, str(path), str(closing)], start_new_session=True)
    end = time.monotonic() + 60
    while not path.with_name(path.name + ".active").exists():
        assert time.monotonic() < end, "the fake recorder did not start"
        time.sleep(0.02)
    return rosbag


def test_a_bag_still_closing_after_rosbag_record_stopped_is_waited_for(tmp_path):
    from snakekit.ros import _close_bag

    path = tmp_path / "sweep_recorded.bag"
    _close_bag(fake_rosbag(path, 1.0), path, hang=30.0)
    assert path.read_text() == "218 messages" and not path.with_name(path.name + ".active").exists()


def test_a_bag_rosbag_never_closes_is_named_with_where_its_messages_are(tmp_path):
    from snakekit.ros import _close_bag

    path = tmp_path / "sweep_recorded.bag"
    with pytest.raises(snakekit.BackendError, match=r"did not close sweep_recorded\.bag within 1 s .* "
                                                    r"what it recorded is in sweep_recorded\.bag\.active"):
        _close_bag(fake_rosbag(path, 100.0), path, hang=1.0)
    assert path.with_name(path.name + ".active").read_text() == "218 messages"   # nothing lost


@pytest.mark.parametrize("kind", ["Time", "Duration"])
def test_a_time_takes_ros_1s_own_field_names_too(kind):
    make = getattr(ros1_messages(), kind)
    assert make(secs=3, nsecs=7) == make(sec=3, nanosec=7) == make(3, 7)
    assert (make(secs=3, nsecs=7).sec, make(secs=3, nsecs=7).nanosec) == (3, 7)


@pytest.mark.parametrize("kind", ["Time", "Duration"])
@pytest.mark.parametrize("nanoseconds", [-1, 1_000_000_000, 2_500_000_000])
def test_nanoseconds_outside_one_second_are_refused_as_ros_1_would_misread_them(kind, nanoseconds):
    with pytest.raises(snakekit.ConfigurationError, match=rf"a {kind}'s nanoseconds must be 0 \.\.\. 999999999, "
                                                         rf"got {nanoseconds}: carry whole seconds into sec"):
        getattr(ros1_messages(), kind)(secs=1, nsecs=nanoseconds)


def test_a_message_holding_a_duration_past_one_second_of_nanoseconds_is_not_sent():
    goal = trajectory_message([1_000_000_000], [[0.1, 0, 0, 0, 0]])
    goal.points[0].time_from_start = type(goal.points[0].time_from_start)(sec=0, nanosec=-500_000_000)  # rosbags' own
    with pytest.raises(FileFormatError, match="a Duration has nanoseconds -500000000, outside 0 ... 999999999"):
        ros1_bytes(goal)
