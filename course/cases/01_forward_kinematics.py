"""Lesson 01's hidden cases, drawn by the grader anew for every grading batch."""

import numpy as np

#: The grader's tolerances per grade id: as the visible checks' (exact math).
TOLERANCES = {"ex01_1_planar_fk_test": {"rtol": 1e-9, "atol": 1e-12},
              "ex01_2_joint_positions_test": {"rtol": 1e-9, "atol": 1e-12},
              "ex01_3_reach_test": {"rtol": 1e-9, "atol": 1e-12}}


def _angles(rng, spec, n):
    """``n`` random joint angles inside the limits, then the limits themselves and a curled arm
    whose heading passes pi (a wrapped heading is wrong there)."""
    q = list(rng.uniform(spec.lower, spec.upper, (n, spec.n_joints)))
    curl = rng.uniform(1.1, 1.5)
    return q + [np.full(spec.n_joints, float(spec.upper)), np.full(spec.n_joints, float(spec.lower)),
                np.array([curl, curl, curl, 0.0, 0.0])]


def ex01_1_planar_fk_test(rng, spec):
    """planar_fk(q): 10 cases."""
    return [(q,) for q in _angles(rng, spec, 7)]


def ex01_2_joint_positions_test(rng, spec):
    """joint_positions(q): 8 cases."""
    return [(q,) for q in _angles(rng, spec, 5)]


def ex01_3_reach_test(rng, spec):
    """reach(n_joints, link_length, tool_offset): 7 cases, other arms than the lesson's, and a
    single joint (no link: the reach is the tool offset)."""
    cases = [(int(rng.integers(2, 10)), float(rng.uniform(0.02, 0.3)), float(rng.uniform(0.0, 0.1)))
             for _ in range(6)]
    return cases + [(1, float(rng.uniform(0.05, 0.2)), float(rng.uniform(0.01, 0.1)))]
