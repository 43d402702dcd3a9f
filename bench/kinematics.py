"""FK, Jacobian and IK: snakekit's public calls next to the bare Pinocchio calls they wrap.

Targets: public FK / Jacobian at most 3x the bare call; IK median under 1 ms and success on
99 % or more of 1,000 random reachable targets. Times are medians of 7 rounds.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin

sys.path.insert(0, str(Path(__file__).resolve().parent))
import snakekit  # noqa: E402
from _common import add_json_argument, per_call, table, write_json  # noqa: E402
from snakekit.kinematics import pinocchio_model  # noqa: E402

N_IK = 1000


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    add_json_argument(parser)
    args = parser.parse_args(argv)
    model, data, tool = pinocchio_model()
    data_rows = []
    rng = np.random.default_rng(0)
    q = rng.uniform(-1.5, 1.5, 5)

    def bare_fk():
        pin.framesForwardKinematics(model, data, q)
        return data.oMf[tool].homogeneous

    def bare_jac():
        return pin.computeFrameJacobian(model, data, q, tool, pin.LOCAL_WORLD_ALIGNED)

    rows, ok = [], True
    for name, ours, bare in [("forward_kinematics", lambda: snakekit.forward_kinematics(q), bare_fk),
                             ("jacobian", lambda: snakekit.jacobian(q), bare_jac)]:
        np.testing.assert_allclose(ours(), bare())
        t_ours, t_bare = per_call(ours, number=20000), per_call(bare, number=20000)
        ratio = t_ours / t_bare
        ok &= ratio <= 3
        data_rows.append({"call": name, "ours_us": t_ours * 1e6, "bare_us": t_bare * 1e6, "ratio": ratio,
                          "target": "<= 3x", "ok": bool(ratio <= 3)})
        rows.append([name, f"{t_ours * 1e6:.2f} us", f"{t_bare * 1e6:.2f} us", f"{ratio:.2f}x", "<= 3x",
                     "ok" if ratio <= 3 else "MISSED"])

    configs = rng.uniform(snakekit.SPEC.lower, snakekit.SPEC.upper, (N_IK, 5))
    targets = [snakekit.tool_pose_2d(c)[:2] for c in configs]
    times, solved = [], 0
    for target in targets:
        t0 = time.perf_counter()
        try:
            sol = snakekit.inverse_kinematics(target)
            solved += np.linalg.norm(snakekit.tool_pose_2d(sol)[:2] - target) < 1e-5
        except snakekit.UnreachableTargetError:
            pass
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    rate = solved / N_IK
    ok &= med < 1e-3 and rate >= 0.99
    rows.append(["inverse_kinematics", f"{med * 1e6:.0f} us", "-", "-", "< 1000 us",
                 "ok" if med < 1e-3 else "MISSED"])
    rows.append(["IK success", f"{100 * rate:.1f} % of {N_IK}", "-", "-", ">= 99 %", "ok" if rate >= 0.99 else "MISSED"])
    rows.append(["IK 95th percentile", f"{np.percentile(times, 95) * 1e6:.0f} us", "-", "-", "-", "-"])
    print(table(rows, ["call", "snakekit (median)", "bare pinocchio", "ratio", "target", ""]))
    write_json(args.json, {"calls": data_rows, "ik_median_us": med * 1e6, "ik_p95_us": float(np.percentile(times, 95)) * 1e6,
                           "ik_success": rate, "ik_targets": N_IK, "ok": bool(ok)})
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
