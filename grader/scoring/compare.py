"""Trajectory checks: each scores a fraction in [0, 1] and says why, with numbers.

Every check returns a :class:`Check`: a ``fraction`` of its ``weight`` (partial credit) and a
message a student can act on: which joint, when, by how much, and the tolerance. The
functions take plain arrays and :class:`snakekit.trajectory.Trajectory` objects only; they
run in the grader's own process, on what the student's kernel handed in.

>>> import numpy as np
>>> from snakekit.trajectory import side_sweep
>>> ref = side_sweep()
>>> point_count(ref, 500).fraction, rate(ref, 10.0).fraction, sweep_count(ref, 50).fraction
(1.0, 1.0, 1.0)
>>> print(rate(Trajectory(ref.times / 10, ref.positions), 10.0).message)
rate: 100 Hz between points, expected 10 Hz (tolerance 1%). Hint: this looks like 100 Hz where 10 Hz was asked: the time step is 0.1 s.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from snakekit.model import SPEC, SnakeSpec
from snakekit.trajectory import Trajectory

__all__ = ["GUESSES", "TEN_TIMES", "STARTS_AT_1", "NOT_HOME", "TRANSPOSE", "Check", "falloff", "align", "tracking", "point_count", "rate", "limits", "sweep_count",
           "home", "smoothness", "count_sweeps"]


#: The grader's own guesses at a mistake from the numbers of a hidden case, as they end a message: the
#: hints of :func:`rate` and :func:`home` and the transpose of :func:`grader.scoring.score._compare_case`.
#: Where the notebook's own check names the mistake, its hint is the one shown, and :data:`GUESSES`
#: (made from these) takes them out (:func:`grader.scoring.verdict.with_local_check`).
TEN_TIMES = " Hint: this looks like {fast:g} Hz where {asked:g} Hz was asked: the time step is {step:g} s."
STARTS_AT_1 = " Hint: the time vector starts at 1 instead of 0."
NOT_HOME = " Hint: the sweep does not return home."
TRANSPOSE = " (the transpose?)"
GUESSES = re.compile("|".join(re.sub(r"\\\{\w+:g\\\}", r"\\S+", re.escape(g))   # a number in the text: any word
                              for g in (TEN_TIMES, STARTS_AT_1, NOT_HOME, TRANSPOSE)))


@dataclass(frozen=True)
class Check:
    """One scored check: ``fraction`` in [0, 1] of ``weight``, and a message with the numbers."""

    name: str
    fraction: float
    message: str
    weight: float = 1.0

    def __post_init__(self):
        f = float(self.fraction)
        object.__setattr__(self, "fraction", 0.0 if not np.isfinite(f) else min(max(f, 0.0), 1.0))

    @property
    def passed(self) -> bool:
        return self.fraction >= 1.0


def falloff(error: float, tol: float, zero_at: float) -> float:
    """Partial credit: 1 up to ``tol``, falling linearly to 0 at ``zero_at`` (same units).

    >>> falloff(0.5, 1.0, 3.0), falloff(2.0, 1.0, 3.0), falloff(5.0, 1.0, 3.0)
    (1.0, 0.5, 0.0)
    """
    if not np.isfinite(error):
        return 0.0
    if error <= tol:
        return 1.0
    return float(max(0.0, 1.0 - (error - tol) / max(zero_at - tol, 1e-300)))


def _deg(x: float) -> str:
    return f"{x:.4g} rad ({np.degrees(x):.3g} deg)"


# --- time alignment ---------------------------------------------------------------------------


def align(student: Trajectory, reference: Trajectory, *, rate: float | None = None):
    """Both trajectories on one time grid, with time measured from each one's first point.

    The grid spans the part both cover, at ``rate`` [Hz] (default: the reference's median
    rate). Returns ``(t, student_positions, reference_positions)``.
    """
    ts = student.times - student.times[0]
    tr = reference.times - reference.times[0]
    if rate is None:
        rate = 1.0 / float(np.median(np.diff(tr))) if len(tr) > 1 else 1.0
    end = min(ts[-1], tr[-1])
    t = np.arange(int(np.floor(end * rate + 1e-9)) + 1) / rate
    s = Trajectory(ts, student.positions, n_joints=student.n_joints).sample(t)
    r = Trajectory(tr, reference.positions, n_joints=reference.n_joints).sample(t)
    return t, s, r


def tracking(student: Trajectory, reference: Trajectory, *, max_tol: float, rms_tol: float,
             zero_factor: float = 10.0, what: str = "joint angle", name: str = "error vs reference",
             weight: float = 1.0) -> Check:
    """Maximum and RMS error per joint against the reference, on a common grid.

    Each joint earns ``falloff`` credit on its maximum and on its RMS error (half each),
    reaching 0 at ``zero_factor`` times the tolerance. A trajectory that covers less time
    than the reference loses the missing share.
    """
    t, s, r = align(student, reference)
    if len(t) < 2:
        return Check(name, 0.0, f"{name}: the {what}s cover {t[-1] if len(t) else 0:.3g} s, nothing to compare", weight)
    err = s - r
    emax = np.abs(err).max(axis=0)
    erms = np.sqrt((err ** 2).mean(axis=0))
    per_joint = [0.5 * falloff(a, max_tol, zero_factor * max_tol) + 0.5 * falloff(b, rms_tol, zero_factor * rms_tol)
                 for a, b in zip(emax, erms)]
    step = float(np.median(np.diff(t)))
    coverage = 1.0 if reference.duration - t[-1] < 1.5 * step else t[-1] / max(reference.duration, 1e-12)
    fraction = float(np.mean(per_joint)) * coverage
    j = int(np.argmax(emax / max_tol))
    i = int(np.argmax(np.abs(err[:, j])))
    head = (f"{name}: largest {what} error joint {j + 1} at t={t[i]:.2f} s is {err[i, j]:+.4g} rad "
            f"({s[i, j]:+.4f} rad, expected {r[i, j]:+.4f} rad; tolerance {max_tol:.3g} rad); "
            "RMS per joint " + " ".join(f"j{k + 1} {e:.3g}" for k, e in enumerate(erms)) +
            f" rad (tolerance {rms_tol:.3g} rad)")
    if coverage < 1:
        head += f"; covers {t[-1]:.2f} s of the reference's {reference.duration:.2f} s"
    if fraction >= 1:
        head = (f"{name}: within tolerance (max {emax.max():.3g} rad <= {max_tol:.3g}, "
                f"RMS {erms.max():.3g} rad <= {rms_tol:.3g})")
    return Check(name, fraction, head + ".", weight)


# --- facts about one trajectory ---------------------------------------------------------------


def point_count(traj: Trajectory, expected: int, *, weight: float = 1.0) -> Check:
    """The number of points; credit falls with the relative difference."""
    n = len(traj)
    f = max(0.0, 1.0 - abs(n - expected) / expected)
    if n == expected:
        return Check("points", 1.0, f"points: {n}, as asked.", weight)
    return Check("points", f, f"points: {n}, expected {expected} (off by {n - expected:+d}).", weight)


def rate(traj: Trajectory, expected_hz: float, *, rel_tol: float = 0.01, weight: float = 1.0) -> Check:
    """The sending rate: median time step, uniformity, and a start at t = 0.

    Credit: half for the median rate (falling to 0 at ten times the tolerance), a quarter for
    a steady step, a quarter for starting at 0 s.
    """
    if len(traj) < 2:
        return Check("rate", 0.0, "rate: a single point has no rate.", weight)
    dt = np.diff(traj.times)
    got = 1.0 / float(np.median(dt))
    rel = abs(got - expected_hz) / expected_hz
    f_rate = falloff(rel, rel_tol, 10 * rel_tol)
    step = 1.0 / expected_hz
    jitter = float(np.abs(dt - 1.0 / got).max())
    f_uniform = 1.0 if jitter <= rel_tol * step else 0.0
    t0 = float(traj.times[0])
    f_start = 1.0 if abs(t0) <= rel_tol * step else 0.0
    f = 0.5 * f_rate + 0.25 * f_uniform + 0.25 * f_start
    parts = []
    if f_rate < 1:
        hint = ""
        if abs(got - 10 * expected_hz) / (10 * expected_hz) < rel_tol:
            hint = TEN_TIMES.format(fast=10 * expected_hz, asked=expected_hz, step=step)
        parts.append(f"{got:.4g} Hz between points, expected {expected_hz:g} Hz (tolerance {rel_tol:.0%}).{hint}")
    if f_uniform < 1:
        i = int(np.argmax(np.abs(dt - 1.0 / got)))
        parts.append(f"the step between points {i} and {i + 1} is {dt[i]:.4g} s, expected a steady {1 / got:.4g} s.")
    if f_start < 1:
        hint = STARTS_AT_1 if abs(t0 - 1) < 1e-6 else ""
        parts.append(f"the first point is at t={t0:.4g} s, expected 0 s.{hint}")
    if not parts:
        return Check("rate", 1.0, f"rate: {got:.4g} Hz, steady, from t=0 s.", weight)
    return Check("rate", f, "rate: " + " ".join(parts), weight)


def limits(traj: Trajectory, spec: SnakeSpec = SPEC, *, weight: float = 1.0) -> Check:
    """Position and velocity limits; credit is the share of points and steps inside them."""
    bad = traj.limit_violations(spec)
    if not bad:
        return Check("limits", 1.0, f"limits: every point within {spec.lower}..{spec.upper} rad and "
                                    f"{spec.velocity_limit} rad/s.", weight)
    t = traj.times
    beyond = np.zeros(len(t), dtype=bool)
    for v in bad:  # one violation per stretch: every sample from its start to its end
        beyond |= (t >= v.start - 1e-12) & (t <= v.end + 1e-12)
    points = int(beyond.sum())
    f = 1.0 - points / len(traj)
    worst = []
    for kind in ("position", "velocity"):
        some = [v for v in bad if v.kind == kind]
        if some:
            w = max(some, key=lambda v: abs(v.value) - abs(v.bound))
            unit = "rad" if kind == "position" else "rad/s"
            worst.append(f"worst {kind}: {w}; {abs(w.value) - abs(w.bound):.4g} {unit} over")
    return Check("limits", f, f"limits: {len(bad)} stretch(es) beyond a limit, at {points} of {len(traj)} points; "
                              + "; ".join(worst) + ".", weight)


def count_sweeps(positions: np.ndarray, *, hysteresis: float = 0.02) -> float:
    """Full side-to-side sweeps in ``positions`` (N, n_joints) [rad]: side changes / 2.

    The side is the sign of the mean joint angle; it must pass ``hysteresis`` [rad] beyond
    zero to count, so noise around home is not a sweep.
    """
    m = np.asarray(positions, dtype=float).mean(axis=1)
    side, changes = 0, 0
    for x in m:
        s = 1 if x > hysteresis else (-1 if x < -hysteresis else 0)
        if s and s != side:
            changes += side != 0
            side = s
    # a sweep goes to one side and the other and back: the first side counts too
    return (changes + (1 if side else 0)) / 2


def sweep_count(traj: Trajectory, expected: int, *, weight: float = 1.0) -> Check:
    """The number of full side-to-side sweeps; credit falls with the relative difference."""
    n = count_sweeps(traj.positions)
    f = max(0.0, 1.0 - abs(n - expected) / expected)
    if n == expected:
        return Check("sweeps", 1.0, f"sweeps: {n:g}, as asked.", weight)
    return Check("sweeps", f, f"sweeps: {n:g}, expected {expected} (off by {n - expected:+g}).", weight)


def home(traj: Trajectory, spec: SnakeSpec = SPEC, *, tol: float = 1e-3, weight: float = 1.0) -> Check:
    """Start and end at home (half the credit each): every joint within ``tol`` [rad] of it."""
    parts, f = [], 0.0
    for label, q in (("starts", traj.positions[0]), ("ends", traj.positions[-1])):
        d = np.abs(q - np.asarray(spec.home))
        if d.max() <= tol:
            f += 0.5
        else:
            j = int(d.argmax())
            parts.append(f"it {label} with joint {j + 1} at {q[j]:+.4f} rad, expected home "
                         f"{spec.home[j]:+.4f} rad: off by {_deg(d[j])} (tolerance {tol:g} rad).")
    if not parts:
        return Check("home", 1.0, f"home: starts and ends at home (within {tol:g} rad).", weight)
    hint = NOT_HOME if len(parts) == 1 and "ends" in parts[0] else ""
    return Check("home", f, "home: " + " ".join(parts) + hint, weight)


def smoothness(traj: Trajectory, reference: Trajectory, *, factor: float = 1.5, weight: float = 1.0) -> Check:
    """Peak joint acceleration against the reference's: full credit up to ``factor`` times it.

    Acceleration is the second finite difference of the positions [rad/s^2]; a jumpy
    trajectory (steps, noise, a reversed segment) has a far larger one than a smooth sweep.
    Credit reaches 0 at ``4 * factor`` times the reference's peak.
    """
    def peak(tr):
        if len(tr) < 3:
            return 0.0, 0, 0
        dt = np.diff(tr.times)
        v = np.diff(tr.positions, axis=0) / dt[:, None]
        a = np.diff(v, axis=0) / dt[1:, None]
        i, j = np.unravel_index(int(np.argmax(np.abs(a))), a.shape)
        return float(np.abs(a).max()), int(i) + 1, int(j)

    ref_peak, _, _ = peak(reference)
    got, i, j = peak(traj)
    tol = factor * max(ref_peak, 1e-9)
    f = falloff(got, tol, 4 * tol)
    if f >= 1:
        return Check("smoothness", 1.0, f"smoothness: peak acceleration {got:.3g} rad/s^2 "
                                        f"(tolerance {tol:.3g}).", weight)
    return Check("smoothness", f, f"smoothness: joint {j + 1} at t={traj.times[i]:.2f} s accelerates at "
                                  f"{got:.3g} rad/s^2, expected at most {tol:.3g} rad/s^2 "
                                  f"({factor:g}x the reference's peak); is there a jump in the trajectory?", weight)
