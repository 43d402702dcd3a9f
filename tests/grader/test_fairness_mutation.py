"""Fairness as a property of every exercise: single-slip variants of the instructor's answers,
graded with the real grader, one batch per lesson (grader/course/fairness.py; in the suite, the batch that also
grades the lesson's known mistakes and forgotten returns: tests/conftest.py's ``graded_slips``).

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
    """The variants of ``lesson`` graded in a batch of their own."""
    from conftest import need_program

    need_program("unshare")
    made, skipped = variants(fairness.ROOT / "course", lesson, fairness.SAMPLE)
    assert made and not skipped
    rows, facts = fairness.grade_lesson(lesson, made, tmp, seed=seed)
    return _shown(lesson, made, skipped, rows, facts)


def _shown(lesson, made, skipped, rows, facts):
    print(f"\n{lesson}: {len(made)} variants graded in {facts['seconds']:.0f} s (seed {facts['seed']})\n"
          + fairness.matrix(rows, skipped, [facts]))
    GRADED.setdefault(lesson, (rows, facts))
    return rows, facts


# ids "lessonNN", not the lesson's name: lesson 07's name marks a test serial, and this one need not be. The variants
# are graded in the batch of the lesson's known mistakes and forgotten returns (tests/conftest.py's graded_slips),
# so each lesson's test joins that batch's xdist group
@pytest.mark.parametrize("lesson", [pytest.param(lesson, marks=pytest.mark.xdist_group(f"slips{lesson[:2]}"))
                                    for lesson in LESSONS], ids=[f"lesson{lesson[:2]}" for lesson in LESSONS])
def test_every_slip_costs_only_its_exercise_and_the_visible_check_agrees_with_the_grade(lesson, graded_slips):
    from conftest import need_program

    need_program("unshare")
    course = graded_slips(lesson)
    made, seconds, stderr = graded_slips.batches[lesson]   # none skipped: the fixture asserts it
    rows, facts = _shown(lesson, made, [], *fairness.rows_of(lesson, made, course, seconds, stderr))
    assert {r.mutant.grade_id for r in rows} == {gid for gid in fairness.SAMPLE if gid.startswith(f"ex{lesson[:2]}_")}
    broken = [f"{r.mutant.grade_id} {r.mutant.operator} (`{r.mutant.where}`): {'; '.join(r.broken)}"
              for r in rows if r.broken]
    assert not broken, f"{lesson}: {len(broken)} of {len(rows)} variants break a fairness rule:\n" + "\n".join(broken)


@pytest.mark.xdist_group("slips01")  # after lesson 01's test above, in its process: its batch is graded once more
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
