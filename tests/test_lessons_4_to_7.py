"""Lessons 04 to 07 as graded: hidden cases handed in, and text that agrees with its cells.

Each instructor notebook runs once, as the grader runs it: a small case server (the wire format
of :mod:`snakekit.handin`) answers its test cells with cases drawn from ``course/cases/<lesson>.py``.
Then:

* every graded cell handed in one result per case, and those results are right, checked against
  an independent computation (the library's own functions, the formulas of the lesson's text);
  where the instructor's function must raise (a sweep beyond the limits), it raised;
* every number the lesson's text states is what its cells print;
* every "predict, then run" question is answered in a cell after the one that shows it.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import socket
import struct
import sys
import tempfile
import threading
import zlib
from pathlib import Path

import pytest

from tests.conftest import need

ROOT = Path(__file__).resolve().parents[1]
LESSONS = ["04_trajectories", "05_simulation", "06_coded_sweep", "07_real_robot"]
SEED = 2024


def read(path: Path):
    return need("nbformat").read(path, as_version=4)


def draw(lesson: str, seed: int = SEED) -> dict[str, list]:
    """Every grade id's cases of ``lesson``, each from its own stream of ``seed``."""
    np = need("numpy")
    import snakekit

    path = ROOT / "course" / "cases" / f"{lesson}.py"
    spec = importlib.util.spec_from_file_location(f"cases_{lesson}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return {name: fn(np.random.default_rng([seed, zlib.crc32(name.encode())]), snakekit.SPEC)
            for name, fn in vars(module).items()
            if callable(fn) and name.startswith("ex") and fn.__module__ == module.__name__}


class CaseServer:
    """Answers each request on a Unix socket with the cases of its grade id (snakekit.handin's format)."""

    def __init__(self, path: Path, cases: dict[str, list]):
        from snakekit.handin import encode_cases

        self.payload = {gid: encode_cases(c) for gid, c in cases.items()}
        self.asked: list[str] = []
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.sock.bind(str(path))
        self.sock.listen(4)
        self.thread = threading.Thread(target=self.serve, daemon=True)
        self.thread.start()

    def serve(self):
        import json

        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            with conn:
                line = b""
                while not line.endswith(b"\n"):
                    chunk = conn.recv(4096)
                    if not chunk:
                        break
                    line += chunk
                gid = json.loads(line)["grade_id"]
                self.asked.append(gid)
                data = self.payload.get(gid, b"")
                conn.sendall(struct.pack(">Q", len(data)) + data)

    def close(self):
        self.sock.close()


@pytest.fixture(scope="module")
def graded():
    """Each lesson's instructor notebook run with drawn cases: its cells, its hand-ins, the cases."""
    nbformat = need("nbformat")
    nbclient = need("nbclient")
    from snakekit.handin import decode_results

    out = {}
    with tempfile.TemporaryDirectory(prefix="sk-") as tmp:   # short: a socket path has at most 107 bytes
        for lesson in LESSONS:
            work, handin = Path(tmp) / lesson, Path(tmp) / f"{lesson}-handin"
            shutil.copytree(ROOT / "course" / "source" / lesson, work,
                            ignore=shutil.ignore_patterns(".ipynb_checkpoints", "*.npz"))
            handin.mkdir()
            cases = draw(lesson)
            server = CaseServer(Path(tmp) / f"{lesson[:2]}.sock", cases)
            env = {"SNAKEKIT_HANDIN_DIR": str(handin), "SNAKEKIT_CASES": str(Path(tmp) / f"{lesson[:2]}.sock"),
                   "SNAKEKIT_TEST": "1", "MPLBACKEND": "Agg",
                   "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
            old = {k: os.environ.get(k) for k in env}
            os.environ.update(env)
            try:
                nb = nbformat.read(work / f"{lesson}.ipynb", as_version=4)
                nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                        resources={"metadata": {"path": str(work)}}).execute()
            finally:
                for k, v in old.items():
                    os.environ.pop(k) if v is None else os.environ.__setitem__(k, v)
                server.close()
            results = {p.stem: decode_results(p.read_bytes()) for p in handin.glob("*.npz")}
            out[lesson] = {"nb": nb, "cases": cases, "results": results, "asked": server.asked}
    return out


def printed(nb) -> str:
    return "\n".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs
                     if o.output_type == "stream")


def markdown(nb) -> str:
    return "\n".join(c.source for c in nb.cells if c.cell_type == "markdown")


def value(result):
    """A handed-in result's single value (a dict with "value"), or the error's text."""
    return result if isinstance(result, str) else result["value"]


# --- hand-ins -----------------------------------------------------------------------------------


