"""Where a class stands and why it fails, from the gradebook and the grader's own records.

The points come from nbgrader's gradebook (as :func:`grader.course.gradebook.scores_of` reads them, in one
query: a score a TA changed in formgrader counts as changed); what each check said, which hint fired and how each hidden
case went come from the verdicts ``snakekit grade`` keeps in the TA's copy of every notebook
(``autograded/<student>/<a>/<notebook>.ipynb``, :func:`grader.feedback.notebook.recorded`); a
resubmission from the earlier notebooks ``collect`` keeps in ``submitted/<student>/<a>/attempts/``.

A failure message is grouped so that the same mistake at different cases counts once: by the hint
that fired (the notebook's own check's, "Your notebook's check fails too: ... Hint: ...", else a grader
check's ``Hint:``), else by the message with its numbers taken out (:func:`without_numbers`).
"""

from __future__ import annotations

import json
import re
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from grader.course.gradebook import ExerciseGrade, SubmissionScores, cell_order
from grader.errors import CourseError
from grader.feedback.notebook import recorded
from grader.files import MAX_FILE
from grader.scoring.rerun import exercise
from grader.scoring.score import label
from grader.scoring.verdict import LOCAL

__all__ = ["ExerciseStanding", "CaseKindRate", "FailureGroup", "ClassStanding", "standing", "without_numbers",
           "hint_of", "mistake_of", "exercise_name"]

#: Examples of students named per failure group.
EXAMPLES = 2
#: A share this close to 0 or to the exercise's points is a zero or full marks [points].
EPS = 1e-6


@dataclass(frozen=True)
class ExerciseStanding:
    """One exercise across the class: how many submissions got full, partial and zero marks."""

    grade_id: str
    max_score: float
    full: int
    partial: int
    zero: int

    @property
    def name(self) -> str:
        return exercise_name(self.grade_id)


@dataclass(frozen=True)
class CaseKindRate:
    """One kind of hidden case of one exercise (:func:`grader.scoring.score.case_kind`): of ``cases``
    met by the class, ``passed`` were right in full."""

    grade_id: str
    kind: str
    cases: int
    passed: int

    @property
    def rate(self) -> float:
        return self.passed / self.cases if self.cases else 0.0


@dataclass(frozen=True)
class FailureGroup:
    """One mistake of one exercise: ``text`` is the hint that fired (``hinted``) or the grader's message
    with its numbers taken out; ``students`` made it (sorted), ``example`` is one student's message."""

    grade_id: str
    text: str
    hinted: bool
    students: tuple[str, ...]
    example: str

    @property
    def count(self) -> int:
        return len(self.students)

    @property
    def shown(self) -> str:
        """The mistake as a teacher reads it: a hint as one of the students got it (their numbers, where the
        grouping has ``#``), else the message without numbers."""
        return (hint_of(self.example, numbers=True) or self.text) if self.hinted else self.text

    @property
    def unwritten(self) -> bool:
        """The hand-out's stub still raised (course/README.md: it raises ``NotImplementedError``): not a mistake, no answer."""
        return not self.hinted and "raised NotImplementedError" in self.text


@dataclass(frozen=True)
class ClassStanding:
    """A class's standing on one assignment.

    Attributes:
        totals: student -> the score every place shows (after the late penalty) [points].
        hours_before_due: student -> hours between the hand-in and the due date (negative: late), for
            the submissions with a time when the gradebook has a due date.
        late: students with a late penalty or a hand-in after the due date.
        resubmitted: students with an earlier notebook kept in ``attempts/``.
        unrecorded: graded students without the grader's verdicts (a notebook that never ran): their
            points count, their messages and cases do not.
        cases: ``(student, grade id)`` -> each hidden case's ``(kind, fraction right)``, as recorded.
    """

    assignment: str
    max_score: float
    totals: dict
    exercises: tuple[ExerciseStanding, ...]
    case_kinds: tuple[CaseKindRate, ...]
    failures: tuple[FailureGroup, ...]
    hours_before_due: dict
    late: tuple[str, ...]
    resubmitted: tuple[str, ...]
    unrecorded: tuple[str, ...]
    cases: dict


def exercise_name(grade_id: str) -> str:
    """``ex06_1_sweep_times_test`` -> ``6.1 sweep_times``."""
    number = exercise(grade_id)
    return f"{number} {label(grade_id)}" if number != grade_id else label(grade_id)


