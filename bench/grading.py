"""Grading throughput: `snakekit grade` against plain serial `nbgrader autograde` and bare nbclient.

60 synthetic submissions of lesson 06 (good ones, ones that fail hidden tests, untouched
stubs, an exception at import, a kernel that exits, a notebook that is not JSON) are graded
three ways, side by side in one run:

* ``snakekit grade 06_coded_sweep`` (sandboxed, its default sandboxes at once, with feedback; the batch's hidden
  cases drawn and the instructor notebook run at them first, then every hand-in scored
  against it, case by case: all of it inside the time);
* ``nbgrader autograde 06_coded_sweep``, as nbgrader runs it: one submission at a time;
* bare nbclient: each notebook executed once as graded, serially and in parallel (one process
  per core, and as many processes as ``snakekit grade`` runs sandboxes), with nothing else:
  the faster of the parallel runs is the lower bound.

The last two get the same hidden cases on a case socket (``SNAKEKIT_CASES``), drawn once
outside the timing, so every notebook does the same hidden work in all three.

Targets (the grader issue): at least 2x plain nbgrader on 2 cores; within 1.5x of the bare
parallel bound. Prints medians over ``--repeats`` rounds; exits 1 if a target is missed.

    python bench/grading.py [--submissions 60] [--repeats 1]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import nbformat

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from grader.batch import default_jobs  # noqa: E402
from grader.scoring.cases import CaseServer, draw  # noqa: E402
from tests.conftest import copy_course  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
LESSON = "06_coded_sweep"


def _solutions():
    nb = nbformat.read(REPO / "course" / "source" / LESSON / f"{LESSON}.ipynb", as_version=4)
    return {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells if c.metadata.get("nbgrader", {}).get("solution")}


def make_submissions(course: Path, n: int) -> dict[str, str]:
    """``n`` submissions: 70 % right, then hidden failures, stubs and broken ones."""
    sol = _solutions()
    kinds = {
        "good": sol,
        "hidden_fail": {**sol, "ex06_1_sweep_times": "def sweep_times(points, rate):\n    return np.arange(points) / 10.0"},
        "stub": {},
        "import_error": {**sol, "ex06_1_sweep_times": "import no_such_module\n" + sol["ex06_1_sweep_times"]},
        "kernel_exit": {**sol, "ex06_3_task2": "import os\nos._exit(1)"},
        "not_json": None,
    }
    plan = (["good"] * 7 + ["hidden_fail", "stub", "import_error"]) * (n // 10) + ["kernel_exit", "not_json"]
    plan = plan[:n - 2] + ["kernel_exit", "not_json"]
    out = {}
    for i, kind in enumerate(plan):
        student = f"s{i:03d}_{kind}"
        folder = course / "submitted" / student / LESSON
        folder.mkdir(parents=True)
        if kinds[kind] is None:
            (folder / f"{LESSON}.ipynb").write_text('{"cells": [ broken')
        else:
            nb = nbformat.read(REPO / "notebooks" / f"{LESSON}.ipynb", as_version=4)
            for c in nb.cells:
                gid = c.metadata.get("nbgrader", {}).get("grade_id")
                if gid in kinds[kind]:
                    c.source = kinds[kind][gid]
            nbformat.write(nb, folder / f"{LESSON}.ipynb")
        out[student] = kind
    return out


def fresh_course(tmp: Path, n: int) -> Path:
    course = tmp / "course"
    copy_course(course)  # with its references: `snakekit grade` reads them from the course
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    subprocess.run([sys.executable, "-m", "nbgrader", "generate_assignment", LESSON, "--force"], cwd=course,
                   env=env, check=True, capture_output=True)
    make_submissions(course, n)
    return course


def time_snakekit(course: Path, jobs: int | None) -> float:
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "grade", LESSON, "--course", str(course),
                        *(["--jobs", str(jobs)] if jobs else [])], capture_output=True, text=True, cwd=REPO)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"snakekit grade failed:\n{r.stderr[-3000:]}")
    return dt


def serving_cases(course: Path):
    """The lesson's hidden cases on a socket, and the variables that point a kernel at it."""
    server = CaseServer(draw(course, LESSON))
    (course / "handin").mkdir(exist_ok=True)
    sock = server.listen(course / "cases.sock")
    return server, {"SNAKEKIT_CASES": sock, "SNAKEKIT_HANDIN_DIR": str(course / "handin")}


def time_nbgrader(course: Path) -> float:
    server, cases = serving_cases(course)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}", **cases}
    t0 = time.perf_counter()
    with server:
        subprocess.run([sys.executable, "-m", "nbgrader", "autograde", LESSON, "--create", "--force"], cwd=course,
                       env=env, capture_output=True, text=True)
    return time.perf_counter() - t0  # nbgrader exits 1 when some submission failed: expected here


