"""Joint trajectories: a validated value type, time scaling, files, and the study's sweep.

A :class:`Trajectory` is a list of timed joint configurations: ``times`` [s] of shape (N,),
``positions`` [rad] of shape (N, n_joints), and optionally ``velocities`` [rad/s].
"""

from __future__ import annotations

import csv
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import (ConfigurationError, FileFormatError, LimitError, NotFiniteError, ShapeError, SnakekitError,
                     TrajectoryError)
from .model import SPEC, SnakeSpec
from .validate import (MAX_DURATION, MAX_POINTS, as_path, check_count, check_duration, check_flag, check_length,
                       check_limits, check_rate, check_spec, excerpt, finite_array, frozen, number, quote, read_npz,
                       readable_file, real_array, sample_count, write_failed, writable_file)


@dataclass(frozen=True)
class Violation:
    """One stretch of a trajectory where a joint is beyond a limit.

    Attributes:
        joint: the joint, counted from 1.
        kind: ``"position"`` [rad]; ``"velocity"`` [rad/s], the speed between consecutive
            points (what a servo given these goals must move at); or ``"stored velocity"``
            [rad/s], the trajectory's own ``velocities`` array.
        time: when the worst value happens [s] (a speed between points is stamped at the
            later point).
        value: the worst value in the stretch.
        bound: the limit it crosses (signed).
        start, end: first and last time of the stretch [s].
        points: how many samples the stretch holds.
    """

    joint: int
    time: float
    kind: str
    value: float
    bound: float
    start: float = 0.0
    end: float = 0.0
    points: int = 1

    def __str__(self) -> str:
        unit = "rad" if self.kind == "position" else "rad/s"
        text = (f"joint {self.joint} at t={self.time:.3f} s: {self.kind} {self.value:+.4f} {unit} "
                f"(limit {self.bound:+.4f})")
        if self.points > 1:
            text += f", beyond it from t={self.start:.3f} to {self.end:.3f} s ({self.points} points)"
        return text


