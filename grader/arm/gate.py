"""The gate: each trajectory is checked again in the lab's own process, outside the student's
code, before the arm moves. The hand-in is arrays only (read with ``allow_pickle=False``).

In order: the arrays form a trajectory of the arm; joint and speed limits
(:meth:`snakekit.Trajectory.limit_violations`); self-collision on the path between goals
(:func:`snakekit.collision.first_collision_on`, on the way the servos take); its duration against the spec's (refused above
``max_duration_ratio`` times); and its run on the simulator against the simulated run of the
spec's trajectory (refused when they part by more than ``sim_tolerance``). A refusal is one
sentence addressed to the student.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from snakekit import SnakekitError, Trajectory
from snakekit.model import SPEC

from grader.arm.jobs import LabSettings


@dataclass(frozen=True)
class Checked:
    """A trajectory the gate let through (or refused: ``reason``), with its simulated run."""

    reason: str
    trajectory: Trajectory | None = None
    sim_times: np.ndarray | None = None
    sim_positions: np.ndarray | None = None
    sim_gap: float = 0.0


def sim_run(trajectory: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """The simulated arm's measured run of ``trajectory`` (as fast as possible): times [s], positions [rad]."""
    from snakekit.sim import SimRobot

    with SimRobot(q0=trajectory.positions[0]) as robot:
        run = robot.run(trajectory, progress=False)
    return run.measured.times - trajectory.times[0], run.measured.positions


@lru_cache(maxsize=4)
def _reference_sim(case: tuple) -> tuple[np.ndarray, np.ndarray]:
    import snakekit

    return sim_run(snakekit.side_sweep(**dict(case)))


def resampled(times: np.ndarray, positions: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``positions`` at the times ``at`` [s], linearly, held at the ends."""
    return np.stack([np.interp(at, times, positions[:, j]) for j in range(positions.shape[1])], axis=1)


def gap(times, positions, ref_times, ref_positions) -> tuple[np.ndarray, int, float]:
    """Per joint, the largest |run - reference| over the reference's times [rad]; and where the
    largest of all is (joint index, time [s])."""
    d = np.abs(resampled(times, positions, ref_times) - ref_positions)
    k, j = np.unravel_index(int(d.argmax()), d.shape)
    return d.max(axis=0), int(j), float(ref_times[k])


def check(handin: dict, s: LabSettings, spec=SPEC) -> Checked:
    """Check a student's handed-in arrays; ``Checked.reason`` is empty when the arm may run them."""
    if "times" not in handin or "positions" not in handin:
        return Checked("your hand-in holds no trajectory (times and positions) at the task's values: "
                       "task2_sweep did not return one when it was graded")
    try:
        tr = Trajectory(np.asarray(handin["times"], dtype=float), np.asarray(handin["positions"], dtype=float),
                        n_joints=spec.n_joints)
    except (SnakekitError, ValueError, TypeError) as e:
        return Checked(f"your sweep is not a trajectory the arm can take: {e}")
    out = tr.limit_violations(spec)
    if out:
        v = out[0]
        if v.kind == "position":
            return Checked(f"your sweep goes beyond the arm's joint limits: joint {v.joint} reaches {v.value:+.3f} rad "
                           f"at t = {v.time:.2f} s (limit {v.bound:+.3f} rad); the arm does not run it")
        return Checked(f"your sweep is too fast for the arm: joint {v.joint} must move at {abs(v.value):.2f} rad/s "
                       f"at t = {v.time:.2f} s (the limit is {abs(v.bound):.2f} rad/s); the arm does not run it")
    from snakekit.collision import first_collision_on
    from snakekit.profile_planner import ReferencePath

    hit = first_collision_on(ReferencePath.from_rest(tr.times, tr.positions), spec=spec)  # the way the servos take
    if hit is not None:
        return Checked(f"your sweep would fold the arm onto itself: at t = {hit.time:.2f} s, {hit.links[0]} and "
                       f"{hit.links[1]} come within {1000 * hit.distance:.0f} mm (the margin is "
                       f"{1000 * spec.collision_margin:.0f} mm); the arm does not run it")
    ref = s.reference_trajectory()
    most = s.max_duration_ratio * ref.duration
    if tr.duration > most:
        return Checked(f"your sweep lasts {tr.duration:.1f} s; the task's lasts {ref.duration:.1f} s, and the lab "
                       f"runs at most {s.max_duration_ratio:g} times that ({most:.1f} s)")
    t, q = sim_run(tr)
    rt, rq = _reference_sim(tuple(sorted(s.case.items())))
    per_joint, j, at = gap(t, q, rt, rq)
    worst = float(per_joint.max())
    if worst > s.sim_tolerance:
        return Checked(f"on the simulator your sweep is {worst:.3f} rad from the task's (joint {j + 1} at "
                       f"t = {at:.2f} s); the lab runs sweeps within {s.sim_tolerance:g} rad of it", tr, t, q, worst)
    return Checked("", tr, t, q, worst)
