"""Compose's `ros` profile: the study's multi-container ROS set-up on our arm (docker/ros/test.sh,
on the private engine of docker/engine.sh): roscore, the arm as a node, robot_state_publisher
and RViz in the browser through noVNC."""

import importlib.machinery
import importlib.util
import re

import pytest

from tests.system._engine import ROOT, on_engine, run_on_engine

pytestmark = pytest.mark.system  # the ROS stack, on the private Docker engine: not in `make test-quick`


def _make_dockerfile():
    """docker/ros/make-dockerfile, loaded as a module."""
    path = ROOT / "docker/ros/make-dockerfile"
    loader = importlib.machinery.SourceFileLoader("make_dockerfile", str(path))
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader(loader.name, loader))
    loader.exec_module(module)
    return module


def test_ros_dockerfile_is_the_students_stages_then_the_ros_stage():
    """The ROS image builds without the students' image: its Dockerfile holds their stages (not the grader's)."""
    make = _make_dockerfile()
    assert make.main(["--check"]) == 0, "run docker/ros/make-dockerfile and commit docker/ros/Dockerfile"
    text = (ROOT / "docker/ros/Dockerfile").read_text()
    assert re.findall(r"^FROM .*", text, re.M) == [
        "FROM debian:bookworm-slim AS base", "FROM base AS venv", "FROM base AS lab", "FROM lab AS students",
        "FROM students AS ros"]
    assert "COPY course/" not in text  # no grader stage: the instructor's course stays out
    students = (ROOT / "docker/Dockerfile").read_text()
    stages = text[:text.index("# --- snakekit's ROS image")]
    # every line of the students' stages is docker/Dockerfile's, in its order
    body = [line for line in stages.splitlines()[2:] if line and line != "FROM lab AS students"]
    lines = students.splitlines()
    at = 0
    for line in body:
        at = lines.index(line, at) + 1
    assert text.endswith((ROOT / "docker/ros/ros-stage.Dockerfile").read_text())


def test_a_stale_ros_dockerfile_is_reported(tmp_path, monkeypatch, capsys):
    make = _make_dockerfile()
    stale = tmp_path / "Dockerfile"
    stale.write_text((ROOT / "docker/ros/Dockerfile").read_text().replace("python3-rospy", "python3-rosbag", 1))
    monkeypatch.setattr(make, "OUT", stale)
    assert make.main(["--check"]) == 1
    assert "docker/ros/Dockerfile is out of date with docker/Dockerfile and docker/ros/ros-stage.Dockerfile: " \
           "run docker/ros/make-dockerfile" in capsys.readouterr().err
    assert make.main([]) == 0 and make.main(["--check"]) == 0  # written again: up to date


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
    # the first up builds the ROS image on an engine without the students' image (their tags removed)
    assert re.search(r"figure: build: the ROS image by the first up, on an engine without the students' image, "
                     r"[\d.]+ s \(\d+ of \d+ steps from the engine's cache", out), out[-3000:]
    # docs/ros.md's `up rviz`: the ROS stack only, and the URL is the last line the student reads
    assert ("up rviz (docs/ros.md): the lab not started; the only service log shown is rviz's (1 line), "
            "the URL its last line") in out
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
    # docs/ros.md's rosnode list and record-and-play block, each line as written
    assert re.search(r"docs/ros\.md's rosnode list \(the four nodes\) and its record-and-play block as written: "
                     r"rosbag record \(Ctrl-C after 4 s\) kept /joint_states [1-9]\d*, /tf [1-9]\d* messages \(rosbag info\); "
                     r"snakekit sweep --out kit-sweep\.bag; rosbag play of it published beside the arm "
                     r"\(rostopic info /joint_states: 2 publishers\)", out), out[-3000:]
    assert "no container, network or volume of the ros profile left" in out