@pytest.mark.parametrize("lesson", LESSONS)
def test_every_graded_cell_hands_in_one_result_per_drawn_case(graded, lesson):
    run = graded[lesson]
    test_cells = [c.metadata["nbgrader"]["grade_id"] for c in run["nb"].cells
                  if c.metadata.get("nbgrader", {}).get("grade")]
    assert sorted(run["cases"]) == sorted(test_cells), "one case function per graded cell"
    assert run["asked"] == test_cells, "each test cell asks for its cases once, in order"
    for gid in test_cells:
        assert len(run["results"][gid]) == len(run["cases"][gid]), gid


def test_lesson4_hands_in_what_the_formulas_give(graded):
    np = need("numpy")
    from snakekit.trajectory import quintic_time_scaling

    run = graded["04_trajectories"]
    for (T, t), r in zip(run["cases"]["ex04_1_quintic_test"], run["results"]["ex04_1_quintic_test"]):
        assert np.allclose(value(r), quintic_time_scaling(T, t), rtol=1e-12, atol=1e-15)
    for (d, v, a), r in zip(run["cases"]["ex04_2_trapezoid_test"], run["results"]["ex04_2_trapezoid_test"]):
        d = abs(d)
        want = [d / v + v / a, v] if d >= v * v / a else [2 * np.sqrt(d / a), np.sqrt(a * d)]
        assert np.allclose(value(r), want, rtol=1e-12), (d, v, a)
    assert any(d < 0 for d, _, _ in run["cases"]["ex04_2_trapezoid_test"]), "a move backwards is among the cases"
    for (a, b, T, rate), r in zip(run["cases"]["ex04_3_sample_10hz_test"], run["results"]["ex04_3_sample_10hz_test"]):
        times = np.arange(int(round(T * rate)) + 1) / rate
        assert np.allclose(r["goal_times"], times)
        assert np.allclose(r["goal_positions"], a + np.outer(quintic_time_scaling(T, times), b - a))
    counts = []
    for (t, p), r in zip(run["cases"]["ex04_4_limit_check_test"], run["results"]["ex04_4_limit_check_test"]):
        want = []
        for k in range(len(t)):                       # the text's definition, point by point
            for j in range(5):
                if abs(p[k, j]) > 1.57:
                    want.append([t[k], j + 1, 0])
                if k and abs(p[k, j] - p[k - 1, j]) / (t[k] - t[k - 1]) > 1.5:
                    want.append([t[k], j + 1, 1])
        got = np.asarray(value(r))
        assert got.shape == (len(want), 3) and np.allclose(got, np.reshape(sorted(want), (-1, 3))), (got, want)
        counts.append(len(want))
    assert counts[-1] == 0 and max(counts) > 0, "one trajectory inside the limits, others beyond them"


def test_lesson5_hands_in_the_step_response_numbers(graded):
    np = need("numpy")
    from snakekit.profile_planner import ProfilePlanner

    run = graded["05_simulation"]
    for (t, y, g), r in zip(run["cases"]["ex05_1_rise_time_test"], run["results"]["ex05_1_rise_time_test"]):
        p = (y - y[0]) / (g - y[0])
        assert value(r) == pytest.approx(t[np.argmax(p >= 0.9)] - t[np.argmax(p >= 0.1)], abs=1e-12)
        assert value(r) > 0
    over = [value(r) for r in run["results"]["ex05_2_overshoot_test"]]
    assert min(over) == 0.0 and max(over) > 1.0, "responses with and without overshoot"
    for (y, g, w), r in zip(run["cases"]["ex05_3_steady_state_error_test"], run["results"]["ex05_3_steady_state_error_test"]):
        assert value(r) == pytest.approx(g - np.mean(y[-w:]), abs=1e-12)
    for (d, pv, pa), r in zip(run["cases"]["ex05_4_profile_velocity_test"], run["results"]["ex05_4_profile_velocity_test"]):
        planner = ProfilePlanner([0.0] * 5, pv, pa)       # the firmware's profile: when does it come to rest?
        planner.set_goal(0.0, [d, 0, 0, 0, 0])
        lo, hi = 0.0, 60.0
        for _ in range(60):
            lo, hi = (lo, (lo + hi) / 2) if not planner.moving((lo + hi) / 2) else ((lo + hi) / 2, hi)
        assert value(r) == pytest.approx(hi, abs=1e-9), (d, pv, pa)


