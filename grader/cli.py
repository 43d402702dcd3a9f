"""``snakekit grade ASSIGNMENT``: grade a class's submissions.

    snakekit grade 06_coded_sweep [--course course/] [--jobs N] [--timeout S] [--cell-timeout S] [--csv FILE]

Exit codes: 0 the batch completed (even if some submissions failed: see the CSV),
1 the grader itself failed, 2 bad arguments.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from snakekit.errors import SnakekitError

from .references import REFERENCES

COURSE = Path("course")


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse exits 2 too; keep one place that says so
        self.print_usage(sys.stderr)
        print(f"snakekit grade: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="snakekit grade", description="Grade every submission of an assignment: nbgrader's "
                "autograde in parallel sandboxes, scored against the reference runs, with feedback.")
    p.add_argument("assignment", help="assignment name, e.g. 06_coded_sweep")
    p.add_argument("--course", type=Path, default=COURSE, help="the nbgrader course folder (default: course/)")
    p.add_argument("--jobs", type=int, default=None, help="submissions graded at once (default: one per core)")
    p.add_argument("--timeout", type=float, default=120.0,
                   help="wall-clock limit of a whole notebook [s]: at its end the running cell is stopped and the "
                        "cells after it do not run (default: 120)")
    p.add_argument("--cell-timeout", type=float, default=None,
                   help="wall-clock limit of one cell [s]: that cell is interrupted and the notebook goes on "
                        "(default: the --timeout)")
    p.add_argument("--memory", type=int, default=4096, help="memory limit per process [MB] (default: 4096)")
    p.add_argument("--csv", type=Path, default=None, help="write the grades here (default: <course>/grades-<assignment>.csv)")
    p.add_argument("--references", type=Path, default=REFERENCES, help="reference runs folder (default: grader/references/)")
    p.add_argument("--student", action="append", default=None, help="grade only this student (repeatable)")
    return p


def main(argv: list[str] | None = None, out=None) -> int:
    out = out or sys.stdout
    args = build_parser().parse_args(argv)
    course = args.course
    problems = []
    if not course.is_dir():
        problems.append(f"no course folder {course} (give --course DIR, the folder with nbgrader_config.py)")
    elif not (course / "source" / args.assignment).is_dir() and not (course / "gradebook.db").exists():
        found = sorted(p.name for p in (course / "source").iterdir()) if (course / "source").is_dir() else []
        problems.append(f"no assignment '{args.assignment}' in {course}/source"
                        + (f"; available: {', '.join(found)}" if found else ""))
    if args.jobs is not None and args.jobs < 1:
        problems.append(f"--jobs must be at least 1, got {args.jobs}")
    if not args.timeout > 0:
        problems.append(f"--timeout must be > 0 s, got {args.timeout:g}")
    if args.cell_timeout is not None and not args.cell_timeout > 0:
        problems.append(f"--cell-timeout must be > 0 s, got {args.cell_timeout:g}")
    if args.memory < 256:
        problems.append(f"--memory must be at least 256 MB, got {args.memory}")
    csv_path = args.csv or course / f"grades-{args.assignment}.csv"
    if args.csv and not args.csv.resolve().parent.is_dir():
        problems.append(f"cannot write --csv {args.csv}: folder {args.csv.resolve().parent} does not exist")
    if problems:
        for p in problems:
            print(f"snakekit grade: {p}", file=sys.stderr)
        return 2
    from .batch import Grader, write_csv

    grader = Grader(course, args.assignment, jobs=args.jobs, timeout=args.timeout, references=args.references,
                    memory=args.memory << 20, cell_timeout=args.cell_timeout)
    students = grader.students()
    if args.student:
        missing = [s for s in args.student if s not in students]
        if missing:
            print(f"snakekit grade: no submission of {args.assignment} by {', '.join(missing)} in "
                  f"{course}/submitted", file=sys.stderr)
            return 2
        students = args.student
    if not students:
        print(f"snakekit grade: no submissions of {args.assignment} in {course}/submitted/<student>/"
              f"{args.assignment}/; nothing to grade", file=sys.stderr)
        write_csv([], csv_path)
        return 0
    try:
        results = grader.run(students)
    except SnakekitError as e:
        print(f"snakekit grade: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("snakekit grade: interrupted; grades written so far are in the gradebook", file=sys.stderr)
        return 130
    write_csv(results, csv_path)
    failed = [r for r in results if r.status != "graded"]
    width = max(len(r.student) for r in results)
    for r in results:
        print(f"{r.student:<{width}}  {r.score:6g} / {r.max_score:g}  {r.status}"
              + (f": {r.detail}" if r.detail and r.status != "graded" else ""), file=out)
    print(f"graded {len(results)} submission(s) of {args.assignment}, {len(failed)} with problems; "
          f"CSV: {csv_path}; feedback: {course / 'feedback'}/<student>/{args.assignment}/", file=out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