def _stretches(values: np.ndarray, times: np.ndarray, lower: float, upper: float, kind: str) -> list[Violation]:
    """The stretches of ``values`` (samples x joints) outside ``[lower, upper]``, one per joint,
    side and contiguous run."""
    out = []
    for side, bad_all in ((1, values > upper), (-1, values < lower)):
        bound = upper if side > 0 else lower
        for j in np.flatnonzero(bad_all.any(axis=0)):
            bad = bad_all[:, j]
            edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(np.int8), [0]])))
            for first, stop in zip(edges[::2], edges[1::2]):
                seg = values[first:stop, j]
                worst = first + int(np.argmax(side * seg))
                out.append(Violation(int(j) + 1, float(times[worst]), kind, float(values[worst, j]), float(bound),
                                     float(times[first]), float(times[stop - 1]), int(stop - first)))
    return out


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Timed joint positions, validated on construction. Arrays are read-only.

    Args:
        times: strictly increasing sample times [s], shape (N,), N >= 1.
        positions: joint angles [rad], shape (N, n_joints).
        velocities: optional joint rates [rad/s], shape (N, n_joints).
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None
    n_joints: int = SPEC.n_joints

    def __post_init__(self):
        n = check_count(self.n_joints, "n_joints", 1, 100, hint="It is how many joints the arm has (default: 5)")
        object.__setattr__(self, "n_joints", n)
        for name in ("times", "positions", "velocities"):  # before any memory is taken for them
            check_length(getattr(self, name), f"trajectory {name}")
        t = real_array(self.times, "times", "(N,)", "Give one time [s] per point")
        p = real_array(self.positions, "positions", f"(N, {n})", f"Give {n} angles [rad] per time")
        if t.ndim != 1 or t.size == 0:
            raise ShapeError("times", "(N,) with N >= 1", t.shape, "give one time [s] per point")
        if p.ndim == 1 and p.size == n and t.size == 1:
            p = p[None, :]
        if p.shape != (t.size, n):
            raise ShapeError("positions", f"({t.size}, {n}) (one row per time, one column per joint)",
                             p.shape, f"The arm has {n} joints; did you pass the transpose?"
                             if p.shape == (n, t.size) else f"The arm has {n} joints: give {n} angles [rad] per time")
        for name, a in (("times", t), ("positions", p)):
            if not np.isfinite(a).all():
                idx = np.argwhere(~np.isfinite(a))[0]
                raise NotFiniteError(f"trajectory {name} hold NaN or infinity (first at index "
                                     f"{tuple(int(i) for i in idx)}); every value must be finite")
        if t.size > 1 and not (np.diff(t) > 0).all():
            i = int(np.argmax(np.diff(t) <= 0))
            raise TrajectoryError(f"trajectory times must increase strictly: times[{i}] = {t[i]:.6g} s "
                                  f"and times[{i + 1}] = {t[i + 1]:.6g} s. Sort the points or drop duplicates.")
        object.__setattr__(self, "times", frozen(t))
        object.__setattr__(self, "positions", frozen(p))
        if self.velocities is not None:
            v = real_array(self.velocities, "velocities", f"{p.shape} (same as positions)",
                           f"Give {n} joint rates [rad/s] per time")
            if v.shape != p.shape:
                raise ShapeError("velocities", f"{p.shape} (same as positions)", v.shape)
            if not np.isfinite(v).all():
                raise NotFiniteError("trajectory velocities hold NaN or infinity")
            object.__setattr__(self, "velocities", frozen(v))

    # --- basic facts ----------------------------------------------------------------

    def __len__(self) -> int:
        return self.times.size

    @property
    def duration(self) -> float:
        """Time from the first to the last point [s]."""
        return float(self.times[-1] - self.times[0])

    def __repr__(self) -> str:
        return (f"Trajectory({len(self)} points, {self.times[0]:.3f}..{self.times[-1]:.3f} s, "
                f"{self.n_joints} joints{', with velocities' if self.velocities is not None else ''})")

    def finite_difference_velocities(self) -> np.ndarray:
        """Joint rates [rad/s] between consecutive points, shape (N-1, n_joints)."""
        return np.diff(self.positions, axis=0) / np.diff(self.times)[:, None]

    def sample(self, t) -> np.ndarray:
        """Positions at time(s) ``t`` [s], linearly interpolated and held beyond the ends."""
        t = finite_array(t, "t", "() or (M,)", "Give the time(s) [s] to sample at")
        if t.ndim > 1:
            raise ShapeError("t", "() or (M,)", t.shape, "Give one time [s], or a list of times")
        return np.stack([np.interp(t, self.times, self.positions[:, j]) for j in range(self.n_joints)], -1)

    def resample(self, rate: float | None = None, *, times=None) -> "Trajectory":
        """A trajectory on a new time grid: every ``1/rate`` s, or at the given ``times``."""
        if times is None:
            if rate is None:
                raise TrajectoryError("resample needs a rate > 0 [Hz] or times, got neither")
            rate = check_rate(rate, hint="It is how many samples per second the new grid has")
            count = sample_count(self.duration, rate, "the resampled trajectory")
            times = self.times[0] + np.arange(count) / rate
        times = finite_array(times, "times", "(M,)", "Give the new sample times [s]")
        if times.ndim != 1:
            raise ShapeError("times", "(M,)", times.shape, "Give the new sample times [s] as a list")
        vel = None
        if self.velocities is not None:
            vel = np.stack([np.interp(times, self.times, self.velocities[:, j])
                            for j in range(self.n_joints)], -1)
        return Trajectory(times, self.sample(times), vel, n_joints=self.n_joints)

    # --- limits -----------------------------------------------------------------------

    def limit_violations(self, spec: SnakeSpec = SPEC, *, velocity: bool = True) -> list[Violation]:
        """Where the trajectory is beyond the limits: one :class:`Violation` per stretch.

        A stretch is a run of consecutive samples where one joint is beyond one limit, on one
        side; its worst value is reported. Positions are checked against the joint limits;
        speeds between consecutive points (``"velocity"``: what a servo given these goals
        must do) and the stored ``velocities``, when given (``"stored velocity"``), against
        the velocity limit.
        """
        spec, velocity = check_spec(spec), check_flag(velocity, "velocity", "True also checks the speeds")
        out = _stretches(self.positions, self.times, spec.lower, spec.upper, "position")
        if velocity:
            vmax = spec.velocity_limit * (1 + 1e-9)
            out += _stretches(self.finite_difference_velocities(), self.times[1:], -vmax, vmax, "velocity")
            if self.velocities is not None:
                out += _stretches(self.velocities, self.times, -vmax, vmax, "stored velocity")
        out = [v if v.kind == "position" else
               Violation(v.joint, v.time, v.kind, v.value, float(np.copysign(spec.velocity_limit, v.value)),
                         v.start, v.end, v.points) for v in out]
        return sorted(out, key=lambda x: (x.start, x.joint, x.kind))

    def check_limits(self, spec: SnakeSpec = SPEC, *, velocity: bool = True) -> "Trajectory":
        """Return ``self`` if it respects the limits, else raise :class:`LimitError`.

        The error lists the first stretches beyond a limit (see :meth:`limit_violations`);
        its ``violations`` hold them all.
        """
        bad = self.limit_violations(spec, velocity=velocity)
        if bad:
            shown = "\n  ".join(str(v) for v in bad[:5])
            more = f"\n  ... and {len(bad) - 5} more" if len(bad) > 5 else ""
            points = sum(v.points for v in bad)
            raise LimitError(
                f"trajectory breaks the arm's limits ({spec.lower}..{spec.upper} rad, "
                f"{spec.velocity_limit} rad/s) in {len(bad)} stretch(es), {points} sample(s) in all:\n  "
                f"{shown}{more}\n"
                "Nothing was sent to the robot. Slow the motion down (longer times) or keep the "
                "angles inside the limits.", bad)
        return self

    # --- files ------------------------------------------------------------------------

    def save(self, path) -> Path:
        """Write to ``.npz`` or ``.csv`` (chosen by the suffix). Returns the path.

        Raises:
            FileFormatError: another suffix.
            FileWriteError: the folder is missing, the path is a folder, or writing failed.
        """
        path = as_path(path, "trajectory file")
        if path.suffix not in (".npz", ".csv"):
            raise FileFormatError(f"cannot save a trajectory as '{path.suffix}' ({path}); use .npz or .csv")
        writable_file(path, "trajectory file", probe=False)
        try:
            if path.suffix == ".npz":
                arrays = {"times": self.times, "positions": self.positions}
                if self.velocities is not None:
                    arrays["velocities"] = self.velocities
                np.savez(path, **arrays)
            else:
                n = self.n_joints
                header = ["time"] + [f"q{j + 1}" for j in range(n)]
                cols = [self.times[:, None], self.positions]
                if self.velocities is not None:
                    header += [f"qd{j + 1}" for j in range(n)]
                    cols.append(self.velocities)
                with open(path, "w", newline="", encoding="utf-8") as f:
                    w = csv.writer(f)
                    w.writerow(header)
                    for row in np.hstack(cols):
                        w.writerow([repr(float(x)) for x in row])
        except OSError as e:
            raise write_failed(path, "trajectory file", e) from e
        return path

    @classmethod
    def load(cls, path, *, n_joints: int = SPEC.n_joints) -> "Trajectory":
        """Read a trajectory written by :meth:`save` (``.npz`` or ``.csv``).

        Raises:
            FileFormatError: missing, truncated or malformed file, with what was wrong.
        """
        n_joints = check_count(n_joints, "n_joints", 1, 100, hint="It is how many joints the arm has (default: 5)")
        path = readable_file(path, "trajectory file")
        if path.suffix == ".npz":
            arrays = read_npz(path, "trajectory file", ("times", "positions"), ("velocities",),
                              fix="save it again with Trajectory.save")
        elif path.suffix == ".csv":
            arrays = _read_csv(path, n_joints)
        else:
            raise FileFormatError(f"cannot read a trajectory from '{path.suffix}' ({path}); use .npz or .csv")
        try:
            return cls(**arrays, n_joints=n_joints)
        except SnakekitError as e:  # the arrays are not a trajectory (shape, order, size, values)
            raise FileFormatError(f"{path} does not hold a valid trajectory: {e}") from None


