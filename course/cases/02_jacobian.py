"""Lesson 02's hidden cases, drawn by the grader anew for every grading batch."""

import numpy as np

#: The grader's tolerances per grade id: as the visible checks' (finite differences: 1e-6; at a
#: singular pose det(J J^T) rounds to up to about 1e-17 either side of 0, so the manipulability, its
#: square root, to up to 3e-9: 1e-8, far below any real mistake).
TOLERANCES = {"ex02_1_planar_jacobian_test": {"rtol": 1e-9, "atol": 1e-12},
              "ex02_2_numerical_jacobian_test": {"rtol": 0.0, "atol": 1e-6},
              "ex02_3_manipulability_test": {"rtol": 1e-9, "atol": 1e-8}}

#: 2.3 may take J from the student's own 2.1 (its text allows it): a slip there is graded again with the
#: lesson's own 2.1.
DEPENDS = {"ex02_3_manipulability_test": ["ex02_1_planar_jacobian"]}


def ex02_1_planar_jacobian_test(rng, spec):
    """planar_jacobian(q): 10 cases, random poses inside the limits, the limits, the straight arm, and a pose
    whose links 3 to 5 point within 2e-3 rad of x (the visible check's kind): entries of the x row near 1e-4 m,
    where only the exact formula is within 1e-9 relative (a finite difference is off by about 1e-11 m)."""
    q = list(rng.uniform(spec.lower, spec.upper, (7, spec.n_joints)))
    near = np.zeros(spec.n_joints)
    near[:2] = rng.uniform(-0.6, 0.6, 2)
    near[2] = -near[0] - near[1] + rng.uniform(-2e-3, 2e-3)
    near[3:] = rng.uniform(-1e-3, 1e-3, spec.n_joints - 3)
    return [(x,) for x in q + [np.full(spec.n_joints, float(spec.upper)), np.zeros(spec.n_joints), near]]


def ex02_2_numerical_jacobian_test(rng, spec):
    """numerical_jacobian on the test functions the check cell names ("g", "tool"), at random
    points and steps: (function name, q, h). 8 cases, the visible check's kinds:
    - six at steps of 0.0003 to 0.002 (the visible 1e-3), where a one-sided difference is off the
      central one by h |f''| / 2, far more than the tolerance (it is right at tiny steps only);
    - one at the default step 1e-6;
    - one large step (0.03 to 0.2, the visible 0.1), where the central difference is off the exact
      Jacobian by far more than the tolerance, so a function that ignores its ``h`` is caught."""
    cases = [("g", rng.uniform(-1.5, 1.5, 3), float(10 ** rng.uniform(-3.5, -2.7))) for _ in range(4)]
    cases += [("tool", rng.uniform(spec.lower, spec.upper, spec.n_joints), float(10 ** rng.uniform(-3.5, -2.7)))
              for _ in range(2)]
    return cases + [("g", rng.uniform(-1.5, 1.5, 3), 1e-6),
                    ("g", rng.uniform(-1.5, 1.5, 3), float(rng.uniform(0.03, 0.2)))]


def ex02_3_manipulability_test(rng, spec):
    """manipulability(q): 10 cases, random poses, the straight arm and the straight arm turned by
    joint 1 alone (singular: w = 0, up to rounding), one of them where det(J J^T) rounds below 0 (the
    visible check's 0.55 rad: an unclipped square root is nan there, so it is wrong graded as locally),
    and the arm bent at joint 5 alone (w small)."""
    q = list(rng.uniform(spec.lower, spec.upper, (6, spec.n_joints)))
    first, below, last = np.zeros(spec.n_joints), np.zeros(spec.n_joints), np.zeros(spec.n_joints)
    first[0], below[0], last[-1] = rng.uniform(-1.5, 1.5), 0.55, rng.uniform(0.5, 1.5)
    return [(x,) for x in q + [np.zeros(spec.n_joints), first, below, last]]
