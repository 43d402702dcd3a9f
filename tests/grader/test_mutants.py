"""The single-slip variants of the instructor's answers (grader/course/mutants.py): each operator
makes the slip it names, once, and gives no variant where it does not apply."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grader.course import fairness
from grader.course.mutants import OPERATORS, exercises, forbidden_names, mutate, variants

ROOT = Path(__file__).resolve().parents[2]
LESSONS = fairness.lessons()

ANSWER = '''def tip(q, lengths):
    """Tip (x, y) [m] of a planar arm."""
    phi = np.cumsum(q)
    x = np.sum(lengths * np.cos(phi))
    y = np.sum(lengths * np.sin(phi))
    return np.array([x, y - 0.0])
'''
Q, LENGTHS = np.array([0.3, -0.2, 0.5]), np.array([0.1, 0.07, 0.05])


def tip_of(source: str):
    import snakekit

    space = {"np": np, "snakekit": snakekit}
    exec(source, space)
    return space["tip"]


def right(q, lengths):
    phi = np.cumsum(q)
    return np.array([np.sum(lengths * np.cos(phi)), np.sum(lengths * np.sin(phi))])


# what each operator's variant of ANSWER returns at (Q, LENGTHS), computed here without the variant
EXPECTED = {
    "degrees": lambda: np.array([np.sum(LENGTHS * np.cos(np.deg2rad(np.cumsum(Q)))), right(Q, LENGTHS)[1]]),
    "cos_for_sin": lambda: np.array([np.sum(LENGTHS * np.sin(np.cumsum(Q)))] * 2),
    "sign": lambda: right(Q, LENGTHS),   # y + 0.0: a sign slip where it changes nothing
    "transpose": lambda: right(Q, LENGTHS),
    "scale_1000": lambda: 1000 * right(Q, LENGTHS),
    "swap_args": None,
}


@pytest.mark.parametrize("operator", ["degrees", "cos_for_sin", "sign", "transpose", "scale_1000"])
def test_an_operator_changes_the_answer_s_result_as_its_slip_does(operator):
    source, where = mutate(ANSWER, operator)
    assert np.allclose(tip_of(source)(Q, LENGTHS), EXPECTED[operator]()), source
    assert where and where in source


def test_a_list_a_forgotten_return_an_exception_and_an_endless_loop_are_what_a_student_writes():
    listed = tip_of(mutate(ANSWER, "list")[0])(Q, LENGTHS)
    assert isinstance(listed, list) and np.allclose(listed, right(Q, LENGTHS))
    assert tip_of(mutate(ANSWER, "no_return")[0])(Q, LENGTHS) is None
    with pytest.raises(NameError, match="q_"):
        tip_of(mutate(ANSWER, "exception")[0])(Q, LENGTHS)
    loop, where = mutate(ANSWER, "endless_loop")
    assert where == "while True:" and loop.index("while True") < loop.index("phi =")


def test_off_by_one_shifts_a_count_else_a_start_else_an_end():
    assert mutate("def f(n, rate):\n    return np.arange(n) / rate\n", "off_by_one")[1] == "return np.arange(n + 1) / rate"
    assert mutate("def f(a, b, n):\n    return np.linspace(a, b, n)\n", "off_by_one")[1] == \
        "return np.linspace(a, b, n + 1)"
    assert mutate("def f(y):\n    return y - y[0]\n", "off_by_one")[1] == "return y - y[1]"
    assert mutate("def f(y):\n    return y[-1]\n", "off_by_one")[1] == "return y[-2]"
    assert mutate(ANSWER, "off_by_one") is None   # no count, no index: it does not apply


def test_an_operator_that_does_not_apply_gives_no_variant():
    plain = "def double(x):\n    return 2 * x\n"
    assert mutate(plain, "cos_for_sin") is None and mutate(plain, "no_clip") is None
    assert mutate(plain, "swap_args") is None and mutate(plain, "forbidden") is None
    assert mutate("x = 1\n", "sign") is None   # no function: nothing to change
    # a clip, an abs and max(0, x) left out; two arguments that commute are never swapped
    assert mutate("def f(x):\n    return np.clip(x, 0, 1)\n", "no_clip")[1] == "return x"
    assert mutate("def f(x):\n    return max(0.0, x)\n", "no_clip")[1] == "return x"
    assert mutate("def f(x, y):\n    return np.hypot(x, y)\n", "swap_args") is None
    assert mutate("def f(x, y):\n    return np.arctan2(y, x)\n", "swap_args")[1] == "return np.arctan2(x, y)"


def test_the_forbidden_call_uses_the_name_the_check_forbids():
    test = 'S = ("snakekit.jacobian", "snakekit.planar_jacobian")\nex.hand_in("ex_test", f, forbid=S, what="J")\n'
    assert forbidden_names(test) == ("snakekit.jacobian", "snakekit.planar_jacobian")
    assert forbidden_names('ex.hand_in("x", f, forbid=("snakekit.SnakeSpec.reach",))') == ("snakekit.SnakeSpec.reach",)
    source, where = mutate("def J(q):\n    return q\n", "forbidden", forbidden_names=("snakekit.jacobian",))
    assert where == "_library = snakekit.jacobian(q)"
    # a property of the robot's spec is read from the lesson's spec, not called
    assert mutate("def reach(n):\n    return n\n", "forbidden",
                  forbidden_names=("snakekit.SnakeSpec.reach",))[1] == "_library = snakekit.SPEC.reach"


@pytest.fixture(scope="module")
def every_variant():
    return [m for lesson in LESSONS for m in variants(ROOT / "course", lesson)[0]]


def test_the_course_has_29_exercises_and_every_operator_applies_somewhere(every_variant):
    found = [gid for lesson in LESSONS for gid, _, _ in exercises(ROOT / "course" / "source" / lesson / f"{lesson}.ipynb")]
    assert len(found) == 29 and len(set(found)) == 29
    made = every_variant
    assert {m.operator for m in made} == set(OPERATORS)
    assert {m.grade_id for m in made} == set(found)


def test_the_suite_s_sample_holds_every_exercise_and_every_operator_and_each_applies():
    found = {gid for lesson in LESSONS for gid, _, _ in exercises(ROOT / "course" / "source" / lesson / f"{lesson}.ipynb")}
    assert set(fairness.SAMPLE) == found
    assert {op for ops in fairness.SAMPLE.values() for op in ops} == set(OPERATORS)
    for lesson in LESSONS:
        made, skipped = variants(ROOT / "course", lesson, fairness.SAMPLE)
        assert not skipped, f"{lesson}: {skipped} do not apply: choose another operator in fairness.SAMPLE"


def test_every_equivalent_variant_is_one_the_operators_make_with_a_reason(every_variant):
    made = {(m.grade_id, m.operator) for m in every_variant}
    for key, why in fairness.EQUIVALENT.items():
        assert key in made and len(why) > 20, key
