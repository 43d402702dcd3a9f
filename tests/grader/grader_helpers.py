"""Helpers for the grader's tests: a copy of the test course, and submissions made from its release."""

from __future__ import annotations

import atexit
import json
import shutil
import tempfile
from pathlib import Path

import nbformat

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]
FIXTURE = HERE / "grader_course"
ASSIGNMENT = "t1_sweep"
REFERENCES = FIXTURE / "references"

#: The instructor's answers, as a student would type them.
GOOD = {
    "ex1_tool_xy": '''def tool_xy(q):
    phi = np.cumsum(q)
    lengths = np.array([0.071, 0.071, 0.071, 0.071, 0.0475])
    return np.array([np.sum(lengths * np.cos(phi)), np.sum(lengths * np.sin(phi))])''',
    "ex2_sweep": '''def my_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):
    t = np.arange(points) / rate
    angle = amplitude * np.sin(2 * np.pi * sweeps * t / t[-1])
    angle[-1] = 0.0
    return snakekit.Trajectory(t, np.repeat(angle[:, None], 5, axis=1))''',
    "ex3_peak_speed": "peak_speed = float(np.abs(my_sweep().finite_difference_velocities()).max())",
}


def snakekit(*args, cwd: Path = REPO, env: dict | None = None):
    """``snakekit ARGS`` as a TA types it in the folder ``cwd``, run in this test process (:func:`snakekit.cli.run`):
    the exit code, stdout and stderr a subprocess would give. A test process that grades several batches keeps one
    warm fork server for them, where each command's own process started and imported everything again and started
    a server of its own (about 4 CPU-s a batch, the server's imports 2.4 of them). The tests of
    what only a process of its own shows (Ctrl-C, the entry point, the TA's whole week) start one.
    """
    from snakekit.cli import run

    return run(args, cwd=cwd, env=env)


def lab_as_a_ta(*args, env: dict, cwd: Path = REPO, timeout: float = 600, tries: int = 3):
    """``snakekit lab ARGS`` in a process of its own, run again after a fault of the lab (exit code 1: a stall of
    this shared test machine in each of the run's tries, the Bus Watchdog), as the command's message tells a TA to
    do, at most ``tries`` times. The last run's ``CompletedProcess``."""
    import subprocess
    import sys

    for _ in range(tries):
        r = subprocess.run([sys.executable, "-m", "snakekit.cli", "lab", *map(str, args)], capture_output=True,
                           text=True, cwd=cwd, env=env, timeout=timeout)
        if r.returncode != 1:
            break
    return r


_released: Path | None = None


def make_course(tmp: Path) -> Path:
    """A fresh copy of the test course, released (``nbgrader generate_assignment``).

    The release is made once per test run (about 5 s of nbgrader) and copied for each caller: every
    course is the same released course, each its own copy to grade, break or write over.
    """
    global _released
    if _released is None:
        from grader.course.assignment import ensure_released

        cache = Path(tempfile.mkdtemp(prefix="snakekit-test-course-"))
        atexit.register(shutil.rmtree, cache, ignore_errors=True)
        shutil.copytree(FIXTURE, cache / "course", ignore=shutil.ignore_patterns("references", "__pycache__"))
        ensure_released(cache / "course", ASSIGNMENT)
        _released = cache / "course"
    course = tmp / "course"
    shutil.copytree(_released, course)
    return course


def use_safe_grading(course: Path, timeout: float) -> None:
    """The course's nbgrader config, as course/nbgrader_config.py does it, with the test course's references
    and ``timeout`` [s] for each notebook of formgrader's Autograde button."""
    with open(course / "nbgrader_config.py", "a") as f:
        f.write("\nfrom grader.commands.nbgrader_plugins import use_safe_grading\nuse_safe_grading(c)\n"
                f"c.SnakekitGrade.references = {str(REFERENCES)!r}\nc.SnakekitGrade.timeout = {timeout}\n")


def release_notebook(course: Path):
    return nbformat.read(course / "release" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)


def submit(course: Path, student: str, answers: dict | None = None, *, edit=None, raw: str | bytes | None = None,
           extra_files: dict | None = None) -> Path:
    """Write ``submitted/<student>/t1_sweep/t1_sweep.ipynb`` from the release notebook.

    ``answers`` replaces answer cells by grade id (default: the good ones, others from GOOD);
    ``edit(nb)`` may change the notebook further; ``raw`` writes these bytes instead.
    """
    folder = course / "submitted" / student / ASSIGNMENT
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{ASSIGNMENT}.ipynb"
    for name, content in (extra_files or {}).items():
        (folder / name).write_text(content)
    if raw is not None:
        path.write_bytes(raw.encode() if isinstance(raw, str) else raw)
        return path
    nb = release_notebook(course)
    chosen = {**GOOD, **(answers or {})}
    for cell in nb.cells:
        gid = cell.get("metadata", {}).get("nbgrader", {}).get("grade_id")
        if gid in chosen and cell.metadata.nbgrader.get("solution"):
            cell.source = chosen[gid]
    if edit is not None:
        edit(nb)
    nbformat.write(nb, path)
    return path


def good_notebook(course: Path, who: str) -> bytes:
    """The release notebook with the instructor's answers typed in (every test cell right), by ``who``."""
    nb = release_notebook(course)
    for cell in nb.cells:
        gid = cell.metadata.get("nbgrader", {}).get("grade_id")
        if gid in GOOD and cell.metadata.nbgrader.get("solution"):
            cell.source = GOOD[gid]
    nb.metadata["author"] = who
    return nbformat.writes(nb).encode()


def grade_ids(nb) -> list[str]:
    return [c.metadata.get("nbgrader", {}).get("grade_id") for c in nb.cells]


def read_csv(path: Path) -> dict[str, dict]:
    import csv

    with open(path) as f:
        return {row["student"]: row for row in csv.DictReader(f)}


def dump(obj) -> str:
    return json.dumps(obj, indent=1, default=str)


def box_title(notebook: Path, gid: str) -> str:
    """How a feedback page names the exercise of test cell ``gid`` of ``notebook`` (its lesson's words)."""
    from grader.scoring.wording import title

    nb = nbformat.read(notebook, as_version=4)
    source = next((c.source for c in nb.cells if c.get("metadata", {}).get("nbgrader", {}).get("grade_id") == gid), "")
    return title(gid, source)
