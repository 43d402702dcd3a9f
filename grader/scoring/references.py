"""References: how the instructor solution's results are judged, recorded once per lesson version.

The expected results themselves are not stored: every grading batch draws its hidden cases anew
(:mod:`grader.scoring.cases`) and runs the instructor notebook ``<course>/source/<a>/<a>.ipynb`` at them
first (:func:`expected`). What ``<course>/references/<assignment>.npz`` keeps is how to judge them,
in a header ``__meta__`` (a JSON string): per exercise its kind (``values``, ``trajectory``,
``run``), the names its results carry, its tolerances and, for runs, the spread of repeated
recordings; and what it was recorded from (the kit version, a hash of the robot spec, of the
source's code cells, and of the cases module). Record them with ``python -m grader.scoring.references``
and check they are current with ``--check``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from snakekit.errors import FileFormatError, SnakekitError
from snakekit.model import SPEC, SnakeSpec
from grader.errors import InstructorReferenceError

from grader.scoring import compare
from grader.scoring.cases import Draw, cases_path, checked_tolerances, draw, execute
from grader.errors import CasesError
from grader.scoring.rules import RULES
from grader.scoring.score import DEFAULT_TOLERANCES, Expected, handed_in_function, kind_of, score_exercise
from grader.scoring.wording import wording

FORMAT = 2
GRADER = Path(__file__).resolve().parents[1]
COURSE = GRADER.parent / "course"


def course_references(course: Path) -> Path:
    """Where a course keeps its references: ``<course>/references/``, beside its cases (``<course>/cases/``)."""
    return Path(course) / "references"


#: The course's references (``course/references/``).
REFERENCES = course_references(COURSE)

#: One encoder tick of the MX-28 [rad]: 2 pi / 4096. Differences below it cannot be seen on
#: the real arm, so no tolerance on a measured angle is tighter than this.
TICK = 2 * np.pi / 4096

#: Per-exercise tolerances of the lessons whose cases module gives none of its own, by assignment
#: and grade id. A grade id's tolerances live in one place: here, or in its lesson's cases module
#: (``TOLERANCES``, course/cases/), never both (:func:`tolerances` refuses a grade id given twice).
OVERRIDES: dict[str, dict[str, dict]] = {
    # each as the lesson's hidden test judges it (its `tol`, absolute, plus 1e-9 relative)
    "05_simulation": {
        "ex05_2_overshoot_test": {"atol": 1e-9},            # percent
        "ex05_4_profile_velocity_test": {"atol": 1e-9},     # the firmware's profile, timed to 1e-12 s
    },
    "07_real_robot": {
        # the planned duration (goals on a 10 ms grid); the end within servo settling is the cases
        # module's atol
        "ex07_2_safe_move_test": {"duration": 0.011},
    },
}


def spec_hash(spec: SnakeSpec = SPEC) -> str:
    """A short hash of everything that defines the arm (a reference is only valid for it)."""
    return hashlib.sha256(repr(spec).encode()).hexdigest()[:16]


def kit_version() -> str:
    import snakekit

    return snakekit.__version__


def cases_hash(course: Path, assignment: str) -> str:
    """A hash of the assignment's cases module (what the hidden cases are drawn from)."""
    path = cases_path(course, assignment)
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16] if path.is_file() else ""


@dataclass(frozen=True)
class Reference:
    """How one assignment's exercises are judged (its header); see the module's docstring."""

    assignment: str
    meta: dict

    @property
    def exercises(self) -> dict:
        return self.meta["exercises"]

    def save(self, path) -> Path:
        path = Path(path)
        with open(path, "wb") as f:  # np.savez(path) would append .npz to other suffixes
            np.savez(f, __meta__=np.array(json.dumps(self.meta, indent=1, sort_keys=True)))
        return path

    @classmethod
    def load(cls, path) -> "Reference":
        path = Path(path)
        if not path.exists():
            raise InstructorReferenceError(f"no reference for this assignment: {path} does not exist. Record it with "
                                 f"`python -m grader.scoring.references {path.stem}`.")
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["__meta__"]))
        except (OSError, ValueError, KeyError, EOFError) as e:
            raise InstructorReferenceError(f"{path} is not a readable reference file ({e}); record it again with "
                                 f"`python -m grader.scoring.references {path.stem}`") from e
        if meta.get("format") != FORMAT:
            raise InstructorReferenceError(f"{path} has format {meta.get('format')}, this grader reads {FORMAT}; record it "
                                 f"again with `python -m grader.scoring.references {path.stem}`")
        return cls(meta["assignment"], meta)

    def source_changed(self, course: Path) -> bool | None:
        """Whether ``course/source/<a>`` or ``course/cases/<a>.py`` changed since the reference
        was recorded from them (None: the reference cannot tell; ``--check`` can)."""
        from grader.course.folder import source_hash

        recorded = self.meta.get("source_hash")
        if recorded is None:
            return None
        return recorded != source_hash(course, self.assignment) or \
            self.meta.get("cases_hash") != cases_hash(course, self.assignment)

    def check_current(self, spec: SnakeSpec = SPEC) -> None:
        """Refuse a reference recorded for another robot spec."""
        if self.meta["spec_hash"] != spec_hash(spec):
            raise InstructorReferenceError(f"the reference for {self.assignment} was recorded for another robot spec "
                                 f"(hash {self.meta['spec_hash']}, now {spec_hash(spec)}); record it again with "
                                 f"`python -m grader.scoring.references {self.assignment}`")


