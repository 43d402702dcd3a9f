"""A Task 2 run saved and loaded as .npz, .mcap (ROS 2) and .bag (ROS 1), beside the bare
library: rosbags writing only the measured /joint_states, the least a ROS bag of the run holds.

The run is Task 2 on the simulator (500 goals at 10 Hz, 50 sweeps and home: 52 s of robot
time, recorded at 100 Hz). Each format is written and read ``--repeat`` times, interleaved so a
busy moment hits each alike; the figures are medians.

Targets: each bag of a Task 2 run written in at most 3 s and read back in at most 1.5 s, and
written in at most 8x the time the bare library takes for /joint_states alone (the bags also
hold the links' frames, 5 transforms a sample, and the goals).

    .venv/bin/python bench/bags.py [--repeat 5]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import table  # noqa: E402


def bare_joint_states(run, path: Path) -> None:
    """The measured samples as sensor_msgs/JointState into a rosbag2 MCAP bag, with rosbags alone."""
    import numpy as np
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    names = [f"joint{i + 1}" for i in range(run.measured.positions.shape[1])]
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as bag:
        c = bag.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        for k, t in enumerate(run.measured.times):
            ns = int(round(t * 1e9))
            msg = T["sensor_msgs/msg/JointState"](
                header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](*divmod(ns, 1_000_000_000)),
                                                frame_id=""),
                name=names, position=np.array(run.measured.positions[k]), velocity=np.array(run.measured.velocities[k]),
                effort=np.array(run.efforts[k]))
            bag.write(c, ns, bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/JointState")))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()

    import snakekit
    from snakekit.run import Run

    with snakekit.make_robot("sim") as robot:
        run = robot.run(snakekit.side_sweep())
    print(f"run: Task 2 on the simulator, {len(run.commanded)} goals, {len(run.measured.times)} samples, "
          f"{run.robot_time:.1f} s of robot time; medians of {args.repeat}")
    writers = {".npz": run.save, ".mcap": run.save, ".bag": run.save}
    times = {name: {"write": [], "read": []} for name in (*writers, "bare rosbags (/joint_states only)")}
    sizes = {}
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        run.save(d / "warm.mcap"), run.save(d / "warm.bag")  # the message types are compiled once a process
        bare_joint_states(run, d / "warm-bare")
        for k in range(args.repeat):
            for suffix, save in writers.items():
                path = d / f"run{k}{suffix}"
                t0 = time.perf_counter()
                save(path)
                times[suffix]["write"].append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                Run.load(path)
                times[suffix]["read"].append(time.perf_counter() - t0)
                sizes[suffix] = path.stat().st_size
            t0 = time.perf_counter()
            bare_joint_states(run, d / f"bare{k}")
            times["bare rosbags (/joint_states only)"]["write"].append(time.perf_counter() - t0)
            sizes["bare rosbags (/joint_states only)"] = sum(p.stat().st_size for p in (d / f"bare{k}").iterdir())
    med = {name: {op: statistics.median(v) if v else None for op, v in ops.items()} for name, ops in times.items()}
    bare = med["bare rosbags (/joint_states only)"]["write"]
    rows = [[name, f"{m['write']:.3f}", "-" if m["read"] is None else f"{m['read']:.3f}",
             f"{sizes[name] / 1e6:.2f}", f"{m['write'] / bare:.2f}"] for name, m in med.items()]
    print(table(rows, ["format", "write [s]", "read [s]", "size [MB]", "write / bare"]))
    ok = all(med[s]["write"] <= 3 and med[s]["read"] <= 1.5 and med[s]["write"] <= 8 * bare for s in (".mcap", ".bag"))
    print(f"targets (a bag written in <= 3 s and <= 8x the bare library's /joint_states, read in <= 1.5 s): "
          f"{'ok' if ok else 'MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
