"""Reference runs: what the instructor's solution hands in, recorded once, with tolerances.

A reference is ``grader/references/<assignment>.npz``: one array per handed-in value, keyed
``<grade_id>/<name>``, and a header ``__meta__`` (a JSON string) with the assignment, the kit
version, a hash of the robot spec and, per exercise, its kind, hidden inputs and tolerances.

The references are made by executing the instructor notebook ``<course>/source/<a>/<a>.ipynb``
with ``SNAKEKIT_HANDIN_DIR`` set: the same hand-in code the students' notebooks run. Regenerate
them with ``python -m grader.references`` and check they are current with ``--check``.

Kinds of exercise, recognised from the handed-in names:

* ``run``: a recorded run (``measured_times``, ``measured_positions`` ... as ``Run.save``
  writes them) and the commanded trajectory (``times``/``positions`` or ``commanded_*``);
* ``trajectory``: a trajectory (``times``, ``positions``);
* ``values``: a function's outputs at hidden inputs. Arrays named ``inputs`` or ``in_*`` are
  the hidden inputs, which a student's hand-in must repeat exactly; the rest are outputs.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from snakekit.errors import FileFormatError, SnakekitError
from snakekit.model import SPEC, SnakeSpec

from . import compare
from .exercises import RULES

FORMAT = 1
HERE = Path(__file__).resolve().parent
REFERENCES = HERE / "references"
COURSE = HERE.parent / "course"

#: One encoder tick of the MX-28 [rad]: 2 pi / 4096. Differences below it cannot be seen on
#: the real arm, so no tolerance on a measured angle is tighter than this.
TICK = 2 * np.pi / 4096

#: Exact math (COURSE.md): 1e-9 relative, and an absolute floor for values near 0.
EXACT = {"rtol": 1e-9, "atol": 1e-12}

#: Per-exercise overrides of the tolerances, by assignment and grade id (e.g. finite
#: differences: ``{"rtol": 1e-6, "atol": 1e-6}``).
OVERRIDES: dict[str, dict[str, dict]] = {
    # each as the lesson's hidden test judges it (its `tol`, absolute, plus 1e-9 relative)
    "00_meet_the_arm": {"ex00_1_tool_distance_test": {"atol": 1e-9}},                # mm
    "02_jacobian": {
        "ex02_2_numerical_jacobian_test": {"atol": 1e-6},   # finite differences
        "ex02_3_manipulability_test": {"atol": 1e-10},      # rounding of a determinant near 0
    },
    "03_inverse_kinematics": {
        "ex03_1_two_link_ik_test": {"atol": 1e-9},          # the tip on target, 1 nm
        "ex03_2_dls_step_test": {"atol": 1e-9},             # 1e-9 rad
        "ex03_3_ik_loop_test": {"atol": 1e-5},              # the solver stops within 1e-6 m
        "ex03_4_task1_test": {"atol": 0.003},               # the servo settles within a few mrad: 3 mm
    },
    "05_simulation": {
        "ex05_2_overshoot_test": {"atol": 1e-9},            # percent
        "ex05_4_profile_velocity_test": {"atol": 1e-9},     # the firmware's profile, timed to 1e-12 s
    },
    "07_real_robot": {
        "ex07_1_ticks_test": {"rtol": 0.0, "atol": 0.0},    # whole ticks
        # the planned duration (goals on a 10 ms grid) and the end within servo settling
        "ex07_2_safe_move_test": {"duration": 0.011, "atol": 0.01},
        "ex07_3_fault_test": {"rtol": 0.0, "atol": 0.0},    # servo ids
    },
    "06_coded_sweep": {
        # the lag is read off a flat RMS minimum: estimates 10 ms apart are the same lag (the
        # lesson's own check uses the same tolerance)
        "ex06_4_phase_lag_test": {"rtol": 0.0, "atol": 0.010},
    },
}

#: Task 2 of the study: what the coded sweep must be.
TASK2 = {"points": 500, "rate": 10.0, "sweeps": 50}


class ReferenceError(SnakekitError):
    """A reference file is missing, unreadable, stale, or could not be recorded."""


def spec_hash(spec: SnakeSpec = SPEC) -> str:
    """A short hash of everything that defines the arm (a reference is only valid for it)."""
    return hashlib.sha256(repr(spec).encode()).hexdigest()[:16]


def kit_version() -> str:
    import snakekit

    return snakekit.__version__


def is_input(name: str) -> bool:
    """Whether a handed-in array is a hidden input (``inputs`` or ``in_*``)."""
    return name == "inputs" or name.startswith("in_")


def kind_of(names) -> str:
    names = set(names)
    if {"measured_times", "measured_positions"} <= names:
        return "run"
    if {"times", "positions"} <= names:
        return "trajectory"
    return "values"


@dataclass(frozen=True)
class Reference:
    """The recorded hand-ins of one assignment's instructor solution, and how to compare."""

    assignment: str
    meta: dict
    arrays: dict = field(repr=False)  # grade_id -> {name: array}

    @property
    def exercises(self) -> dict:
        return self.meta["exercises"]

    def save(self, path) -> Path:
        path = Path(path)
        flat = {f"{gid}/{name}": a for gid, d in self.arrays.items() for name, a in d.items()}
        with open(path, "wb") as f:  # np.savez(path) would append .npz to other suffixes
            np.savez(f, __meta__=np.array(json.dumps(self.meta, indent=1, sort_keys=True)), **flat)
        return path

    @classmethod
    def load(cls, path) -> "Reference":
        path = Path(path)
        if not path.exists():
            raise ReferenceError(f"no reference for this assignment: {path} does not exist. Record it with "
                                 f"`python -m grader.references {path.stem}`.")
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["__meta__"]))
                arrays: dict = {}
                for key in z.files:
                    if key != "__meta__":
                        gid, name = key.split("/", 1)
                        arrays.setdefault(gid, {})[name] = z[key]
        except (OSError, ValueError, KeyError, EOFError) as e:
            raise ReferenceError(f"{path} is not a readable reference file ({e}); record it again with "
                                 f"`python -m grader.references {path.stem}`") from e
        if meta.get("format") != FORMAT:
            raise ReferenceError(f"{path} has format {meta.get('format')}, this grader reads {FORMAT}; record it again")
        return cls(meta["assignment"], meta, arrays)

    def source_changed(self, course: Path) -> bool | None:
        """Whether ``course/source/<a>`` changed since the reference was recorded from it (None:
        the reference predates this record and cannot tell; ``--check`` can)."""
        from .course import source_hash

        recorded = self.meta.get("source_hash")
        return None if recorded is None else recorded != source_hash(course, self.assignment)

    def check_current(self, spec: SnakeSpec = SPEC) -> None:
        """Refuse a reference recorded for another robot spec."""
        if self.meta["spec_hash"] != spec_hash(spec):
            raise ReferenceError(f"the reference for {self.assignment} was recorded for another robot spec "
                                 f"(hash {self.meta['spec_hash']}, now {spec_hash(spec)}); record it again with "
                                 f"`python -m grader.references {self.assignment}`")