# --- the expected results of one batch ------------------------------------------------------


def expected(ref: Reference, batch: Draw, handins: dict[str, list], *, where: str = "the instructor notebook",
             sources: dict | None = None, signatures: dict | None = None) -> dict[str, Expected]:
    """The batch's expected results from the instructor's hand-ins at ``batch``'s cases.

    Raises :class:`InstructorReferenceError` (the batch cannot be graded) when the instructor solution did
    not hand in a result for every case, handed in what the reference does not describe, or does
    not score full marks against itself. ``sources``: the test cells' sources by grade id (the
    feedback names the function each hands in); ``signatures``: the parameters of the notebook's functions
    (:func:`grader.scoring.wording.signatures`: the feedback names each argument as the function does).
    """
    out = {}
    for gid, cases in batch.cases.items():
        ex = ref.exercises.get(gid)
        results = handins.get(gid)
        if ex is None:
            raise InstructorReferenceError(f"{batch.assignment}: the cases module draws cases for {gid}, which the "
                                 f"reference does not describe; record it again (`python -m grader.scoring.references "
                                 f"{batch.assignment}`)")
        if results is None or len(results) != len(cases):
            got = "nothing" if results is None else f"{len(results)} results"
            raise InstructorReferenceError(f"{where} handed in {got} for {gid}, which has {len(cases)} hidden cases "
                                 f"(seed {batch.seed}): its test cell must call ex.hand_in('{gid}', ...)")
        for k, r in enumerate(results):
            if isinstance(r, str) and r.startswith("returned"):
                raise InstructorReferenceError(f"{where}: {gid} {r} at hidden case {k} {_args(cases[k])} (seed {batch.seed})")
        if results and all(isinstance(r, str) for r in results):
            raise InstructorReferenceError(f"{where}: {gid} raised at every one of its {len(results)} hidden cases (seed "
                                 f"{batch.seed}), the first: {results[0]}; a solution that only raises grades "
                                 "nothing (is something the notebook needs missing on this machine?)")
        kind = kind_of(results)
        names = sorted(set().union(*(r for r in results if isinstance(r, dict))))
        if kind != ex["kind"] or (names and names != ex["outputs"]):
            raise InstructorReferenceError(f"{where}: {gid} handed in {kind} {names}, the reference describes {ex['kind']} "
                                 f"{ex['outputs']}; record it again (`python -m grader.scoring.references "
                                 f"{batch.assignment}`)")
        try:
            tol = checked_tolerances(ex["tolerances"], f"{batch.assignment}'s reference: {gid}")
        except CasesError as bad:
            raise InstructorReferenceError(f"{bad}; record it again (`python -m grader.scoring.references {batch.assignment}`)") from None
        source = (sources or {}).get(gid, "")
        handed = handed_in_function(gid, source)
        e = Expected(gid, kind, list(cases), results, tol, handed, wording(gid, source, handed, signatures) if source else None)
        own = score_exercise(gid, results, e, 1.0)
        if own.score < 1.0:
            raise InstructorReferenceError(f"{where}: {gid} scores {own.score:g} of 1 against itself at the cases of seed "
                                 f"{batch.seed} ({own.message}); fix the solution, the cases or the tolerance")
        out[gid] = e
    return out


def _args(args) -> str:
    from grader.scoring.cases import describe

    return "(" + ", ".join(describe(a, 40) for a in args) + ")"


# --- recording ------------------------------------------------------------------------------


