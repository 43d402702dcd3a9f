"""The test course's hidden cases, drawn by the grader anew for every grading batch."""

import numpy as np


def ex1_tool_xy_test(rng, spec):
    """tool_xy(q): 8 random poses within +-1.5 rad."""
    return [(rng.uniform(-1.5, 1.5, spec.n_joints),) for _ in range(8)]


def ex2_sweep_test(rng, spec):
    """graded_run(points, rate, sweeps, amplitude): one short sweep on the simulator (5 to 8 s),
    slow enough to stay inside the velocity limit."""
    rate = float(rng.choice([10.0, 20.0]))
    points = int(rng.integers(5, 8) * rate)
    sweeps = int(rng.integers(2, 4))
    amplitude = float(np.round(rng.uniform(0.1, 0.25), 3))
    return [(points, rate, sweeps, amplitude)]
