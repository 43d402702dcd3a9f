"""``snakekit report ASSIGNMENT``: the teacher's view of a graded class, as one offline page and CSVs.

    snakekit report 06_coded_sweep [--course DIR] [--out DIR] [--threshold 0.8]

Run after ``snakekit grade``. It reads the gradebook, the grader's verdicts in ``autograded/``, the
notebooks in ``submitted/`` and the trajectories kept for the lab; it writes ``report.html`` and a CSV
per table into ``--out`` (default: ``<course>/report-<assignment>/``, beside the grades CSV) and changes
nothing else: no grade, no page of a student's.

Exit codes: 0 written; 2 bad arguments or nothing to report yet (one line says what to do).
"""

from __future__ import annotations

import sys
import time
from itertools import combinations
from pathlib import Path

from grader.course.folder import default_course
from grader.files import CommandParser

__all__ = ["build_parser", "main", "build", "default_out"]


def build_parser() -> CommandParser:
    from grader.report.alike import THRESHOLD

    p = CommandParser(prog="snakekit report", description=(
        "The teacher's view of a graded class, in one offline page (report.html) and a CSV per table: per exercise "
        "the share of full, partial and zero marks, each kind of hidden case's pass rate, the totals, late and "
        "resubmitted counts; the most frequent mistakes per exercise (grouped by the hint that fired, else by the "
        "message without its numbers), those no hint recognised apart; and the pairs of submissions too alike to be "
        "chance (answer cells without the hand-out's and the solution's code; the same wrong trajectory). It flags; "
        "it never changes a grade. Run it after snakekit grade."))
    p.add_argument("assignment", help="assignment name, e.g. 06_coded_sweep")
    p.add_argument("--course", type=Path, default=default_course(),
                   help="the nbgrader course folder (default: the current folder when it holds nbgrader_config.py, "
                        "else course/)")
    p.add_argument("--out", type=Path, default=None,
                   help="the folder to write report.html and the CSVs into (default: <course>/report-<assignment>/, "
                        "beside the grades CSV); files of an earlier report there are replaced")
    p.add_argument("--threshold", type=float, default=THRESHOLD,
                   help=f"flag a pair whose answer cells are at least this alike, in (0, 1] (default: {THRESHOLD:g})")
    return p


def default_out(course: Path, assignment: str) -> Path:
    return Path(course) / f"report-{assignment}"


def _lab_case_right(cases: dict) -> set:
    """``(student, grade id)`` right in full at the case kept for the lab: Task 2 at its defaults, else the last case."""
    right = set()
    for key, kinds in cases.items():
        at = [f for k, f in kinds if k == "at its defaults"] or [f for _, f in kinds[-1:]]
        if at and at[0] >= 1 - 1e-6:
            right.add(key)
    return right


def build(course: Path, assignment: str, *, threshold: float):
    """``(standing, code pairs, trajectory pairs)`` of the class (see :mod:`grader.report`)."""
    from grader.report import alike
    from grader.report.standing import standing

    s = standing(course, assignment)
    answers, handout = alike.answer_cells(course, assignment)
    common = alike.common_limit(max(len(answers), len(s.totals)))
    code = alike.code_pairs(answers, handout, threshold=threshold, common=common)
    same = alike.trajectory_pairs(alike.kept_trajectories(course, assignment), _lab_case_right(s.cases), common=common)
    # the same wrong trajectory from the same mistake a hint named is that mistake's, not a copy: a
    # wrong formula gives the same numbers to everyone who writes it
    known = {frozenset(pair) for f in s.failures if f.hinted for pair in combinations(f.students, 2)}
    same = [p for p in same if frozenset((p.first, p.second)) not in known]
    return s, code, same


def _problem(args) -> str:
    """What stops the report before anything is read ("" if nothing)."""
    from grader.course.folder import check_assignment
    from grader.errors import CourseError

    course = args.course
    if not course.is_dir():
        return f"no course folder {course} (give --course DIR, the folder with nbgrader_config.py)"
    try:
        check_assignment(course, args.assignment)
    except CourseError as e:
        return str(e)
    if not 0 < args.threshold <= 1:
        return f"--threshold must be in (0, 1], got {args.threshold:g}"
    if args.out is not None:
        from grader.files import KEPT

        if args.out.exists() and not args.out.is_dir():
            return f"--out {args.out} is a file; give a folder (it is created if it does not exist)"
        inside = [name for name in KEPT if args.out.resolve().is_relative_to((course / name).resolve())]
        if inside or args.out.resolve() == course.resolve():
            where = f"inside {course}/{inside[0]}/ ({KEPT[inside[0]]})" if inside else "the course folder itself"
            return f"--out {args.out} is {where}; give a folder of its own (default: {default_out(course, args.assignment)})"
    if not any((course / "submitted").glob(f"*/{args.assignment}/*.ipynb")):
        return (f"the class of {args.assignment} is empty: no notebook in {course}/submitted/*/{args.assignment}/; "
                f"collect the submissions first (snakekit collect {args.assignment} --from DOWNLOAD)")
    return ""


def main(argv: list[str] | None = None, out=None) -> int:
    from grader.errors import CourseError
    from grader.files import one_line
    from grader.report.page import PAGE, write_report

    out = out or sys.stdout
    args = build_parser().parse_args(argv)
    problem = _problem(args)
    if problem:
        print(f"snakekit report: {one_line(problem)}", file=sys.stderr)
        return 2
    started = time.monotonic()
    try:
        s, code, same = build(args.course, args.assignment, threshold=args.threshold)
    except CourseError as e:
        print(f"snakekit report: {one_line(str(e))}", file=sys.stderr)
        return 2
    folder = args.out or default_out(args.course, args.assignment)
    write_report(folder, s, code, same, args.threshold)
    print(f"snakekit report: {len(s.totals)} submissions of {args.assignment}: {folder / PAGE} and a CSV per table "
          f"in {folder} ({len(code)} pairs of answers and {len(same)} of trajectories flagged, to read; no grade "
          f"changed; {time.monotonic() - started:.1f} s)", file=out)
    return 0