def test_lesson6_hands_in_sweeps_runs_and_lags(graded):
    np = need("numpy")
    import snakekit

    run = graded["06_coded_sweep"]
    for (n, f), r in zip(run["cases"]["ex06_1_sweep_times_test"], run["results"]["ex06_1_sweep_times_test"]):
        assert np.allclose(value(r), np.arange(n) / f, rtol=1e-12)
    for (t, k, a), r in zip(run["cases"]["ex06_2_sweep_positions_test"], run["results"]["ex06_2_sweep_positions_test"]):
        assert r["positions"].shape == (len(t), 5) and bool(r["last_row_exactly_home"])
        assert np.allclose(r["positions"][:-1, 2], a * np.sin(2 * np.pi * k * t[:-1] / t[-1]), atol=1e-12)
    cases, results = run["cases"]["ex06_3_task2_test"], run["results"]["ex06_3_task2_test"]
    assert isinstance(results[-1], str) and results[-1].startswith("LimitError: "), results[-1]
    assert abs(cases[-1][3]) > snakekit.SPEC.upper, "the last case is a sweep beyond the limits"
    for (n, f, k, a), r in zip(cases[:-1], results[:-1]):
        sweep = snakekit.side_sweep(points=n, rate=f, sweeps=k, amplitude=a)
        assert np.allclose(r["times"], sweep.times) and np.allclose(r["positions"], sweep.positions, atol=1e-12)
        with snakekit.make_robot("sim") as robot:
            again = robot.run(sweep)
        assert np.allclose(r["measured_positions"], again.measured.positions, atol=1e-6)   # the simulator repeats itself
        assert r["times"][-1] <= 20, "hidden runs stay short"
    for (n, f, k, a, joint), r in zip(run["cases"]["ex06_4_phase_lag_test"], run["results"]["ex06_4_phase_lag_test"]):
        with snakekit.make_robot("sim") as robot:
            rec = robot.run(snakekit.side_sweep(points=n, rate=f, sweeps=k, amplitude=a))
        t, m = rec.measured.times, rec.measured.positions[:, joint]
        inside = (t >= 0.5) & (t <= rec.commanded.times[-1])
        lags = np.arange(0, 0.5005, 0.001)
        best = lags[np.argmin([np.mean((m[inside] - np.interp(t[inside] - L, rec.commanded.times,
                                                               rec.commanded.positions[:, joint])) ** 2) for L in lags])]
        assert value(r) == pytest.approx(best, abs=0.002)


def test_lesson7_hands_in_ticks_moves_and_recoveries(graded):
    np = need("numpy")
    from snakekit import hardware

    run = graded["07_real_robot"]
    for (q,), r in zip(run["cases"]["ex07_1_ticks_test"], run["results"]["ex07_1_ticks_test"]):
        assert np.array_equal(r["ticks"], hardware.radians_to_ticks(q)) and bool(r["whole_numbers"])
    upper = 1.57
    for (start, target, margin), r in zip(run["cases"]["ex07_2_safe_move_test"], run["results"]["ex07_2_safe_move_test"]):
        if np.abs(target).max() > upper - margin:
            assert bool(r["refused"]) and bool(r["arm_still"]), (target, margin)
            continue
        assert not bool(r["refused"]) and int(r["moves"]) == 1
        assert float(r["duration"]) == pytest.approx(max(1.875 * np.abs(target - start).max() / 1.5, 0.2), abs=0.011)
        assert np.allclose(r["final"], target, atol=0.01)
    assert sum(bool(r["refused"]) for r in run["results"]["ex07_2_safe_move_test"]) == 2
    for (ids,), r in zip(run["cases"]["ex07_3_fault_test"], run["results"]["ex07_3_fault_test"]):
        assert r["rebooted"].tolist() == sorted(ids.tolist()) and bool(r["torque_on"]) and bool(r["errors_cleared"])


# --- the text agrees with the cells ---------------------------------------------------------------

