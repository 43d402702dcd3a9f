"""Fairness as a property of every exercise, tested by mutation.

For each lesson, every single-slip variant of the instructor's answers (:mod:`grader.course.mutants`)
is typed into the lesson's student notebook (``notebooks/NN_*.ipynb``, generated from the source),
every other answer cell holding the instructor's answer, and handed in as one student. The lesson's
variants are graded in one batch by ``snakekit grade`` on a copy of the course, as a TA grades a
class (the command run in this process: the lessons' batches share one warm fork server); each exercise's loss is counted from its full points (every answer right earns them all:
``tests/lessons/test_course.py``). The graded notebook of each variant shows
what its visible checks said (the same cells ``snakekit check`` runs). Each variant must meet the
rules of grader/README.md ("Fairness, tested by mutation"):

- no other exercise loses points, except one that builds on it (``DEPENDS``), and that one at
  most half of its points; an endless loop or an exception costs no other exercise anything;
- when the visible check passes the variant, the graded cases pass it too, and such a variant is
  one of :data:`EQUIVALENT` (the same results at every input the exercise allows, with the reason).

``python -m grader.course.fairness [--all] [--seed N] [LESSON ...]`` prints the matrix (exercise x
operator -> points lost in its exercise, points lost elsewhere, local and graded verdicts) and the
rules broken, as Markdown; it exits 1 when a rule is broken. Without ``--all`` it grades
:data:`SAMPLE`, a few operators per exercise that together hold every operator and every exercise.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import runpy
import shutil
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from snakekit import cli

from grader.course.folder import course_copy_ignore
from grader.course.mutants import OPERATORS, Mutant, Skipped, exercises, variants
from grader.scoring.rerun import exercise

ROOT = Path(__file__).resolve().parents[2]
#: the operators that must cost their own exercise only, even one that builds on it
CONTAINED = ("endless_loop", "exception")
#: each notebook's time [s]; a cell gets a third (60 s): lesson 06's and 07's slowest cells take about 20 s with
#: their hidden cases on a loaded machine, and each endless loop costs the batch twice the cell's limit
TIMEOUT = 180.0
#: lesson 07 runs the arm's bus emulator in real time: on a loaded machine its instructor notebook needs longer.
#: Lesson 04's notebook runs in about 10 s on a loaded machine: 40 s holds it, and 4.1's endless loop (which 4.1's
#: check and 4.3's check each call) costs its batch 2 x 40 s, not 2 x 180 s
TIMEOUTS = {"07_real_robot": 360.0, "04_trajectories": 40.0}
#: One cell's limit where it is not a third of the notebook's: lesson 04's is half, so that 4.1's endless loop,
#: stopped in 4.1's check at the cell limit, uses up the notebook's time in 4.3's check, before 4.4's runs (4.3
#: and 4.4 are then graded in a second run with the lesson's own 4.1: an endless loop costs only its exercise)
CELL_TIMEOUTS = {"04_trajectories": 20.0}
#: Notebooks graded at once where it is not two (one per core): lesson 07's kernel waits on the emulated arm in
#: real time most of its wall clock (about a fifth of it is busy), so four at once take little more CPU than
#: two and halve its batches (8 students: 171 s with 2 at once, 102 s with 4, quiet machine)
JOBS = {"07_real_robot": 4}

#: Variants that give the same results as the instructor's answer at every input the exercise's
#: task allows, so neither the visible check nor the graded cases can (or should) refuse them:
#: (answer grade id, operator) -> why. (A list where the task asks an array is not one: it fails both ways alike,
#: tests/lessons/test_list_where_array.py.)
EQUIVALENT = {
    ("ex04_1_quintic", "transpose"): "s has the shape of t (a number or a 1-D array): .T leaves it as it is",
    ("ex04_1_quintic", "swap_args"): "np.clip(0, r, 1) is min(max(0, r), 1), which is np.clip(r, 0, 1)",
    ("ex04_2_trapezoid", "transpose"): "a 1-D pair [duration, peak speed]: .T leaves it as it is",
    ("ex04_3_sample_10hz", "list"): "np.asarray of a Trajectory is a 0-d object array, whose tolist() is the "
                                    "Trajectory itself",
    ("ex06_3_task2", "list"): "np.asarray of a Trajectory is a 0-d object array, whose tolist() is the Trajectory itself",
    ("ex01_1_planar_fk", "transpose"): "a 1-D pose (x, y, heading): .T leaves it as it is",
    ("ex06_1_sweep_times", "transpose"): "1-D send times: .T leaves them as they are",
    ("ex07_1_ticks", "transpose"): "the task's q is a vector of joint angles, so its ticks are 1-D: .T leaves them "
                                   "as they are",
    ("ex03_1_two_link_ik", "swap_args"): "np.clip(-1.0, c2, 1.0) is min(max(-1, c2), 1), which is np.clip(c2, -1, 1)",
}
#: exercises whose answer is one number: as a 0-d array (.T) or back from one (.tolist()) it is the same number
NUMBERS = ("ex00_1_tool_distance", "ex01_3_reach", "ex02_3_manipulability", "ex05_1_rise_time", "ex05_2_overshoot",
           "ex05_3_steady_state_error", "ex05_4_profile_velocity", "ex06_4_phase_lag")
EQUIVALENT.update({(gid, op): f"the answer is one number: {how}" for gid in NUMBERS for op, how in (
    ("transpose", "np.asarray(x).T is the same number, as a 0-d array"),
    ("list", "np.asarray(x).tolist() gives the same float back"))})

#: The operators graded in the suite, per answer cell: every exercise and every operator at least once. The one
#: endless loop is 4.1's, which 4.3 builds on (each endless loop costs its batch two cell limits, 2 x 60 s, per
#: cell it stops: the first run's and the run from scratch after it).
SAMPLE = {
    "ex00_1_tool_distance": ["scale_1000"],
    "ex01_1_planar_fk": ["degrees"],
    "ex01_2_joint_positions": ["transpose"],
    "ex01_3_reach": ["forbidden"],
    "ex02_1_planar_jacobian": ["cos_for_sin"],
    "ex02_2_numerical_jacobian": ["no_return"],
    "ex02_3_manipulability": ["no_clip"],
    "ex03_1_two_link_ik": ["swap_args"],
    "ex03_2_dls_step": ["sign"],
    "ex03_3_ik_loop": ["off_by_one"],
    "ex03_4_task1": ["exception"],
    "ex04_1_quintic": ["forbidden", "endless_loop"],
    "ex04_2_trapezoid": ["list"],
    "ex04_3_sample_10hz": ["off_by_one"],
    "ex04_4_limit_check": ["swap_args"],
    "ex05_1_rise_time": ["sign"],
    "ex05_2_overshoot": ["exception"],
    "ex05_3_steady_state_error": ["list"],
    "ex05_4_profile_velocity": ["degrees"],
    "ex06_1_sweep_times": ["off_by_one"],
    "ex06_2_sweep_positions": ["cos_for_sin"],
    "ex06_3_task2": ["swap_args"],
    "ex06_4_phase_lag": ["scale_1000"],
    "ex07_1_ticks": ["transpose"],
    "ex07_2_safe_move": ["no_return"],
    "ex07_3_fault": ["scale_1000"],
    "ex08_1_sweep_message": ["off_by_one"],
    "ex08_2_read_joint_states": ["sign"],
    "ex08_3_compare_runs": ["no_clip"],
}


@dataclass
class Row:
    """One variant's grade: points lost in its own exercise and in each other one, and both verdicts."""

    mutant: Mutant
    points: float                      # its exercise's points
    lost_own: float
    lost_elsewhere: dict               # exercise -> points lost there
    local: str                         # "pass" / "fail": its exercise's visible check, as the notebook ran
    status: str                        # the CSV's status for the variant
    broken: list = field(default_factory=list)

    @property
    def graded(self) -> str:
        return "full" if self.lost_own <= 1e-9 else "fail" if self.lost_own >= self.points - 1e-9 else "partial"


