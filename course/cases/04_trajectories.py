"""Lesson 04's hidden cases, drawn by the grader anew for every grading batch.

One function per handed-in grade id, taking ``(rng, spec)`` and returning the cases: each a
tuple of the positional arguments the test cell's hand-in calls (see grader/README.md, "Cases").
"""

import numpy as np

#: 4.3's move is timed by 4.1's quintic: a slip there is graded again with the lesson's own.
DEPENDS = {"ex04_3_sample_10hz_test": ["ex04_1_quintic"]}


def ex04_1_quintic_test(rng, spec):
    """quintic(T, t): the polynomial and the hold are judged at cases of their own: 2 durations with 20 times
    inside the move, 3 with 20 times that run past both ends (3 before 0, 14 inside, 3 after T), and a
    scalar t inside. A cubic for the quintic is wrong at every case; a quintic never clipped is right at the
    three inside it, half the exercise."""
    cases = []
    for T in rng.uniform(0.1, 10.0, 2):
        cases.append((float(T), np.sort(rng.uniform(0.0, T, 20))))
    for T in rng.uniform(0.1, 10.0, 3):
        cases.append((float(T), np.sort(np.concatenate([rng.uniform(-0.2 * T, 0.0, 3), rng.uniform(0.0, T, 14),
                                                        rng.uniform(T, 1.2 * T, 3)]))))
    T = float(rng.uniform(0.5, 5.0))
    cases.append((T, float(rng.uniform(0.0, T))))
    return cases


def ex04_2_trapezoid_test(rng, spec):
    """trapezoid(distance, v_max, a_max): 8 moves, as many triangles as trapezoids and as many backwards as
    forwards (a triangle: |d| below v_max^2 / a_max, from 5 % of it; a trapezoid: 1.2 to 4 times it), no
    move at all, a move backwards, and one exactly on the border between triangle and trapezoid. Drawn at
    random sizes alone, trapezoids would be most moves, and a trapezoid with no triangle nearly right.
    The first triangle is a long one at v_max above 1.25 rad/s: longer than v_max / a_max (the
    visible check's 0.6 rad move is one too), so the border taken at v_max / a_max fails at every draw."""
    cases = []
    for k, (share, sign) in enumerate(((0.05, 1.0), (0.05, -1.0), (0.05, 1.0), (0.05, -1.0),
                                       (1.2, 1.0), (1.2, -1.0), (1.2, 1.0), (1.2, -1.0))):
        v, a = float(rng.uniform(0.2, 3.0)), float(rng.uniform(0.5, 40.0))
        factor = rng.uniform(share, 0.95) if share < 1.0 else rng.uniform(share, 4.0)
        if k == 0:  # a long triangle: 0.8 v^2 / a > v / a when v > 1.25
            v, factor = float(rng.uniform(1.5, 3.0)), rng.uniform(0.8, 0.95)
        cases.append((float(sign * factor * v * v / a), v, a))
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


def _beyond(rng, times, positions, spec, sides):
    """The walk held inside the position limits, then 1 to 3 goals put beyond them on each of ``sides``
    (+1 upper, -1 lower): which limit a case breaks is part of the case, not of the draw's luck."""
    q = np.clip(positions, -0.9 * spec.upper, 0.9 * spec.upper)
    for side in sides:
        for _ in range(int(rng.integers(1, 4))):
            k, j = int(rng.integers(len(times))), int(rng.integers(5))
            q[k, j] = side * float(spec.upper + rng.uniform(0.01, 0.3))
    return times, q


def ex04_4_limit_check_test(rng, spec):
    """limit_violations, as (times, positions): 5 random walks (every one also too fast here and there), two
    beyond the upper position limit only, two beyond the lower only, one beyond both, and one slow walk
    inside them (no violation)."""
    cases = [_beyond(rng, *_random_walk(rng, int(rng.integers(5, 30)), 0.15), spec, sides)
             for sides in ((1,), (1,), (-1,), (-1,), (1, -1))]
    times = np.arange(10) * 0.1
    cases.append((times, 0.5 * np.sin(np.outer(times, rng.uniform(0.5, 1.0, 5)))))
    return cases
