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

from tests.conftest import need, notebook_client

ROOT = Path(__file__).resolve().parents[2]
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
        ("the *final joint error* printed after each move above, about 0.002 rad",
         "max(np.abs(run.measured.positions[-1] - run.commanded.positions[-1]).max() for run in panel.runs[:3])",
         (0.001, 0.004), None),
        ("At the end of an arm about 0.3 m long, 0.002 rad is 0.6 mm", "1000 * 0.3 * 0.002", 0.6, 1e-9),
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
        ("it can come out a hair below 0 (about $-10^{-18}$)",
         "np.linalg.det(snakekit.planar_jacobian(np.array([0.55, 0, 0, 0, 0]))[:2] @ "
         "snakekit.planar_jacobian(np.array([0.55, 0, 0, 0, 0]))[:2].T)", (-1e-17, -1e-19), None),
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
        # the plot draws each velocity ellipse (semi-axes: J_xy's singular values) scaled by 0.2, as the text says
        ("a drawn ellipse's area is $0.2^2 \\pi w = 0.04 \\pi w$",
         "[np.pi * np.prod(0.2 * np.linalg.svd(snakekit.planar_jacobian(np.full(5, b))[:2])[1]) / "
         "(np.pi * manipulability(np.full(5, b))) for b in (0.3, 1.2)]", [0.04, 0.04], 1e-12),
        ("ell = U @ np.diag(S) @ circle * 0.2", "0.2", 0.2, 0),
        # the hidden kind of 2.1 the visible check has too: entries of J near 0, where a finite difference misses
        ("a pose where some entries of $J$ are near 0",
         "[np.abs(snakekit.planar_jacobian(np.array([0.3, -0.2, -0.099, 0.0, 0.0]))[0, 2:]).max(), "
         "np.abs(numerical_jacobian(snakekit.tool_pose_2d, np.array([0.3, -0.2, -0.099, 0.0, 0.0])) - "
         "planar_jacobian(np.array([0.3, -0.2, -0.099, 0.0, 0.0])))[0, 2:].max() > 1e-12]", [1.895e-4, 1], 5e-7),
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
        ("stops after 8 steps", "n_steps", 8, 0),
        ("`q = [-0.1452, 0.4584, -0.1078, 0.7242, 1.3185]` rad", "solve_ik(np.array([0.22, 0.12]))",
         [-0.1452, 0.4584, -0.1078, 0.7242, 1.3185], 5e-5),
        ("(0.412 m away, beyond the 0.3315 m reach)", "[np.hypot(0.40, 0.10), spec.reach]", [0.412, 0.3315], 5e-4),
        ("**What it shows.** 8 steps", "n_steps", 8, 0),
        # the predict cell shows the student's own solution: the q its solve_ik returned, the tool within 1 um
        ("`q = [-0.1452, 0.4584, -0.1078, 0.7242, 1.3185]` rad", "q", [-0.1452, 0.4584, -0.1078, 0.7242, 1.3185],
         5e-5),
        ("the tool within 1 µm of the target", "[errors[-1] < 1e-6, np.allclose(path[-1], q)]", [1, 1], 0),
        ("From 0.16 m it drops to 0.09 m, then *rises* to 0.27 m", "errors[:3]", [0.16, 0.09, 0.27], 0.005),
        ("(0.15 m, 0.016 m, 0.0012 m, 3 µm)", "np.array(errors[4:8]) / [0.15, 0.016, 0.0012, 3e-6]", [1, 1, 1, 1], 0.1),
        ("near `[[0.2502, 0.1001, 0.2996], [0.1208, 0.2197, 1.5948], [0.2803, -0.0793, -0.3975]]`", "poses",
         [[0.2502, 0.1001, 0.2996], [0.1208, 0.2197, 1.5948], [0.2803, -0.0793, -0.3975]], 5e-4),
        ("within about a millimetre of each target", "1000 * np.abs(poses[:, :2] - np.array(TASK1)[:, :2]).max()",
         (0.05, 2.0), None),
    ],
    "04_trajectories": [
        ("Worked number: `quintic(2.0, 1.0)` is `0.5`", "quintic(2.0, 1.0)", 0.5, 1e-12),
        ("`trapezoid(1.0, 1.5, 3.0)` is `[1.1667, 1.5]`", "trapezoid(1.0, 1.5, 3.0)", [1.1667, 1.5], 5e-5),
        ("`trapezoid(0.3, 1.5, 3.0)` is `[0.6325, 0.9487]`", "trapezoid(0.3, 1.5, 3.0)", [0.6325, 0.9487], 5e-5),
        ("The quintic asks the highest peak speed, $1.875/T$", "peak(quintic_time_scaling)", 1.875, 0.01),
        ("against $1.5/T$ for the cubic", "peak(cubic_time_scaling)", 1.5, 0.01),
        ("and $1.333/T$ for this trapezoid", "peak(trapezoidal_time_scaling)", 1.333, 0.01),
        ("a 1 s move at 10 Hz has 11 goals, the last at 1.0 s", "[len(sample_move(np.zeros(5), np.ones(5), 1.0)), "
         "sample_move(np.zeros(5), np.ones(5), 1.0).times[-1]]", [11, 1.0], 1e-12),
        ("Three steps are too fast for joint 1", "(steps(fast) > spec.velocity_limit).sum()", 3, 0),
        ("faster still (up to 3.65 rad/s between goals)", "steps(fast).max()", 3.65, 0.005),
        ("**margin of 5 mm**", "1000 * spec.collision_margin", 5, 1e-9),
    ],
    "05_simulation": [
        ("The speed ramps up for about 0.13 s", "t[np.argmax(speed >= 0.95 * cruise)]", 0.13, 0.015),
        ("peaks at 1.38 rad/s", "speed.max()", 1.38, 0.005),
        ("settles to cruise at 1.32 rad/s", "cruise", 1.32, 0.005),
        ("The firmware's own profile ramps up in 35 ms", "1000 * pv_rad_s(55) / pa_rad_s2(100)", 35, 0.5),
        ("PV = 55 (1.32 rad/s) and PA = 100 (37.45 rad/s²)", "[pv_rad_s(55), pa_rad_s2(100)]", [1.32, 37.45], 0.005),
        ("PV = 62 (1.487 rad/s)", "pv_rad_s(62)", 1.487, 0.0005),
        ("`profile_move_time(1.0, 62, 100)` is about 0.712 s", "profile_move_time(1.0, 62, 100)", 0.712, 0.0005),
        ("within about a quarter of a milliradian (0.01°)", "[1000 * abs(sse), np.degrees(abs(sse))]", [0.25, 0.01],
         0.005),
        ("0.71 s with Profile Velocity 62 and 1.37 s with 31",
         "[profile_move_time(1.0, 62, 100), profile_move_time(1.0, 31, 100)]", [0.71, 1.37], 0.005),
        # the answer and what it shows both say the time the cell prints for Profile Velocity 0 (its last run)
        ("the arm gets there in 0.25 s", "0.01 * (1 + np.argmax(np.abs(np.array(samples) - 1.0) < 0.01))", 0.25,
         0.005),
    ],
    "06_coded_sweep": [
        ("`sweep_times(4, 10.0)` is `[0.0, 0.1, 0.2, 0.3]`", "sweep_times(4, 10.0)", [0.0, 0.1, 0.2, 0.3], 1e-12),
        ("**What it shows.** 49.9 s: 500 goals span 499 intervals of 0.1 s", "sweep_times(500, 10.0)[-1]", 49.9, 1e-9),
        ("It comes out around **11 degrees**", "np.degrees(run.tracking_error()[0])", (10.5, 11.5), None),
        ("amplitude is only 0.2 rad = **11.5 degrees**", "np.degrees(0.2)", 11.5, 0.05),
        ("once the 0.16 s lag is taken out", "estimate_lag(run, 0)", 0.16, 0.005),
        ("About 11 degrees of raw error shrink to about 1 degree", "[np.degrees(run.tracking_error()[0]), "
         "np.degrees(np.abs(run.measured.positions[inside, 0] - run.commanded.sample(t[inside] - estimate_lag(run, 0))"
         "[:, 0]).max())]", [11.0, 1.0], 0.5),
    ],
    "07_real_robot": [
        ("0 rad is 2048, $\\pi/2$ is 3072, $-1$ rad is 1396", "to_ticks(np.array([0.0, np.pi / 2, -1.0]))",
         [2048, 3072, 1396], 0),
        ("**What it shows.** 3071: tick 3072 is 1.5708 rad", "[hardware.position_limit_ticks()[1], "
         "float(hardware.ticks_to_radians(3072))]", [3071, 1.5708], 5e-5),
        ("from home the largest joint distance is 0.4 rad, so T = 1.875 x 0.4 / 1.5 = 0.5 s", "1.875 * 0.4 / 1.5", 0.5,
         1e-12),
        # the bus runs in real time: on a loaded machine a goal may leave a cycle late, and the peak moves a little
        ("it peaks at about 0.5 N m on every joint", "np.abs(home_run.efforts).max(axis=0)", [0.5] * 5, 0.1),
        # mid-move: each joint's load peaks in the middle half of the 1 s move (0.50 to 0.57 s after its start). Read
        # as a student reads the plot, over 5 samples (their median): on a loaded machine a goal that left a cycle late
        # makes one sample's load jump (a suite run beside other work: a peak 0.31 s from the middle)
        ("on every joint mid-move",
         "np.abs(home_run.measured.times[2:-2][np.median(np.lib.stride_tricks.sliding_window_view("
         "np.abs(home_run.efforts), 5, axis=0), axis=-1).argmax(axis=0)] - 0.5).max()", (0.0, 0.25), None),
        # where the joints turn fastest: there each joint's load is within 20 % of its peak (0.98 to 1 quiet and beside
        # stress-ng). The load is flat there: 0.87 to 0.97 of its peak 0.1 s either side, so on a loaded machine the
        # peak sample can lie 0.1 s from the speed's (a CI run: 0.102 s), the load where the speed peaks cannot
        ("where the joints turn fastest",
         "(np.abs(home_run.efforts)[np.abs(home_run.measured.velocities).argmax(axis=0), np.arange(5)]"
         " / np.abs(home_run.efforts).max(axis=0)).min()", (0.8, 1.0), None),
        ("is almost 0 once the arm holds still at home", "np.abs(home_run.efforts[-10:]).max()", (0.0, 0.06), None),
        # 12 runs on a busy machine: 0.90 to 1.04, larger than the simulator's in 5 of them
        ("About the same: within about 10 % of the simulator's",
         "(run.tracking_error() / sim_run.tracking_error()).mean()", (0.85, 1.15), None),
    ],
    "08_ros": [
        ("point 1 is at `sec=0, nanosec=100000000`", "[sweep_message(snakekit.side_sweep()).points[1].time_from_start."
         "sec, sweep_message(snakekit.side_sweep()).points[1].time_from_start.nanosec]", [0, 100000000], 0),
        ("the last, point 499, at `sec=49, nanosec=900000000`", "[sweep_message(snakekit.side_sweep()).points[499]."
         "time_from_start.sec, sweep_message(snakekit.side_sweep()).points[499].time_from_start.nanosec]",
         [49, 900000000], 0),
        ("500 goals at 10 Hz, 50 sweeps of 0.2 rad", "[len(sweep), 1 / np.diff(sweep.times).mean(), "
         "np.abs(sweep.positions).max()]", [500, 10, 0.2], 1e-3),
        ("all 500 points, 32074 bytes on the wire", "[len(goal.points), len(ros1_bytes(goal))]", [500, 32074], 0),
        # without the live arm (under test), the bag is the simulator's run at the node's rate
        ("a `JointState` on `/joint_states` 50 times a second", "(len(times) - 1) / times[-1]", 50, 0.5),
        ("$\\sqrt{0.05^2 / 3} = 0.0289$ rad", "compare_runs([0.0, 0.5, 1.0], one, ramp_t, ramp)['rms'][0]", 0.0289, 5e-5),
        ("its largest error is 0.05 rad, on joint 1 at 0.5 s", "[compare_runs([0.0, 0.5, 1.0], one, ramp_t, ramp)[k] "
         "for k in ('largest', 'joint', 'when')]", [0.05, 1, 0.5], 1e-12),
        ("its samples are among the reference's, and every error is 0", "result['largest']", 0.0, 1e-12),
    ],
}
# names the expressions use, defined in the kernel after the lesson has run
PRELUDE = "Q5 = np.array([0.3, 0.5, -0.4, 0.6, 0.2])\nTASK1 = [(0.25, 0.10, 0.3), (0.12, 0.22, 1.6), (0.28, -0.08, -0.4)]\n"
# for lessons 4 and 5: a scaling's peak speed x T (on the lesson's 2 s grid), a trajectory's step speeds on
# joint 1, the Profile Velocity and Acceleration registers in SI units
PRELUDE += ("peak = lambda f: np.gradient(f(2.0, np.linspace(0, 2.0, 400)), np.linspace(0, 2.0, 400)).max() * 2.0\n"
            "steps = lambda tr: np.abs(np.diff(tr.positions[:, 0])) / np.diff(tr.times)\n"
            "pv_rad_s = lambda pv: pv * 0.229 * 2 * np.pi / 60\n"
            "pa_rad_s2 = lambda pa: pa * 214.577 * 2 * np.pi / 3600\n")


