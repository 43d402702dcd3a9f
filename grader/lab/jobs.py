"""The lab's settings for an assignment, its jobs, and the queue kept between sessions.

The queue is ``<course>/lab/<assignment>/queue.json``, written atomically (a temporary file,
then ``os.replace``) after every change of state, so a session stopped at any moment leaves
it whole and the next start goes on from there.
"""

from __future__ import annotations

import csv
import json
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from snakekit.errors import ConfigurationError

#: The states a student sees (``snakekit lab --status``).
STATES = ("queued", "refused", "running", "graded", "lab fault")
#: The states a session runs (a job left ``running`` by a session that died runs again; a
#: ``lab fault`` one too, unless it faulted ``max_faults`` times: it is then left for the TA).
RUNNABLE = ("queued", "running", "lab fault")

#: The course's trajectory exercises the lab knows without a ``lab.json``: the grade id whose
#: hand-in is the trajectory, and the spec's own values (the study's Task 2).
DEFAULTS = {"06_coded_sweep": {"exercise": "ex06_3_task2_test",
                               "case": {"points": 500, "rate": 10.0, "sweeps": 50, "amplitude": 0.2}}}


class LabError(ConfigurationError):
    """Bad arguments or a course the lab cannot work on yet (exit 2: nothing moved)."""


@dataclass(frozen=True)
class LabSettings:
    """How the lab runs an assignment.

    Attributes:
        assignment: the assignment's name.
        exercise: the grade id whose hand-in is the trajectory.
        case: the spec's values of the sweep (``snakekit.side_sweep``'s arguments).
        max_duration_ratio: refuse a trajectory longer than this times the spec's.
        sim_tolerance: refuse a trajectory whose simulated run leaves the reference's by more [rad].
        band_factor: the bands are this times the calibration's spread (the most two runs differ)...
        band_floor: ...and at least this [rad].
        max_points: the lab grade's points.
        stall_delay: a run is made again when a goal left this much later than planned after the
            one before [s]: the arm waited on that one meanwhile, which changes the motion. Shorter
            delays, and the sum of many, are taken out by comparing on the sweep's own clock.
        max_faults: a job that ended in a fault of the lab this many times in a row is left for the
            TA (still ``lab fault``, not run again until ``snakekit lab A --retry STUDENT``).
    """

    assignment: str
    exercise: str
    case: dict
    max_duration_ratio: float = 1.5
    sim_tolerance: float = 0.1
    band_factor: float = 2.0
    band_floor: float = 0.01
    max_points: float = 1.0
    stall_delay: float = 0.05
    max_faults: int = 3

    def reference_trajectory(self):
        """The spec's trajectory: what every student's is run against."""
        import snakekit

        return snakekit.side_sweep(**self.case)


def lab_dir(course: Path, assignment: str) -> Path:
    return Path(course) / "lab" / assignment


def settings(course: Path, assignment: str) -> LabSettings:
    """The lab settings: ``<course>/lab/<a>/lab.json`` over :data:`DEFAULTS`.

    Raises:
        LabError: the assignment is unknown, or not one whose hand-in is a trajectory.
    """
    course = Path(course)
    known = sorted(p.name for p in (course / "source").iterdir() if p.is_dir()) if (course / "source").is_dir() else []
    if assignment not in known:
        raise LabError(f"unknown assignment '{assignment}': the course {course} has "
                       f"{', '.join(known) or 'no assignments in source/'}")
    values = dict(DEFAULTS.get(assignment, {}))
    path = lab_dir(course, assignment) / "lab.json"
    if path.is_file():
        try:
            values.update(json.loads(path.read_text()))
        except (OSError, ValueError) as e:
            raise LabError(f"{path} is not readable JSON ({e}); see docs/lab.md for its fields") from e
    if "exercise" not in values or "case" not in values:
        raise LabError(f"{assignment} has no exercise the lab runs (its hand-in is not a trajectory); name one in "
                       f"{path} as {{\"exercise\": GRADE_ID, \"case\": {{\"points\": ..., \"rate\": ..., "
                       "\"sweeps\": ..., \"amplitude\": ...}}")
    fields = set(LabSettings.__dataclass_fields__) - {"assignment"}
    unknown = sorted(set(values) - fields)
    if unknown:
        raise LabError(f"{path}: unknown field(s) {', '.join(unknown)}; known: {', '.join(sorted(fields))}")
    return LabSettings(assignment=assignment, **values)