def _student(m: Mutant) -> str:
    return f"{m.grade_id.split('_')[0]}_{m.grade_id.split('_')[1]}_{m.operator}"


def notebook(lesson: str, answers: dict, replaced: dict | None = None):
    """The lesson's student notebook with ``answers`` (answer grade id -> source) typed in, then ``replaced``."""
    import nbformat

    nb = nbformat.read(ROOT / "notebooks" / f"{lesson}.ipynb", as_version=4)
    chosen = {**answers, **(replaced or {})}
    for c in nb.cells:
        gid = c.metadata.get("nbgrader", {}).get("grade_id")
        if gid in chosen and c.metadata.nbgrader.get("solution"):
            c.source = chosen[gid]
    return nb


def points(lesson: str) -> dict:
    """Points per exercise of ``lesson``, from its student notebook's graded cells."""
    import nbformat

    out = {}
    for c in nbformat.read(ROOT / "notebooks" / f"{lesson}.ipynb", as_version=4).cells:
        meta = c.metadata.get("nbgrader", {})
        if meta.get("grade") and meta.get("points"):
            out[exercise(meta["grade_id"])] = out.get(exercise(meta["grade_id"]), 0.0) + float(meta["points"])
    return out


def _local(course: Path, lesson: str, student: str) -> dict:
    """Exercise -> "pass"/"fail": whether its test cell ran without an error in the graded notebook."""
    import nbformat

    path = course / "autograded" / student / lesson / f"{lesson}.ipynb"
    if not path.exists():
        return {}
    out = {}
    for c in nbformat.read(path, as_version=4).cells:
        meta = c.metadata.get("nbgrader", {})
        if c.cell_type == "code" and meta.get("grade") and not meta.get("solution"):
            failed = any(o.get("output_type") == "error" for o in c.get("outputs", []))
            out[exercise(meta["grade_id"])] = "fail" if failed else "pass"
    return out


