"""The emulated bus: MX-28(2.0) servos behind a pseudo-terminal any serial client can open.

>>> from snakekit.emulator import BusEmulator
>>> with BusEmulator(motion="profile") as bus:
...     print(bus.port)                                    # open this with the SDK
/dev/pts/...

The emulator runs in a background thread (:meth:`BusEmulator.start`) or in the foreground
(:meth:`BusEmulator.serve`). It keeps a record of every instruction packet that reached
the bus (:attr:`BusEmulator.record`), decoded, so tests can check what a driver sent.
"""

from __future__ import annotations

import collections
import math
import os
import random
import select
import sys
import threading
import time
import traceback

from ..errors import ConfigurationError, InputTypeError
from ..host import realtime
from ..model import SPEC, SnakeSpec
from ..validate import as_configuration, check_count, check_flag, check_spec, length_of, number, quote
from . import protocol as p
from .control_table import FIRMWARE_VERSION_ADDRESS, MODEL_NUMBER_ADDRESS, field_at, to_signed
from .faults import NO_FAULTS, Faults
from .motion import MOTION_SOURCES, MotionSource
from .record import Received, Write
from .servo import OVERLOAD, EmulatedServo
from .tcp import FtdiChip, PtyLine, TcpLine

SWITCH_INTERVAL = 0.0005  # s, while an emulator thread runs
STALL = 0.02  # s: a serve loop later than its wait by more than this was held up by the machine
_CLASS_LOCK = threading.Lock()
BAUD_RATES = (9600, 57600, 115200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000)