# (lesson, what the text states, a pattern of what a cell prints, the text's number, how near it must be)
STATED = [
    ("04_trajectories", r"The quintic asks the highest peak speed, \$1\.875/T\$", r"quintic\s+peak ds/dt x T = ([\d.]+)", 1.875, 0.01),
    ("04_trajectories", r"against \$1\.5/T\$ for the cubic", r"cubic\s+peak ds/dt x T = ([\d.]+)", 1.5, 0.01),
    ("04_trajectories", r"and \$1\.333/T\$ for this trapezoid", r"trapezoidal\s+peak ds/dt x T = ([\d.]+)", 1.333, 0.01),
    ("04_trajectories", r"Three steps are too fast for joint 1", r"-> (\d+) too fast", 3, 0),
    ("05_simulation", r"ramps up for about 0\.13 s", r"95 % of its cruise after ([\d.]+) s", 0.13, 0.015),
    ("05_simulation", r"peaks at 1\.38 rad/s", r"peak ([\d.]+) rad/s", 1.38, 0.015),
    ("05_simulation", r"cruise at 1\.32 rad/s", r"cruise ([\d.]+) rad/s", 1.32, 0.015),
    ("05_simulation", r"about a quarter of a milliradian", r"steady-state error (-?[\d.]+) mrad", -0.25, 0.05),
    ("05_simulation", r"0\.71 s with Profile Velocity 62", r"Profile Velocity 62: .*predicted ([\d.]+) s", 0.71, 0.005),
    ("05_simulation", r"1\.37 s with 31", r"Profile Velocity 31: .*predicted ([\d.]+) s", 1.37, 0.005),
    ("05_simulation", r"gets there in about 0\.3 s", r"Profile Velocity  0: within 0.01 rad of the goal after ([\d.]+) s", 0.3, 0.06),
    ("06_coded_sweep", r"last at 49\.9 s|49\.9 s: 500 goals span 499 intervals", r"last at ([\d.]+) s", 49.9, 0),
    ("06_coded_sweep", r"around \*\*11 degrees\*\*", r"^\s+1\s+([\d.]+) deg", 11.0, 0.6),
    ("06_coded_sweep", r"once the 0\.16 s lag is taken out", r"^\s+1\s+[\d.]+ deg\s+(\d+) ms", 160, 5),
    ("06_coded_sweep", r"shrink to about 1 degree", r"^\s+1\s+[\d.]+ deg\s+\d+ ms\s+([\d.]+) deg", 1.0, 0.5),
    ("07_real_robot", r"3071: tick 3072 is 1\.5708 rad", r"position limits in ticks: \d+\.\.(\d+)", 3071, 0),
    # the bus runs in real time: on a loaded machine a goal may leave a cycle late, and the peak moves a little
    ("07_real_robot", r"peaks at about 0\.5 N m", r"largest load while moving home: ([\d.]+) N m", 0.5, 0.1),
    ("07_real_robot", r"almost 0 once the arm holds still", r"holding still at home: ([\d.]+) N m", 0.0, 0.06),
]


@pytest.mark.parametrize("lesson, stated, shown, number, near", STATED,
                         ids=[f"{s[0][:2]}-{s[1][:30]}" for s in STATED])
def test_the_text_states_what_the_cells_print(graded, lesson, stated, shown, number, near):
    nb = graded[lesson]["nb"]
    assert re.search(stated, markdown(nb)), f"{lesson}'s text should say {stated!r}"
    found = re.search(shown, printed(nb), re.M)
    assert found, f"{lesson} should print {shown!r}:\n{printed(nb)[-3000:]}"
    assert abs(float(found.group(1)) - number) <= near, (stated, found.group(0))


def test_the_bus_run_is_about_as_good_as_the_simulator_as_the_text_says(graded):
    """Lesson 7 says the bus run's tracking error is similar to the simulator's, a little larger."""
    np = need("numpy")
    out = printed(graded["07_real_robot"]["nb"])
    bus = np.array(re.search(r"tracking error, bus: \[([^\]]+)\]", out).group(1).split(), dtype=float)
    sim = np.array(re.search(r"tracking error, sim: \[([^\]]+)\]", out).group(1).split(), dtype=float)
    assert np.all(bus >= 0.8 * sim) and np.all(bus <= 2.0 * sim), (bus, sim)


# Each "predict, then run" question, and what the student version says after the cell that shows it.
ANSWERED = {
    "04_trajectories": ["The quintic asks the highest peak speed", "Three steps are too fast"],
    "05_simulation": ["The arm stops within about a quarter of a milliradian", "Almost twice as long"],
    "06_coded_sweep": ["49.9 s: 500 goals span 499 intervals", "The right shape, late"],
    "07_real_robot": ["3071: tick 3072 is 1.5708 rad", "Similar, and usually a little larger on the bus"],
}


@pytest.mark.parametrize("lesson", LESSONS)
def test_every_prediction_is_answered_after_the_cell_that_shows_it(lesson):
    cells = read(ROOT / "notebooks" / f"{lesson}.ipynb").cells
    questions = [i for i, c in enumerate(cells) if c.cell_type == "markdown" and "**Predict, then run.**" in c.source]
    assert len(questions) == len(ANSWERED[lesson])
    for i, answer in zip(questions, ANSWERED[lesson]):
        assert cells[i + 1].cell_type == "code", "the cell that shows it follows the question"
        later = [j for j in range(i + 2, len(cells)) if cells[j].cell_type == "markdown" and answer in cells[j].source]
        assert later, f"{lesson}: {answer!r} should come after the question at cell {i}"
        between = [c for c in cells[i + 1:later[0]] if c.metadata.get("nbgrader", {}).get("grade")]
        assert not between, "the answer comes before the next exercise's check"


@pytest.mark.parametrize("lesson", LESSONS)
def test_each_lesson_says_once_that_hidden_cases_exist(lesson):
    text = markdown(read(ROOT / "notebooks" / f"{lesson}.ipynb"))
    assert text.count("**Hidden cases.**") == 1
    assert "drawn anew for every grading" in text
