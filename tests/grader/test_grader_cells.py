"""A runaway cell costs only its exercise: by default one cell gets a third of the notebook's time.

The cell is interrupted (the kernel lives on), its exercise gets what it handed in (nothing), and the
exercises after it still run and hand in. The student's page and the TA's copy in formgrader say what
happened in a student's words: the per-cell limit, an endless loop, the function that ran.
``--help`` and grader/README.md say so.
"""

from __future__ import annotations

import html
import re
import subprocess
import sys
from pathlib import Path

import nbformat

from conftest import need_program
from grader_helpers import ASSIGNMENT, REFERENCES, make_course, read_csv, snakekit, submit

REPO = Path(__file__).resolve().parents[2]
TIMEOUT = 45  # the notebook's clock [s]: its cells get 15 s each, 5x what a cell of the test course needs


def test_one_cell_gets_a_third_of_the_notebooks_time_by_default():
    from grader.batch import Grader

    assert Grader(REPO / "course", "04_trajectories", timeout=120).cell_timeout == 40
    assert Grader(REPO / "course", "04_trajectories", timeout=120, cell_timeout=200).cell_timeout == 120
    assert Grader(REPO / "course", "04_trajectories", timeout=120, cell_timeout=10).cell_timeout == 10


def test_help_and_the_readme_say_what_a_stopped_cell_costs():
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "grade", "--help"], capture_output=True, text=True,
                       timeout=120, cwd=REPO)
    text = " ".join(r.stdout.split())
    assert "that cell is interrupted (the kernel lives on), it costs only its exercise, and the cells after it " \
           "still run and hand in (default: a third of --timeout, 40 s at the default 120" in text, text
    readme = " ".join((REPO / "grader" / "README.md").read_text().split())
    assert "default: a third of the `--timeout`, 40 s at the default 120 s" in readme
    assert "so a runaway cell costs only its exercise" in readme


def test_an_endless_loop_in_one_exercise_leaves_the_others_their_points(tmp_path):
    need_program("unshare")
    course = make_course(tmp_path)
    submit(course, "good")
    # a loop that waits for an arrival that never comes (a busy one is the corpus's: test_grader_adversarial.py)
    submit(course, "loop", {"ex1_tool_xy": "import time\n\ndef tool_xy(q):\n    arrived = False\n    while not arrived:\n"
                                           "        time.sleep(0.05)"})
    r = snakekit("grade", ASSIGNMENT, "--course", course, "--references", REFERENCES, "--timeout", TIMEOUT)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = read_csv(course / f"grades-{ASSIGNMENT}.csv")
    assert float(rows["good"]["score"]) == 7.0
    loop = rows["loop"]
    # ex1 (2 points) hangs in its hidden cases and is interrupted; ex2 (4) and ex3 (1) still run and hand in
    assert (loop["status"], float(loop["score"])) == ("timeout", 5.0), loop
    assert re.search(r"a cell ran longer than 15 s and was interrupted", loop["detail"]), loop["detail"]
    # what the student reads (the page) and the TA sees (formgrader shows the autograded notebook's verdict)
    said = ("0 / 2 points nothing was handed in: the cell was stopped after the per-cell limit of 15 s, while your "
            "`tool_xy` ran (exercise 1 tool_xy). That usually means an endless loop: a `while` whose condition "
            "never becomes false, or a loop whose counter is never advanced. Run the cell in your notebook: if it "
            "does not finish, stop it (Kernel > Interrupt) and look at the loops of `tool_xy`.")
    page = html.unescape(re.sub(r"<[^>]+>", " ", (course / "feedback" / "loop" / ASSIGNMENT / f"{ASSIGNMENT}.html")
                                .read_text()))
    assert said in " ".join(page.split()), page[page.find("1 tool_xy: "):][:600]
    assert "KeyboardInterrupt: ." not in page
    ran = nbformat.read(course / "autograded" / "loop" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)
    cell = next(c for c in ran.cells if c.metadata.get("nbgrader", {}).get("grade_id") == "ex1_tool_xy_test")
    shown = " ".join(html.unescape(re.sub(r"<[^>]+>", " ", o["data"]["text/html"]))
                     for o in cell.outputs if "snakekit_grader" in o.get("metadata", {}))
    assert said.split(" ", 4)[-1] in " ".join(shown.split()), shown
