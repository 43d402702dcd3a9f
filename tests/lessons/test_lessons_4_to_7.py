"""Lessons 04 to 07 as graded: every test cell hands in its results at the hidden cases, and they are right.

Each instructor notebook runs once, as the grader runs it: a small case server (the wire format
of :mod:`snakekit.handin`) answers its test cells with cases drawn from ``course/cases/<lesson>.py``.
Then:

* every graded cell handed in one result per case, and those results are right, checked against
  an independent computation (the library's own functions, the formulas of the lesson's text);
  where the instructor's function must raise (a sweep beyond the limits), it raised.

The numbers the lessons' text states, and the answers to their questions, are checked in
tests/lessons/test_lesson_text.py.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import socket
import struct
import sys
import tempfile
import threading
import warnings
import zlib
from pathlib import Path

import pytest

from tests.conftest import handin_faults, need, notebook_client

ROOT = Path(__file__).resolve().parents[2]
LESSONS = ["04_trajectories", "05_simulation", "06_coded_sweep", "07_real_robot"]
SEED = 2024


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


@pytest.fixture(scope="module", params=LESSONS)
def graded(request):
    """A lesson's instructor notebook run with drawn cases: its cells, its hand-ins, the cases. One
    lesson per fixture, so lesson 07 (on the emulated bus in real time) runs with the ``serial``
    tests and the others beside them."""
    nbformat = need("nbformat")
    need("nbclient")
    from snakekit.handin import decode_results

    lesson = request.param
    with tempfile.TemporaryDirectory(prefix="sk-") as tmp:   # short: a socket path has at most 107 bytes
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
            for attempt in (1, 2):  # once more after a busy machine's fault on the emulated bus, as the grader does
                nb = nbformat.read(work / f"{lesson}.ipynb", as_version=4)
                notebook_client(nb, timeout=300, kernel_name="python3",
                                resources={"metadata": {"path": str(work)}}).execute()
                faults = handin_faults(handin)
                if not faults or attempt == 2:
                    break
                warnings.warn(f"a busy machine's fault on the emulated bus in a hand-in, the notebook was run again: "
                              f"{faults[0]}", stacklevel=1)
                for p in handin.glob("*.npz"):
                    p.unlink()
                server.asked.clear()   # what the run graded asked for
        finally:
            for k, v in old.items():
                os.environ.pop(k) if v is None else os.environ.__setitem__(k, v)
            server.close()
        results = {p.stem: decode_results(p.read_bytes()) for p in handin.glob("*.npz")}
        return {"nb": nb, "cases": cases, "results": results, "asked": server.asked}


def value(result):
    """A handed-in result's single value (a dict with "value"), or the error's text."""
    return result if isinstance(result, str) else result["value"]


# --- hand-ins -----------------------------------------------------------------------------------


def test_every_graded_cell_hands_in_one_result_per_drawn_case(graded):
    run = graded
    test_cells = [c.metadata["nbgrader"]["grade_id"] for c in run["nb"].cells
                  if c.metadata.get("nbgrader", {}).get("grade")]
    assert sorted(run["cases"]) == sorted(test_cells), "one case function per graded cell"
    assert run["asked"] == test_cells, "each test cell asks for its cases once, in order"
    for gid in test_cells:
        assert len(run["results"][gid]) == len(run["cases"][gid]), gid


@pytest.mark.parametrize("graded", ["04_trajectories"], indirect=True)
def test_lesson4_hands_in_what_the_formulas_give(graded):
    np = need("numpy")
    from snakekit.trajectory import quintic_time_scaling

    run = graded
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


@pytest.mark.parametrize("graded", ["05_simulation"], indirect=True)
def test_lesson5_hands_in_the_step_response_numbers(graded):
    np = need("numpy")
    from snakekit.profile_planner import ProfilePlanner

    run = graded
    for (t, y, g), r in zip(run["cases"]["ex05_1_rise_time_test"], run["results"]["ex05_1_rise_time_test"]):
        p = (y - y[0]) / (g - y[0])
        assert value(r) == pytest.approx(t[np.argmax(p >= 0.9)] - t[np.argmax(p >= 0.1)], abs=1e-12)
        assert value(r) > 0
    over = [value(r) for r in run["results"]["ex05_2_overshoot_test"]]
    assert min(over) == 0.0 and max(over) > 1.0, "responses with and without overshoot"
    windows = []
    for (y, g, *w), r in zip(run["cases"]["ex05_3_steady_state_error_test"], run["results"]["ex05_3_steady_state_error_test"]):
        windows.append(w[0] if w else 10)                 # a case without a window: the text's default, 10
        assert value(r) == pytest.approx(g - np.mean(y[-windows[-1]:]), abs=1e-12)
    assert any(len(c) == 2 for c in run["cases"]["ex05_3_steady_state_error_test"]), "a case at the default window"
    for (d, pv, pa), r in zip(run["cases"]["ex05_4_profile_velocity_test"], run["results"]["ex05_4_profile_velocity_test"]):
        planner = ProfilePlanner([0.0] * 5, pv, pa)       # the firmware's profile: when does it come to rest?
        planner.set_goal(0.0, [d, 0, 0, 0, 0])
        lo, hi = 0.0, 60.0
        for _ in range(60):
            lo, hi = (lo, (lo + hi) / 2) if not planner.moving((lo + hi) / 2) else ((lo + hi) / 2, hi)
        assert value(r) == pytest.approx(hi, abs=1e-9), (d, pv, pa)


@pytest.mark.parametrize("graded", ["06_coded_sweep"], indirect=True)
def test_lesson6_hands_in_sweeps_runs_and_lags(graded):
    np = need("numpy")
    import snakekit

    run = graded
    for (n, f), r in zip(run["cases"]["ex06_1_sweep_times_test"], run["results"]["ex06_1_sweep_times_test"]):
        assert np.allclose(value(r), np.arange(n) / f, rtol=1e-12)
    for (t, k, a), r in zip(run["cases"]["ex06_2_sweep_positions_test"], run["results"]["ex06_2_sweep_positions_test"]):
        assert r["joint_goals"].shape == (len(t), 5) and bool(r["last_row_home"])
        assert np.allclose(r["joint_goals"][:-1, 2], a * np.sin(2 * np.pi * k * t[:-1] / t[-1]), atol=1e-12)
    cases, results = run["cases"]["ex06_3_task2_test"], run["results"]["ex06_3_task2_test"]
    assert cases[-1] == (), "the last case is Task 2 itself: task2_sweep() at its defaults"
    task2 = snakekit.side_sweep()
    assert np.allclose(results[-1]["times"], task2.times) and np.allclose(results[-1]["positions"], task2.positions,
                                                                          atol=1e-12)
    assert isinstance(results[-2], str) and results[-2].startswith("LimitError: "), results[-2]
    assert abs(cases[-2][3]) > snakekit.SPEC.upper, "the case before it is a sweep beyond the limits"
    for (n, f, k, a), r in zip(cases[:-2], results[:-2]):
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


@pytest.mark.parametrize("graded", ["07_real_robot"], indirect=True)
def test_lesson7_hands_in_ticks_moves_and_recoveries(graded):
    np = need("numpy")
    from snakekit import hardware

    run = graded
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