def read(path: Path):
    return need("nbformat").read(path, as_version=4)


def markdown(nb) -> str:
    return "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")


def computed(name: str, expressions: list[str], work: Path, monkeypatch) -> list:
    """Run the instructor version of ``name``, then evaluate ``expressions`` in its kernel. A lesson run as a
    student runs it, checks and all, leaves nothing in the temporary folder (a check runs again and again)."""
    nbformat = need("nbformat")
    need("nbclient")
    shutil.copytree(COURSE / "source" / name, work, ignore=shutil.ignore_patterns(".ipynb_checkpoints", "*.npz"))
    scratch = work.parent / f"{work.name}-tmp"
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))   # the kernel's temporary folder (this process keeps its own)
    monkeypatch.setenv("SNAKEKIT_TEST", "1")
    monkeypatch.delenv("SNAKEKIT_HANDIN_DIR", raising=False)
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    nb = read(work / f"{name}.ipynb")
    probe = PRELUDE + "import json\nprint(json.dumps([np.asarray(eval(e), dtype=float).tolist() for e in %r]))" % (
        expressions,)
    nb.cells.append(nbformat.v4.new_code_cell(probe))
    notebook_client(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(work)}}).execute()
    left = sorted(str(p.relative_to(scratch)) for p in scratch.rglob("*"))
    assert left == [], f"a run of {name} left these in the temporary folder: {left[:10]}"
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


@pytest.mark.parametrize("name", sorted(CLAIMS))
def test_the_text_before_a_demonstration_that_waits_says_it_waits(name):
    """A demonstration that needs an exercise waits for it (``checks.waiting_for``) and never falls back on the
    library's version: the text before it says so, not that something else draws it meanwhile (lesson 1's
    "until 1.2 is done, the library draws it", above a cell that only printed that it waited)."""
    import re

    cells = read(ROOT / "notebooks" / f"{name}.ipynb").cells
    for before, cell in zip(cells, cells[1:]):
        if cell.cell_type == "code" and "waiting_for(" in cell.source and before.cell_type == "markdown":
            until = re.search(r"[Uu]ntil (\d+\.\d+)[^.]*", before.source)
            if until:
                assert "waits" in until.group(0) and "library" not in until.group(0), (name, before.source)
