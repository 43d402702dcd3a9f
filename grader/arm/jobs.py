"""The lab's settings for an assignment, its jobs, and the queue kept between sessions.

The queue is ``<course>/lab/<assignment>/queue.json``, written atomically (a temporary file,
then ``os.replace``) after every change of state, so a session stopped at any moment leaves
it whole and the next start goes on from there; each change is a read-modify-write under the
queue's own lock, so no copy of it writes another's job away.
"""

from __future__ import annotations

import csv
import json
import os
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from snakekit import validate
from snakekit.errors import ConfigurationError, FileFormatError, SnakekitError
from grader.errors import LabError, NoLab

#: The states a student sees (``snakekit lab --status``).
STATES = ("queued", "refused", "running", "graded", "lab fault")
#: The states a session runs (a job left ``running`` by a session that died runs again; a
#: ``lab fault`` one too, unless it faulted ``max_faults`` times: it is then left for the TA).
RUNNABLE = ("queued", "running", "lab fault")

#: Each number of the settings: its unit and range (:func:`snakekit.validate.number`'s keywords).
#: The ranges keep every check on: no value lets a trajectory through that the defaults would
#: refuse by a wide margin, or runs the arm unattended for long.
NUMBERS = {
    "max_duration_ratio": dict(unit="", at_least=1.0, at_most=4.0),
    "sim_tolerance": dict(unit="rad", above=0.0, at_most=0.5),
    "band_factor": dict(unit="", at_least=1.0, at_most=20.0),
    "band_floor": dict(unit="rad", above=0.0, at_most=0.5),
    "max_points": dict(unit="", above=0.0, at_most=1000.0),
    "stall_delay": dict(unit="s", above=0.0, at_most=1.0),
    "max_faults": dict(unit="", at_least=1, at_most=20, integer=True),
}
#: The numbers of ``case`` (:func:`snakekit.side_sweep`'s arguments) and their ranges.
CASE_NUMBERS = {
    "points": dict(unit="", at_least=2, at_most=100_000, integer=True),
    "rate": dict(unit="Hz", above=0.0, at_most=validate.MAX_RATE),
    "sweeps": dict(unit="", at_least=1, at_most=100_000, integer=True),
    "amplitude": dict(unit="rad", above=0.0, at_most=1.57),
}


def _number(value, name: str, bounds: dict):
    """``value`` checked by :func:`snakekit.validate.number`; its error as a :class:`LabError` (exit 2),
    with at most a short excerpt of the value."""
    kind = {list: "a JSON list", dict: "a JSON object"}.get(type(value))
    if kind:
        value = kind  # refused as text below: the message says what it is, not all of it
    elif isinstance(value, str) and len(value) > 40:
        value = value[:40] + "..."
    try:
        return validate.number(value, name, **bounds)
    except SnakekitError as e:
        text = str(e).replace(f"{kind!r} (str)", kind) if kind else str(e)
        raise LabError(f"{text}; see docs/lab.md for the fields") from None


def checked_values(values: dict, where: str) -> dict:
    """The settings ``values`` with every number checked (finite, of the right type, in range;
    booleans refused), before anything moves. ``where`` names the file in the messages.

    Raises:
        LabError: a value out of range or of the wrong type; the message names ``where``, the
            key, the value and what is allowed.
    """
    out = dict(values)
    if not isinstance(out.get("exercise"), str) or not out["exercise"]:
        raise LabError(f"{where}: \"exercise\" must be a grade id (text), got {out.get('exercise')!r:.60}")
    for key, bounds in NUMBERS.items():
        if key in out:
            out[key] = _number(out[key], f'{where}: "{key}"', bounds)
    case = out.get("case")
    if not isinstance(case, dict):
        raise LabError(f'{where}: "case" must be a JSON object of {", ".join(CASE_NUMBERS)}, got {case!r:.60}')
    missing, unknown = sorted(set(CASE_NUMBERS) - set(case)), sorted(set(case) - set(CASE_NUMBERS))
    if missing or unknown:
        raise LabError(f'{where}: "case" must hold exactly {", ".join(CASE_NUMBERS)}'
                       + (f"; missing {', '.join(missing)}" if missing else "")
                       + (f"; unknown {', '.join(map(repr, unknown))}" if unknown else ""))
    out["case"] = {k: _number(case[k], f'{where}: "case.{k}"', b) for k, b in CASE_NUMBERS.items()}
    return out


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

    def __post_init__(self):
        fields = {k: getattr(self, k) for k in ("exercise", "case", *NUMBERS)}
        for k, v in checked_values(fields, "the lab settings").items():
            object.__setattr__(self, k, v)

    def reference_trajectory(self):
        """The spec's trajectory: what every student's is run against."""
        import snakekit

        return snakekit.side_sweep(**self.case)