def _csv_header_problem(header: list[str], n: int) -> str | None:
    """What is wrong with a trajectory .csv header, or None if it is one of the two forms."""
    want = ["time"] + [f"q{j + 1}" for j in range(n)]
    full = want + [f"qd{j + 1}" for j in range(n)]
    if header in (want, full):
        return None
    forms = f"expected {','.join(want)} (optionally followed by qd1..qd{n})"
    extra = [h for h in header if h not in full]
    missing = [h for h in want if h not in header]
    some_qd = [h for h in full[n + 1:] if h in header]
    if extra:
        return (f"has the column(s) {excerpt(', '.join(extra))} that a trajectory does not have; {forms}. "
                "Remove them (nothing is dropped silently)")
    if missing:
        return f"lacks the column(s) {', '.join(missing)}; {forms}"
    if some_qd and len(some_qd) < n:
        lacking = [h for h in full[n + 1:] if h not in header]
        return (f"has velocities for some joints only (lacks {', '.join(lacking)}); {forms}. "
                f"Give all of qd1..qd{n}, or none")
    return f"has its columns in another order or repeated ({excerpt(','.join(header))}); {forms}"


def _not_utf8(path: Path, e: UnicodeDecodeError) -> FileFormatError:
    """The error for a file that is not UTF-8 text, naming the first bad line and byte."""
    with open(path, "rb") as f:
        for line_no, line in enumerate(f, start=1):
            try:
                line.decode("utf-8")
            except UnicodeDecodeError as bad:
                byte = line[bad.start]
                return FileFormatError(
                    f"{path}, line {line_no}: byte 0x{byte:02x} is not UTF-8 text, so this is not a file "
                    "Trajectory.save wrote (it may be in another encoding, e.g. Latin-1). Save it again "
                    "as UTF-8 ('CSV UTF-8' in a spreadsheet), with only numbers below the header")
    return FileFormatError(f"{path} is not UTF-8 text ({e}); save it again as UTF-8")


