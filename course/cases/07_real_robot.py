"""Lesson 07's hidden cases, drawn by the grader anew for every grading batch.

One function per handed-in grade id, taking ``(rng, spec)`` and returning the cases: each a
tuple of the positional arguments the test cell's hand-in calls (see grader/README.md, "Cases").
7.2 and 7.3 run on the bus emulator in real time: few cases, short moves.
"""

import numpy as np

#: 7.2: a planned duration is sampled every 10 ms; the servo settles within 0.01 rad (the lesson's check).
TOLERANCES = {"ex07_1_ticks_test": {"rtol": 0.0, "atol": 0.0},
              "ex07_2_safe_move_test": {"rtol": 0.0, "atol": 0.011},
              "ex07_3_fault_test": {"rtol": 0.0, "atol": 0.0}}


def ex07_1_ticks_test(rng, spec):
    """to_ticks(q): 40 angles in [-pi, pi], 5 joint angles within the limits, and one number alone."""
    return [(rng.uniform(-np.pi, np.pi, 40),), (rng.uniform(spec.lower, spec.upper),),
            (float(rng.uniform(-np.pi, np.pi)),)]


def ex07_2_safe_move_test(rng, spec):
    """graded_safe_move(start, target, margin): two moves from a bent pose, a short one (0.2 s at least),
    and two targets too close to the limits, one on each side (one only because of a wide margin)."""
    start = rng.uniform(-0.4, 0.4, 5)
    cases = [(start, rng.uniform(-0.6, 0.6, 5), 0.05), (rng.uniform(-0.4, 0.4, 5), rng.uniform(-0.6, 0.6, 5), 0.1)]
    cases.append((start, start + rng.uniform(-0.05, 0.05, 5), 0.05))
    near = np.zeros(5)
    j = int(rng.integers(5))
    near[j] = float(rng.choice([-1.0, 1.0]) * rng.uniform(spec.upper - 0.04, spec.upper))
    cases.append((np.zeros(5), near, 0.05))
    wide = np.zeros(5)   # on the other side from the near one: a refusal of one side only fails one of the two
    wide[int(rng.integers(5))] = -np.sign(near[j]) * float(rng.uniform(1.1, 1.3))
    cases.append((np.zeros(5), wide, 0.5))
    return cases


def ex07_3_fault_test(rng, spec):
    """graded_recover(ids): two servos overloading, one, and none."""
    ids = sorted(int(i) for i in rng.choice([1, 2, 3, 4, 5], 2, replace=False))
    return [(np.array(ids),), (np.array([int(rng.integers(1, 6))]),), (np.zeros(0, dtype=int),)]
