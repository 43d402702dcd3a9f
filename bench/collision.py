"""The self-collision check: one pose, Task 2's path with its interpolation, and Task 2 on
the simulator now that it computes contacts between links.

Targets (issue 23): at most 20 us a pose (`snakekit.clearance`, the closest pair of
non-neighbouring links); Task 2's 500-goal sweep, path between goals included, checked in at
most 10 ms (`collision.first_collision`; a robot's `run` checks the servos' way, shown beside it); Task 2 as fast
as possible (`SimRobot.run`, the check included) within 1.05x a bare `mj_step` loop of the
same motion. The cost of the contacts themselves is shown beside it: the same bare loop with
contacts disabled. Medians of repeated rounds.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parent))

import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import snakekit  # noqa: E402
from _common import add_json_argument, per_call, table, write_json  # noqa: E402
from sim import bare_reference  # noqa: E402
from snakekit import collision  # noqa: E402
from snakekit.sim import SimRobot  # noqa: E402

REPEAT = 7


def pose_time() -> tuple[float, float]:
    """Median time of one `snakekit.clearance` call and of the bare Pinocchio call it makes [s]."""
    qs = np.random.default_rng(0).uniform(-1.57, 1.57, (2000, 5))
    c = collision._checker(snakekit.SPEC)
    it = iter(np.tile(qs, (REPEAT + 1, 1)))
    ours = per_call(lambda: snakekit.clearance(next(it)), number=len(qs), repeat=REPEAT)
    import pinocchio as pin

    it = iter(np.tile(qs, (REPEAT + 1, 1)))
    bare = per_call(lambda: pin.computeDistances(c.model, c.data, c.geometry, c.gdata, next(it)),
                    number=len(qs), repeat=REPEAT)
    return ours, bare


def poses_computed(times, positions):
    """The path check's answer, and how many poses it computed the distances of."""
    c = collision._checker(snakekit.SPEC)
    counted, plain = [0], c.distances

    def counting(q):
        counted[0] += 1
        return plain(q)

    c.distances = counting
    try:
        return collision.first_collision(times, positions), counted[0]
    finally:
        del c.distances


def sweep_check() -> tuple[float, int]:
    """Median time of checking Task 2's path [s], and how many poses it evaluates."""
    sweep = snakekit.side_sweep()
    hit, poses = poses_computed(sweep.times, sweep.positions)
    assert hit is None
    t = per_call(lambda: collision.first_collision(sweep.times, sweep.positions), number=1, repeat=3 * REPEAT)
    return t, poses


def sweep_check_servos() -> float:
    """Median time of checking Task 2 on the way the servos take (each joint on its profile,
    `profile_planner.ReferencePath` planned from rest, then the path check): what every
    robot's `run` does first [s]."""
    from snakekit.profile_planner import ReferencePath

    sweep = snakekit.side_sweep()
    assert collision.first_collision_on(ReferencePath.from_rest(sweep.times, sweep.positions)) is None
    return per_call(lambda: collision.first_collision_on(ReferencePath.from_rest(sweep.times, sweep.positions)),
                    number=1, repeat=3 * REPEAT)


def random_path_check() -> tuple[float, int, int]:
    """A harder path: 500 goals, each a random step of up to 0.15 rad a joint (what 1.5 rad/s
    allows at 10 Hz) from the last, kept inside the limits; median time [s], poses evaluated,
    and whether it was refused."""
    rng = np.random.default_rng(5)
    q = np.zeros((500, 5))
    for k in range(1, 500):
        q[k] = np.clip(q[k - 1] + rng.uniform(-0.15, 0.15, 5), -1.2, 1.2)
    times = np.arange(500) / 10.0
    hit, poses = poses_computed(times, q)
    t = per_call(lambda: collision.first_collision(times, q), number=1, repeat=REPEAT)
    return t, poses, hit is not None