def _csv_line_problem(path: Path, width: int) -> FileFormatError | None:
    """The first malformed data line of a .csv, found by reading it line by line (only called
    when the vectorised read failed, to say where and why)."""
    with open(path, newline="", encoding="utf-8-sig") as f:
        reader = csv.reader(f)
        try:
            next(reader, None)
            return _first_bad_row(path, reader, width)
        except csv.Error as e:  # a field longer than csv's limit (131072 characters): not a number either
            what = (f"a value longer than {csv.field_size_limit()} characters" if "field limit" in str(e)
                    else excerpt(str(e)))
            return FileFormatError(f"{path}, line {reader.line_num}: {what}; a trajectory .csv holds only numbers "
                                   "below its header")


def _first_bad_row(path: Path, reader, width: int) -> FileFormatError | None:
    """The error for the first row of ``reader`` that is not ``width`` numbers, or None."""
    for row in reader:
        line = reader.line_num
        if not row:
            continue
        if len(row) != width:
            return FileFormatError(f"{path}, line {line}: {len(row)} values, expected {width}; " + (
                "the file may be truncated" if len(row) < width else "remove the extra values"))
        for x in row:
            try:
                float(x)
            except ValueError:
                return FileFormatError(f"{path}, line {line}: not a number ({quote(x)}); a trajectory .csv "
                                       "holds only numbers below its header")
    return None


