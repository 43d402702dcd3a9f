"""Control-cycle rate on the emulated bus: DynamixelSnake vs the same cycle with the bare SDK.

Run as ``python bench/bus.py``. One cycle is what a control loop does each period: one
SyncRead of Present Load, Velocity and Position (addresses 126..135) of the five servos and
one SyncWrite of their goals. The emulator runs in its own process (``snakekit emulator``'s
entry point) so it does not share the interpreter lock with the client being measured; the
pty moves bytes without wire delay, so this measures the software, not the bus.

The wire-time limits printed after are computed from the packet sizes, not measured.
"""

from __future__ import annotations

import argparse
import math
import re
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

IDS = (1, 2, 3, 4, 5)
BLOCK_ADDRESS, BLOCK_SIZE = 126, 10  # Present Load (2) + Velocity (4) + Position (4)


def start_emulator(motion: str, *options: str) -> tuple[subprocess.Popen, str]:
    """``snakekit emulator --motion MOTION OPTIONS...`` in its own process: (process, port to open)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys; from snakekit.emulator import cli; sys.exit(cli(sys.argv[1:]))",
         "--motion", motion, *options], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    m = re.search(r" on (\S+) at ", line)
    if not m:
        proc.kill()
        raise SystemExit(f"the emulator did not start: {line!r} {proc.stderr.read()}")
    return proc, m.group(1)


def stop_emulator(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGTERM)  # stops it like Ctrl-C, even when started with SIGINT ignored
    try:
        proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()


def goals(k: int) -> np.ndarray:
    """A small wave inside the limits, different every cycle [rad]."""
    return np.full(5, 0.2 * math.sin(k * 0.01))


def rate_snakekit(robot, seconds: float) -> float:
    k, t0 = 0, time.perf_counter()
    end = t0 + seconds
    while time.perf_counter() < end:
        robot.read()
        robot.command(goals(k))
        k += 1
    return k / (time.perf_counter() - t0)


class BareSdkLoop:
    """The same cycle written directly with the SDK: no checks, no retries, no conversions but ticks."""

    def __init__(self, port_name: str, baudrate: int = 4_000_000):
        import dynamixel_sdk as sdk

        self.sdk = sdk
        self.port = sdk.PortHandler(port_name)
        if not (self.port.openPort() and self.port.setBaudRate(baudrate)):
            raise SystemExit(f"could not open {port_name}")
        self.ph = sdk.PacketHandler(2.0)
        self.failed = 0
        self.reader = sdk.GroupSyncRead(self.port, self.ph, BLOCK_ADDRESS, BLOCK_SIZE)
        self.writer = sdk.GroupSyncWrite(self.port, self.ph, 116, 4)
        for i in IDS:
            self.reader.addParam(i)
            self.writer.addParam(i, [0, 8, 0, 0])

    def cycle(self, q) -> None:
        sdk, reader, writer = self.sdk, self.reader, self.writer
        if reader.txRxPacket() != sdk.COMM_SUCCESS:
            self.failed += 1
        state = []
        for i in IDS:
            if not reader.isAvailable(i, BLOCK_ADDRESS, BLOCK_SIZE):
                continue
            state.append((reader.getData(i, 126, 2), reader.getData(i, 128, 4), reader.getData(i, 132, 4)))
        for i, x in zip(IDS, q):
            tick = int(round(2048 + x * 4096 / (2 * math.pi)))
            writer.changeParam(i, [tick & 0xFF, tick >> 8 & 0xFF, tick >> 16 & 0xFF, tick >> 24 & 0xFF])
        writer.txPacket()

    def rate(self, seconds: float) -> float:
        k, t0 = 0, time.perf_counter()
        end = t0 + seconds
        while time.perf_counter() < end:
            self.cycle(goals(k))
            k += 1
        return k / (time.perf_counter() - t0)

    def close(self):
        self.port.closePort()


def wire_limits() -> list[tuple[int, int, float, float]]:
    """(baud, return delay register, cycle time [ms], rate [Hz]) from the packet sizes."""
    sync_write = 14 + len(IDS) * (1 + 4)          # header..len(7) + inst + addr(2) + len(2) + CRC(2) + id+data
    sync_read = 14 + len(IDS)                      # same framing, one id each
    status = 11 + BLOCK_SIZE                       # header..err(9) + data + CRC(2)
    total = sync_write + sync_read + len(IDS) * status
    rows = []
    for baud in (1_000_000, 4_000_000):
        for delay in (250, 0):
            seconds = total * 10 / baud + len(IDS) * delay * 2e-6  # 10 bits a byte (start, 8, stop)
            rows.append((baud, delay, 1000 * seconds, 1 / seconds))
    return rows, (sync_write, sync_read, status, total)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=1.0, help="length of one measurement [s]")
    ap.add_argument("--repeats", type=int, default=7, help="measurements per implementation")
    ap.add_argument("--motion", choices=("profile", "mujoco"), default="profile",
                    help="the emulator's motion source")
    ap.add_argument("--json", metavar="PATH", help="write the results as JSON to PATH")
    args = ap.parse_args(argv)

    from snakekit.hardware import DynamixelSnake

    proc, port = start_emulator(args.motion)
    try:
        # Both clients share the port, taking turns; the watchdog's keep-alive would talk while
        # the bare loop is measured, so it is off here (it sends nothing while the bus is busy).
        robot = DynamixelSnake(port, watchdog=0)
        bare = BareSdkLoop(port)
        rate_snakekit(robot, 0.2), bare.rate(0.2)  # warm up
        ours, theirs = [], []
        for _ in range(args.repeats):  # interleaved, so drifts hit both alike
            ours.append(rate_snakekit(robot, args.seconds))
            theirs.append(bare.rate(args.seconds))
        retried, failed = robot.retried, bare.failed
        bare.close()
        robot.close()
    finally:
        stop_emulator(proc)

    med_ours, med_bare = statistics.median(ours), statistics.median(theirs)
    print(f"control cycle = SyncRead of {BLOCK_SIZE} bytes x 5 servos + SyncWrite of 5 goals, "
          f"emulated bus ({args.motion} motion) on a pty, {args.repeats} x {args.seconds:g} s each")
    print()
    print(f"| {'client':<28} | {'median [Hz]':>11} | {'min [Hz]':>9} | {'max [Hz]':>9} | {'cycle [ms]':>10} |")
    print(f"|{'-' * 30}|{'-' * 13}|{'-' * 11}|{'-' * 11}|{'-' * 12}|")
    for name, xs in (("snakekit DynamixelSnake", ours), ("bare dynamixel-sdk", theirs)):
        med = statistics.median(xs)
        print(f"| {name:<28} | {med:>11.0f} | {min(xs):>9.0f} | {max(xs):>9.0f} | {1000 / med:>10.3f} |")
    ratio = med_ours / med_bare
    missed = []
    print()
    print(f"ratio snakekit / bare SDK: {ratio:.2f}  (target >= 0.80: {'met' if ratio >= 0.8 else 'MISSED'})")
    print(f"snakekit rate: {med_ours:.0f} Hz  (target >= 1000 Hz: {'met' if med_ours >= 1000 else 'MISSED'})")
    print(f"packets retried by snakekit: {retried}; bare SDK reads failed: {failed}")
    if ratio < 0.8:
        missed.append("ratio")
    if med_ours < 1000:
        missed.append("rate")
    print()
    rows, (sw, sr, st, total) = wire_limits()
    print(f"wire-time limits (computed): SyncWrite {sw} B + SyncRead {sr} B + 5 x status {st} B = {total} B a cycle")
    print()
    print(f"| {'bus [baud]':>10} | {'return delay (register)':>23} | {'cycle [ms]':>10} | {'max rate [Hz]':>13} |")
    print(f"|{'-' * 12}|{'-' * 25}|{'-' * 12}|{'-' * 15}|")
    for baud, delay, ms, hz in rows:
        words = f"{delay} = {delay * 2} us a servo"
        print(f"| {baud:>10} | {words:>23} | {ms:>10.3f} | {hz:>13.0f} |")
    print()
    print("The pty has no wire delay: the measured rates are the software's (client and emulator")
    print("process share the machine). DynamixelSnake waits in pyserial's read timeout for the")
    print("reply; the bare SDK spins until it arrives.")
    if missed:
        print(f"MISSED: {', '.join(missed)}")
    if args.json:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from _common import spread, write_json

        write_json(args.json, {"ours_hz": spread(ours), "bare_hz": spread(theirs), "ratio": ratio,
                               "seconds": args.seconds, "repeats": args.repeats, "motion": args.motion,
                               "missed": missed})
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
