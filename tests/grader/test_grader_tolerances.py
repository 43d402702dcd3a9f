"""The grader's tolerances (a course's cases module, ``TOLERANCES``, and the recorded reference) are
checked like every other setting: a NaN or negative one would judge every case the same, whatever the hand-in."""

import math

import pytest

from grader.scoring.cases import Draw, draw
from grader.errors import CasesError
from grader.scoring.references import Reference, expected
from grader.errors import InstructorReferenceError
from grader.scoring.score import score_exercise

A = "t1_values"
GID = "ex_t1_double_test"
BAD = [("nan", math.nan, "nan"), ("inf", math.inf, "inf"), ("-inf", -math.inf, "-inf"), ("negative", -1e-9, "-1e-09"),
       ("text", "abc", "'abc'"), ("true", True, "True"), ("null", None, "None"), ("a list", [1e-9], "[1e-09]")]
KEYS = ["rtol", "atol", "max", "rms", "commanded_max", "commanded_rms"]
CASES = [(k, *b) for k in KEYS for b in BAD] + [("rtol", "above 1", 1.5, "1.5")]


def cases_module(course, tolerance_text: str):
    (course / "cases").mkdir(parents=True, exist_ok=True)
    (course / "cases" / f"{A}.py").write_text(
        f"TOLERANCES = {{{GID!r}: {tolerance_text}}}\n\n"
        f"def {GID}(rng, spec):\n    return [(float(x),) for x in rng.uniform(-1, 1, 3)]\n")


@pytest.mark.parametrize("key, kind, value, shown", CASES, ids=[f"{c[0]}-{c[1]}" for c in CASES])
def test_a_bad_tolerance_in_a_cases_module_stops_the_draw_naming_it(tmp_path, key, kind, value, shown):
    cases_module(tmp_path, repr({key: value}).replace("nan", "float('nan')").replace("inf", "float('inf')"))
    with pytest.raises(CasesError) as e:
        draw(tmp_path, A, seed=1)
    rng = "from 0 to 1" if key == "rtol" else ">= 0"
    assert str(e.value).startswith(f"{tmp_path / 'cases' / (A + '.py')}: TOLERANCES[{GID!r}]: tolerance {key!r} "
                                   f"must be a finite number {rng}, got {shown}")


def test_good_tolerances_are_kept_as_numbers(tmp_path):
    cases_module(tmp_path, "{'atol': 0, 'rtol': 1e-6}")
    assert draw(tmp_path, A, seed=1).settings[GID]["tolerances"] == {"atol": 0.0, "rtol": 1e-6}


@pytest.mark.parametrize("key, kind, value, shown", CASES, ids=[f"{c[0]}-{c[1]}" for c in CASES])
def test_a_bad_tolerance_in_a_reference_is_refused_before_grading(key, kind, value, shown):
    ref = Reference(A, {"exercises": {GID: {"kind": "values", "outputs": ["value"], "tolerances": {key: value}}}})
    batch = Draw(A, 1, {GID: [(0.5,), (0.25,)]})
    with pytest.raises(InstructorReferenceError, match=r"record it again \(`python -m grader.scoring.references t1_values`\)") as e:
        expected(ref, batch, {GID: [{"value": 1.0}, {"value": 0.5}]})
    assert str(e.value).startswith(f"{A}'s reference: {GID}: tolerance {key!r} must be a finite number")
    assert f"got {shown}" in str(e.value)


def test_the_nan_tolerance_the_check_refuses_would_have_failed_a_right_answer():
    """Why the check is there: with atol NaN the instructor's own answer scores nothing."""
    good = Reference(A, {"exercises": {GID: {"kind": "values", "outputs": ["value"], "tolerances": {"atol": 1e-9}}}})
    batch = Draw(A, 1, {GID: [(0.5,)]})
    e = expected(good, batch, {GID: [{"value": 1.0}]})[GID]
    assert score_exercise(GID, [{"value": 1.0}], e, 1.0).score == 1.0
    assert score_exercise(GID, [{"value": 7.0}], e, 1.0).score == 0.0
    e_nan = type(e)(e.grade_id, e.kind, e.cases, e.results, {"atol": math.nan, "rtol": math.nan}, e.function)
    assert score_exercise(GID, [{"value": 1.0}], e_nan, 1.0).score == 0.0


