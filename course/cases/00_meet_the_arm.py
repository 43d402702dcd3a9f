"""Lesson 00's hidden cases, drawn by the grader anew for every grading batch."""

import numpy as np

#: The grader's tolerance per grade id: as the visible check's (distance in mm).
TOLERANCES = {"ex00_1_tool_distance_test": {"rtol": 1e-9, "atol": 1e-9}}


def ex00_1_tool_distance_test(rng, spec):
    """distance_mm(q, target): 8 cases, joint angles inside the limits, targets around the arm;
    one target on the tool itself (distance 0) and one at the limits."""
    cases = [(rng.uniform(spec.lower, spec.upper, spec.n_joints), rng.uniform(-0.3, 0.3, 2)) for _ in range(6)]
    q = rng.uniform(spec.lower, spec.upper, spec.n_joints)
    phi = np.cumsum(q)
    on_tool = np.array([np.sum(spec.lengths * np.cos(phi)), np.sum(spec.lengths * np.sin(phi))])
    cases.append((q, on_tool))
    cases.append((np.full(spec.n_joints, float(spec.upper)), rng.uniform(-0.3, 0.3, 2)))
    return cases
