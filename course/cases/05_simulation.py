"""Lesson 05's hidden cases, drawn by the grader anew for every grading batch.

One function per handed-in grade id, taking ``(rng, spec)`` and returning the cases: each a
tuple of the positional arguments the test cell's hand-in calls (see grader/README.md, "Cases").
"""

import numpy as np


def _second_order(zeta, omega, start, target, n=300, dt=0.01):
    """A textbook step response: start -> target, damping ratio zeta, natural frequency omega [rad/s]."""
    t = np.arange(n) * dt
    wd = omega * np.sqrt(1 - zeta ** 2)
    s = 1 - np.exp(-zeta * omega * t) * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta ** 2) * np.sin(wd * t))
    return t, start + (target - start) * s


def _responses(rng, k=6):
    """k step responses, up and down, starting anywhere; some overshoot (low damping), one never
    passes its target (critically damped, cut off before it arrives). The first goes up and the
    second down, both overshooting by 9 % or more (damping ratio 0.6 or less): every draw holds a
    step down that passes its target, where an overshoot taken at max(y), or divided by the step's
    size, is wrong (as in 5.2's visible check)."""
    out = []
    for i, (zeta, omega) in enumerate(zip(rng.uniform(0.2, 0.95, k - 1), rng.uniform(5.0, 30.0, k - 1))):
        start, target = rng.uniform(-1.0, 1.0), rng.uniform(-1.5, 1.5)
        if abs(target - start) < 0.2:
            target = start + 0.5
        if i < 2:
            zeta = min(zeta, 0.6)
            if (target > start) != (i == 0):
                start, target = target, start
        out.append((*_second_order(zeta, omega, start, target), float(target)))
    start, target = rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)
    t = np.arange(120) * 0.01
    out.append((t, start + (target - start) * (1 - np.exp(-rng.uniform(3.0, 5.0) * t)), float(target)))
    return out


def ex05_1_rise_time_test(rng, spec):
    """rise_time(t, y, target): 6 step responses."""
    return [(t, y, g) for t, y, g in _responses(rng)]


def ex05_2_overshoot_test(rng, spec):
    """overshoot(y, target): 6 step responses (one never passes its target: 0)."""
    return [(y, g) for _, y, g in _responses(rng)]


def ex05_3_steady_state_error_test(rng, spec):
    """steady_state_error(y, target, window): 6 step responses, windows from 1 to 40 samples, and one
    response with the window left at the function's default (the last, cut off before it arrives, so
    that its last samples differ)."""
    responses = _responses(rng)
    cases = [(y, g, int(w)) for (_, y, g), w in zip(responses, rng.integers(1, 40, 6))]
    _, y, target = responses[-1]
    return cases + [(y, target)]


def ex05_4_profile_velocity_test(rng, spec):
    """profile_move_time(distance, profile_velocity, profile_acceleration): 8 moves of either sign,
    a short one that never reaches its profile velocity (a triangle), and a long one with a Profile
    Velocity above the arm's speed limit (the firmware plans it all the same), fast enough that a
    speed clipped to the limit takes longer."""
    cases = [(float(d), int(pv), int(pa)) for d, pv, pa in
             zip(rng.uniform(-2.5, 2.5, 8), rng.integers(5, 200, 8), rng.integers(5, 300, 8))]
    cases.append((float(rng.uniform(0.005, 0.02)), int(rng.integers(40, 80)), int(rng.integers(50, 150))))
    # the largest register within the limit: 62 for 1.5 rad/s (units of 0.229 rev/min)
    top = int(spec.velocity_limit / (0.229 * 2 * np.pi / 60))
    # at least 1 rad, at 18.7 rad/s^2 or more: past 1.5 rad/s within the first 0.12 rad
    cases.append((float(rng.choice([-1, 1]) * rng.uniform(1.0, 2.5)), int(rng.integers(top + 1, 200)),
                  int(rng.integers(50, 300))))
    return cases