# --- one home for a grade id's tolerance ------------------------------------------------------------
from pathlib import Path  # noqa: E402

from grader.scoring import references  # noqa: E402

COURSE = Path(__file__).resolve().parents[2] / "course"
LESSONS = sorted(p.stem for p in (COURSE / "cases").glob("0*.py"))


@pytest.mark.parametrize("assignment", LESSONS)
def test_every_tolerance_has_one_home_and_the_reference_holds_it(assignment):
    """No tolerance of a lesson is given both in OVERRIDES and in its cases module (lesson 03's 3.1
    once was, 1e-9 in one and 1e-7 in the other, and one won silently); the recorded reference
    holds each one as given."""
    batch = draw(COURSE, assignment, seed=1)
    ref = Reference.load(references.REFERENCES / f"{assignment}.npz")
    for gid, ex in ref.exercises.items():
        here = references.OVERRIDES.get(assignment, {}).get(gid, {})
        there = batch.settings.get(gid, {}).get("tolerances", {})
        assert not set(here) & set(there), (gid, here, there)
        for key, value in {**here, **there}.items():
            assert ex["tolerances"][key] == value, (gid, key, ex["tolerances"][key], value)
    assert set(references.OVERRIDES.get(assignment, {})) <= set(ref.exercises)


def test_a_tolerance_given_twice_is_refused_naming_both_homes(tmp_path, monkeypatch):
    cases_module(tmp_path, "{'atol': 1e-7}")
    batch = draw(tmp_path, A, seed=1)
    monkeypatch.setitem(references.OVERRIDES, A, {GID: {"atol": 1e-9}})
    with pytest.raises(CasesError) as e:
        references.tolerances(A, GID, "values", batch, [])
    assert str(e.value) == (f"{A}: {GID}'s tolerance atol is given twice, in grader.scoring.references.OVERRIDES "
                            "and in the cases module's TOLERANCES; keep it in the cases module (course/cases/) alone")
    monkeypatch.setitem(references.OVERRIDES, A, {GID: {"rtol": 1e-6}})
    assert references.tolerances(A, GID, "values", batch, [])["atol"] == 1e-7


@pytest.mark.parametrize("grade_id, name", [("ex03_1_two_link_ik_test", "TIP_TOL"), ("ex03_2_dls_step_test", "STEP_TOL")])
def test_3_1_and_3_2_are_judged_with_one_tolerance_in_the_notebook_and_graded(grade_id, name):
    """3.1's tip tolerance and 3.2's step tolerance are one number each: the check cell's TIP_TOL / STEP_TOL is the
    grader's atol (3.1 was 1 nm locally and 0.1 um graded, so a tip 5e-8 m off passed graded and failed in the
    notebook; 3.2 was 1e-9 rad both ways, which a Jacobian by lesson 2's finite differences missed at some draws
    only: 3 of 4 batches took points while the notebook's check passed)."""
    import re

    import nbformat

    nb = nbformat.read(COURSE / "source" / "03_inverse_kinematics" / "03_inverse_kinematics.ipynb", as_version=4)
    source = next(c.source for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") == grade_id)
    local = float(re.search(rf"^{name} = ([\d.e+-]+)", source, re.M).group(1))
    tols = re.findall(r"\btol=([^,)]+)", source)
    assert tols and set(tols) == {name}, f"every tolerance of {grade_id}'s check is {name}: {tols}"
    graded = draw(COURSE, "03_inverse_kinematics", seed=1).settings[grade_id]["tolerances"]
    assert graded["atol"] == local == 1e-7
    assert graded["rtol"] == 1e-9   # the check's close() default rtol