_NUMBER = re.compile(r"(?<![A-Za-z_])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_RUN = re.compile(r"#(?:[\s,]*(?:#|\.\.\.))+")


def without_numbers(message: str) -> str:
    """``message`` with every number a ``#`` (a list of them one ``#``): the same mistake at other cases.

    >>> without_numbers("sweep_times(4, 10.0): value is 0.4 at index [3], expected 0.3: off by 0.1.")
    'sweep_times(#): value is # at index [#], expected #: off by #.'
    >>> without_numbers("exercise 6.3: task2_sweep raised")
    'exercise #: task2_sweep raised'
    >>> without_numbers("2 of 7 hidden cases wrong; the first: f([0.1, 0.2, ..., 0.9], 2)") == \\
    ...     without_numbers("5 of 7 hidden cases wrong; the first: f([1, 2], 3)")
    True
    """
    text = _NUMBER.sub("#", message)
    return _RUN.sub("#", text).strip()


_CALL = r"\w+(?: at the hidden case )?\([^()]*\):? "   # sweep_times(4, 10.0): / estimate_lag at the hidden case (...):
_CASE = re.compile(r"^(?:# of # hidden cases (?:wrong|gave no trajectory)(?: \(some in part\))?; the first: )?(?:" + _CALL + ")?")
#: where a message goes on to another case or check, or to what the notebook's own check said
_NEXT = re.compile(r" (?:\w+(?: at the hidden case )?\([^()]*\): |# of # hidden cases|[\w ]+: right in every hidden case|" + re.escape(LOCAL) + ")")


def mistake_of(message: str) -> str:
    """The mistake a message without a hint names: its first line without numbers, without the count of
    cases and the case it was met at, up to where it goes on to another case or check.

    >>> mistake_of("7 of 7 hidden cases wrong; the first: sweep_times(725, 50.48): your function raised "
    ...            "NotImplementedError: exercise 6.1: sweep_times")
    'your function raised NotImplementedError: exercise #: sweep_times'
    >>> mistake_of("graded_run(): sweeps: 3, expected 20 (off by -17). graded_run(): commanded vs ...")
    'sweeps: #, expected # (off by #).'
    >>> mistake_of("5 of 5 hidden cases wrong; the first: f([ 0.  , 0.1, ..., 28.0..., 1, 0.08): 'q' is 1 at index [2]")
    "'q' is # at index [#]"
    >>> mistake_of("3 of 3 hidden cases wrong; the first: estimate_lag at the hidden case (151, 10.0, 4, 0.05, 3): "
    ...            "lag of joint is 0.2 s, expected 0.178 s: off by 22 ms.")
    'lag of joint is # s, expected # s: off by # ms.'
    """
    first = without_numbers(message.strip().splitlines()[0] if message.strip() else "")
    first = _CASE.sub("", first)
    return _NEXT.split(first, maxsplit=1)[0]


_HINTS = (re.compile(re.escape(LOCAL) + r".*?Hint: (.+?)(?=$| Hint: )", re.S),
          re.compile(r"Hint: (.+?)(?=$| Hint: |\. [A-Z])", re.S))


def hint_of(message: str, *, numbers: bool = False) -> str:
    """The first hint that fired in a grader's message, its numbers taken out unless ``numbers`` ("" if none).

    >>> hint_of("rate: 100 Hz between points, expected 10 Hz (tolerance 1%). Hint: this looks like 100 Hz where 10 Hz was asked: the time step is 0.1 s.")
    'this looks like # Hz where # Hz was asked: the time step is # s.'
    >>> hint_of("0 of 6 right. Your notebook's check fails too: x is 331.5 m. Hint: millimetres?"), hint_of("0 of 6 right.")
    ('millimetres?', '')
    >>> hint_of("rate: 100 Hz. Hint: this looks like 100 Hz where 10 Hz was asked.", numbers=True)
    'this looks like 100 Hz where 10 Hz was asked.'
    """
    for pattern in _HINTS:
        m = pattern.search(message)
        if m:
            return m.group(1).strip() if numbers else without_numbers(m.group(1).strip())
    return ""


def _records(course: Path, assignment: str, student: str) -> list | None:
    """The grader's verdicts on the student's notebooks (None when none was recorded)."""
    found = None
    for path in sorted((course / "autograded" / student / assignment).glob("*.ipynb")):
        if path.stat().st_size > MAX_FILE:
            continue
        try:  # read as JSON: only the metadata is needed, and a class has hundreds
            rec = recorded(json.loads(path.read_bytes()))
        except (OSError, ValueError, AttributeError):
            rec = None
        if rec is not None:
            found = (found or []) + rec[4]
    return found


def _gradebook(course: Path, assignment: str) -> tuple[dict, dict]:
    """``(scores, hours)``: student -> :class:`grader.course.gradebook.SubmissionScores` of the gradebook, in one
    query (nbgrader's objects load a class's grades one by one: 50 s for 500 submissions); student -> hours
    between the hand-in and the due date, where the gradebook has both. A student's extension of the due
    date (nbgrader's) is not counted."""
    from nbgrader.api import Assignment, BaseCell, Grade, Notebook, SubmittedAssignment, SubmittedNotebook

    from grader.course.folder import gradebook

    order = cell_order(course, assignment)
    grades, penalty, stamps = defaultdict(list), defaultdict(dict), {}
    with gradebook(course) as gb:
        due = gb.db.query(Assignment.duedate).filter(Assignment.name == assignment).scalar()
        rows = (gb.db.query(SubmittedAssignment.student_id, SubmittedAssignment.timestamp, Notebook.name,
                            SubmittedNotebook.late_submission_penalty, BaseCell.name, Grade.max_score,
                            Grade.auto_score, Grade.manual_score, Grade.extra_credit)
                .select_from(Grade)
                .join(SubmittedNotebook, Grade.notebook_id == SubmittedNotebook.id)
                .join(SubmittedAssignment, SubmittedNotebook.assignment_id == SubmittedAssignment.id)
                .join(Assignment, SubmittedAssignment.assignment_id == Assignment.id)
                .join(Notebook, SubmittedNotebook.notebook_id == Notebook.id)
                .join(BaseCell, Grade.cell_id == BaseCell.id)
                .filter(Assignment.name == assignment))
        for student, stamp, nb, late, gid, max_score, auto, manual, extra in rows:
            grades[student].append(ExerciseGrade(gid, nb, float(max_score or 0), auto, manual, float(extra or 0)))
            penalty[student][nb] = float(late or 0)
            stamps[student] = stamp
    scores, hours = {}, {}
    for student, gs in grades.items():
        gs.sort(key=lambda g: (order.get(g.grade_id, len(order)), g.notebook, g.grade_id))
        late = sum(penalty[student].values())
        stamp = stamps[student]
        seconds = max(0.0, (stamp - due).total_seconds()) if stamp is not None and due is not None else 0.0
        scores[student] = SubmissionScores(student, assignment, sum(g.max_score for g in gs),
                                           round(sum(g.score for g in gs), 4), late, seconds, tuple(gs))
        if stamp is not None and due is not None:
            hours[student] = round((due - stamp).total_seconds() / 3600, 3)
    return dict(sorted(scores.items())), hours


def standing(course: Path, assignment: str) -> ClassStanding:
    """The class's standing on ``assignment`` (graded with ``snakekit grade``).

    Raises:
        CourseError: no submission of ``assignment`` is in the gradebook yet.
    """
    course = Path(course)
    scores, hours = _gradebook(course, assignment)
    if not scores:
        raise CourseError(f"no submission of {assignment} is in the gradebook of {course} yet: grade it first "
                          f"(snakekit grade {assignment})")
    first = next(iter(scores.values()))
    per_exercise = defaultdict(list)
    for s in scores.values():
        for g in s.exercises:
            per_exercise[(g.grade_id, g.max_score)].append(g.score)
    exercises = tuple(ExerciseStanding(gid, m, sum(x >= m - EPS for x in xs), sum(EPS < x < m - EPS for x in xs),
                                       sum(x <= EPS for x in xs)) for (gid, m), xs in per_exercise.items())
    kinds, groups, unrecorded = defaultdict(lambda: [0, 0]), defaultdict(list), []
    examples, cases = {}, {}
    for student in sorted(scores):
        records = _records(course, assignment, student)
        if records is None:
            unrecorded.append(student)
            continue
        for ex in records:
            cases[(student, ex.grade_id)] = ex.cases
            for kind, fraction in ex.cases:
                k = kinds[(ex.grade_id, kind)]
                k[0] += 1
                k[1] += fraction >= 1 - EPS
            if ex.score >= ex.max_score - EPS or not ex.message:
                continue
            hint = hint_of(ex.message)
            key = (ex.grade_id, hint or mistake_of(ex.message), bool(hint))
            groups[key].append(student)
            examples.setdefault(key, ex.message)
    order = {e.grade_id: i for i, e in enumerate(exercises)}
    case_kinds = tuple(CaseKindRate(gid, kind, n, ok) for (gid, kind), (n, ok) in
                       sorted(kinds.items(), key=lambda kv: (order.get(kv[0][0], len(order)), kv[0][1])))
    failures = tuple(sorted((FailureGroup(gid, text, hinted, tuple(who), examples[(gid, text, hinted)])
                             for (gid, text, hinted), who in groups.items()),
                            key=lambda f: (order.get(f.grade_id, len(order)), -f.count, f.text)))
    attempts = tuple(sorted(s for s in scores if any((course / "submitted" / s / assignment / "attempts").glob("*"))))
    late = tuple(sorted(s for s, x in scores.items() if x.seconds_late > 0 or x.late_penalty > 0
                        or hours.get(s, 0.0) < 0))
    return ClassStanding(assignment, first.max_score, {s: x.score for s, x in sorted(scores.items())}, exercises,
                         case_kinds, failures, hours, late, attempts, tuple(unrecorded), cases)
