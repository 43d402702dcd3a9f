"""`snakekit report` on a class of 500 submissions of lesson 06, and how its time grows with the class.

The class is made from the hand-written lesson 06 class of ``tests/grader/class_submissions/``,
graded once by ``snakekit grade`` (or ``--graded COURSE``, a course folder where it was graded): each
new submission is one of them copied with slips and renames (its answer cells' names changed, a
number of one cell changed, a comment added), with its grades in the gradebook (nbgrader's API), its
verdicts in ``autograded/`` and its kept trajectory (moved by float noise in some); so nothing is
graded again, and the report reads as many notebooks, verdicts and trajectories as a real class's.

Target (issue 34): 500 submissions in under 60 s on 2 cores, the similarity screen included. Prints
the time of ``snakekit report`` (the whole command, a process of its own) for each class size;
exits 1 if the largest is over the target. Not part of the test suite.

    python bench/report.py [--sizes 125 250 500] [--graded COURSE]
"""

from __future__ import annotations

import argparse
import os
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import nbformat
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests" / "grader"))
LESSON = "06_coded_sweep"
TARGET = 60.0  # [s] for 500 submissions on 2 cores
#: names the copies rename, each to another name of the same length class (a copy hides its source)
RENAMES = {"times": "stamps", "positions": "goals", "rate": "hz", "t": "tt", "q": "qq", "dt": "step", "traj": "plan"}


def grade_class(tmp: Path) -> Path:
    from test_class_grades import grade_class as grade

    result = grade(LESSON, tmp)
    print(f"graded the lesson 06 class ({len(result['rows'])} submissions) in {result['seconds']:.0f} s", flush=True)
    return Path(result["course"])


def _renamed(source: str, rng: random.Random) -> str:
    out = source
    for old, new in RENAMES.items():
        if rng.random() < 0.5:
            out = re.sub(rf"\b{old}\b", new, out)
    if rng.random() < 0.3:   # a slip: one number changed
        out = re.sub(r"\b2\b", "3", out, count=1)
    return out + f"\n# {rng.randrange(10**6)}\n"


def synthesise(graded: Path, dest: Path, size: int, seed: int = 1) -> Path:
    """A course of ``size`` submissions copied from the graded class in ``graded`` (see the module)."""
    from nbgrader.api import Gradebook

    rng = random.Random(seed)
    shutil.copytree(graded, dest, ignore=shutil.ignore_patterns("submitted", "autograded", "feedback", "backups",
                                                                "gradebook.db", "report-*"))
    shutil.copy2(graded / "gradebook.db", dest / "gradebook.db")
    with Gradebook(f"sqlite:///{graded / 'gradebook.db'}") as gb:
        base = {}
        for sub in gb.find_assignment(LESSON).submissions:
            base[sub.student.id] = {(nb.name, g.name): g.auto_score for nb in sub.notebooks for g in nb.grades}
    names = sorted(base)
    with Gradebook(f"sqlite:///{dest / 'gradebook.db'}") as gb:
        for k in range(size - len(names)):
            source = names[k % len(names)]
            student = f"s{k:04d}"
            nb = nbformat.read(graded / "submitted" / source / LESSON / f"{LESSON}.ipynb", as_version=4)
            for cell in nb.cells:
                meta = cell.metadata.get("nbgrader", {})
                if meta.get("solution") and not meta.get("grade"):
                    cell.source = _renamed(cell.source, rng)
            folder = dest / "submitted" / student / LESSON
            folder.mkdir(parents=True)
            nbformat.write(nb, folder / f"{LESSON}.ipynb")
            shutil.copytree(graded / "autograded" / source / LESSON, dest / "autograded" / student / LESSON)
            for kept in (dest / "autograded" / student / LESSON / "lab").glob("*.npz"):
                if rng.random() < 0.5:   # float noise, as another machine's last digit
                    with np.load(kept) as z:
                        arrays = {n: z[n] + 1e-13 * rng.random() for n in z.files}
                    np.savez(kept, **arrays)
            gb.update_or_create_student(student)
            sub = gb.add_submission(LESSON, student)
            for nbsub in sub.notebooks:
                for g in nbsub.grades:
                    g.auto_score = base[source].get((nbsub.name, g.name))
            gb.db.commit()
    for source in names:
        shutil.copytree(graded / "submitted" / source, dest / "submitted" / source)
        if (graded / "autograded" / source).is_dir():
            shutil.copytree(graded / "autograded" / source, dest / "autograded" / source)
    return dest


def time_report(course: Path) -> tuple[float, str]:
    started = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "report", LESSON, "--course", str(course)],
                       capture_output=True, text=True, timeout=1800, cwd=REPO)
    seconds = time.monotonic() - started
    if r.returncode != 0:
        raise SystemExit(f"snakekit report failed ({r.returncode}): {r.stderr[-2000:]}")
    return seconds, r.stdout.strip()


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[125, 250, 500])
    p.add_argument("--graded", type=Path, default=None, help="a course folder where the lesson 06 class was graded")
    args = p.parse_args(argv)
    os.environ.setdefault("PATH", "")
    with tempfile.TemporaryDirectory() as tmp:
        graded = args.graded or grade_class(Path(tmp) / "graded")
        rows = []
        for size in args.sizes:
            course = synthesise(graded, Path(tmp) / f"class{size}" / "course", size)
            seconds, said = time_report(course)
            rows.append((size, seconds))
            print(f"{size} submissions: snakekit report in {seconds:.1f} s ({seconds / size * 1000:.0f} ms each)\n  {said}",
                  flush=True)
            shutil.rmtree(course.parent)
    print("\n| submissions | seconds | per submission [ms] | vs the first size |\n|---|---|---|---|")
    for size, seconds in rows:
        print(f"| {size} | {seconds:.1f} | {seconds / size * 1000:.0f} | {seconds / rows[0][1]:.2f}x |")
    largest = rows[-1]
    ok = largest[0] < 500 or largest[1] < TARGET
    print(f"\n{largest[0]} submissions in {largest[1]:.1f} s: target {TARGET:g} s for 500 {'met' if ok else 'MISSED'} "
          f"(load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} cores)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
