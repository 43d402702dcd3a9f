"""Lesson 8's live part, run once: the instructor version with ROS 1 here and quick mode off starts its own
master and the arm's node, sends the student's sweep message, records a bag with ``rosbag record``, reads it
back with 8.2 and compares it with the simulator's reference with 8.3. Every other run of the lesson (the
suite's, the grader's) leaves the live arm out (``checks.live_off``), so this is where the live cells are run.
"""

import json
import os
import shutil
import sys
from pathlib import Path

import numpy as np

from tests.conftest import need, need_program, notebook_client

ROOT = Path(__file__).resolve().parents[2]
LESSON = ROOT / "course" / "source" / "08_ros"
PROBE = ("import json\nprint(json.dumps({'rms': result['rms'].tolist(), 'largest': result['largest'], 'swing': [positions.min(0).tolist(), "
         "positions.max(0).tolist()], 'rate': (len(times) - 1) / times[-1], 'bag': sorted(AnyReader([Path("
         "'sweep_recorded.bag')]).__enter__().topics)}))")


def test_the_live_part_sends_the_sweep_records_it_and_it_follows_the_reference(tmp_path, monkeypatch):
    need_program("roscore"), need_program("rosbag")
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
    assert "goal done: 40 points" in said["08-code-07"] and "left out" not in said["08-code-07"], said["08-code-07"]
    got = json.loads(said[nb.cells[-1].id].strip().splitlines()[-1])
    assert got["bag"] == ["/joint_states"]                      # what rosbag record was asked for
    assert abs(got["rate"] - 50) < 5, got["rate"]                 # the node's 50 Hz
    low, high = np.array(got["swing"])
    assert (high > 0.12).all() and (low < -0.12).all(), got["swing"]    # every joint swung both ways
    # the same simulator in real time against its own run: timing alone (0.005 rad on a quiet machine)
    assert (np.array(got["rms"]) < 0.05).all(), got["rms"]
    # what the text says of a live run: the node's word, and the errors left (timing alone)
    text = "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")
    for quote in ("`goal done: 40 points, 4.40 s`, the motion's time, which runs 0.50 s past the last goal",
                  "under a tenth of a degree rms, and under a degree at most"):
        assert quote in text, quote
    assert "goal done: 40 points, 4.40 s (the last goal at 3.90 s, then 0.50 s to settle)" in said["08-code-07"]
    assert np.degrees(got["rms"]).max() < 0.1 and np.degrees(got["largest"]) < 1.0, (got["rms"], got["largest"])


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
    assert said == ("This cell waits for exercise 8.1 and the cell after it that sends the sweep: it records "
                    "sweep_recorded.bag, which is not there yet; run them first.\n"), said
