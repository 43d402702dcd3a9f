"""Lesson 04's hidden cases, drawn by the grader anew for every grading batch.

One function per handed-in grade id, taking ``(rng, spec)`` and returning the cases: each a
tuple of the positional arguments the test cell's hand-in calls (see grader/README.md, "Cases").
"""

import numpy as np

#: 4.3's move is timed by 4.1's quintic: a slip there is graded again with the lesson's own.
DEPENDS = {"ex04_3_sample_10hz_test": ["ex04_1_quintic"]}


def ex04_1_quintic_test(rng, spec):
    """quintic(T, t): 5 durations with 20 times each (before 0, inside, after T), and a scalar t."""
    cases = []
    for T in rng.uniform(0.1, 10.0, 5):
        cases.append((float(T), np.sort(rng.uniform(-0.2 * T, 1.2 * T, 20))))
    T = float(rng.uniform(0.5, 5.0))
    cases.append((T, float(rng.uniform(0.0, T))))
    return cases


def ex04_2_trapezoid_test(rng, spec):
    """trapezoid(distance, v_max, a_max): 9 moves of either sign (trapezoids and triangles), no move at
    all, a move backwards, and one exactly on the border between triangle and trapezoid."""
    cases = [(float(d), float(v), float(a)) for d, v, a in
             zip(rng.uniform(-2.0, 2.0, 9), rng.uniform(0.2, 3.0, 9), rng.uniform(0.5, 40.0, 9))]
    v, a = float(rng.uniform(0.5, 2.0)), float(rng.uniform(1.0, 10.0))
    cases += [(0.0, v, a), (-float(rng.uniform(1.0, 2.0)) * v * v / a, v, a), (v * v / a, v, a)]
    return cases


def ex04_3_sample_10hz_test(rng, spec):
    """sample_move(q_start, q_end, duration, rate): 4 moves at 10, 10, 25 and 5 Hz, 0.5 to 4 s, none a whole
    number of goal periods: two a little over one (round(T f) rounds down: the last goal before the end),
    two a little under (it rounds up: the last goal after the end, where the quintic must be clipped)."""
    cases = []
    for rate, part in zip((10.0, 10.0, 25.0, 5.0), (rng.uniform(0.1, 0.4), rng.uniform(0.6, 0.9),
                                                    rng.uniform(0.1, 0.4), rng.uniform(0.6, 0.9))):
        periods = int(rng.integers(int(0.5 * rate), int(4.0 * rate)))
        cases.append((rng.uniform(-1.0, 1.0, 5), rng.uniform(-1.0, 1.0, 5), float((periods + part) / rate), rate))
    return cases


def _random_walk(rng, n, step):
    times = np.cumsum(rng.uniform(0.05, 0.2, n))
    return times, np.cumsum(rng.normal(0.0, step, (n, 5)), axis=0)


def ex04_4_limit_check_test(rng, spec):
    """limit_violations, as (times, positions): 5 random walks that break both limits here and there,
    and one slow walk inside them (no violation)."""
    cases = [_random_walk(rng, int(rng.integers(5, 30)), 0.15) for _ in range(5)]
    times = np.arange(10) * 0.1
    cases.append((times, 0.5 * np.sin(np.outer(times, rng.uniform(0.5, 1.0, 5)))))
    return cases