def lab_dir(course: Path, assignment: str) -> Path:
    return Path(course) / "lab" / assignment


def settings(course: Path, assignment: str) -> LabSettings:
    """The lab settings: ``<course>/lab/<a>/lab.json`` (the course's: which exercise the lab runs, at which
    case), over :class:`LabSettings`' defaults (the lab's own checks).

    Raises:
        NoLab: the assignment is unknown, or not one whose hand-in is a trajectory.
        LabError: ``lab.json`` is not readable, or a value in it is out of range or of the wrong type.
    """
    course = Path(course)
    known = sorted(p.name for p in (course / "source").iterdir() if p.is_dir()) if (course / "source").is_dir() else []
    if assignment not in known:
        raise NoLab(f"unknown assignment '{assignment}': the course {course} has "
                       f"{', '.join(known) or 'no assignments in source/'}")
    values = {}
    path = lab_dir(course, assignment) / "lab.json"
    if path.is_file():
        try:
            given = json.loads(path.read_text(encoding="utf-8-sig"))
        except (OSError, ValueError) as e:
            raise LabError(f"{path} is not readable JSON ({str(e)[:200]}); see docs/lab.md for its fields") from e
        if not isinstance(given, dict):
            raise LabError(f"{path} must hold one JSON object of fields ({{\"sim_tolerance\": 0.1, ...}}), got a "
                           f"{type(given).__name__}; see docs/lab.md for its fields")
        values.update(given)
    if "exercise" not in values or "case" not in values:
        raise NoLab(f"{assignment} has no exercise the lab runs (its hand-in is not a trajectory); name one in "
                       f"{path} as {{\"exercise\": GRADE_ID, \"case\": {{\"points\": ..., \"rate\": ..., "
                       "\"sweeps\": ..., \"amplitude\": ...}}")
    fields = set(LabSettings.__dataclass_fields__) - {"assignment"}
    unknown = sorted(set(values) - fields)
    if unknown:
        raise LabError(f"{path}: unknown field(s) {', '.join(unknown)[:200]}; known: {', '.join(sorted(fields))}")
    s = LabSettings(assignment=assignment, **checked_values(values, str(path)))
    reference_checked(s, str(path))
    return s


def reference_checked(s: LabSettings, where: str):
    """The settings' reference trajectory, if the arm may run it as it is (calibration runs it
    ungated): inside the joint and speed limits, never folding the arm, at most
    :data:`snakekit.validate.MAX_DURATION` long.

    Raises:
        LabError: it is not; the message names ``where`` and the case.
    """
    from snakekit.collision import first_collision

    try:
        ref = s.reference_trajectory()
        validate.check_duration(ref.duration, "its duration")
    except SnakekitError as e:
        raise LabError(f"{where}: the \"case\" {s.case} is not a sweep the arm may run: "
                       f"{str(e).splitlines()[0].rstrip(':')}; choose a slower or smaller case") from None
    hit = first_collision(ref.times, ref.positions)
    if hit is not None:
        raise LabError(f"{where}: the \"case\" {s.case} would fold the arm ({hit.links[0]} and {hit.links[1]} at "
                       f"t = {hit.time:.2f} s); choose a smaller amplitude")
    return ref


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
    from grader.lms.collect import read_manifest

    for k, listed in enumerate(read_manifest(course, assignment)):
        rank.setdefault(listed, k)
    for s in students:
        if s not in rank:
            stamp = Path(course) / "submitted" / s / assignment / "timestamp.txt"
            rank[s] = 1e12 + (stamp.stat().st_mtime if stamp.is_file() else 1e12)
    return sorted(students, key=lambda s: (rank[s], s))


