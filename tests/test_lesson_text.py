"""What a lesson's text states agrees with what its cells compute, and every "predict, then run"
question is answered after the cell that shows it.

Each claim below is a number (or a few) that a lesson's text (markdown, or a code comment) states, quoted as it stands,
with an expression that computes it in the kernel of the instructor version, run top to bottom.
The test fails when the quote is no longer in the lesson (the text changed: update the claim)
or when the computed value is off the stated one by more than the stated precision.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

import pytest

from tests.conftest import need

ROOT = Path(__file__).resolve().parents[1]
COURSE = ROOT / "course"

# lesson -> (quote from its markdown, expression in its instructor kernel, stated value, tolerance)
# A stated value may be a number, a list (compared entry by entry) or a (low, high) range for words
# such as "about a millimetre".
CLAIMS = {
    "00_meet_the_arm": [
        ("Joints 71 mm apart", "1000 * snakekit.SPEC.lengths[:4]", [71, 71, 71, 71], 1e-9),
        ("tool point 47.5 mm beyond joint 5", "1000 * snakekit.SPEC.lengths[4]", 47.5, 1e-9),
        ("every joint limited to ±1.57 rad", "[snakekit.SPEC.lower, snakekit.SPEC.upper]", [-1.57, 1.57], 1e-12),
        ("and 1.5 rad/s", "snakekit.SPEC.velocity_limit", 1.5, 1e-12),
        ("at home the tool is at $(0.3315, 0)$", "snakekit.tool_pose_2d(np.zeros(5))[:2]", [0.3315, 0.0], 1e-12),
        ("`distance_mm(np.zeros(5), (0.3, 0.0))` is 31.5", "distance_mm(np.zeros(5), (0.3, 0.0))", 31.5, 1e-9),
        ("[ 0.8 -0.6  1.   0.4 -1.2]", "2 * np.array([0.4, -0.3, 0.5, 0.2, -0.6])", [0.8, -0.6, 1.0, 0.4, -1.2],
         1e-12),
        ("[0.4 0.1 0.6 0.8 0.2]", "np.cumsum([0.4, -0.3, 0.5, 0.2, -0.6])", [0.4, 0.1, 0.6, 0.8, 0.2], 1e-12),
        ("Each move ends within about a millimetre of its target",
         "max(distance_mm(run.measured.positions[-1], t[:2]) for run, t in zip(panel.runs, targets))", (0.02, 2.0),
         None),
    ],
    "01_forward_kinematics": [
        ("`planar_fk(np.zeros(5))` is `[0.3315, 0.0, 0.0]`", "planar_fk(np.zeros(5))", [0.3315, 0.0, 0.0], 1e-12),
        ("$1.2 \\times 3 = 3.6$ rad $= 206°$", "np.degrees(planar_fk(np.array([1.2, 1.2, 1.2, 0, 0]))[2])", 206.0, 0.5),
        ("$x = 0, 0.071, 0.142, 0.213, 0.284, 0.3315$", "joint_positions(np.zeros(5))[:, 0]",
         [0, 0.071, 0.142, 0.213, 0.284, 0.3315], 1e-12),
        ("`reach(5, 0.071, 0.0475)` is `0.3315`", "reach(5, 0.071, 0.0475)", 0.3315, 1e-12),
        ("$\\sqrt{0.30^2 + 0.15^2} = 0.3354$ m", "np.hypot(0.30, 0.15)", 0.3354, 5e-5),
        ("by 3.9 mm", "1000 * (np.hypot(0.30, 0.15) - reach(5, 0.071, 0.0475))", 3.9, 0.05),
        ("and the reach (1.3): 331.5 mm", "1000 * spec.reach", 331.5, 1e-9),
    ],
    "02_jacobian": [
        ("column 1 is $[0, 0.3315, 1]$", "planar_jacobian(np.zeros(5))[:, 0]", [0, 0.3315, 1], 1e-12),
        ("column 5 is $[0, 0.0475, 1]$", "planar_jacobian(np.zeros(5))[:, 4]", [0, 0.0475, 1], 1e-12),
        ("the result is `[[3.0, 2.0]]`", "numerical_jacobian(lambda q: np.array([q[0] * q[1]]), np.array([2.0, 3.0]))",
         [[3.0, 2.0]], 1e-6),
        ("`manipulability(np.zeros(5))` is 0", "manipulability(np.zeros(5))", 0.0, 1e-10),
        ("`manipulability(np.full(5, 0.5))` is about 0.0406", "manipulability(np.full(5, 0.5))", 0.0406, 5e-5),
        ("With $h = 10^{-6}$ the largest difference is about $10^{-10}$",
         "np.abs(numerical_jacobian(snakekit.tool_pose_2d, Q5, 1e-6) - snakekit.planar_jacobian(Q5)).max()",
         (1e-11, 1e-9), None),
        ("With $h = 10^{-12}$ rounding dominates: about $10^{-4}$ to $10^{-5}$",
         "np.abs(numerical_jacobian(snakekit.tool_pose_2d, Q5, 1e-12) - snakekit.planar_jacobian(Q5)).max()",
         (1e-6, 1e-3), None),
        ("accurate to about $10^{-10}$ with $h = 10^{-6}$",
         "np.abs(numerical_jacobian(snakekit.tool_pose_2d, Q5, 1e-6) - snakekit.planar_jacobian(Q5)).max()",
         (1e-11, 1e-9), None),
        ("Gently bent wins", "manipulability(np.full(5, 0.3)) > max(manipulability(np.zeros(5)), "
                             "manipulability(np.full(5, 1.2)))", 1, 0),
    ],
    "03_inverse_kinematics": [
        ("`two_link_ik(0.1, 0.1, 0.1, 0.1)` is `[[0, 1.5708], [1.5708, -1.5708]]`", "two_link_ik(0.1, 0.1, 0.1, 0.1)",
         [[0, 1.5708], [1.5708, -1.5708]], 5e-5),
        ("for `two_link_ik(0.1, 0.0, 0.07, 0.03)` the formula gives 1.0000000000000002",
         "(0.1 * 0.1 - 0.07 * 0.07 - 0.03 * 0.03) / (2 * 0.07 * 0.03) - 1", 2.220446049250313e-16, 0),
        ("so $e = (-0.0815, 0.1)$", "np.array([0.25, 0.1]) - snakekit.tool_pose_2d(np.zeros(5))[:2]", [-0.0815, 0.1],
         1e-12),
        ("the new $q$ is `[0.1442, 0.1133, 0.0824, 0.0515, 0.0207]` rad", "dls_step(np.zeros(5), (0.25, 0.1))",
         [0.1442, 0.1133, 0.0824, 0.0515, 0.0207], 5e-5),
        ("stops after 8 steps", "it", 8, 0),
        ("`q = [-0.1452, 0.4584, -0.1078, 0.7242, 1.3185]` rad", "solve_ik(np.array([0.22, 0.12]))",
         [-0.1452, 0.4584, -0.1078, 0.7242, 1.3185], 5e-5),
        ("(0.412 m away, beyond the 0.3315 m reach)", "[np.hypot(0.40, 0.10), spec.reach]", [0.412, 0.3315], 5e-4),
        ("**What it shows.** 8 steps", "it", 8, 0),
        ("(0.16 m, 0.09 m, then 0.27 m)", "errors[:3]", [0.16, 0.09, 0.27], 0.005),
        ("(0.15 m, 0.016 m, 0.0012 m, 3 µm)", "np.array(errors[4:8]) / [0.15, 0.016, 0.0012, 3e-6]", [1, 1, 1, 1], 0.1),
        ("near `[[0.2502, 0.1001, 0.2996], [0.1208, 0.2197, 1.5948], [0.2803, -0.0793, -0.3975]]`", "poses",
         [[0.2502, 0.1001, 0.2996], [0.1208, 0.2197, 1.5948], [0.2803, -0.0793, -0.3975]], 5e-4),
        ("within about a millimetre of each target", "1000 * np.abs(poses[:, :2] - np.array(TASK1)[:, :2]).max()",
         (0.05, 2.0), None),
    ],
}
# names the expressions use, defined in the kernel after the lesson has run
PRELUDE = "Q5 = np.array([0.3, 0.5, -0.4, 0.6, 0.2])\nTASK1 = [(0.25, 0.10, 0.3), (0.12, 0.22, 1.6), (0.28, -0.08, -0.4)]\n"


def read(path: Path):
    return need("nbformat").read(path, as_version=4)


def markdown(nb) -> str:
    return "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")


def computed(name: str, expressions: list[str], work: Path, monkeypatch) -> list:
    """Run the instructor version of ``name``, then evaluate ``expressions`` in its kernel."""
    nbformat, nbclient = need("nbformat"), need("nbclient")
    shutil.copytree(COURSE / "source" / name, work, ignore=shutil.ignore_patterns(".ipynb_checkpoints", "*.npz"))
    monkeypatch.setenv("SNAKEKIT_TEST", "1")
    monkeypatch.delenv("SNAKEKIT_HANDIN_DIR", raising=False)
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    nb = read(work / f"{name}.ipynb")
    probe = PRELUDE + "import json\nprint(json.dumps([np.asarray(eval(e), dtype=float).tolist() for e in %r]))" % (
        expressions,)
    nb.cells.append(nbformat.v4.new_code_cell(probe))
    nbclient.NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(work)}}).execute()
    out = "".join(o.get("text", "") for o in nb.cells[-1].outputs if o.output_type == "stream")
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.parametrize("name", sorted(CLAIMS))
def test_the_numbers_a_lesson_states_are_the_ones_its_cells_compute(name, tmp_path, monkeypatch):
    np = need("numpy")
    text = "\n".join(c.source for c in read(COURSE / "source" / name / f"{name}.ipynb").cells)   # comments too
    claims = CLAIMS[name]
    missing = [quote for quote, *_ in claims if quote not in text]
    assert missing == [], f"{name} no longer says these (update the claims with the text): {missing}"
    values = computed(name, [expr for _, expr, *_ in claims], tmp_path / name, monkeypatch)
    wrong = []
    for (quote, expr, stated, tol), value in zip(claims, values):
        value = np.asarray(value, dtype=float)
        if tol is None:
            ok = stated[0] <= float(value) <= stated[1]
        else:
            ok = value.shape == np.shape(stated) and bool(np.all(np.abs(value - stated) <= tol))
        if not ok:
            wrong.append(f"{quote!r}: {expr} is {value.tolist()}, the text says {stated}"
                         + (f" (within {tol})" if tol is not None else ""))
    assert wrong == [], f"{name}'s text disagrees with its cells:\n" + "\n".join(wrong)


def test_a_claim_the_cells_disagree_with_is_found(tmp_path, monkeypatch):
    """The comparison above fails on a stated number that is off (lesson 1's old "by 3.5 mm")."""
    values = computed("01_forward_kinematics", ["1000 * (np.hypot(0.30, 0.15) - reach(5, 0.071, 0.0475))"],
                      tmp_path / "l1", monkeypatch)
    assert abs(values[0] - 3.5) > 0.05 and abs(values[0] - 3.9) <= 0.05


@pytest.mark.parametrize("name", sorted(CLAIMS))
def test_every_prediction_is_answered_after_the_cell_that_shows_it(name):
    """In the student version, a "predict, then run" question is followed by the cell that shows
    the answer, and then by a markdown cell that says it (**What it shows.**)."""
    student = read(ROOT / "notebooks" / f"{name}.ipynb")
    cells = student.cells
    asked = [i for i, c in enumerate(cells) if c.cell_type == "markdown" and "**Predict, then run.**" in c.source]
    assert asked, name
    for i in asked:
        assert cells[i + 1].cell_type == "code", (name, cells[i].source[:80])
        after = cells[i + 2]
        assert after.cell_type == "markdown" and after.source.startswith("**What it shows.**"), (name, after.source[:80])
        assert len(after.source) > 80, after.source


@pytest.mark.parametrize("name", sorted(CLAIMS))
def test_each_lesson_says_once_that_hidden_cases_exist_and_what_kind(name):
    text = markdown(read(ROOT / "notebooks" / f"{name}.ipynb"))
    assert text.count("**How your work is graded.**") == 1, name
    graded = text.split("**How your work is graded.**")[1].split("\n\n")[0]
    assert "*hidden cases*" in graded and "drawn anew for every grading" in graded, graded