def _spread(runs: list[list]) -> tuple[float, float]:
    """Largest and RMS difference [rad] of repeated runs' measured angles from the first."""
    from snakekit.trajectory import Trajectory

    emax, erms = 0.0, 0.0
    for k, first in enumerate(runs[0]):
        if not isinstance(first, dict):
            continue
        ref = Trajectory(first["measured_times"], first["measured_positions"])
        for other in runs[1:]:
            _, s, f = compare.align(Trajectory(other[k]["measured_times"], other[k]["measured_positions"]), ref)
            d = s - f
            emax = max(emax, float(np.abs(d).max()))
            erms = max(erms, float(np.sqrt((d ** 2).mean(axis=0)).max()))
    return emax, erms


def _same(a: list, b: list) -> bool:
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):
        if isinstance(x, str) or isinstance(y, str):
            if not (isinstance(x, str) and isinstance(y, str) and x.split(":")[0] == y.split(":")[0]):
                return False
        elif set(x) != set(y) or not all(x[n].shape == y[n].shape and np.array_equal(x[n], y[n], equal_nan=True)
                                         for n in x):
            return False
    return True


def tolerances(assignment: str, gid: str, kind: str, batch: Draw, runs: list[list]) -> dict:
    """An exercise's tolerances: the kind's default, the run's spread, then this module's OVERRIDES
    or the cases module's TOLERANCES (a key given in both is refused: :class:`CasesError`)."""
    if kind == "values":
        tol = dict(DEFAULT_TOLERANCES["values"])
    elif kind == "trajectory":
        tol = dict(DEFAULT_TOLERANCES["trajectory"])
    else:
        # Simulator-derived: the measured angles of the same solution, recorded `repeats` times,
        # differ by at most `spread` (0 when the simulator is deterministic on this machine).
        # Allow three times that, and never less than one encoder tick (2 pi/4096 = 1.53e-3 rad),
        # the smallest difference the real arm can show.
        emax, erms = _spread([r[gid] for r in runs])
        tol = {"max": max(3 * emax, TICK), "rms": max(3 * erms, TICK / 2), "commanded_max": 1e-6,
               "commanded_rms": 1e-6}
    here, there = OVERRIDES.get(assignment, {}).get(gid, {}), batch.settings.get(gid, {}).get("tolerances", {})
    twice = sorted(set(here) & set(there))
    if twice:
        raise CasesError(f"{assignment}: {gid}'s tolerance {', '.join(twice)} is given twice, in "
                         "grader.scoring.references.OVERRIDES and in the cases module's TOLERANCES; "
                         "keep it in the cases module (course/cases/) alone")
    tol.update(here)
    tol.update(there)
    return tol


def record_reference(assignment: str, course: Path = COURSE, *, repeats: int = 3, seed: int | None = None) -> Reference:
    """Execute the instructor solution ``repeats`` times at one draw of the cases; the reference
    describes its hand-ins (kinds, names, tolerances from the spread of its runs)."""
    from grader.course.folder import source_hash

    notebook = Path(course) / "source" / assignment / f"{assignment}.ipynb"
    if not notebook.exists():
        raise InstructorReferenceError(f"no instructor notebook {notebook}")
    try:
        batch = draw(course, assignment, seed)
        runs = [execute(notebook, batch) for _ in range(max(1, repeats))]
    except CasesError as e:
        raise InstructorReferenceError(str(e)) from e
    exercises = {}
    for gid in batch.cases:
        results = runs[0].get(gid)
        if results is None:
            raise InstructorReferenceError(f"{notebook} handed nothing in for {gid} (its test cell must call "
                                 f"ex.hand_in('{gid}', ...))")
        kind = kind_of(results)
        exercises[gid] = {"kind": kind, "outputs": sorted(set().union(*(r for r in results if isinstance(r, dict)))),
                          "tolerances": tolerances(assignment, gid, kind, batch, runs)}
        if kind == "values" and gid not in RULES:
            # a run on the simulator or the emulator may differ from run to run: within the
            # exercise's tolerance (each run scores full marks against the first), or it is refused
            e = Expected(gid, kind, list(batch.cases[gid]), results, exercises[gid]["tolerances"])
            for other in runs[1:]:
                if _same(results, other.get(gid, [])):
                    continue
                sc = score_exercise(gid, other.get(gid), e, 1.0)
                if sc.score < 1.0:
                    raise InstructorReferenceError(f"{gid}: the instructor's results differ between two runs at the same "
                                         f"cases (seed {batch.seed}) by more than the tolerance ({sc.message}); "
                                         "widen it (the cases module's TOLERANCES) or make the exercise repeatable")
                exercises[gid]["repeatable"] = False
        if kind == "run":
            emax, erms = _spread([r[gid] for r in runs])
            exercises[gid]["spread"] = {"max": emax, "rms": erms, "repeats": len(runs)}
    meta = {"format": FORMAT, "assignment": assignment, "kit_version": kit_version(), "spec_hash": spec_hash(),
            "recorded_from": f"source/{assignment}/{assignment}.ipynb", "source_hash": source_hash(course, assignment),
            "cases_hash": cases_hash(course, assignment), "exercises": exercises}
    ref = Reference(assignment, meta)
    for run in runs:  # every run scores full marks against itself, or a tolerance is wrong
        expected(ref, batch, run, where=str(notebook))
    return ref