#: The most a hand-in may hold, unpacked [bytes]: Task 2's is about 60 kB; a file that unpacks to
#: more is refused before it is read (a hand-in is never a reason to run out of memory).
MAX_HANDIN_BYTES = 64 * 2**20


def load_handin(path: Path) -> dict:
    """The hand-in's arrays, read with ``allow_pickle=False`` (never unpickled, never run).

    Raises:
        FileFormatError: the file is not a whole ``.npz`` of numeric arrays (truncated, bit-flipped,
            too large once unpacked, object arrays); the message is for the student's feedback.
    """
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            size = sum(i.file_size for i in z.infolist())
        if size > MAX_HANDIN_BYTES:
            raise FileFormatError(f"your hand-in unpacks to {size / 2**20:.0f} MB, more than the "
                                  f"{MAX_HANDIN_BYTES // 2**20} MB a sweep can take")
        with np.load(path, allow_pickle=False) as z:
            return {k: np.array(z[k]) for k in z.files}
    except FileFormatError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError, RuntimeError, NotImplementedError) as e:
        raise FileFormatError(f"your hand-in file cannot be read as arrays of numbers: it is damaged or not the "
                              f"grader's ({type(e).__name__}: {str(e)[:120]})") from e


class Queue:
    """The jobs of one assignment, as saved in ``queue.json`` (one dict per student).

    Every change is a read-modify-write of the file under its own lock (``.queue.lock``, an
    ``flock``): the jobs this copy changes are written over the file's, every other job is kept
    as the file has it (and this copy takes it up), so no copy ever writes another's job away.
    """

    def __init__(self, path: Path, assignment: str, jobs: list[dict] | None = None):
        self.path, self.assignment, self.jobs = Path(path), assignment, jobs or []

    @classmethod
    def load(cls, course: Path, assignment: str) -> "Queue":
        path = lab_dir(course, assignment) / "queue.json"
        return cls(path, assignment, _read_jobs(path))

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
        self._write([job])

    def save(self) -> None:
        """Write every job of this copy (the file's other jobs stay)."""
        self._write(self.jobs)

    def _write(self, changed: list[dict]) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with _flocked(self.path.with_name(".queue.lock")):
            mine = {j["student"]: j for j in self.jobs}
            ours = {j["student"] for j in changed}
            merged = []
            for theirs in _read_jobs(self.path):
                name = theirs["student"]
                if name not in ours:
                    if name in mine:
                        mine[name].clear()
                        mine[name].update(theirs)  # the file's is newer: this copy takes it up
                    else:
                        mine[name] = theirs
                merged.append(mine.pop(name))
            merged += [j for j in self.jobs if j["student"] in mine]  # new here, not yet in the file
            self.jobs[:] = merged
            write_atomic(self.path, json.dumps({"assignment": self.assignment, "jobs": self.jobs}, indent=1))
            rows = [[j["student"], j["state"], j.get("points", ""), j["reason"], j["attempts"], j["updated"]]
                    for j in self.jobs]
            write_atomic(self.path.with_name("status.csv"), _csv([["student", "state", "points", "reason",
                                                                   "attempts", "updated"]] + rows))


def _read_jobs(path: Path) -> list[dict]:
    """The jobs in ``queue.json`` (none if there is no file yet), checked to be the lab's queue."""
    if not path.is_file():
        return []
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        jobs = data["jobs"]
        if not isinstance(jobs, list) or not all(
                isinstance(j, dict) and isinstance(j.get("student"), str) and j.get("state") in STATES
                and isinstance(j.get("reason", ""), str) for j in jobs):
            raise ValueError("its jobs are not a list of jobs with a student and a state")
    except (OSError, ValueError, TypeError, KeyError) as e:
        raise LabError(f"{path} is not the lab's queue ({str(e)[:200]}); move it away to start a new queue") from e
    for j in jobs:
        j.setdefault("reason", "")
        j.setdefault("attempts", 0)
        j.setdefault("updated", "")
    return jobs


@contextmanager
def _flocked(path: Path):
    """Hold an exclusive ``flock`` on ``path`` for the block (waits for another holder)."""
    import fcntl

    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


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