def _test_cells() -> dict[str, str]:
    """The instructor's test cells by grade id: what autograde runs (their hidden tests, in a
    course that still has them)."""
    nb = nbformat.read(REPO / "course" / "source" / LESSON / f"{LESSON}.ipynb", as_version=4)
    return {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells
            if c.metadata.get("nbgrader", {}).get("grade") and not c.metadata["nbgrader"].get("solution")}


def _execute(path: str, tests: dict[str, str]) -> None:
    """Execute one submission as graded: its test cells as autograde restores them, the cases served."""
    import nbclient

    try:
        nb = nbformat.read(path, as_version=4)
    except Exception:  # noqa: BLE001 - the broken notebook: nothing to run
        return
    for c in nb.cells:
        gid = c.get("metadata", {}).get("nbgrader", {}).get("grade_id")
        if gid in tests:
            c.source = tests[gid]
    client = nbclient.NotebookClient(nb, timeout=120, kernel_name="python3", allow_errors=True,
                                     resources={"metadata": {"path": str(Path(path).parent)}},
                                     extra_arguments=["--IPKernelApp.log_level=ERROR"])  # no start-up warning per kernel
    try:
        client.execute()
    except Exception:  # noqa: BLE001 - a dead kernel ends that notebook
        pass


def time_bare(course: Path, jobs: int) -> float:
    paths = sorted(str(p) for p in (course / "submitted").glob(f"*/{LESSON}/{LESSON}.ipynb"))
    tests = _test_cells()
    server, cases = serving_cases(course)
    os.environ.update(cases)  # the kernels (and the pool's processes) inherit them
    t0 = time.perf_counter()
    try:
        with server:
            if jobs == 1:
                for p in paths:
                    _execute(p, tests)
            else:
                with ProcessPoolExecutor(jobs) as pool:
                    list(pool.map(_execute, paths, [tests] * len(paths)))
    finally:
        for k in cases:
            os.environ.pop(k, None)
    return time.perf_counter() - t0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--submissions", type=int, default=60)
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--jobs", type=int, default=None,
                   help="snakekit grade's sandboxes at once (default: its own, one more than the cores)")
    args = p.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    cores = os.cpu_count() or 1
    jobs = args.jobs or default_jobs()
    runs = {"snakekit": lambda c: time_snakekit(c, args.jobs), "nbgrader": time_nbgrader,
            "bare1": lambda c: time_bare(c, 1), "bareN": lambda c: time_bare(c, cores)}
    if jobs != cores:  # the bound with as many processes as snakekit grade's sandboxes, too: the lower counts
        runs["bareJ"] = lambda c: time_bare(c, jobs)
    times: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(args.repeats):
        for key, fn in runs.items():
            with tempfile.TemporaryDirectory(prefix="snakekit-bench-") as tmp:
                course = fresh_course(Path(tmp), args.submissions)
                times[key].append(fn(course))
    n = args.submissions
    med = {k: statistics.median(v) for k, v in times.items()}
    names = {"snakekit": f"snakekit grade ({jobs} sandboxes, sandboxed, scored, feedback)",
             "nbgrader": "nbgrader autograde (serial)", "bare1": "bare nbclient, serial",
             "bareN": f"bare nbclient, {cores} processes", "bareJ": f"bare nbclient, {jobs} processes"}
    rows = [[names[k], f"{med[k]:.1f}", f"{n / med[k] * 60:.1f}", f"{med[k] / n:.2f}"] for k in runs]
    bound = min((k for k in ("bareN", "bareJ") if k in med), key=med.get)  # the faster bare run
    print(f"{n} submissions of {LESSON}, {args.repeats} round(s), medians; {cores} cores")
    print(table(rows, ["method", "wall [s]", "submissions/min", "s/submission"]))
    speedup = med["nbgrader"] / med["snakekit"]
    vs_bound = med["snakekit"] / med[bound]
    vs_serial = med["snakekit"] / med["bare1"]
    print(f"\nspeed-up over plain nbgrader: {speedup:.2f}x (target >= 2x)")
    print(f"snakekit grade / bare parallel bound ({names[bound]}, the faster): {vs_bound:.2f}x (target <= 1.5x); "
          f"/ bare serial: {vs_serial:.2f}x")
    missed = [m for m, ok in (("speed-up over nbgrader", speedup >= 2), ("vs the bare bound", vs_bound <= 1.5)) if not ok]
    if missed:
        print("MISSED: " + ", ".join(missed))
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
