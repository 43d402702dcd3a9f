"""Lesson 06's hidden cases, drawn by the grader anew for every grading batch.

One function per handed-in grade id, taking ``(rng, spec)`` and returning the cases: each a
tuple of the positional arguments the test cell's hand-in calls (see grader/README.md, "Cases").
The sweeps are short (at most 20 s of robot time), so a simulator run costs a fraction of Task 2's.
"""

import numpy as np

#: The lag is the minimum of a flat rms curve; the simulator repeats itself, and the lesson's method at the
#: run's own times gives one lag to the millisecond (another reasonable window moves it by 1 ms at most, measured
#: on these sweeps). 6 ms apart is the same lag (the lesson's check): the lag that minimises the mean absolute
#: difference instead of the rms lies within 4 ms of it on every sweep drawn here (:data:`SLOW`, :data:`BRISK`),
#: so either measure passes, at every draw. Lags tried 20 ms apart miss the slow sweep's by 8 ms or more: they fail.
TOLERANCES = {"ex06_4_phase_lag_test": {"rtol": 0.0, "atol": 0.006}}

#: 6.3's sweep is built from 6.1 and 6.2: a slip there is graded again with the lesson's own.
DEPENDS = {"ex06_3_task2_test": ["ex06_1_sweep_times", "ex06_2_sweep_positions"]}


def _uneven_end(rng):
    """(points, rate) where the steps of 1/rate, added in floating point, end just short of points/rate:
    ``np.arange(0, points / rate, 1 / rate)`` holds one time too many there (about one case in eight)."""
    while True:
        points, rate = int(rng.integers(2, 800)), float(rng.uniform(1.0, 200.0))
        if len(np.arange(0, points / rate, 1 / rate)) != points:
            return points, rate


def ex06_1_sweep_times_test(rng, spec):
    """sweep_times(points, rate): 5 cases, one where floating-point steps of 1/rate end just short of the
    end (:func:`_uneven_end`), and one goal alone."""
    cases = [(int(n), float(f)) for n, f in zip(rng.integers(2, 800, 5), rng.uniform(1.0, 200.0, 5))]
    return cases + [_uneven_end(rng), (1, float(rng.uniform(1.0, 50.0)))]


def ex06_2_sweep_positions_test(rng, spec):
    """sweep_positions(times, sweeps, amplitude): 5 runs of 20 to 300 goals at 5 to 50 Hz."""
    return [(np.arange(int(n)) / f, int(k), float(a)) for n, f, k, a in
            zip(rng.integers(20, 300, 5), rng.uniform(5.0, 50.0, 5), rng.integers(1, 6, 5), rng.uniform(0.05, 0.5, 5))]


#: The rates of 6.3's sweeps inside the limits: each once, so a sweep that ignores its rate argument
#: (and sends Task 2's 10 Hz) is wrong in two of the three, whatever the seed.
RATES = (5.0, 10.0, 20.0)


def _sweep(rng, spec, max_points, rate):
    """(points, rate, sweeps, amplitude) of a sweep at ``rate`` [Hz] well inside the limits: at least
    8 goals a sweep, a peak speed of at most 2/3 of the velocity limit, at most 20 s long."""
    rate = float(rate)
    points = int(rng.integers(40, min(max_points, int(20 * rate) + 2)))     # at most 20 s of robot time
    amplitude = float(rng.uniform(0.05, 0.3))
    fastest = spec.velocity_limit * 2 / 3 * (points - 1) / (amplitude * 2 * np.pi * rate)
    sweeps = int(rng.integers(1, max(2, min(points // 8, int(fastest)) + 1)))
    return points, rate, sweeps, amplitude


def ex06_3_task2_test(rng, spec):
    """task2_sweep(points, rate, sweeps, amplitude): 3 sweeps inside the limits (run on the simulator),
    one at each of :data:`RATES`,
    one beyond the position limits (the instructor's raises LimitError: so must the student's), and
    Task 2 itself: ``task2_sweep()`` at its defaults (the empty case; its 50 s run costs the
    simulator about as much as the lesson's own run of it)."""
    cases = [_sweep(rng, spec, 200, rate) for rate in rng.permutation(RATES)]
    points, rate, sweeps, _ = _sweep(rng, spec, 200, rng.choice(RATES))
    return cases + [(points, rate, sweeps, float(rng.uniform(spec.upper + 0.1, 2.5))), ()]


#: 6.4's slow, small sweep: its peak speed [rad/s]. The simulated servo lags it by 0.169 to 0.172 s (measured
#: over this band, 200 draws), 8 ms or more from the nearest of 0.16 and 0.18 s and 18 ms or more from the nearest
#: of 0.15 and 0.2 s: lags tried 20 ms or 50 ms apart miss it by more than the 6 ms tolerance, at every draw. The
#: mean absolute difference finds its lag 1 to 4 ms earlier than the rms: inside the tolerance.
SLOW = (0.099, 0.102)

#: The peak speed [rad/s] the other two sweeps of 6.4 reach at least. Slower still, the lag grows (0.19 to 0.22 s
#: below 0.08 rad/s) and the mean absolute difference finds it up to 7 ms earlier than the rms: a student who
#: measured the agreement that defensible way would lose the case at some draws and not at others. From this
#: speed on the two measures agree within 2 ms.
BRISK = 0.15


def ex06_4_phase_lag_test(rng, spec):
    """graded_lag(points, rate, sweeps, amplitude, joint): 3 sweeps at 10 Hz, 100 to 200 goals, one joint
    each (the lesson's text: 10 Hz goals, so the lag is about half a goal period plus the servo's). The
    first is slow and small (peak speed in :data:`SLOW`), which lags more, between the steps of a 20 ms grid
    and of a 50 ms one; the others peak at :data:`BRISK` or faster, with at least 12 goals a sweep."""
    cases = []
    for k, joint in enumerate(rng.choice(5, 3, replace=False)):
        points = int(rng.integers(100, 200))
        if k == 0:
            sweeps = int(rng.integers(3, 6))
            amplitude = float(rng.uniform(*SLOW)) * (points / 10.0) / (2 * np.pi * sweeps)
        else:
            amplitude = float(rng.uniform(0.05, 0.15))
            fewest = max(3, int(np.ceil(BRISK * points / (amplitude * 2 * np.pi * 10.0))))
            sweeps = int(rng.integers(fewest, points // 12 + 1))
        cases.append((points, 10.0, sweeps, amplitude, int(joint)))
    return cases