def differences(old: Reference, new: Reference) -> list[str]:
    """What differs between two references: what they were recorded from, kinds, names, tolerances."""
    out = []
    for key in ("assignment", "kit_version", "spec_hash", "source_hash", "cases_hash"):
        if old.meta.get(key) != new.meta.get(key):
            out.append(f"{key}: {old.meta.get(key)} -> {new.meta.get(key)}")
    if set(old.exercises) != set(new.exercises):
        out.append(f"exercises: {sorted(old.exercises)} -> {sorted(new.exercises)}")
    for gid in sorted(set(old.exercises) & set(new.exercises)):
        a, b = old.exercises[gid], new.exercises[gid]
        for key in ("kind", "outputs"):
            if a.get(key) != b.get(key):
                out.append(f"{gid} {key}: {a.get(key)} -> {b.get(key)}")
        ta, tb = a.get("tolerances", {}), b.get("tolerances", {})
        for key in sorted(set(ta) | set(tb)):
            x, y = ta.get(key), tb.get(key)
            # a run's tolerance follows its measured spread: within a factor 2 is the same
            if x is None or y is None or not (y / 2 <= x <= 2 * y if x and y else x == y):
                out.append(f"{gid} tolerance {key}: {x} -> {y}")
    return out


def check_repeats(ref: Reference) -> int:
    """How many runs ``--check`` needs to record ``ref`` again: a run's tolerance follows the spread
    of repeated recordings (3 runs); a values or trajectory exercise's does not (1 run). Whether
    values come out the same run after run is checked when they are recorded.

    >>> check_repeats(Reference("a", {"exercises": {"x": {"kind": "values"}, "y": {"kind": "run"}}}))
    3
    >>> check_repeats(Reference("a", {"exercises": {"x": {"kind": "values"}}}))
    1
    """
    return 3 if any(e.get("kind") == "run" for e in ref.exercises.values()) else 1


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m grader.scoring.references",
                                description="Record the reference runs from the instructor notebooks.")
    p.add_argument("assignments", nargs="*", help="assignment names (default: every one with a reference)")
    p.add_argument("--course", type=Path, default=COURSE, help="the nbgrader course folder (default: course/)")
    p.add_argument("--out", type=Path, default=None, help="where references live (default: <course>/references/)")
    p.add_argument("--check", action="store_true", help="only check that the stored references are current")
    p.add_argument("--repeats", type=int, default=None,
                   help="runs of each instructor notebook (default: 3 when recording; with --check, 3 for a "
                        "reference with a run exercise and 1 for one of values and trajectories only, whose "
                        "tolerances do not depend on the repeats)")
    args = p.parse_args(argv)
    args.out = args.out or course_references(args.course)
    if args.repeats is not None and args.repeats < 1:
        print(f"--repeats must be at least 1, got {args.repeats}", file=sys.stderr)
        return 2
    names = args.assignments or sorted(f.stem for f in args.out.glob("*.npz"))
    if not names:
        print(f"no references in {args.out}; name the assignments to record", file=sys.stderr)
        return 2
    stale = 0
    try:
        for name in names:
            path = args.out / f"{name}.npz"
            if args.check:
                old = Reference.load(path)
                repeats = args.repeats or check_repeats(old)
                diff = differences(old, record_reference(name, args.course, repeats=repeats))
                if diff:
                    stale += 1
                    print(f"{path} is stale:\n  " + "\n  ".join(diff), file=sys.stderr)
                else:
                    print(f"{path} is current")
            else:
                new = record_reference(name, args.course, repeats=args.repeats or 3)
                args.out.mkdir(parents=True, exist_ok=True)
                new.save(path)
                print(f"wrote {path} ({len(new.exercises)} exercises: {', '.join(sorted(new.exercises))})")
    except (InstructorReferenceError, FileFormatError) as e:
        print(f"grader.scoring.references: {e}", file=sys.stderr)
        return 1
    if stale:
        print("regenerate with `python -m grader.scoring.references`", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