def grade_students(lesson: str, students: dict, tmp: Path, *, seed: int | None = None, jobs: int | None = None,
                   timeout: float | None = None, cell_timeout: float | None = None) -> tuple[Path, float, str]:
    """Grade one batch of ``lesson`` on a copy of the course in ``tmp``: ``students`` maps each student to the
    answers typed into the lesson's student notebook (answer grade id -> source; every other answer the
    instructor's). Returns the graded course folder, the batch's seconds and ``snakekit grade``'s stderr."""
    import nbformat

    course = tmp / "course"
    shutil.copytree(ROOT / "course", course, ignore=course_copy_ignore)
    right = {gid: answer for gid, answer, _ in exercises(ROOT / "course" / "source" / lesson / f"{lesson}.ipynb")}
    for name, replaced in students.items():
        folder = course / "submitted" / name / lesson
        folder.mkdir(parents=True)
        nbformat.write(notebook(lesson, right, replaced), folder / f"{lesson}.ipynb")
    timeout = timeout or TIMEOUTS.get(lesson, TIMEOUT)
    jobs = jobs or JOBS.get(lesson, 2)
    cell_timeout = cell_timeout or CELL_TIMEOUTS.get(lesson, timeout / 3)
    command = ["grade", lesson, "--course", str(course), "--jobs", str(jobs), "--timeout", f"{timeout:g}",
               "--cell-timeout", f"{cell_timeout:g}"]
    command += ["--seed", str(seed)] if seed is not None else []
    started = time.monotonic()
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    # the TA's command, in this process: the batches of one process share its warm fork server
    r = cli.run(command, cwd=ROOT, env=env)
    if r.returncode != 0:
        raise RuntimeError(f"snakekit grade {lesson} exited {r.returncode}:\n{r.stderr[-3000:]}")
    return course, time.monotonic() - started, r.stderr


def grade_lesson(lesson: str, mutants: list[Mutant], tmp: Path, *, seed: int | None = None, jobs: int | None = None,
                 timeout: float | None = None, cell_timeout: float | None = None) -> tuple[list[Row], dict]:
    """Grade ``mutants`` of ``lesson`` in one batch; the rows, and the batch's facts (seed, seconds)."""
    course, seconds, stderr = grade_students(lesson, variant_students(mutants), tmp, seed=seed, jobs=jobs,
                                             timeout=timeout, cell_timeout=cell_timeout)
    return rows_of(lesson, mutants, course, seconds, stderr, seed=seed)


def variant_students(mutants: list[Mutant]) -> dict:
    """Each variant as a student of its own (:func:`grade_students`'s ``students``): its answer typed in, every other
    answer the instructor's. Their names (``ex04_1_endless_loop``) are those of no other submission."""
    return {_student(m): {m.grade_id: m.source} for m in mutants}


