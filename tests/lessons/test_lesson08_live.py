"""Lesson 8's live part, run once: the instructor version with ROS 1 here and quick mode off starts its own
master and the arm's node; the notebook's own node (``rospy.init_node``) lists the master's nodes and topics,
echoes ``/joint_states`` with ``rostopic``, publishes the student's message of Task 2, hears the arm move and
has ``rosbag record`` keep it; 8.2 reads the bag back and 8.3 compares it with the simulator's reference. Every
other run of the lesson (the suite's, the grader's) leaves the live arm out (``checks.live_off``), so this is
where the live cells are run.
"""

import json
import os
import re
import shutil
import sys
from pathlib import Path

import numpy as np

from tests.conftest import need, need_program, notebook_client

ROOT = Path(__file__).resolve().parents[2]
LESSON = ROOT / "course" / "source" / "08_ros"
PROBE = ("import json\nprint(json.dumps({'rms': result['rms'].tolist(), 'largest': result['largest'], 'swing': [positions.min(0).tolist(), "
         "positions.max(0).tolist()], 'rate': (len(times) - 1) / times[-1], 'heard': heard.tolist(), 'bag': sorted(AnyReader([Path("
         "'sweep_recorded.bag')]).__enter__().topics)}))")


def test_the_students_node_sends_task_2_hears_the_arm_move_records_it_and_it_follows_the_reference(tmp_path, monkeypatch):
    need_program("roscore"), need_program("rosbag"), need_program("rostopic")
    nbformat = need("nbformat")
    need("nbclient")
    shutil.copytree(LESSON, tmp_path / "lesson", ignore=shutil.ignore_patterns(".ipynb_checkpoints", "*.bag"))
    for switch in ("SNAKEKIT_TEST", "SNAKEKIT_QUICK", "SNAKEKIT_CASES", "SNAKEKIT_HANDIN_DIR"):
        monkeypatch.delenv(switch, raising=False)
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(tmp_path / "lesson" / "08_ros.ipynb", as_version=4)
    nb.cells.append(nbformat.v4.new_code_cell(PROBE))
    notebook_client(nb, timeout=300, kernel_name="python3",
                    resources={"metadata": {"path": str(tmp_path / "lesson")}}).execute()
    said = {c.id: "".join(o.get("text", "") for o in c.outputs if o.output_type == "stream") for c in nb.cells
            if c.cell_type == "code"}
    assert "your message of Task 2: 500 points, the last at 49.9 s, 32074 bytes on the wire" in said["08-code-07"]
    assert "left out" not in "".join(said[i] for i in ("08-code-07", "08-code-07c", "08-code-07e", "08-code-07h"))
    # the student's own node joined the master, and the arm listens to its publisher
    me = re.search(r"you are the node (/sweep_sender_\S+); /arm/command has 1 subscriber\(s\)", said["08-code-07c"])
    assert me, said["08-code-07c"]
    me = me[1]
    # what the master knows, as the text describes it; three joint states echoed by rostopic, at home
    listed = said["08-code-07e"]
    assert f"nodes: /rosout, /snakekit_arm, {me}" in listed, listed
    for line in (f"/arm/command   published by  {me}", "/joint_states  published by  /snakekit_arm",
                 "/rosout_agg    published by  /rosout", "/arm/command   subscribed by /snakekit_arm",
                 "/rosout        subscribed by /rosout"):
        assert line in listed, (line, listed)
    echoed = listed.split("\n", listed.count("published by") + listed.count("subscribed by") + 1)[-1]
    assert echoed.count("\n---\n") == 3 and echoed.count("  - joint1\n  - joint2\n  - joint3\n  - joint4\n  - joint5\n") == 3
    assert echoed.count("position: [0.0, 0.0, 0.0, 0.0, 0.0]") == 3 and echoed.count("effort: []") == 3, echoed
    stamps = [int(s) * 10**9 + int(n) for s, n in re.findall(r"stamp: \n    secs: (\d+)\n    nsecs: +(\d+)", echoed)]
    assert len(stamps) == 3 and all(0.01 < d * 1e-9 < 0.04 for d in np.diff(stamps)), stamps   # "20 ms apart"
    # the student's publish ran the whole sweep, and the student's subscriber heard the arm swing and come home
    sent = said["08-code-07h"]
    assert "published 500 points on /arm/command" in sent, sent
    assert "goal done: 500 points, 50.40 s (the last goal at 49.90 s, then 0.50 s to settle)" in sent, sent
    got = json.loads(said[nb.cells[-1].id].strip().splitlines()[-1])
    heard = np.array(got["heard"])
    assert len(heard) > 50 * 50, len(heard)                       # 50 a second, for the sweep's 50.4 s
    assert (heard.max(0) > 0.18).all() and (heard.min(0) < -0.18).all(), (heard.max(0), heard.min(0))
    assert np.degrees(np.abs(heard[-1])).max() < 0.2, heard[-1]        # "ended within 0.2 degrees of home"
    assert re.search(rf"you heard {len(heard)} joint states: joint 1 went from -1[01]\.\d to 1[01]\.\d deg", sent), sent
    assert got["bag"] == ["/joint_states"]                      # what rosbag record was asked for
    assert abs(got["rate"] - 50) < 5, got["rate"]                 # the node's 50 Hz
    low, high = np.array(got["swing"])
    assert (high > 0.18).all() and (low < -0.18).all(), got["swing"]    # every joint swung both ways
    # what the text says of a live run: the node's word, what was heard, and the errors left (timing alone)
    text = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    for quote in ("`goal done: 500 points, 50.40 s`, is the motion's time, which runs 0.50 s past the last goal",
                  "your subscriber heard about 2,500 of them", "ended within 0.2 degrees of home",
                  "agree to within a millionth of a radian"):
        assert quote in text, quote
    assert 2400 < len(heard) < 2700, len(heard)
    # the node stamps each state when the simulated arm was there, so the recording is the reference run itself
    assert got["largest"] < 1e-6 and max(got["rms"]) < 1e-6, (got["rms"], got["largest"])


def test_a_cell_that_reads_the_recorded_bag_before_it_exists_says_what_it_waits_for_and_blames_no_answer(tmp_path, monkeypatch):
    nbformat = need("nbformat")
    need("nbclient")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(LESSON / "08_ros.ipynb", as_version=4)
    cells = {c.id: c for c in nb.cells}
    nb.cells = [cells[i] for i in ("08-code-02", "ex08_2_read_joint_states", "08-code-10")]   # set-up, 8.2, the bag's plot
    notebook_client(nb, timeout=300, kernel_name="python3",
                    resources={"metadata": {"path": str(tmp_path)}}).execute()
    said = "".join(o.get("text", "") for o in nb.cells[-1].outputs if o.output_type == "stream")
    assert said == ("This cell waits for exercise 8.1 and the cells after it that send the sweep: they record "
                    "sweep_recorded.bag, which is not there yet; run them first.\n"), said
