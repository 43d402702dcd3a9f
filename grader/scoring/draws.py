"""Which hidden cases each student's attempt meets: drawn once per attempt, kept beside the gradebook.

A batch draws its hidden cases anew, so a case a student saw in one feedback is of no use for the
next submission. But the same submission must meet the same cases whenever it is graded again (a
regrade of the class, ``grade --student`` after a hand-set score): otherwise a grade no one touched
could change. So ``<course>/draws/<assignment>.json`` keeps, per student, the seed their attempt was
graded at and a hash of the notebooks of that attempt. Graded again, an unchanged attempt meets its
own seed's cases; a new attempt (other notebooks) gets the batch's fresh draw. ``--seed`` grades
every student at the seed given (and keeps it for them).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

__all__ = ["attempt", "groups", "keep", "load", "resubmitted", "ungraded_attempts"]

FOLDER = "draws"


def _path(course: Path, assignment: str) -> Path:
    return Path(course) / FOLDER / f"{assignment}.json"


def load(course: Path, assignment: str) -> dict[str, dict]:
    """student -> {"seed": int, "attempt": hash}; empty when none is kept (or the file is unreadable:
    every attempt then meets a fresh draw, as before this file existed)."""
    try:
        data = json.loads(_path(course, assignment).read_text())
    except (OSError, ValueError):
        return {}
    if not isinstance(data, dict):
        return {}
    return {s: v for s, v in data.items() if isinstance(v, dict) and isinstance(v.get("seed"), int)
            and isinstance(v.get("attempt"), str)}


def attempt(course: Path, assignment: str, student: str, notebooks: list[str]) -> str:
    """A hash of what the student handed in: the assignment's notebooks, byte for byte (a missing one
    counts as empty)."""
    h = hashlib.sha256()
    folder = Path(course) / "submitted" / student / assignment
    for name in sorted(notebooks):
        path = folder / f"{name}.ipynb"
        data = path.read_bytes() if path.is_file() and not path.is_symlink() else b""
        h.update(name.encode() + b"\0" + hashlib.sha256(data).digest())
    return h.hexdigest()


def groups(course: Path, assignment: str, students: list[str], notebooks: list[str],
           seed: int | None) -> list[tuple[int | None, list[str]]]:
    """The batches to grade ``students`` in: (seed, students), the kept seeds first (each an attempt
    graded before and unchanged), then the new attempts at ``None`` (a fresh draw). With ``seed``
    given, one batch at it."""
    if seed is not None:
        return [(seed, list(students))]
    kept = load(course, assignment)
    new = resubmitted(course, assignment, students, notebooks)
    by_seed: dict[int | None, list[str]] = {}
    for s in students:
        by_seed.setdefault(kept[s]["seed"] if s in kept and s not in new else None, []).append(s)
    return sorted(by_seed.items(), key=lambda kv: (kv[0] is None, kv[0] or 0))


def resubmitted(course: Path, assignment: str, students: list[str], notebooks: list[str]) -> set[str]:
    """The ``students`` graded before whose notebooks have changed since: a new attempt (a first hand-in is
    not one)."""
    kept = load(course, assignment)
    return {s for s in students if s in kept and kept[s]["attempt"] != attempt(course, assignment, s, notebooks)}


def keep(course: Path, assignment: str, seed: int, students: list[str], notebooks: list[str]) -> None:
    """Record that ``students``' current attempts were graded at ``seed`` (written whole or not at all)."""
    path = _path(course, assignment)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = load(course, assignment)
    for s in students:
        data[s] = {"seed": int(seed), "attempt": attempt(course, assignment, s, notebooks)}
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    os.replace(tmp, path)


def ungraded_attempts(course: Path, assignment: str, notebooks: list[str]) -> list[str]:
    """The students whose notebooks in ``submitted/`` changed since they were graded: collected again
    and not graded since, so the gradebook's score and their page are the earlier attempt's."""
    folder = Path(course) / "submitted"
    students = sorted(p.name for p in folder.iterdir() if (p / assignment).is_dir()) if folder.is_dir() else []
    return sorted(resubmitted(course, assignment, students, notebooks))
