"""Fairness as a property of every exercise: single-slip variants of the instructor's answers,
graded with the real grader, one batch per lesson (grader/course/fairness.py).

For every lesson the suite grades the sample of variants (``fairness.SAMPLE``: every exercise of the
course, every operator) and asserts the rules on each variant: no other exercise loses points but
one that builds on it (at most half of it), an endless loop or an exception costs only its
exercise, and a variant the visible check passes is one the graded cases pass too and is listed
as equivalent. ``python -m grader.course.fairness --all`` grades every operator on every exercise
(grader/README.md keeps its matrix).
"""

from __future__ import annotations

import pytest

from grader.course import fairness
from grader.course.mutants import variants

LESSONS = fairness.lessons()


#: lesson -> (rows, facts) of its batch in this run, so the seed test grades lesson 01 once more, not twice
GRADED = {}


def _grade(lesson, tmp, seed=None):
    from conftest import need_program

    need_program("unshare")
    made, skipped = variants(fairness.ROOT / "course", lesson, fairness.SAMPLE)
    assert made and not skipped
    rows, facts = fairness.grade_lesson(lesson, made, tmp, seed=seed)
    print(f"\n{lesson}: {len(made)} variants graded in {facts['seconds']:.0f} s (seed {facts['seed']})\n"
          + fairness.matrix(rows, skipped, [facts]))
    GRADED.setdefault(lesson, (rows, facts))
    return rows, facts


# ids "lessonNN", not the lesson's name: lesson 07's name marks a test serial, and this one need not be
@pytest.mark.parametrize("lesson", LESSONS, ids=[f"lesson{lesson[:2]}" for lesson in LESSONS])
def test_every_slip_costs_only_its_exercise_and_the_visible_check_agrees_with_the_grade(lesson, tmp_path):
    rows, facts = _grade(lesson, tmp_path)
    assert {r.mutant.grade_id for r in rows} == {gid for gid in fairness.SAMPLE if gid.startswith(f"ex{lesson[:2]}_")}
    broken = [f"{r.mutant.grade_id} {r.mutant.operator} (`{r.mutant.where}`): {'; '.join(r.broken)}"
              for r in rows if r.broken]
    assert not broken, f"{lesson}: {len(broken)} of {len(rows)} variants break a fairness rule:\n" + "\n".join(broken)


def test_a_second_run_at_another_seed_gives_the_same_matrix(tmp_path):
    """The matrix is a property of the course, not of one draw of hidden cases (lesson 01: three exercises;
    its batch above, or one at seed 11, against one at another seed)."""
    first, facts = GRADED.get("01_forward_kinematics") or _grade("01_forward_kinematics", tmp_path / "a", seed=11)
    second, again = _grade("01_forward_kinematics", tmp_path / "b", seed=int(facts["seed"]) + 1)
    assert facts["seed"] != again["seed"]

    def matrix(rows):
        return [(r.mutant.grade_id, r.mutant.operator, round(r.lost_own, 9), sorted(r.lost_elsewhere.items()), r.local,
                 r.graded) for r in rows]

    assert matrix(first) == matrix(second)
