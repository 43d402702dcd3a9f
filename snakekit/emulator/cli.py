"""``snakekit emulator``: serve an emulated MX-28 bus on a pseudo-terminal (or a TCP port) until Ctrl-C."""

from __future__ import annotations

import argparse
import signal
import sys
from typing import TextIO

from ..validate import excerpt
from .faults import Faults


def _overload(text: str) -> tuple[int, float]:
    servo, _, after = text.partition("@")
    try:
        return int(servo), float(after or 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--overload takes ID or ID@SECONDS (e.g. 3@5), got "
                                         f"{excerpt(repr(text))}") from None


def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="snakekit emulator",
        description="Emulate five Dynamixel MX-28 (Protocol 2.0) servos on a pseudo-terminal (or a TCP "
                    "port, --tcp). Open the printed port with the Dynamixel SDK, or with "
                    "snakekit.make_robot('hardware', port=...).")
    ap.add_argument("--motion", choices=("mujoco", "profile"), default="mujoco",
                    help="how the servos move: the MuJoCo arm (default) or the firmware profile alone")
    ap.add_argument("--ids", default="1,2,3,4,5", help="servo ids, base to tip (default 1,2,3,4,5)")
    ap.add_argument("--baud", type=int, default=4_000_000, help="bus speed [baud] (default 4000000)")
    ap.add_argument("--timing", action="store_true",
                    help="wait the return delay and wire time of each status packet")
    ap.add_argument("--drop", type=float, default=0.0, metavar="P", help="drop instruction packets with probability P")
    ap.add_argument("--corrupt", type=float, default=0.0, metavar="P", help="corrupt status packets with probability P")
    ap.add_argument("--delay", type=float, default=0.0, metavar="P", help="delay replies with probability P")
    ap.add_argument("--delay-time", type=float, default=0.1, metavar="S", help="how late a delayed reply is [s]")
    ap.add_argument("--missing", default="", metavar="IDS", help="comma-separated ids that never answer")
    ap.add_argument("--overload", type=_overload, default=None, metavar="ID[@S]",
                    help="servo ID reports an overload alert (after S seconds)")
    ap.add_argument("--seed", type=int, default=0, help="random seed of the faults")
    ap.add_argument("--tcp", metavar="HOST:PORT", default=None,
                    help="serve on TCP (one client at a time, as snakekit bridge does) instead of a "
                         "pseudo-terminal; the port to open is then socket://HOST:PORT")
    ap.add_argument("--latency-timer", type=int, default=0, metavar="MS",
                    help="model the USB adapter's FTDI latency timer: replies are held up to MS ms "
                         "(16 is the chip's default, 1 the kit's; default 0: answer at once)")
    return ap


def _ids(text: str) -> tuple[int, ...]:
    return tuple(int(x) for x in text.replace(" ", "").split(",") if x)


def cli(argv: list[str], *, output: TextIO | None = None) -> int:
    """Run the emulator in the foreground; print the port to open; stop on Ctrl-C (or SIGTERM).

    Returns the exit status (0 after Ctrl-C, 2 on bad options).
    """
    from .bus import BusEmulator

    out = output or sys.stdout
    ap = parser()
    try:
        args = ap.parse_args(argv)
        faults = Faults(drop=args.drop, corrupt=args.corrupt, delay=args.delay, delay_time=args.delay_time,
                        missing=_ids(args.missing), overload=(args.overload[0],) if args.overload else (),
                        overload_after=args.overload[1] if args.overload else 0.0, seed=args.seed)
        bus = BusEmulator(ids=_ids(args.ids), motion=args.motion, baudrate=args.baud, timing=args.timing,
                          faults=faults, tcp=args.tcp, latency_timer=args.latency_timer)
    except SystemExit as e:
        return int(e.code or 0)
    except ValueError as e:
        print(f"snakekit emulator: {e}", file=sys.stderr)
        return 2

    def terminate(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        print(f"emulator: {bus.describe()}", file=out, flush=True)
        if faults != Faults():
            print(f"faults: {faults.describe()}", file=out, flush=True)
        print("open that port with the Dynamixel SDK or snakekit.make_robot('hardware', port=...); "
              "Ctrl-C stops", file=out, flush=True)
        bus.serve()
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        bus.stop()
        print(f"emulator stopped ({len(bus.record)} packets received)", file=out, flush=True)
    return 0