class BusEmulator:
    """MX-28(2.0) servos on a pseudo-terminal, or on a TCP port.

    Args:
        ids: servo ids on the bus, base to tip (joint i is driven by ``ids[i]``).
        motion: ``"mujoco"`` (the simulated arm), ``"profile"`` (the firmware profile,
            followed exactly) or a :class:`~snakekit.emulator.motion.MotionSource`.
        q0: initial joint angles [rad] (default: home).
        baudrate: the bus speed [baud]; only used for wire timing.
        timing: wait the Return Delay Time and the wire time of each status packet
            before sending it, like a real bus (off: answer at once).
        boot_time: how long a servo is silent after REBOOT or FACTORY_RESET [s].
        faults: faults to inject from the start.
        record_limit: how many received packets to keep.
        spec: the arm.
        tcp: ``HOST:PORT`` (or ``PORT``, on 127.0.0.1; 0 picks a free port) to serve on TCP,
            one client at a time, instead of a pseudo-terminal: :attr:`port` is then
            ``socket://HOST:PORT``, which the driver opens as it would ``snakekit bridge``.
        latency_timer: model the USB adapter's FTDI latency timer [ms] (1..255; 0: answer
            at once). The chip holds the replies and sends them to the host when its buffer
            fills (:data:`~snakekit.emulator.tcp.CHIP_PACKET` bytes) or at the next expiry of its latency timer; the
            timer restarts at every USB transfer, and an idle chip makes one each period.
    """

    def __init__(self, *, ids=None, motion: str | MotionSource = "mujoco", q0=None,
                 baudrate: int = 4_000_000, timing: bool = False, boot_time: float = 0.05,
                 faults: Faults = NO_FAULTS, record_limit: int = 200_000, spec: SnakeSpec = SPEC,
                 tcp: str | None = None, latency_timer: int = 0):
        check_spec(spec)
        wrong = f"ids must be {spec.n_joints} distinct servo ids in 0..252, base to tip, e.g. (1, 2, 3, 4, 5); got "
        # (checked before the ids are read one by one: an iterable of a million is refused at once)
        if ids is not None and (isinstance(ids, (str, bytes)) or not hasattr(ids, "__iter__")):
            raise InputTypeError(wrong + quote(ids))
        if ids is not None and length_of(ids) != spec.n_joints:
            raise ConfigurationError(wrong + quote(ids))
        ids = tuple(number(i, "each servo id", at_least=0, at_most=p.MAX_ID, integer=True)
                    for i in (spec.servo_ids if ids is None else ids))
        if len(set(ids)) != len(ids):
            raise ConfigurationError(wrong + quote(ids))
        timing = check_flag(timing, "timing", "It waits the wire time of each reply, like a real bus")
        boot_time = number(boot_time, "boot_time", "s", at_least=0, at_most=10,
                           hint="It is how long a rebooted servo stays silent (default: 0.05)")
        record_limit = check_count(record_limit, "record_limit", 0, 10_000_000,
                                   hint="It is how many received packets the emulator keeps")
        if isinstance(baudrate, bool) or baudrate not in BAUD_RATES:
            raise ConfigurationError(f"an MX-28 runs at one of {', '.join(map(str, BAUD_RATES))} baud, got "
                                     f"{quote(baudrate)}")
        if isinstance(latency_timer, bool) or not isinstance(latency_timer, int) or not 0 <= latency_timer <= 255:
            raise ConfigurationError(f"latency_timer is a whole number of milliseconds, 1..255 as on an FTDI chip "
                                     f"(0: not modelled), got {quote(latency_timer)}")
        q0 = spec.home if q0 is None else as_configuration(q0, spec, "q0")
        if isinstance(motion, str):
            if motion not in MOTION_SOURCES:
                raise ConfigurationError(f"unknown motion source {quote(motion)}; choose one of "
                                         f"{', '.join(MOTION_SOURCES)}")
            kw = {"spec": spec} if motion == "mujoco" else {}
            motion = MOTION_SOURCES[motion](q0, **kw)
        elif not isinstance(motion, MotionSource):
            raise InputTypeError(f"motion is one of {', '.join(map(repr, MOTION_SOURCES))} or a MotionSource, got "
                                 f"{quote(motion)} ({type(motion).__name__})")
        self.motion, self.ids, self.baudrate, self.timing = motion, ids, baudrate, timing
        self.boot_time = boot_time
        self.spec = spec
        self.servos = [EmulatedServo(i, j, motion, stall_torque=spec.servo.stall_torque) for j, i in enumerate(ids)]
        self.record: collections.deque[Received] = collections.deque(maxlen=record_limit)
        #: packets whose handling raised (the first traceback is printed), for tests
        self.errors: list[tuple[p.Packet, Exception]] = []
        self._by_id = {s.id: s for s in self.servos}
        self._parser = p.Parser()
        self._lock = threading.RLock()
        self._t0 = time.perf_counter()
        self._faults = NO_FAULTS
        self._fault_budget: int | None = None
        self._rng = random.Random(0)
        self._overload_at = math.inf
        self._heard = 0.0  # when the last instruction packet reached the servos (the Bus Watchdog's clock)
        #: how long [s] each time the machine held the serve loop up (not counted by the watchdog)
        self.stalls: collections.deque[float] = collections.deque(maxlen=1000)
        self.faults = faults
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        #: the modelled USB latency timer [ms] (0: replies leave at once)
        self.latency_timer = latency_timer
        self._line = TcpLine(tcp) if tcp is not None else PtyLine()
        self._chip = FtdiChip(self._line, latency_timer) if latency_timer else None
        self._wake_r, self._wake_w = os.pipe()
        #: what a client opens: the pseudo-terminal (``/dev/pts/N``) or ``socket://HOST:PORT``
        self.port = self._line.port
        self.closed = False

    # --- clock and faults -------------------------------------------------------------------

    def now(self) -> float:
        """The emulator clock [s] (wall clock since creation)."""
        return time.perf_counter() - self._t0

    @property
    def faults(self) -> Faults:
        return self._faults

    @faults.setter
    def faults(self, faults: Faults) -> None:
        if not isinstance(faults, Faults):
            raise InputTypeError(f"faults must be a snakekit.emulator.Faults, got {type(faults).__name__}")
        with self._lock:
            self._faults = faults
            self._fault_budget = faults.count
            self._rng = random.Random(faults.seed)
            self._overload_at = self.now() + faults.overload_after if faults.overload else math.inf
            if faults.overload and not faults.overload_after:
                self._overload(self.now())

    def inject_overload(self, servo_id: int) -> None:
        """Make ``servo_id`` report an overload alert now (torque goes off, as in the firmware)."""
        with self._lock:
            self._servo(servo_id).raise_hardware_error(self.now(), OVERLOAD)

    def _overload(self, t: float) -> None:
        self._overload_at = math.inf
        for i in self._faults.overload:
            if i in self._by_id:
                self._by_id[i].raise_hardware_error(t, OVERLOAD)

    def _roll(self, rate: float) -> bool:
        if rate <= 0 or self._fault_budget == 0:
            return False
        if self._rng.random() >= rate:
            return False
        if self._fault_budget is not None:
            self._fault_budget -= 1
        return True

    def _servo(self, servo_id: int) -> EmulatedServo:
        try:
            return self._by_id[servo_id]
        except KeyError:
            raise ConfigurationError(f"no emulated servo with id {servo_id}; ids: {sorted(self._by_id)}") from None

    def servo(self, servo_id: int) -> EmulatedServo:
        """The emulated servo with id ``servo_id`` (to inspect its control table)."""
        return self._servo(servo_id)

    # --- the record -------------------------------------------------------------------------

    def received(self, name: str | None = None) -> list[Received]:
        """The recorded instruction packets (optionally only those named ``name``, e.g. "SYNC_WRITE")."""
        with self._lock:
            return [r for r in self.record if name is None or r.packet.name == name]

    def clear_record(self) -> None:
        with self._lock:
            self.record.clear()

    def writes(self, address: int, size: int) -> list[Write]:
        """Every value written to the ``size``-byte register at ``address``, by any write instruction."""
        out = []
        for r in self.received():
            pk = r.packet
            for servo_id, start, data in p.write_blocks(pk):
                if start <= address and address + size <= start + len(data):
                    raw = int.from_bytes(data[address - start:address - start + size], "little")
                    value = to_signed(raw, size) if _signed(address) else raw
                    out.append(Write(r.time, servo_id, value, pk.name, r.fault == "dropped"))
        return out

    # --- running ----------------------------------------------------------------------------

    _threads_running = 0
    _saved_switch_interval = None

    def start(self) -> "BusEmulator":
        """Serve in a background thread; returns self.

        While an emulator thread runs, Python's thread switch interval is lowered to 0.5 ms
        (restored when the last one stops): a client in the same process that polls the
        port would otherwise keep the emulator waiting up to 5 ms for each switch.
        """
        if self._thread is None:
            with _CLASS_LOCK:
                if BusEmulator._threads_running == 0:
                    BusEmulator._saved_switch_interval = sys.getswitchinterval()
                    sys.setswitchinterval(min(BusEmulator._saved_switch_interval, SWITCH_INTERVAL))
                BusEmulator._threads_running += 1
            self._thread = threading.Thread(target=self.serve, name=f"bus-emulator {self.port}", daemon=True)
            self._thread.start()
        return self

    def serve(self) -> None:
        """Answer packets until :meth:`stop` (or Ctrl-C in the foreground), under ``SCHED_FIFO``
        where allowed (``host.realtime``): the servos' processors answer whatever else runs."""
        with realtime():
            self._serve()

    def _serve(self) -> None:
        advance = getattr(self.motion, "advance", None)
        line = self._line
        listened = self.now()
        while not self._stop.is_set():
            watching = any(s.watchdog_period for s in self.servos)
            wait = 0.005 if watching else 0.05
            if self._chip is not None:
                wait = self._chip.wait(wait)
            ready, _, _ = select.select(line.readers() + [self._wake_r], [], [], wait)
            self._not_listening((read_at := self.now()) - listened - wait)   # what this read brings was there by then
            if self._chip is not None:
                self._chip.poll()
            if ready:
                data = line.receive(ready)
                if data is None:
                    break
                if data:
                    for packet in self._parser.feed(data):
                        try:
                            self.handle(packet, read_at)
                        except Exception as e:  # a bug must not kill the bus: keep it, go on
                            self.errors.append((packet, e))
                            if len(self.errors) == 1:
                                traceback.print_exc()
            with self._lock:
                t = self.now()
                self._watchdog(t)
                if t >= self._overload_at:
                    self._overload(t)
                if advance is not None:
                    advance(t)
            listened = self.now()

    def _not_listening(self, late: float) -> None:
        """The serve loop came back ``late`` [s] after its wait: the machine held this thread up.
        Real servos listen all the time, so the Bus Watchdog does not count that time as the
        client's silence (a packet sent meanwhile reached them; only this thread read it late)."""
        if late > STALL:
            with self._lock:
                self._heard += late
                self.stalls.append(late)

    def stop(self) -> None:
        """Stop serving, close the pty and free the motion source. Safe to call twice."""
        if self.closed:
            return
        self.closed = True
        self._stop.set()
        os.write(self._wake_w, b"x")
        if self._thread is not None:
            if self._thread is not threading.current_thread():
                self._thread.join(timeout=5)
            with _CLASS_LOCK:
                BusEmulator._threads_running -= 1
                if BusEmulator._threads_running == 0 and BusEmulator._saved_switch_interval:
                    sys.setswitchinterval(BusEmulator._saved_switch_interval)
        self._line.close()
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass
        self.motion.close()

    close = stop

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
        return False

    def __del__(self):
        try:
            self.stop()
        except Exception:
            pass

    def describe(self) -> str:
        ids = self.ids
        span = f"{ids[0]}-{ids[-1]}" if ids == tuple(range(ids[0], ids[0] + len(ids))) else ", ".join(map(str, ids))
        latency = f", USB latency timer {self.latency_timer} ms" if self.latency_timer else ""
        return f"{len(ids)} MX-28 servos (ids {span}) on {self.port} at {self.baudrate} baud{latency}"

    # --- the firmware -----------------------------------------------------------------------

    def handle(self, packet: p.Packet, arrived: float | None = None) -> None:
        """Process one received packet and send the replies (public for unit tests). The Bus Watchdog goes by
        ``arrived`` [s], when the serve loop read it: this thread held up after the read left the bus no quieter."""
        with self._lock:
            t = self.now()
            if packet.instruction == p.STATUS:
                return  # a status packet from another device: not for us
            fault = ""
            if self._roll(self._faults.drop):
                fault = "dropped"
            elif self._roll(self._faults.delay):
                fault = "delayed"
            self.record.append(Received(t, packet, fault))
            if fault == "dropped":
                return
            self._watchdog(t if arrived is None else min(arrived, t))
            self._heard = t
            replies = self._execute(t, packet)
            if not replies:
                return
            out = []
            for servo, pkt in replies:
                if self._roll(self._faults.corrupt):
                    i = self._rng.randrange(7, len(pkt))
                    pkt = pkt[:i] + bytes((pkt[i] ^ 0x5A,)) + pkt[i + 1:]
                out.append((servo, pkt))
        if fault == "delayed":
            time.sleep(self._faults.delay_time)
        for servo, pkt in out:
            if self.timing:
                _sleep(servo.return_delay + len(pkt) * 10 / self.baudrate)
            self._send(pkt)

    def _watchdog(self, t: float) -> None:
        """Stop every torque-on servo whose Bus Watchdog period passed since the last packet."""
        for s in self.servos:
            period = s.watchdog_period
            if period and s.memory.get("Torque Enable") and t - self._heard > period:
                s.watchdog_stop(self._heard + period)

    def _send(self, data: bytes) -> None:
        (self._chip or self._line).write(data)

    def _present(self, t: float, servo_id: int) -> EmulatedServo | None:
        s = self._by_id.get(servo_id)
        if s is None or servo_id in self._faults.missing or t < s.booting_until:
            return None
        return s

    def _refresh(self, t: float, servos) -> None:
        pos, vel, eff = self.motion.state(t)
        for s in servos:
            s.refresh(t, float(pos[s.joint]), float(vel[s.joint]), float(eff[s.joint]))

    def _execute(self, t: float, pk: p.Packet) -> list[tuple[EmulatedServo, bytes]]:
        inst, params, bid = pk.instruction, pk.params, pk.id
        broadcast = bid == p.BROADCAST_ID
        if broadcast:
            targets = [s for s in (self._present(t, i) for i in sorted(self._by_id)) if s]
        else:
            s = self._present(t, bid)
            targets = [s] if s else []
        if not targets:
            return []
        if not pk.crc_ok:
            return [] if broadcast else [(s, p.status(s.id, s.error_byte(p.CRC_ERROR)))]

        def reply(s, error=0, data=b"", level=2):
            if broadcast and inst not in (p.PING,):
                return []
            if s.status_return_level < level:
                return []
            return [(s, p.status(s.id, s.error_byte(error), data))]

        if inst == p.PING:
            return [(s, p.status(s.id, s.error_byte(), s.memory.read(MODEL_NUMBER_ADDRESS, 2)[1] + s.memory.read(FIRMWARE_VERSION_ADDRESS, 1)[1])) for s in targets]
        if inst in (p.READ, p.WRITE, p.REG_WRITE) and len(params) < (4 if inst == p.READ else 3):
            return [] if broadcast else reply(s, p.DATA_LENGTH_ERROR, level=1)
        if inst == p.READ:
            if broadcast:
                return []
            address, length = p.u16(params, 0), p.u16(params, 2)
            if len(params) != 4:
                return reply(s, p.DATA_LENGTH_ERROR, level=1)
            self._refresh(t, [s])
            error, data = s.memory.read(address, length)
            return reply(s, error, data, level=1)
        if inst in (p.WRITE, p.REG_WRITE):
            address, data = p.u16(params, 0), params[2:]
            out = []
            for s in targets:
                answers = s.status_return_level >= 2  # as set when the instruction arrived
                error = s.write(t, address, data) if inst == p.WRITE else s.register(address, data)
                if answers and not broadcast:
                    out.append((s, p.status(s.id, s.error_byte(error))))
            self._reindex()
            return out
        if inst == p.ACTION:
            out = []
            for s in targets:
                s.action(t)
                out += reply(s)
            self._reindex()
            return out
        if inst == p.REBOOT:
            out = []
            for s in targets:
                out += reply(s)
                s.reboot(t, self.boot_time)
            return out
        if inst == p.FACTORY_RESET:
            if broadcast:
                return []  # the MX-28 ignores a broadcast factory reset
            option = params[0] if len(params) == 1 else -1
            out = reply(s)  # the reply leaves before the reset
            error = s.factory_reset(t, option, self.boot_time)
            if error:
                return reply(s, error)
            self._reindex()
            return out
        if inst in (p.SYNC_READ, p.SYNC_WRITE, p.BULK_READ, p.BULK_WRITE) and not broadcast:
            return reply(s, p.INSTRUCTION_ERROR)
        if inst == p.SYNC_READ:
            if len(params) < 4:
                return []
            address, length = p.u16(params, 0), p.u16(params, 2)
            wanted = [self._present(t, i) for i in params[4:]]
            wanted = [s for s in wanted if s is not None]
            self._refresh(t, wanted)
            out = []
            for s in wanted:
                error, data = s.memory.read(address, length)
                if s.status_return_level >= 1:
                    out.append((s, p.status(s.id, s.error_byte(error), data)))
            return out
        if inst == p.BULK_READ:
            blocks = [(params[i], p.u16(params, i + 1), p.u16(params, i + 3))
                      for i in range(0, len(params) - 4, 5)]
            wanted = [(self._present(t, i), a, n) for i, a, n in blocks]
            wanted = [w for w in wanted if w[0] is not None]
            self._refresh(t, [w[0] for w in wanted])
            out = []
            for s, a, n in wanted:
                error, data = s.memory.read(a, n)
                if s.status_return_level >= 1:
                    out.append((s, p.status(s.id, s.error_byte(error), data)))
            return out
        if inst in (p.SYNC_WRITE, p.BULK_WRITE):
            for servo_id, address, data in p.write_blocks(pk):
                s = self._present(t, servo_id)
                if s is not None:
                    s.write(t, address, data)
            self._reindex()
            return []
        return [] if broadcast else reply(s, p.INSTRUCTION_ERROR)

    def _reindex(self) -> None:
        self._by_id = {s.id: s for s in self.servos}


def _signed(address: int) -> bool:
    try:
        return field_at(address).signed
    except KeyError:
        return False


def _sleep(seconds: float) -> None:
    """Sleep ``seconds`` [s], spinning the last 0.2 ms for sub-millisecond precision."""
    end = time.perf_counter() + seconds
    if seconds > 3e-4:
        time.sleep(seconds - 2e-4)
    while time.perf_counter() < end:
        pass