# --- recording ------------------------------------------------------------------------------


@contextlib.contextmanager
def _env(**values):
    old = {k: os.environ.get(k) for k in values}
    os.environ.update(values)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def execute_for_handins(notebook: Path, *, timeout: int = 600) -> dict:
    """Execute ``notebook`` in a scratch copy of its folder; return its hand-ins by grade id."""
    import nbclient
    import nbformat

    with tempfile.TemporaryDirectory(prefix="snakekit-ref-") as tmp:
        work = Path(tmp) / "work"
        shutil.copytree(notebook.parent, work)
        handin = Path(tmp) / "handin"
        handin.mkdir()
        nb = nbformat.read(work / notebook.name, as_version=4)
        with _env(SNAKEKIT_HANDIN_DIR=str(handin), MPLBACKEND="Agg"):
            client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                             resources={"metadata": {"path": str(work)}})
            try:
                client.execute()
            except nbclient.exceptions.CellExecutionError as e:
                raise ReferenceError(f"the instructor notebook {notebook} failed, so no reference was "
                                     f"recorded:\n{str(e)[-2000:]}") from e
        out = {}
        for f in sorted(handin.glob("*.npz")):
            with np.load(f, allow_pickle=False) as z:
                out[f.stem] = {k: z[k] for k in z.files}
        return out