def task2_fast() -> dict:
    """`SimRobot.run(side_sweep())` against bare `mj_step` loops of the same motion, with the
    model's contacts and with contacts disabled."""
    sweep = snakekit.side_sweep()
    with SimRobot() as robot:
        m, dt = robot.model, robot.dt
    steps = int(round((sweep.duration + 0.5) / dt))
    vel = bare_reference(sweep, steps, dt)
    m_off = SimRobot().model
    m_off.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT

    def bare(model):
        d = mujoco.MjData(model)
        t0 = time.perf_counter()
        for i in range(steps):
            d.ctrl[:] = vel[i]
            mujoco.mj_step(model, d)
        return time.perf_counter() - t0

    ours, on, off = [], [], []
    for _ in range(REPEAT):
        with SimRobot() as robot:
            t0 = time.perf_counter()
            robot.run(sweep)
            ours.append(time.perf_counter() - t0)
        on.append(bare(m))
        off.append(bare(m_off))
    med = {k: statistics.median(v) for k, v in (("ours", ours), ("bare", on), ("bare_no_contacts", off))}
    med["robot_time"] = sweep.duration + 0.5
    return med


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_json_argument(parser)
    args = parser.parse_args(argv)

    pose, pose_bare = pose_time()
    sweep, sweep_poses = sweep_check()
    servos = sweep_check_servos()
    rand, rand_poses, rand_refused = random_path_check()
    t2 = task2_fast()
    overhead = t2["ours"] / t2["bare"]
    contacts = t2["bare"] / t2["bare_no_contacts"]
    print(f"Self-collision check (medians of {REPEAT}+ rounds)")
    print(table([
        ["one pose: snakekit.clearance(q)", f"{pose * 1e6:.1f} us", "<= 20 us", "met" if pose <= 20e-6 else "MISSED"],
        ["  the bare pinocchio.computeDistances it calls", f"{pose_bare * 1e6:.1f} us", "-", ""],
        [f"Task 2's 500 goals, path included ({sweep_poses} poses computed)", f"{sweep * 1e3:.2f} ms", "<= 10 ms",
         "met" if sweep <= 10e-3 else "MISSED"],
        ["Task 2 on the servos' way (their profiles planned, then checked): what a robot's run does",
         f"{servos * 1e3:.2f} ms", "-", ""],
        [f"500 random 0.15 rad steps ({rand_poses} poses computed, {'refused' if rand_refused else 'accepted'})",
         f"{rand * 1e3:.2f} ms", "-", ""],
        ["Task 2 fast: SimRobot.run (check + contacts)", f"{t2['ours'] * 1e3:.0f} ms", "", ""],
        ["  bare mj_step loop, same motion, same model", f"{t2['bare'] * 1e3:.0f} ms",
         f"ratio {overhead:.3f}x (<= 1.05x)", "met" if overhead <= 1.05 else "MISSED"],
        ["  bare mj_step loop, contacts disabled", f"{t2['bare_no_contacts'] * 1e3:.0f} ms",
         f"contacts cost {contacts:.3f}x", ""],
        ["  real-time factor of SimRobot.run", f"{t2['robot_time'] / t2['ours']:.0f}x", "", ""],
    ], ["", "time", "target", ""]))
    ok = pose <= 20e-6 and sweep <= 10e-3 and overhead <= 1.05
    write_json(args.json, {"pose_us": pose * 1e6, "pose_bare_us": pose_bare * 1e6, "sweep_ms": sweep * 1e3,
                           "sweep_poses": sweep_poses, "sweep_servos_ms": servos * 1e3, "random_ms": rand * 1e3, "random_poses": rand_poses,
                           "random_refused": rand_refused, "task2_ours_s": t2["ours"], "task2_bare_s": t2["bare"],
                           "task2_bare_no_contacts_s": t2["bare_no_contacts"], "task2_overhead": overhead,
                           "contacts_cost": contacts, "ok": ok})
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
