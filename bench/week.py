"""A TA's week on lesson 06, timed step by step: collect, grade, return, export.

The 60 submissions of ``bench/grading.py`` (good ones, hidden failures, stubs, broken ones)
are handed in as a Canvas download (``<name>_<user id>_<file id>_06_coded_sweep.ipynb``, a
roster mapping the Canvas ids), then each step is one ``snakekit`` command, as the TA types it:

    snakekit collect 06_coded_sweep --from download.zip
    snakekit grade 06_coded_sweep
    snakekit return 06_coded_sweep          (the Canvas feedback zip)
    snakekit export --lms canvas

Prints each step's wall time and the total.

    python bench/week.py [--submissions 60]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table  # noqa: E402
from grading import LESSON, REPO, fresh_course  # noqa: E402


def canvas_download(course: Path, tmp: Path) -> Path:
    """Move the generated submissions into a Canvas-style zip and a roster."""
    path = tmp / "download.zip"
    roster = ["student,name,canvas_id"]
    with zipfile.ZipFile(path, "w") as z:
        for i, folder in enumerate(sorted((course / "submitted").iterdir())):
            uid, student = 1000 + i, folder.name
            z.write(folder / LESSON / f"{LESSON}.ipynb", f"student{i:03d}_{uid}_{50000 + i}_{LESSON}.ipynb")
            roster.append(f"{student},Student {i:03d},{uid}")
            for f in sorted((folder / LESSON).iterdir()):
                f.unlink()
            (folder / LESSON).rmdir()
            folder.rmdir()
    (course / "roster.csv").write_text("\n".join(roster) + "\n")
    return path


def step(*args) -> float:
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", *map(str, args)], capture_output=True, text=True,
                       cwd=REPO)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"snakekit {args[0]} failed ({r.returncode}):\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}")
    return wall


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--submissions", type=int, default=60)
    args = p.parse_args(argv)
    os.environ.setdefault("MPLBACKEND", "Agg")
    with tempfile.TemporaryDirectory(prefix="snakekit-week-") as tmp:
        course = fresh_course(Path(tmp), args.submissions)
        download = canvas_download(course, Path(tmp))
        times = {
            "collect": step("collect", LESSON, "--course", course, "--from", download),
            "grade": step("grade", LESSON, "--course", course),
            "return": step("return", LESSON, "--course", course),
            "export": step("export", "--course", course, "--lms", "canvas"),
        }
    total = sum(times.values())
    n = args.submissions
    rows = [[f"snakekit {k}", f"{v:.1f}", f"{v / n:.3f}"] for k, v in times.items()]
    rows.append(["total", f"{total:.1f}", f"{total / n:.3f}"])
    print(f"a week of {LESSON}: {n} submissions from a Canvas download; {os.cpu_count()} cores (shared machine)")
    print(table(rows, ["step", "wall [s]", "s/submission"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