def _spread(runs: list[dict]) -> tuple[float, float]:
    """Largest and RMS difference [rad] of repeated runs' measured angles from the first."""
    from snakekit.trajectory import Trajectory

    first = Trajectory(runs[0]["measured_times"], runs[0]["measured_positions"])
    emax, erms = 0.0, 0.0
    for r in runs[1:]:
        _, s, f = compare.align(Trajectory(r["measured_times"], r["measured_positions"]), first)
        d = s - f
        emax = max(emax, float(np.abs(d).max()))
        erms = max(erms, float(np.sqrt((d ** 2).mean(axis=0)).max()))
    return emax, erms


def record(assignment: str, course: Path = COURSE, *, repeats: int = 3) -> Reference:
    """Execute the instructor solution ``repeats`` times and make the reference from its hand-ins."""
    notebook = Path(course) / "source" / assignment / f"{assignment}.ipynb"
    if not notebook.exists():
        raise ReferenceError(f"no instructor notebook {notebook}")
    runs = [execute_for_handins(notebook) for _ in range(max(1, repeats))]
    handins = runs[0]
    if not handins:
        raise ReferenceError(f"{notebook} handed nothing in (no snakekit.checks.hand_in call ran)")
    exercises = {}
    for gid, arrays in handins.items():
        kind = kind_of(arrays)
        ex: dict = {"kind": kind, "inputs": sorted(n for n in arrays if is_input(n)),
                    "outputs": sorted(n for n in arrays if not is_input(n))}
        if kind == "values":
            for other in runs[1:]:
                if gid in RULES:  # judged by a rule: a simulated or emulated move may vary
                    arrays_ = {n: a for n, a in arrays.items() if is_input(n)}
                else:
                    arrays_ = arrays
                for name, a in arrays_.items():
                    b = other.get(gid, {}).get(name)
                    if b is None or b.shape != a.shape or not np.array_equal(a, b, equal_nan=True):
                        raise ReferenceError(f"{gid}: '{name}' differs between two runs of the instructor "
                                             "notebook; seed the hidden inputs with snakekit.checks.rng")
            ex["tolerances"] = dict(EXACT)
        elif kind == "trajectory":
            # a trajectory is exact math: the same formula in another order differs by ~1e-15 rad
            ex["tolerances"] = {"max": 1e-6, "rms": 1e-6}
        else:
            emax, erms = _spread([r[gid] for r in runs])
            # Simulator-derived: the measured angles of the same solution, recorded `repeats`
            # times, differ by at most `spread_max` (0 when the simulator is deterministic on
            # this machine). Allow three times that, and never less than one encoder tick
            # (2 pi/4096 = 1.53e-3 rad), the smallest difference the real arm can show.
            ex["spread"] = {"max": emax, "rms": erms, "repeats": len(runs)}
            ex["tolerances"] = {"max": max(3 * emax, TICK), "rms": max(3 * erms, TICK / 2),
                                "commanded_max": 1e-6, "commanded_rms": 1e-6, **TASK2}
        ex["tolerances"].update(OVERRIDES.get(assignment, {}).get(gid, {}))
        exercises[gid] = ex
    ref = Reference(assignment, {"exercises": exercises}, handins)
    for gid in exercises:  # the instructor's own hand-in must earn full marks, or a tolerance is wrong
        from .score import score_exercise

        sc = score_exercise(gid, handins[gid], ref, 1.0)
        if sc.score < 1.0:
            raise ReferenceError(f"{gid}: the instructor solution scores {sc.score:g} of 1 against its own "
                                 f"reference ({sc.message}); fix the hand-in or the tolerance in OVERRIDES")
    from .course import source_hash

    meta = {"format": FORMAT, "assignment": assignment, "kit_version": kit_version(), "spec_hash": spec_hash(),
            "recorded_from": f"source/{assignment}/{assignment}.ipynb", "source_hash": source_hash(course, assignment),
            "exercises": exercises}
    return Reference(assignment, meta, handins)


