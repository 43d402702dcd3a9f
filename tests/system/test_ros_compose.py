"""Compose's `ros` profile: the study's multi-container ROS set-up on our arm (docker/ros/test.sh,
on the private engine of docker/engine.sh): roscore, the arm as a node, robot_state_publisher
and RViz in the browser through noVNC."""

import re

import pytest

from tests.system._engine import on_engine, run_on_engine

pytestmark = pytest.mark.system  # the ROS stack, on the private Docker engine: not in `make test-quick`


@on_engine
def test_ros_profile_moves_the_arm_refuses_a_fold_plays_a_bag_and_shows_the_arm_in_rviz(capsys):
    """docker/ros/test.sh: the ROS image built and sized; the stack up; a node inside it drives the arm."""
    out = run_on_engine("docker/ros/test.sh", capsys, what="the ROS test", timeout_min=40, modules=("PIL",),
                        show=("figure:", "ros-test:", "rviz-check:"))
    assert "ros-test: passed" in out
    size = re.search(r"figure: ROS image ([\d.]+) GB \(snakekit-lab ([\d.]+) GB; (\d+) MB added", out)
    assert size and float(size.group(1)) <= 1.5 and float(size.group(2)) < float(size.group(1)), out[-3000:]
    assert re.search(r"the rviz service prints: open http://127\.0\.0\.1:\d+/vnc\.html\?autoconnect=1&resize=scale",
                     out), out[-3000:]
    assert "the arm's node, started 5 s before roscore, waited for it and runs (no restart)" in out
    # the refusal in the kit's own words, and nothing moved
    assert re.search(r"ros-test: the folding goal is refused on /rosout \(goal refused: the trajectory would fold "
                     r"the arm onto itself: .*\); the arm stays at home \(\d+ joint states, all 0 rad\)", out), out[-3000:]
    # the sweep followed as the kit's simulator runs it
    assert re.search(r"ros-test: the sweep \(40 points, 3\.9 s\) moved the arm: \d+ joint states, joint 1 up to "
                     r"0\.2000 rad, each within [\d.e+-]+ rad of the kit's own simulator run \(tolerance 1e-06 rad\)",
                     out), out[-3000:]
    assert re.search(r"ros-test: rosbag play of sweep\.bag \(written by Run\.save\) published its joint states: "
                     r"\d+ received, equal to the run's measured positions \(float64, exactly\), its first sample at t = 0 s "
                     r"included", out), out[-3000:]
    # RViz in noVNC: the arm drawn at home, and drawn elsewhere after the pose goal
    shots = re.findall(r"rviz-check: \S+/artifacts/ros/(home|pose)\.png: noVNC's canvas \d+x\d+, \d+ colours, "
                       r"(\d+) pixels of the arm's links(?:, (\d+) pixels of the links moved)?", out)
    assert [s[0] for s in shots] == ["home", "pose"], out[-3000:]
    assert int(shots[1][2]) > 2000, shots
    assert "rosbag record -l 100: /joint_states 100, /tf 100 messages, copied out" in out
    assert re.search(r"docs/ros\.md's rostopic pub of the sweep: the arm says goal done: 100 points, 1\d\.\d\d s", out), out[-3000:]
    assert "no container, network or volume of the ros profile left" in out
