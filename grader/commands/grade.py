"""``snakekit grade ASSIGNMENT``: grade a class's submissions.

    snakekit grade 06_coded_sweep [--course course/] [--jobs N] [--timeout S] [--cell-timeout S] [--csv FILE]
                                  [--student S]... [--regenerate]

Before anything runs, the release and the reference are compared with the source: when they
differ, nothing is graded (exit 2) and the command that fixes it is printed (``--regenerate``
runs it). The gradebook is backed up to ``<course>/backups/`` before the batch writes it.

Exit codes: 0 the batch completed (even if some submissions failed: see the CSV),
1 the grader itself failed, 2 bad arguments or a stale release/reference.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from snakekit.errors import SnakekitError

from grader.course.folder import default_course
from grader.files import CommandParser
from grader.scoring import references as recorded_references
from grader.scoring import draws



def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(prog="snakekit grade", description="Grade every submission of an assignment: nbgrader's "
                "autograde in parallel sandboxes, scored against the reference runs, with feedback.")
    p.add_argument("assignment", help="assignment name, e.g. 06_coded_sweep")
    p.add_argument("--course", type=Path, default=default_course(),
                   help="the nbgrader course folder (default: the current folder when it holds "
                        "nbgrader_config.py, else course/)")
    p.add_argument("--jobs", type=int, default=None, help="submissions graded at once (default: one more than the cores)")
    p.add_argument("--timeout", type=float, default=120.0,
                   help="wall-clock limit of a whole notebook [s]: at its end the running cell is stopped and the "
                        "cells after it do not run; a submission stopped by a clock runs once more from the start "
                        "and the timeout counts only if it comes again (default: 120)")
    p.add_argument("--cell-timeout", type=float, default=None,
                   help="wall-clock limit of one cell [s]: that cell is interrupted (the kernel lives on), it "
                        "costs only its exercise, and the cells after it still run and hand in (default: a third "
                        "of --timeout, 40 s at the default 120: the slowest cells of the course, on a loaded machine and "
                        "with their hidden cases, take about 15 s)")
    p.add_argument("--memory", type=int, default=4096, help="memory limit per process [MB] (default: 4096)")
    p.add_argument("--csv", type=Path, default=None, help="write the grades here (default: <course>/grades-<assignment>.csv)")
    p.add_argument("--references", type=Path, default=None,
                   help="reference runs folder (default: <course>/references/)")
    p.add_argument("--student", action="append", default=None,
                   help="grade only this student (repeatable); the other rows of the CSV are kept")
    p.add_argument("--seed", type=int, default=None, help="grade every student at the hidden cases of this seed "
                   "(printed when a batch starts; default: each attempt graded before and unchanged meets the cases "
                   "it met then, kept in <course>/draws/<assignment>.json, and a new attempt a fresh draw)")
    p.add_argument("--regenerate", action="store_true", help="if the release or the reference no longer matches "
                   "the source, regenerate them (nbgrader generate_assignment --force; grader.scoring.references) first")
    return p


def _refs_command(args, assignment: str) -> str:
    extra = ""
    if args.course.resolve() != recorded_references.COURSE.resolve():
        extra += f" --course {args.course}"
    if args.references.resolve() != recorded_references.course_references(args.course).resolve():
        extra += f" --out {args.references}"
    return f"python -m grader.scoring.references {assignment}{extra}"


def check_current(args, out) -> list[str]:
    """Problems (each with the command that fixes it) if the release, the gradebook or the
    reference no longer match ``source/<a>``; with ``--regenerate`` they are fixed instead."""
    from grader.course.folder import (backup_gradebook, extra_notebooks, gradebook, regenerate, release_differences,
                                      source_hash)
    from grader.scoring.references import Reference, record_reference

    course, a = args.course, args.assignment
    problems = []
    if not (course / "source" / a).is_dir():
        return problems  # graded from the gradebook alone: nothing to compare with
    known = False
    if (course / "gradebook.db").exists():
        with gradebook(course) as gb:
            known = any(x.name == a and x.notebooks for x in gb.assignments)
    extra = extra_notebooks(course, a) if known else []
    if extra:  # regenerating would release it: the stray copy is what to remove
        return [f"an extra notebook is in {course}/source/{a}/: {', '.join(extra)}; remove it (or move it out of "
                "source/) and run the command again"]
    diffs = release_differences(course, a) if known else []
    if diffs and args.regenerate:
        backup = backup_gradebook(course)
        collected = sorted(p.parent.name for p in (course / "submitted").glob(f"*/{a}") if p.is_dir())
        cells = next((d for d in diffs if d.startswith("the gradebook's cells")), None)
        if collected and cells:  # their test cells are the old release's: nbgrader's checksums tell the change
            print(f"snakekit grade: warning: {len(collected)} submission(s) of {a} were collected from the release "
                  f"before this one, whose test cells differ ({cells.split('(', 1)[1].split(')', 1)[0]}): grading "
                  "marks such a cell 'tests tampered'; to grade them as they were released, undo the change in "
                  f"{course}/source/{a} (the gradebook before it: {backup})", file=sys.stderr)
        print(f"snakekit grade: the release of {a} is stale ({diffs[0]}); running nbgrader generate_assignment "
              f"{a} --force", file=out)
        regenerate(course, a)
    elif diffs:
        problems.append(f"the release of {a} no longer matches {course}/source/{a}: " + "; ".join(diffs)
                        + f". Regenerate it: `cd {course} && nbgrader generate_assignment {a} --force` "
                        f"(then release it again on a hub), or run `snakekit grade {a} --regenerate`")
    ref = Reference.load(args.references / f"{a}.npz")
    changed = ref.source_changed(course)
    if changed and args.regenerate:
        print(f"snakekit grade: {course}/source/{a} or its cases changed since its reference was recorded; "
              "recording it again",
              file=out)
        record_reference(a, course).save(args.references / f"{a}.npz")
    elif changed:
        what = f"{course}/source/{a}" if ref.meta.get("source_hash") != source_hash(course, a) else \
            f"{course}/cases/{a}.py"
        problems.append(f"{what} changed since {args.references}/{a}.npz was recorded from it. "
                        f"Record it again: `{_refs_command(args, a)}`, or run `snakekit grade {a} --regenerate`")
    elif changed is None:
        print(f"snakekit grade: {args.references}/{a}.npz does not say which source it was recorded from; "
              f"`{_refs_command(args, a)} --check` tells whether it is current", file=sys.stderr)
    return problems


def _keep_draw(course: Path, assignment: str, batch, results: list, notebooks: list[str]) -> None:
    """Keep the seed each graded attempt met (:mod:`grader.scoring.draws`), so a regrade meets it again."""
    if batch.draw is not None and results:
        draws.keep(course, assignment, batch.draw.seed, [r.student for r in results], notebooks)


def interrupted(course: Path, assignment: str, results: list, students: list[str], csv_path: Path) -> int:
    """After a Ctrl-C: the CSV gets the students graded before it (as the gradebook has them), the
    others' rows stay as they were; says who is left and how to grade them. Exit code 130."""
    from grader.course.gradebook import class_rows, read_class_csv, write_csv
    from grader.files import excerpt, uninterrupted

    if results:
        with uninterrupted():
            write_csv(class_rows(course, assignment, results, read_class_csv(csv_path)), csv_path)
    done = {r.student for r in results}
    left = [s for s in students if s not in done]
    again = " ".join(f"--student {s}" for s in left[:20])
    print(f"snakekit grade: interrupted; {len(done)} submission(s) graded before it are in the gradebook and "
          f"{csv_path}, the other {len(left)} are as they were"
          + (f" (grade them: `snakekit grade {assignment}{'' if course == default_course() else f' --course {course}'} "
             f"{excerpt(again, 300, quote=False)}`"
             f"{' ...' if len(left) > 20 else ''})" if left else ""), file=sys.stderr)
    return 130