def differences(old: Reference, new: Reference) -> list[str]:
    """What differs between two references, beyond each exercise's own tolerance."""
    out = []
    for key in ("assignment", "kit_version", "spec_hash"):
        if old.meta.get(key) != new.meta.get(key):
            out.append(f"{key}: {old.meta.get(key)} -> {new.meta.get(key)}")
    if set(old.exercises) != set(new.exercises):
        out.append(f"exercises: {sorted(old.exercises)} -> {sorted(new.exercises)}")
    for gid in sorted(set(old.exercises) & set(new.exercises)):
        a, b = old.exercises[gid], new.exercises[gid]
        for key in ("kind", "inputs", "outputs"):
            if a.get(key) != b.get(key):
                out.append(f"{gid} {key}: {a.get(key)} -> {b.get(key)}")
        tol = b.get("tolerances", {})
        atol = tol.get("max", tol.get("atol", 1e-12))
        rtol = tol.get("rtol", 0.0)
        for name in sorted(set(old.arrays.get(gid, {})) | set(new.arrays.get(gid, {}))):
            x, y = old.arrays.get(gid, {}).get(name), new.arrays.get(gid, {}).get(name)
            if x is None or y is None or x.shape != y.shape:
                out.append(f"{gid}/{name}: shape {None if x is None else x.shape} -> {None if y is None else y.shape}")
            elif x.dtype.kind in "fc" and not np.allclose(x, y, rtol=rtol, atol=atol, equal_nan=True):
                out.append(f"{gid}/{name}: values moved by up to {np.nanmax(np.abs(x - y)):.3g}")
            elif x.dtype.kind not in "fc" and not np.array_equal(x, y):
                out.append(f"{gid}/{name}: values changed")
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m grader.references",
                                description="Record the reference runs from the instructor notebooks.")
    p.add_argument("assignments", nargs="*", help="assignment names (default: every one with a reference)")
    p.add_argument("--course", type=Path, default=COURSE, help="the nbgrader course folder (default: course/)")
    p.add_argument("--out", type=Path, default=REFERENCES, help="where references live (default: grader/references/)")
    p.add_argument("--check", action="store_true", help="only check that the stored references are current")
    args = p.parse_args(argv)
    names = args.assignments or sorted(f.stem for f in args.out.glob("*.npz"))
    if not names:
        print(f"no references in {args.out}; name the assignments to record", file=sys.stderr)
        return 2
    stale = 0
    try:
        for name in names:
            new = record(name, args.course)
            path = args.out / f"{name}.npz"
            if args.check:
                diff = differences(Reference.load(path), new)
                if diff:
                    stale += 1
                    print(f"{path} is stale:\n  " + "\n  ".join(diff), file=sys.stderr)
                else:
                    print(f"{path} is current")
            else:
                args.out.mkdir(parents=True, exist_ok=True)
                new.save(path)
                print(f"wrote {path} ({len(new.exercises)} exercises: {', '.join(sorted(new.exercises))})")
    except (ReferenceError, FileFormatError) as e:
        print(f"grader.references: {e}", file=sys.stderr)
        return 1
    if stale:
        print("regenerate with `python -m grader.references`", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