def handin_path(course: Path, student: str, s: LabSettings) -> Path:
    """Where the grader keeps a student's trajectory at the spec's values (arrays only)."""
    return Path(course) / "autograded" / student / s.assignment / "lab" / f"{s.exercise}.npz"


def graded_students(course: Path, assignment: str) -> list[str]:
    root = Path(course) / "autograded"
    return sorted(p.name for p in root.iterdir() if (p / assignment).is_dir()) if root.is_dir() else []


def ordered(course: Path, assignment: str, students: list[str], order: str) -> list[str]:
    """``student``: by id; ``collected``: as ``collected/<a>.csv`` lists them, else by submission time."""
    if order == "student":
        return sorted(students)
    rank: dict[str, float] = {}
    from ..collect import read_manifest

    for k, listed in enumerate(read_manifest(course, assignment)):
        rank.setdefault(listed, k)
    for s in students:
        if s not in rank:
            stamp = Path(course) / "submitted" / s / assignment / "timestamp.txt"
            rank[s] = 1e12 + (stamp.stat().st_mtime if stamp.is_file() else 1e12)
    return sorted(students, key=lambda s: (rank[s], s))


def load_handin(path: Path) -> dict:
    """The hand-in's arrays, read with ``allow_pickle=False`` (never unpickled, never run)."""
    with np.load(path, allow_pickle=False) as z:
        return {k: np.array(z[k]) for k in z.files}


class Queue:
    """The jobs of one assignment, as saved in ``queue.json`` (one dict per student)."""

    def __init__(self, path: Path, assignment: str, jobs: list[dict] | None = None):
        self.path, self.assignment, self.jobs = Path(path), assignment, jobs or []

    @classmethod
    def load(cls, course: Path, assignment: str) -> "Queue":
        path = lab_dir(course, assignment) / "queue.json"
        if not path.is_file():
            return cls(path, assignment)
        try:
            data = json.loads(path.read_text())
        except ValueError as e:
            raise LabError(f"{path} is not the lab's queue ({e}); move it away to start a new queue") from e
        return cls(path, assignment, data["jobs"])

    @staticmethod
    def runnable(job: dict) -> bool:
        """Whether a session runs ``job``: queued, left running, or a lab fault not left for the TA."""
        return job["state"] in RUNNABLE and not job.get("held", False)

    def retry(self, student: str) -> dict:
        """Queue ``student``'s job again, whatever its state (the TA's ``--retry``); its count of faults starts anew."""
        job = self.job(student)
        if job is None:
            raise LabError(f"--retry {student}: {student} has no job in the lab's queue of {self.assignment}")
        self.set(job, "queued", "queued again by the TA", faults=0, held=False)
        return job

    def job(self, student: str) -> dict | None:
        return next((j for j in self.jobs if j["student"] == student), None)

    def add(self, student: str) -> dict:
        j = self.job(student)
        if j is None:
            j = {"student": student, "state": "queued", "reason": "", "attempts": 0, "updated": _now()}
            self.jobs.append(j)
        return j

    def set(self, job: dict, state: str, reason: str = "", **extra) -> None:
        assert state in STATES
        job.update(state=state, reason=reason, updated=_now(), **extra)
        self.save()

    def save(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(self.path, json.dumps({"assignment": self.assignment, "jobs": self.jobs}, indent=1))
        rows = [[j["student"], j["state"], j.get("points", ""), j["reason"], j["attempts"], j["updated"]]
                for j in self.jobs]
        write_atomic(self.path.with_name("status.csv"), _csv([["student", "state", "points", "reason", "attempts",
                                                               "updated"]] + rows))


def _csv(rows) -> str:
    import io

    buf = io.StringIO()
    csv.writer(buf).writerows(rows)
    return buf.getvalue()


def write_atomic(path: Path, text: str | bytes) -> None:
    """Write ``path`` whole or not at all (a temporary file in the same folder, then a rename)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(text.encode() if isinstance(text, str) else text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
