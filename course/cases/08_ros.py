"""Lesson 08's hidden cases, drawn by the grader anew for every grading batch.

One function per handed-in grade id, taking ``(rng, spec)`` and returning the cases: each a
tuple of the positional arguments the test cell's hand-in calls (see grader/README.md, "Cases").
No case needs a ROS master: the messages and bags are ROS's own formats, written without ROS.
"""

import numpy as np

TOLERANCES = {
    # a time_from_start is whole nanoseconds, the nearest one (the text asks it rounded): sec + nanosec * 1e-9 is
    # within 1e-14 s of it up to 50 s, and one nanosecond less (t * 1e9 cut, not rounded) is off by 1e-9 s;
    # the positions are copied as they are
    "ex08_1_sweep_message_test": {"rtol": 0.0, "atol": 5e-10},
    # stamps subtracted in whole nanoseconds, then times 1e-9: within 1e-15 s of the exact difference; a wall-clock
    # stamp (1.7e9 s) turned into float seconds first is off by up to 2.4e-7 s, into float nanoseconds by 128 ns,
    # cut to microseconds by up to 1e-6 s: none of those is the time the text asks
    "ex08_2_read_joint_states_test": {"rtol": 0.0, "atol": 1e-9},
}

#: A wall clock's stamp [ns]: about when a live recording is made (ROS time is the Unix time).
WALL = 1_700_000_000_000_000_000


def _task2():
    """The study's Task 2, as ``snakekit.side_sweep()`` builds it: 500 goals at 10 Hz, 50 sweeps of 0.2 rad."""
    times = np.arange(500) / 10.0
    angle = 0.2 * np.sin(2 * np.pi * 50 * times / times[-1])
    angle[-1] = 0.0
    return times, np.repeat(angle[:, None], 5, axis=1)


def ex08_1_sweep_message_test(rng, spec):
    """sweep_message(trajectory), handed its (times, positions): Task 2 itself; sweeps at 3, 7 and 12 Hz, whose
    send times are not whole milliseconds (where t * 1e9 cut, not rounded, is a nanosecond short); one goal alone,
    past a whole second; goals at uneven times."""
    cases = [_task2()]
    for rate in rng.permutation([3.0, 7.0, 12.0]):
        n = int(rng.integers(5, 60))
        cases.append((np.arange(n) / rate, rng.uniform(spec.lower, spec.upper, (n, spec.n_joints))))
    cases.append((np.array([float(rng.uniform(1.01, 9.99))]), rng.uniform(spec.lower, spec.upper, (1, spec.n_joints))))
    n = int(rng.integers(3, 12))
    uneven = np.concatenate([[0.0], np.cumsum(rng.uniform(0.05, 1.5, n - 1))])
    return cases + [(uneven, rng.uniform(spec.lower, spec.upper, (n, spec.n_joints)))]


def _states(rng, n, start, period_ns, jitter_ns=0):
    """n stamps [ns] from ``start``, ``period_ns`` apart (each moved by up to ``jitter_ns``), and n rows of angles."""
    stamps = start + np.arange(n, dtype=np.int64) * period_ns
    if jitter_ns:
        stamps = stamps + rng.integers(-jitter_ns, jitter_ns + 1, n)
    return stamps, rng.uniform(-1.5, 1.5, (n, 5))


def ex08_2_read_joint_states_test(rng, spec):
    """read_joint_states(path), handed (suffix, stamps, positions, order, received): ROS 1 and ROS 2 bags stamped from
    1 s and filed at their stamps (the kit's own bags), the joints in the arm's order; live recordings: a wall
    clock's stamps 50 Hz apart with a jitter of whole nanoseconds, each message filed in the bag 1 to 15 ms after
    its stamp, the joints shuffled; and a bag without joint states (it must raise ValueError). The hand-in keeps
    what read_joint_states returned: a list where the text asks a numpy array is wrong in every case."""
    in_order = np.arange(5)
    cases = []
    for suffix in (".bag", ".mcap"):
        stamps, positions = _states(rng, int(rng.integers(5, 80)), 1_000_000_000, 10_000_000)
        cases.append((suffix, stamps, positions, in_order, stamps))
    for suffix in (".bag", ".mcap"):
        stamps, positions = _states(rng, int(rng.integers(5, 80)), WALL + int(rng.integers(0, 10**15)), 20_000_000,
                                    jitter_ns=2_000_000)
        received = np.maximum.accumulate(stamps + rng.integers(1_000_000, 15_000_001, len(stamps)))
        cases.append((suffix, stamps, positions, rng.permutation(5), received))
    none = np.zeros(0, dtype=np.int64)
    return cases + [(".bag", none, np.zeros((0, 5)), in_order, none)]


def ex08_3_compare_runs_test(rng, spec):
    """compare_runs(times, positions, ref_times, ref_positions): a reference sweep at 100 Hz and recordings of it
    at 50 Hz that lag it by 0.05 to 0.2 s with noise: one inside it (with one reading 0.1 to 0.3 rad further below the
    reference than any other is off, so its largest error is a negative difference), one that starts before it, one that ends after it,
    one on the reference's own times, one without lag with a joint 0.05 to 0.1 rad off all along (the largest rms) and
    another 0.15 to 0.3 rad below once (the largest error: on another joint than the largest rms, since 70 readings or
    more share that one), and one that never overlaps it (it must raise ValueError)."""
    cases = []
    for kind in ("inside", "before", "after", "same", "spike", "apart"):
        duration = float(rng.uniform(2.0, 6.0))
        ref_t = np.arange(0.0, duration, 0.01)
        sweeps, amplitude = int(rng.integers(1, 5)), rng.uniform(0.05, 0.4, 5)
        def sweep(t):
            return amplitude * np.sin(2 * np.pi * sweeps * np.clip(t, 0, duration) / duration)[:, None]
        start, end = {"inside": (0.3, duration - 0.3), "before": (-0.7, duration - 0.5), "after": (0.4, duration + 0.8),
                      "same": (0.0, duration), "spike": (0.3, duration - 0.3),
                      "apart": (duration + 1.0, duration + 3.0)}[kind]
        t = ref_t if kind == "same" else np.arange(start, end, 0.02) + float(rng.uniform(0, 0.02))
        lag = 0.0 if kind == "spike" else float(rng.uniform(0.05, 0.2))
        recorded = sweep(t - lag) + rng.normal(0, 0.002, (len(t), 5))
        if kind == "inside":   # one reading far below the reference: the largest error is negative
            k, j = int(rng.choice(np.flatnonzero((t > 0.1) & (t < duration - 0.1)))), int(rng.integers(5))
            recorded[k, j] = sweep(t[k:k + 1])[0, j] - np.abs(recorded - sweep(t)).max() - float(rng.uniform(0.1, 0.3))
        if kind == "spike":    # the largest rms on one joint, the largest error on another
            steady, once = (int(j) for j in rng.choice(5, 2, replace=False))
            recorded[:, steady] += float(rng.uniform(0.05, 0.1))
            recorded[int(rng.integers(len(t))), once] -= float(rng.uniform(0.15, 0.3))
        cases.append((t, recorded, ref_t, sweep(ref_t)))
    return cases