def _read_csv(path: Path, n: int) -> dict:
    """The arrays of a trajectory .csv, read in one vectorised pass (``numpy.loadtxt``)."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            first = f.readline(4097)  # a header is shorter: time,q1..q100,qd1..qd100 is under 1300 characters
            if len(first) > 4096:
                raise FileFormatError(f"{path}: its first line is longer than 4096 characters (it starts "
                                      f"{quote(first[:30])}), so it is not the header time,q1..q{n}; this is not a "
                                      "file Trajectory.save wrote")
            if not first.strip():
                raise FileFormatError(f"{path} is empty; a trajectory .csv starts with the header "
                                      f"time,q1..q{n}")
            header = [h.strip() for h in next(csv.reader([first]))]
            problem = _csv_header_problem(header, n)
            if problem:
                raise FileFormatError(f"{path} {problem}")
            width = len(header)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)  # "input contained no data": checked below
                    a = np.loadtxt(f, delimiter=",", dtype=float, ndmin=2, comments=None, quotechar='"',
                                   max_rows=MAX_POINTS + 1)  # one more than allowed: enough to refuse the file
            except ValueError as e:
                raise _csv_line_problem(path, width) or FileFormatError(f"{path}: {excerpt(str(e))}") from None
            if a.shape[0] > MAX_POINTS:
                raise FileFormatError(f"{path} holds more than {MAX_POINTS} points, more than the kit handles; "
                                      "it was not read. Resample it to a lower rate, or split it")
    except UnicodeDecodeError as e:
        raise _not_utf8(path, e) from e
    except OSError as e:
        raise FileFormatError(f"{path} could not be read ({e.strerror or e})") from e
    if a.shape[0] == 0:
        raise FileFormatError(f"{path} has a header but no points")
    if a.shape[1] != width:
        raise _csv_line_problem(path, width) or FileFormatError(
            f"{path}: {a.shape[1]} values per line, expected {width}")
    out = {"times": a[:, 0], "positions": a[:, 1: n + 1]}
    if width == 2 * n + 1:
        out["velocities"] = a[:, n + 1:]
    return out


# --- time scaling (Modern Robotics, ch. 9) ----------------------------------------------


def _times(t) -> np.ndarray:  # a time scaling's t [s]: finite (NaN would come back as NaN positions)
    return finite_array(t, "t", "() or (M,)", "Give the time(s) [s] from the start of the move")


def _move_time(T) -> float:
    """A time scaling's ``T``, checked: a duration > 0 [s] (0 would divide by zero, < 0 run backwards)."""
    return number(T, "T", "s", above=0, hint="T is how long the move takes")


def cubic_time_scaling(T: float, t):
    """s(t) in [0, 1] with zero start and end velocity: 3(t/T)^2 - 2(t/T)^3.

    >>> round(float(cubic_time_scaling(2.0, 1.0)), 6)
    0.5
    """
    r = np.clip(_times(t) / _move_time(T), 0, 1)
    return 3 * r**2 - 2 * r**3


def quintic_time_scaling(T: float, t):
    """s(t) in [0, 1] with zero start/end velocity and acceleration: 10r^3 - 15r^4 + 6r^5.

    >>> round(float(quintic_time_scaling(2.0, 1.0)), 6)
    0.5
    """
    r = np.clip(_times(t) / _move_time(T), 0, 1)
    return 10 * r**3 - 15 * r**4 + 6 * r**5


def trapezoidal_time_scaling(T: float, t, *, accel_fraction: float = 0.25):
    """s(t) in [0, 1]: constant acceleration for ``accel_fraction*T``, cruise, then brake.

    >>> round(float(trapezoidal_time_scaling(2.0, 1.0)), 6)
    0.5
    """
    T = _move_time(T)
    accel_fraction = number(accel_fraction, "accel_fraction", above=0, at_most=0.5,
                            hint="It is the share of T spent speeding up, and again slowing down (default: 0.25)")
    ta = accel_fraction * T
    v = 1.0 / (T - ta)
    a = v / ta
    t = np.clip(_times(t), 0, T)
    return np.where(t < ta, 0.5 * a * t**2,
                    np.where(t <= T - ta, v * (t - ta / 2), 1 - 0.5 * a * (T - t) ** 2))


# Each scaling with its peak speed, as a multiple of the average speed 1/T (so a move of
# distance d in time T peaks at factor * d / T):
#   cubic       s' = 6 r (1 - r) / T, largest at r = 1/2:          6/4   = 1.5
#   quintic     s' = 30 r^2 (1 - r)^2 / T, largest at r = 1/2:     30/16 = 1.875
#   trapezoidal cruise speed 1 / (T - ta), with ta = T/4 (default): 1/(1 - 1/4) = 4/3
_SCALINGS = {"cubic": (cubic_time_scaling, 6 / 4), "quintic": (quintic_time_scaling, 30 / 16),
             "trapezoidal": (trapezoidal_time_scaling, 1 / (1 - 0.25))}


