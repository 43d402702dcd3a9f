"""The control cycle through ``snakekit bridge`` against the direct port, and against the USB latency timer.

Run as ``python bench/bridge.py``. One cycle is ``robot.read()`` + ``robot.command(q)``
(a SyncRead of the five servos' state and a SyncWrite of their goals), by ``DynamixelSnake``.

1. Through the bridge vs direct: two emulators, each in its own process (``snakekit
   emulator``); one is opened directly, the other through the bridge (``snakekit/bridge.py``
   run alone, in a process of its own, as on the host of a container). The two robots are
   measured in turn, so drifts of the machine's load hit both. Measured with the emulator
   answering at once (the software alone: the bridge's extra hops weigh most), and with the
   modelled FTDI latency timer at 1 ms (the kit's setting on a real U2D2) and at 16 ms (the
   chip's default, where the kit may not set it: Windows, macOS). Target: >= 0.8x.
2. The latency timer: the direct cycle rate with the timer modelled at 16 ms (the chip's
   default) and at 1 ms.
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from bus import rate_snakekit, start_emulator, stop_emulator  # noqa: E402

BRIDGE = HERE.parent / "snakekit" / "bridge.py"


def start_bridge(port: str) -> tuple[subprocess.Popen, str]:
    """The bridge file run alone on ``port``, on a free TCP port of 127.0.0.1: (process, URL to open)."""
    proc = subprocess.Popen([sys.executable, str(BRIDGE), port, "--listen", "127.0.0.1:0"],
                            stderr=subprocess.PIPE, text=True)
    line = proc.stderr.readline()
    m = re.search(r"\(open (socket://\S+)\)", line)
    if not m:
        proc.kill()
        raise SystemExit(f"the bridge did not start: {line!r} {proc.stderr.read()}")
    return proc, m.group(1)


def robot_on(port: str):
    from snakekit.hardware import DynamixelSnake

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "the kit wrote its EEPROM settings")  # fresh emulated servos
        return DynamixelSnake(port, watchdog=0)


def through_the_bridge(latency: int, seconds: float, repeats: int) -> dict:
    extra = ["--latency-timer", str(latency)] if latency else []
    direct_emu, direct_port = start_emulator("profile", *extra)
    bridged_emu, bridged_port = start_emulator("profile", *extra)
    bridge, url = start_bridge(bridged_port)
    try:
        direct, bridged = robot_on(direct_port), robot_on(url)
        rate_snakekit(direct, 0.2), rate_snakekit(bridged, 0.2)  # warm up
        ours, theirs = [], []
        for _ in range(repeats):
            theirs.append(rate_snakekit(direct, seconds))
            ours.append(rate_snakekit(bridged, seconds))
        retried = direct.retried + bridged.retried
        direct.close()
        bridged.close()
    finally:
        stop_emulator(bridge)
        stop_emulator(direct_emu)
        stop_emulator(bridged_emu)
    return {"latency_ms": latency, "bridge_hz": ours, "direct_hz": theirs, "retried": retried,
            "ratio": statistics.median(ours) / statistics.median(theirs)}


def latency_rates(seconds: float, repeats: int) -> dict:
    out = {}
    for ms in (16, 1):
        emu, port = start_emulator("profile", "--latency-timer", str(ms))
        try:
            robot = robot_on(port)
            rate_snakekit(robot, 0.2)
            out[ms] = [rate_snakekit(robot, seconds) for _ in range(repeats)]
            robot.close()
        finally:
            stop_emulator(emu)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=1.0, help="length of one measurement [s]")
    ap.add_argument("--repeats", type=int, default=5, help="measurements per client")
    ap.add_argument("--json", metavar="PATH", help="write the results as JSON to PATH")
    args = ap.parse_args(argv)

    rows = [through_the_bridge(latency, args.seconds, args.repeats) for latency in (0, 1, 16)]
    timers = latency_rates(args.seconds, args.repeats)

    print(f"control cycle = robot.read() + robot.command(q) by DynamixelSnake, emulated bus (profile motion) "
          f"in its own process, {args.repeats} x {args.seconds:g} s each")
    print()
    print(f"| {'USB latency timer (modelled)':<30} | {'direct [Hz]':>11} | {'bridge [Hz]':>11} | {'ratio':>6} | target |")
    print(f"|{'-' * 32}|{'-' * 13}|{'-' * 13}|{'-' * 8}|--------|")
    missed = []
    for r in rows:
        name = f"{r['latency_ms']} ms" if r["latency_ms"] else "none (answers at once)"
        met = r["ratio"] >= 0.8
        print(f"| {name:<30} | {statistics.median(r['direct_hz']):>11.0f} | {statistics.median(r['bridge_hz']):>11.0f} "
              f"| {r['ratio']:>6.2f} | {'met' if met else 'MISSED':>6} |")
        if not met:
            missed.append(f"bridge ratio at latency {r['latency_ms']} ms")
    print()
    print(f"packets retried: {sum(r['retried'] for r in rows)}")
    print()
    print("The direct cycle against the modelled latency timer:")
    print()
    print(f"| {'USB latency timer':<18} | {'median [Hz]':>11} | {'min [Hz]':>9} | {'max [Hz]':>9} | {'bound 1/timer [Hz]':>18} |")
    print(f"|{'-' * 20}|{'-' * 13}|{'-' * 11}|{'-' * 11}|{'-' * 20}|")
    for ms, xs in timers.items():
        print(f"| {f'{ms} ms':<18} | {statistics.median(xs):>11.0f} | {min(xs):>9.0f} | {max(xs):>9.0f} | {1000 / ms:>18.0f} |")
    print()
    print("Each read waits for the chip's timer, so one cycle a timer period is the bound. The bridge adds two")
    print("TCP hops and a process of its own to each exchange; on a busy machine the figures vary from run to run.")
    if missed:
        print(f"MISSED: {', '.join(missed)}")
    if args.json:
        from _common import spread, write_json

        write_json(args.json, {
            "bridge": [{"latency_ms": r["latency_ms"], "bridge_hz": spread(r["bridge_hz"]),
                        "direct_hz": spread(r["direct_hz"]), "ratio": r["ratio"]} for r in rows],
            "latency_hz": {str(ms): spread(xs) for ms, xs in timers.items()},
            "seconds": args.seconds, "repeats": args.repeats, "missed": missed})
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