def main(argv: list[str] | None = None, out=None) -> int:
    out = out or sys.stdout
    args = build_parser().parse_args(argv)
    if os.environ.get("SNAKEKIT_GRADING_URL"):  # an instructor's or TA's server on the class's hub
        from grader.lms.hub_grading import grade_on_hub

        return grade_on_hub(args, out)
    course = args.course
    args.references = args.references or recorded_references.course_references(course)
    problems, known = [], course.is_dir()
    from grader.course.folder import check_assignment
    from grader.errors import CourseError
    from grader.files import check_output, excerpt, one_line

    if not course.is_dir():
        problems.append(f"no course folder {course} (give --course DIR, the folder with nbgrader_config.py)")
    else:
        try:
            check_assignment(course, args.assignment)
        except CourseError as e:
            problems.append(str(e))
            known = False  # then the references' advice would name an assignment that is not there
    if args.jobs is not None and args.jobs < 1:
        problems.append(f"--jobs must be at least 1, got {args.jobs}")
    if not args.timeout > 0:
        problems.append(f"--timeout must be > 0 s, got {args.timeout:g}")
    if args.cell_timeout is not None and not args.cell_timeout > 0:
        problems.append(f"--cell-timeout must be > 0 s, got {args.cell_timeout:g}")
    if args.memory < 256:
        problems.append(f"--memory must be at least 256 MB, got {args.memory}")
    if known and not args.references.is_dir():
        problems.append(f"no references folder {args.references}; give --references DIR, or record them with "
                        f"`{_refs_command(args, args.assignment)}`")
    elif known and not (args.references / f"{args.assignment}.npz").is_file():
        problems.append(f"no reference {args.references}/{args.assignment}.npz: every test cell would keep the "
                        f"kernel's own verdict. Record it: `{_refs_command(args, args.assignment)}`")
    csv_path = args.csv or course / f"grades-{args.assignment}.csv"
    if course.is_dir():
        try:
            check_output(csv_path, course, suffix=".csv", what="--csv", command="snakekit grade")
        except CourseError as e:
            problems.append(str(e))
    if problems:
        for p in problems:
            print(f"snakekit grade: {one_line(p)}", file=sys.stderr)
        return 2
    from grader.arm.keep import HOOKS
    from grader.batch import Grader
    from grader.course.gradebook import NO_TIME, class_rows, read_class_csv, write_csv
    from grader.course.folder import backup_gradebook
    from grader.feedback.notebook import LOAD_NOTE
    from grader.scoring.verdict import SECOND_RUN

    grader = Grader(course, args.assignment, jobs=args.jobs, timeout=args.timeout, references=args.references,
                    memory=args.memory << 20, cell_timeout=args.cell_timeout, seed=args.seed, hooks=HOOKS)
    students = grader.students()
    if args.student:
        missing = [s for s in args.student if s not in students]
        if missing:
            import difflib

            lower = {s.lower(): s for s in students}
            def shown(name):  # quoted when a space at either end would not be seen
                return excerpt(name, quote=name != name.strip())

            def suggestion(name):
                parts = [p.strip() for p in name.replace(";", ",").split(",") if p.strip()]
                if len(parts) > 1 and all(p in students for p in parts):   # names run together: one --student each
                    return f"did you mean {' '.join(f'--student {p}' for p in parts)}? (one --student per student)"
                near = difflib.get_close_matches(name.strip().lower(), list(lower), n=1, cutoff=0.6)
                return f"did you mean {lower[near[0]]}?" if near else None

            said = {m: suggestion(m) for m in missing}
            meant = "; ".join((f"{shown(m)}: " if len(missing) > 1 else "") + said[m] for m in missing if said[m])
            print(f"snakekit grade: no submission of {args.assignment} by {', '.join(shown(m) for m in missing)} in "
                  f"{course}/submitted" + (f" ({meant})" if meant else "")
                  + (f"; {len(students)} student(s) have one: {excerpt(', '.join(students), quote=False)}" if students
                     else "; no student has one yet") + "; nothing was graded: give each --student as its folder "
                  "in submitted/ names it", file=sys.stderr)
            return 2
        students = list(dict.fromkeys(args.student))   # a name given twice is graded once
        if len(students) < len(args.student):
            twice = sorted({s for s in args.student if args.student.count(s) > 1})
            print(f"snakekit grade: {', '.join(twice)} given more than once: graded once", file=sys.stderr)
    if not students:
        print(f"snakekit grade: no submissions of {args.assignment} in {course}/submitted/<student>/"
              f"{args.assignment}/; collect them first (`snakekit collect {args.assignment} --from DOWNLOAD` "
              f"or `nbgrader collect {args.assignment}`)", file=sys.stderr)
        return 2
    try:
        stale = check_current(args, out)
    except SnakekitError as e:
        print(f"snakekit grade: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"snakekit grade: interrupted before anything was graded; the gradebook and {csv_path} are as they "
              "were", file=sys.stderr)
        return 130
    if stale:
        for p in stale:
            print(f"snakekit grade: {p}", file=sys.stderr)
        print("snakekit grade: nothing was graded", file=sys.stderr)
        return 2
    try:  # the lab's settings, when the course has a lab for it: a bad value stops grading before the backup
        from grader.arm.keep import lab_case

        lab_case(course, args.assignment)
    except SnakekitError as e:
        print(f"snakekit grade: {one_line(e)}; nothing was graded", file=sys.stderr)
        return 2
    backup = backup_gradebook(course)
    # an attempt graded before and unchanged meets the cases it met then; a new attempt, a fresh draw
    notebooks = sorted(p.stem for p in (course / "source" / args.assignment).glob("*.ipynb"))
    results = []
    new = draws.resubmitted(course, args.assignment, students, notebooks)  # their hand-set scores are not carried
    try:
        for seed, group in draws.groups(course, args.assignment, students, notebooks, args.seed):
            batch = Grader(course, args.assignment, jobs=args.jobs, timeout=args.timeout, references=args.references,
                           memory=args.memory << 20, cell_timeout=args.cell_timeout, seed=seed, hooks=HOOKS,
                           new_attempts=new)
            try:
                done = batch.run(group)
            except KeyboardInterrupt as e:
                _keep_draw(course, args.assignment, batch, getattr(e, "results", []), notebooks)
                raise
            _keep_draw(course, args.assignment, batch, done, notebooks)
            results += done
    except SnakekitError as e:
        print(f"snakekit grade: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        return interrupted(course, args.assignment, results + getattr(e, "results", []), students, csv_path)
    rows = class_rows(course, args.assignment, results, read_class_csv(csv_path))
    write_csv(rows, csv_path)
    failed = [r for r in results if r.status != "graded"]
    width = max(len(r.student) for r in results)
    by_student = {r["student"]: r for r in rows}
    for r in results:
        row = by_student.get(r.student, {})
        late = f"  (late: {row['raw_score']} - {row['late_penalty']})" if float(row.get("late_penalty") or 0) else ""
        print(f"{r.student:<{width}}  {row.get('score', f'{r.score:g}'):>6} / {r.max_score:g}  {r.status}"
              + (f": {r.detail}" if r.detail and r.status != "graded" else "") + late, file=out)
    no_time = [r.student for r in results if by_student.get(r.student, {}).get("status") == NO_TIME]
    if no_time:
        course_opt = "" if course == default_course() else f" --course {course}"
        print(f"no submission time for the notebook of {len(no_time)} student(s): "
              f"{excerpt(', '.join(no_time), quote=False)} "
              f"(graded as on time, status '{NO_TIME}' in the CSV; the earlier attempt's time stays with it in "
              f"attempts/); give them theirs: `snakekit collect {args.assignment}{course_opt} --from ZIP --times "
              f"TIMES.csv`, then `snakekit grade {args.assignment}{course_opt} "
              f"{excerpt(' '.join(f'--student {s}' for s in no_time), 300, quote=False)}`", file=out)
    again = [r.student for r in results if r.status == "graded" and SECOND_RUN in r.detail]
    noted = [r.student for r in results if r.status == "graded" and LOAD_NOTE.search(r.detail)]
    if again or noted:
        print(f"{len(again)} graded on a second run" + (f" ({excerpt(', '.join(again), quote=False)})" if again else "")
              + (f", {len(noted)} with a note of the machine's load to grade again on a quiet machine "
                 f"({excerpt(', '.join(noted), quote=False)})" if noted else "") + ": the CSV's detail says why",
              file=out)
    print(f"graded {len(results)} submission(s) of {args.assignment}, {len(failed)} with problems; "
          f"CSV ({len(rows)} student(s)): {csv_path}; feedback: {course / 'feedback'}/<student>/{args.assignment}/"
          + (f"; gradebook backed up to {backup}" if backup else ""), file=out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