def rows_of(lesson: str, mutants: list[Mutant], course: Path, seconds: float, stderr: str, *,
            seed: int | None = None) -> tuple[list[Row], dict]:
    """The rows of ``mutants`` graded in the batch that graded ``course`` (as :func:`variant_students`; other
    students may have been graded beside them), and the batch's facts (seed, seconds)."""
    from nbgrader.api import Gradebook

    with open(course / f"grades-{lesson}.csv", newline="") as f:
        status = {row["student"]: row["status"] for row in csv.DictReader(f)}
    scores = {}
    with Gradebook(f"sqlite:///{course / 'gradebook.db'}") as gb:
        for name in variant_students(mutants):
            per = {}
            for g in gb.find_submission_notebook(lesson, lesson, name).grades:
                per[exercise(g.name)] = per.get(exercise(g.name), 0.0) + float(g.score or 0.0)
            scores[name] = per
    pts = points(lesson)   # every answer right earns them (tests/lessons/test_course.py): a variant's loss is from full
    depends = runpy.run_path(str(course / "cases" / f"{lesson}.py")).get("DEPENDS", {})
    rows = []
    for m in mutants:
        name = _student(m)
        own = exercise(m.grade_id)
        lost = {ex: full - scores[name].get(ex, 0.0) for ex, full in pts.items()}
        row = Row(m, pts[own], lost.pop(own), {ex: v for ex, v in lost.items() if abs(v) > 1e-9},
                  _local(course, lesson, name).get(own, "not run"), status.get(name, "no row"))
        row.broken = rules(row, depends, pts)
        rows.append(row)
    drawn = re.search(r"drawn with seed (\d+)", stderr)
    facts = {"seconds": seconds, "variants": len(mutants), "full": pts, "seed": drawn.group(1) if drawn else seed}
    return rows, facts


def builds_on(depends: dict, test_id: str, answer_id: str) -> bool:
    return answer_id in depends.get(test_id, ())


def rules(row: Row, depends: dict, pts: dict) -> list[str]:
    """The fairness rules ``row`` breaks, one line each (empty: fair)."""
    m, out = row.mutant, []
    for ex, lost in row.lost_elsewhere.items():
        dependent = any(exercise(t) == ex and builds_on(depends, t, m.grade_id) for t in depends)
        allowed = 0.0 if m.operator in CONTAINED or not dependent else 0.5 * pts[ex]
        if lost > allowed + 1e-9:
            why = (f"it builds on {exercise(m.grade_id)} and may lose at most half ({allowed:g})" if dependent
                   and m.operator not in CONTAINED else "it does not build on it" if not dependent
                   else f"{m.operator.replace('_', ' ')} must cost only its own exercise")
            out.append(f"{ex} lost {lost:g} of {pts[ex]:g}: {why}")
    if row.local == "pass" and row.lost_own > 1e-9:
        out.append(f"the visible check passes it, graded it loses {row.lost_own:g} of {row.points:g}")
    if row.local == "pass" and row.lost_own <= 1e-9 and (m.grade_id, m.operator) not in EQUIVALENT:
        out.append("neither the visible check nor the graded cases refuse it, and it is not listed as equivalent")
    return out


def matrix(rows: list[Row], skipped: list[Skipped], facts: list[dict]) -> str:
    """The Markdown table of every variant and its totals."""
    lines = ["| exercise | operator | the slip | lost in its exercise | lost elsewhere | local check | graded | fair |",
             "|---|---|---|---:|---|---|---|---|"]
    for r in rows:
        elsewhere = ", ".join(f"{ex}: {v:g}" for ex, v in sorted(r.lost_elsewhere.items())) or "0"
        slip = r.mutant.where.replace("|", "\\|")
        slip = slip if len(slip) <= 70 else slip[:67] + "..."
        fair = "yes" if not r.broken else "**no**: " + "; ".join(r.broken)
        if not r.broken and (r.mutant.grade_id, r.mutant.operator) in EQUIVALENT:
            fair = "yes (equivalent)"
        lines.append(f"| {exercise(r.mutant.grade_id)} | {r.mutant.operator} | `{slip}` | {r.lost_own:g}/{r.points:g} | "
                     f"{elsewhere} | {r.local} | {r.graded} | {fair} |")
    lines += ["", totals(rows, skipped, facts)]
    return "\n".join(lines)