def joint_trajectory(q_start, q_end, duration: float | None = None, *, method: str = "quintic",
                     rate: float = 100.0, spec: SnakeSpec = SPEC, speed_fraction: float = 0.8) -> Trajectory:
    """A straight joint-space move from ``q_start`` to ``q_end`` [rad] sampled at ``rate`` [Hz].

    With ``duration=None`` the move takes the shortest time that keeps every joint's peak
    speed at ``speed_fraction`` of the velocity limit.

    >>> import numpy as np
    >>> tr = joint_trajectory(np.zeros(5), [0.5, 0, 0, 0, 0], 1.0, rate=10)
    >>> len(tr), float(tr.positions[-1, 0])
    (11, 0.5)
    """
    if not isinstance(method, str) or method not in _SCALINGS:
        raise TrajectoryError(f"unknown time scaling {quote(method)}; choose one of {sorted(_SCALINGS)}")
    scaling, peak = _SCALINGS[method]
    a = check_limits(q_start, spec, "q_start")
    b = check_limits(q_end, spec, "q_end")
    rate = check_rate(rate, hint="It is how many points per second the move is sampled at (default: 100)")
    if duration is None:
        speed_fraction = number(speed_fraction, "speed_fraction", above=0, at_most=1,
                                hint="It is the share of the velocity limit the fastest joint may reach "
                                "(default: 0.8); or give the duration [s]")
        duration = max(peak * float(np.abs(b - a).max()) / (speed_fraction * spec.velocity_limit), 1.0 / rate)
        if duration > MAX_DURATION:
            raise ConfigurationError(f"at speed_fraction={speed_fraction:g} the move takes {duration:.4g} s, "
                                     f"longer than the {MAX_DURATION:g} s the kit accepts; raise speed_fraction "
                                     "(default: 0.8)")
    else:
        duration = check_duration(duration, hint="Give how long the move takes, or leave it out for the fastest "
                                  "move inside the velocity limit")
    sample_count(duration, rate, "the move")
    n = max(int(np.ceil(duration * rate - 1e-9)), 1)
    t = np.linspace(0.0, duration, n + 1)
    s = scaling(duration, t)
    ds = np.gradient(s, t) if n > 1 else np.zeros_like(t)
    return Trajectory(t, a + np.outer(s, b - a), np.outer(ds, b - a), n_joints=spec.n_joints)


def side_sweep(*, points: int = 500, rate: float = 10.0, sweeps: int = 50,
               amplitude: float = 0.2, spec: SnakeSpec = SPEC) -> Trajectory:
    """The study's Task 2: ``points`` goals at ``rate`` Hz making ``sweeps`` side-to-side sweeps.

    Every joint follows ``amplitude * sin(2 pi t / period)`` [rad], so the arm curls to one
    side, then the other; the sweeps fill the run exactly, so it starts and ends at home.

    >>> tr = side_sweep()
    >>> len(tr), round(tr.duration, 1), bool(abs(tr.positions[[0, -1]]).max() < 1e-12)
    (500, 49.9, True)
    """
    spec = check_spec(spec)
    points = check_count(points, "points", 2, 100_000, hint="It is how many goals the sweep sends (the task: 500)")
    rate = check_rate(rate, hint="It is how many goals per second are sent (the task: 10)")
    sweeps = check_count(sweeps, "sweeps", 1, points, hint="It is how many side-to-side sweeps fill the run "
                         "(the task: 50)")
    amplitude = number(amplitude, "amplitude", "rad", hint="It is how far each joint swings (default: 0.2)")
    t = np.arange(points) / rate
    period = t[-1] / sweeps
    w = 2 * np.pi / period
    pos = amplitude * np.sin(w * t)
    pos[-1] = 0.0  # exact home (sin(2 pi k) is ~1e-15, not 0)
    vel = amplitude * w * np.cos(w * t)
    n = spec.n_joints
    tr = Trajectory(t, np.repeat(pos[:, None], n, 1), np.repeat(vel[:, None], n, 1), n_joints=n)
    return tr.check_limits(spec)