def totals(rows: list[Row], skipped: list[Skipped], facts: list[dict]) -> str:
    elsewhere = sum(1 for r in rows if any("lost" in b for b in r.broken))
    disagree = sum(1 for r in rows if r.local == "pass" and r.lost_own > 1e-9)
    undetected = sum(1 for r in rows if r.local == "pass" and r.lost_own <= 1e-9)
    stricter = sum(1 for r in rows if r.local == "fail" and r.lost_own <= 1e-9)
    seconds = sum(f["seconds"] for f in facts)
    return (f"Totals: {len(rows)} variants of {len({r.mutant.grade_id for r in rows})} exercises in {len(facts)} "
            f"batches ({seconds:.0f} s of grading), {len(skipped)} operator-exercise pairs where the operator does not "
            f"apply; {elsewhere} variants cost another exercise more than it may lose; {disagree} local-pass/graded-fail "
            f"disagreements; {undetected} variants neither refuses ({sum(1 for r in rows if not r.broken and r.local == 'pass')} "
            f"of them listed as equivalent); {stricter} the visible check refuses and the grader gives full marks.")


def lessons() -> list[str]:
    return sorted(p.name for p in (ROOT / "course" / "source").iterdir() if (p / f"{p.name}.ipynb").exists())


def run(names: list[str], *, everything: bool, seed: int | None, save: Path | None = None, out=sys.stdout) -> int:
    """Grade ``names``' variants, lesson by lesson; print the matrix. With ``save``, each lesson's
    rows are also written to ``save/<lesson>.json`` as soon as its batch ends (``--table`` reads them)."""
    rows, skipped, facts = [], [], []
    for lesson in names:
        made, missed = variants(ROOT / "course", lesson, None if everything else SAMPLE)
        with tempfile.TemporaryDirectory(prefix="snakekit-fairness-") as tmp:
            got, fact = grade_lesson(lesson, made, Path(tmp), seed=seed)
        print(f"{lesson}: {len(made)} variants graded in {fact['seconds']:.0f} s", file=sys.stderr, flush=True)
        if save is not None:
            save.mkdir(parents=True, exist_ok=True)
            (save / f"{lesson}.json").write_text(json.dumps(
                {"rows": [asdict(r) for r in got], "skipped": [asdict(k) for k in missed], "facts": fact}, indent=1))
        rows, skipped, facts = rows + got, skipped + missed, facts + [fact]
    print(matrix(rows, skipped, facts), file=out)
    return 1 if any(r.broken for r in rows) else 0


def read_saved(paths: list[Path]) -> tuple[list[Row], list[Skipped], list[dict]]:
    """The rows, skipped pairs and batches that ``--save`` wrote, each row judged by the rules as they are now."""
    rows, skipped, facts = [], [], []
    for path in paths:
        data = json.loads(Path(path).read_text())
        got = [Row(**{**r, "mutant": Mutant(**r["mutant"])}) for r in data["rows"]]
        for row in got:   # judged again by today's rules (EQUIVALENT may have grown since)
            depends = runpy.run_path(str(ROOT / "course" / "cases" / f"{row.mutant.lesson}.py")).get("DEPENDS", {})
            row.broken = rules(row, depends, data["facts"]["full"])
        rows += got
        skipped += [Skipped(**k) for k in data["skipped"]]
        facts.append(data["facts"])
    return rows, skipped, facts


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m grader.course.fairness", description=__doc__.split("\n\n")[0])
    p.add_argument("lessons", nargs="*", help="lessons to grade (default: all)")
    p.add_argument("--all", action="store_true", help=f"every operator on every exercise ({len(OPERATORS)} operators), "
                   "not the suite's sample")
    p.add_argument("--seed", type=int, default=None, help="the hidden cases' seed (default: drawn for each batch)")
    p.add_argument("--save", type=Path, default=None, help="also write each lesson's rows to DIR/<lesson>.json")
    p.add_argument("--table", type=Path, nargs="+", default=None, help="print the matrix of these saved lessons "
                   "(files --save wrote), grading nothing")
    args = p.parse_args(argv)
    if args.table:
        rows, skipped, facts = read_saved(args.table)
        print(matrix(rows, skipped, facts))
        return 1 if any(r.broken for r in rows) else 0
    unknown = sorted(set(args.lessons) - set(lessons()))
    if unknown:
        print(f"fairness: no lesson {', '.join(unknown)} (lessons: {', '.join(lessons())})", file=sys.stderr)
        return 2
    return run(args.lessons or lessons(), everything=args.all, seed=args.seed, save=args.save)


if __name__ == "__main__":
    sys.exit(main())
