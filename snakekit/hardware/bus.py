"""The servo bus through the unmodified dynamixel-sdk: the port, packets, and one retry loop.

The driver (:mod:`snakekit.hardware.driver`) asks this layer for reads, writes, pings and
group packets; lost or corrupt packets are sent again here, in :meth:`Bus.retry`, the only
retry loop of the hardware backend.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from contextlib import contextmanager
from typing import Callable

from ..bridge import check_latency_timer, is_url
from ..errors import BackendError, MissingDependencyError

try:
    import dynamixel_sdk as sdk
    import serial
    from dynamixel_sdk.protocol2_packet_handler import (PKT_ERROR, PKT_ID, PKT_INSTRUCTION, PKT_LENGTH_H,
                                                        PKT_LENGTH_L, PKT_PARAMETER0)
except ImportError as e:  # pragma: no cover - the kit's environment has it
    raise MissingDependencyError("the hardware backend needs dynamixel-sdk: install the kit's environment "
                                 "with tools/setup (or `pip install dynamixel-sdk`)") from e

from .port import Port

COMM_RESULTS = {
    sdk.COMM_PORT_BUSY: "port busy", sdk.COMM_TX_FAIL: "could not send the packet",
    sdk.COMM_RX_FAIL: "no status packet", sdk.COMM_TX_ERROR: "malformed instruction packet",
    sdk.COMM_RX_WAITING: "status packet incomplete", sdk.COMM_RX_TIMEOUT: "timed out",
    sdk.COMM_RX_CORRUPT: "corrupt status packet", sdk.COMM_NOT_AVAILABLE: "not available",
}
#: the longest lag [s] of a late status packet the bus waits out after a failure
MAX_LATENESS = 0.4
#: the share of the Bus Watchdog's period the bus may stay silent waiting out late bytes (one stall of a
#: busy computer taught it a lateness of MAX_LATENESS, and every wait after it outlasted a 0.5 s watchdog)
SILENCE_SHARE = 0.6
SUPPORTED_BAUD_RATES = "57600, 1000000, 2000000, 3000000 or 4000000"


def describe(result: int) -> str:
    """The SDK's communication result in words.

    >>> describe(sdk.COMM_RX_TIMEOUT)
    'timed out'
    """
    return COMM_RESULTS.get(result, str(result))


def status_params(rxpacket) -> int:
    """How many parameter bytes a (de-stuffed) status packet carries: LEN - 4."""
    return sdk.DXL_MAKEWORD(rxpacket[PKT_LENGTH_L],
                            rxpacket[PKT_LENGTH_H]) - 4


def expected_params(txpacket) -> int:
    """How many parameter bytes the status answering ``txpacket`` must carry: the block asked
    for by a READ, 3 for a PING (model number, firmware), none for anything else."""
    inst = txpacket[PKT_INSTRUCTION]
    if inst == sdk.INST_READ:
        return sdk.DXL_MAKEWORD(txpacket[PKT_PARAMETER0 + 2], txpacket[PKT_PARAMETER0 + 3])
    return 3 if inst == sdk.INST_PING else 0


class CheckedPacketHandler(sdk.Protocol2PacketHandler):
    """The SDK's Protocol 2.0 packet handler, taking a status packet only when it answers
    this request: the servo id asked, and the length of the block asked for.

    The SDK itself checks the header, the status instruction (0x55) and the CRC, but it
    passes over a status from another id without a word, and cuts a longer block to the
    length asked for. A status packet that arrives late (the answer to an earlier, given-up
    request) then reads as this request's answer: a 35-byte status block cut to the 10
    bytes of the joint state gave -3.14 rad and 3143 rad/s on every joint. Here anything
    else than the answer is ``COMM_RX_CORRUPT``, counted in :attr:`rejected`, and the
    caller (:meth:`Bus.retry`) drains the line and asks again.
    """

    def __init__(self):
        super().__init__()
        #: status packets refused as not the answer (wrong id or block length)
        self.rejected = 0

    def _answers(self, rxpacket, servo_id: int, params: int) -> bool:
        ok = (rxpacket[PKT_ID] == servo_id and status_params(rxpacket) == params)
        if not ok:
            self.rejected += 1
        return ok

    def txRxPacket(self, port, txpacket):
        """One instruction and its status packet (the SDK's, without skipping other ids)."""
        result = self.txPacket(port, txpacket)
        if result != sdk.COMM_SUCCESS:
            return None, result, 0
        inst = txpacket[PKT_INSTRUCTION]
        if inst in (sdk.INST_BULK_READ, sdk.INST_SYNC_READ):
            return None, sdk.COMM_NOT_AVAILABLE, 0
        if txpacket[PKT_ID] == sdk.BROADCAST_ID or inst == sdk.INST_ACTION:
            port.is_using = False
            return None, result, 0
        params = expected_params(txpacket)
        port.setPacketTimeout(params + 11)
        rxpacket, result = self.rxPacket(port, False)
        if result == sdk.COMM_SUCCESS and not self._answers(rxpacket, txpacket[PKT_ID], params):
            result = sdk.COMM_RX_CORRUPT
        error = rxpacket[PKT_ERROR] if result == sdk.COMM_SUCCESS else 0
        return rxpacket, result, error

    def readRx(self, port, dxl_id, length):
        """One status packet of a SyncRead: the block of servo ``dxl_id``, ``length`` bytes."""
        rxpacket, result = self.rxPacket(port, False)
        if result == sdk.COMM_SUCCESS and not self._answers(rxpacket, dxl_id, length):
            result = sdk.COMM_RX_CORRUPT
        if result != sdk.COMM_SUCCESS:
            return [], result, 0
        return rxpacket[PKT_PARAMETER0 + 1:PKT_PARAMETER0 + 1 + length], result, rxpacket[PKT_ERROR]


class SyncRead(sdk.GroupSyncRead):
    """The SDK's SyncRead, keeping each status packet's error byte (the SDK drops it).

    Args:
        check: optional ``check(servo_id, data) -> str | None``: a reason when a servo's
            block cannot be a true reading (the exchange then counts as corrupt).
    """

    def __init__(self, *args, check=None):
        super().__init__(*args)
        self.errors: dict[int, int] = {}
        self.failed_id: int | None = None
        self.check = check
        #: why the last exchange's data was refused, when a check refused it
        self.implausible: str | None = None
        #: the first refused block since :meth:`forget`: ``(servo id, why)``. A read whose every
        #: try failed names it even when a later try timed out or came back corrupt.
        self.refused: tuple[int, str] | None = None

    def forget(self) -> None:
        """Forget the refused block of earlier tries (call before a new read's tries)."""
        self.refused = None

    def rxPacket(self):
        self.last_result = False
        self.failed_id = None
        result = sdk.COMM_RX_FAIL
        for dxl_id in self.data_dict:
            self.data_dict[dxl_id], result, self.errors[dxl_id] = self.ph.readRx(self.port, dxl_id, self.data_length)
            if result != sdk.COMM_SUCCESS:
                self.failed_id = dxl_id
                return result
        self.last_result = True
        return result

    def exchange(self) -> tuple[int, int | None]:
        """One SyncRead, for :meth:`Bus.retry` (with ``by_servo=True``): ``(result, the servo whose block
        failed, or None)``; corrupt unless every servo's whole block arrived and passed the check."""
        self.implausible = None
        result = self.txRxPacket()
        if result == sdk.COMM_SUCCESS and not all(self.isAvailable(i, self.start_address, self.data_length)
                                                  for i in self.data_dict):
            result = sdk.COMM_RX_CORRUPT
        if result == sdk.COMM_SUCCESS and self.check is not None:
            for i in self.data_dict:
                why = self.check(i, bytes(self.data_dict[i]))
                if why:
                    self.failed_id, self.implausible = i, why
                    self.refused = self.refused or (i, why)
                    return sdk.COMM_RX_CORRUPT, i
        return result, (None if result == sdk.COMM_SUCCESS else self.failed_id)


def reported(failed: list[tuple[int, object]], by_servo: bool = False) -> tuple[int, object]:
    """Which of the failed tries of one request is reported (:meth:`Bus.retry`): ``by_servo`` (each try's value
    is the servo it failed at), only the tries of the servo that failed the most (the first such to fail); of
    those, a corrupt one, else the last."""
    if by_servo:
        counts = Counter(v for _, v in failed)
        most = max(counts.values())
        worst = next(v for _, v in failed if counts[v] == most)
        failed = [(r, v) for r, v in failed if v == worst]
    return next(((r, v) for r, v in failed if r == sdk.COMM_RX_CORRUPT), failed[-1])


class Bus:
    """One open Dynamixel bus: the SDK port and packet handler, a lock, and the retry loop.

    Args:
        port: serial port name (``/dev/ttyUSB0``, the emulator's pseudo-terminal) or a pyserial
            URL (``socket://host:7800`` for ``snakekit bridge``, ``rfc2217://host:port``).
        baudrate: bus speed [baud].
        retries: how many times a lost or corrupt packet is sent again.

    Raises:
        BackendError: the port can't be opened, or the SDK does not support ``baudrate``.
    """

    def __init__(self, port: str, baudrate: int, retries: int):
        self.name = str(port)
        self.retries = int(retries)
        #: how long [s] a request is tried, more often than :attr:`retries` says if need be, before it counts as
        #: failed (0: the tries alone). DynamixelSnake's start-up sets it: nothing moves yet, so a computer that
        #: stalls a few tenths of a second while the arm connects costs a wait, not a failed start.
        self.patience = 0.0
        #: how many tries the last failed request took
        self.tries_made = 0
        #: packets sent again after a loss or corruption, since the bus was opened
        self.retried = 0
        #: bytes thrown away because no request of ours was waiting for them (late or stray)
        self.stray_bytes = 0
        #: answers refused because more bytes followed them (a late status read as the answer)
        self.leftovers = 0
        self._suspect = False  # an exchange failed: late bytes may still come
        self._failed_at = 0.0  # when the last failed exchange began (perf_counter [s])
        #: the longest that late bytes were seen to lag behind a failed request [s]
        self.lateness = 0.0
        #: the longest the bus may stay silent while it waits out late bytes [s]: below the servos'
        #: Bus Watchdog period once it is armed (:data:`SILENCE_SHARE` of it), so that waiting out one
        #: stall of a busy computer never stops the arm
        self.silence_limit = math.inf
        #: when the bus last carried a packet (time.perf_counter() [s])
        self.last_used = time.perf_counter()
        self._lock = threading.RLock()
        #: the USB adapter's latency timer (:class:`snakekit.bridge.LatencyTimer`; set to 1 ms when
        #: the kit may), or None for a port without one (a pseudo-terminal, a socket)
        self.latency_timer = check_latency_timer(self.name)
        self.port = Port(self.name)
        self.ph = CheckedPacketHandler()
        try:
            opened = self.port.openPort()
        except Exception as e:  # pyserial raises SerialException (an OSError) for a bad path
            if "exclusive" in str(e).lower() or "lock" in str(e).lower():
                raise BackendError(f"the servo bus at {self.name} is in use by another program (another "
                                   "notebook kernel or snakekit command?); close the robot there first "
                                   "(robot.close()) or stop that program") from e
            if is_url(self.name):
                raise BackendError(f"could not open the servo bus at {self.name}: {e}; check that the "
                                   "bridge runs on that host (snakekit bridge PORT --listen HOST:PORT) and "
                                   "the address (socket://HOST:PORT)") from e
            raise BackendError(f"could not open the servo bus at {self.name}: {e}; check the port "
                               "name, that the adapter is plugged in, and that you may use it "
                               "(the 'dialout' group)") from e
        if not opened or not self.port.setBaudRate(int(baudrate)):
            if self.port.is_open:
                self.port.closePort()
            raise BackendError(f"{baudrate} baud is not a rate the Dynamixel SDK supports on "
                               f"{self.name}; use {SUPPORTED_BAUD_RATES}")

    @property
    def is_open(self) -> bool:
        return bool(self.port.is_open)

    @contextmanager
    def hold(self):
        """Hold the bus; after any exception (Ctrl-C included) the SDK's port flag is reset."""
        with self._lock:
            try:
                yield
            finally:
                self.port.is_using = False
                self.last_used = time.perf_counter()

    def _learn(self, since: float | None) -> None:
        """Late bytes arrived now, for a request sent at ``since`` (perf_counter [s])."""
        if since is not None:
            self.lateness = min(max(self.lateness, time.perf_counter() - since), MAX_LATENESS)

    def _bytes_follow(self, seconds: float) -> bool:
        """Whether bytes wait on the line or arrive within ``seconds`` [s]; they are thrown away
        and counted."""
        waiting = self.port.getBytesAvailable()
        if waiting:
            self.stray_bytes += len(self.port.read_within(waiting))
            return True
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            data = self.port.read_within(4096)
            if data:
                self.stray_bytes += len(data)
                return True
        return False

    def _discard(self) -> None:
        """Throw away (and count) what is waiting on the line: nothing an earlier request left
        is read as the answer to the next one."""
        self._bytes_follow(0.0)
        self.port.clearPort()

    def drain(self, quiet: float, longest: float = 0.5, since: float | None = None) -> None:
        """Throw away (and count) bytes until the line has been quiet for ``quiet`` [s] (at most
        ``longest`` [s]): a status packet that arrives after the SDK gave up must not be taken
        as the next answer. ``since``: when the failed request was sent (perf_counter [s]), to
        learn how late bytes come (:attr:`lateness`)."""
        quiet, longest = min(quiet, self.silence_limit), min(longest, self.silence_limit)
        now = time.perf_counter()
        end, quiet_until = now + longest, now + quiet
        while now < min(end, quiet_until):
            data = self.port.read_within(4096)
            if data:
                self.stray_bytes += len(data)
                self._learn(since)
                quiet_until = time.perf_counter() + quiet
            now = time.perf_counter()

    @property
    def quiet_time(self) -> float:
        """How long the line must stay quiet after a failed exchange [s]: twice the SDK's packet
        timeout, at least 50 ms, and a quarter longer than late bytes were seen to lag behind a
        failed request on this bus (:attr:`lateness`)."""
        return min(max(2 * self.port.packet_timeout / 1000.0, 0.05, 1.25 * self.lateness), self.silence_limit)

    def attempt(self, call: Callable[[], tuple[int, object]], *, answered: bool = True) -> tuple[int, object]:
        """One packet exchange ``call()`` with the bus held, taken only when nothing else came.

        Before it, what waits on the line is thrown away (and counted). After a successful
        exchange, a byte left on the line means the "answer" may have been a late status of an
        earlier request with the true answer behind it: the exchange counts as corrupt. After
        any failure the next exchanges must also leave the line quiet for :attr:`quiet_time`
        until one does (late packets arrive in order, so a late one read as an answer is always
        followed by the true one). A failed exchange drains the line. ``answered=False``: an
        instruction no servo answers (SyncWrite), sent after the clean-up, checked for nothing.
        """
        with self.hold():
            self._discard()
            started = time.perf_counter()
            try:
                result, value = call()
            except IndexError:  # the SDK indexed a status packet too short for what it wanted
                result, value = sdk.COMM_RX_CORRUPT, None
            if not answered:
                return result, value
            since = started
            if result == sdk.COMM_SUCCESS and self._bytes_follow(self.quiet_time if self._suspect else 0.0):
                result = sdk.COMM_RX_CORRUPT  # the "answer" was late bytes of the failed request before
                self.leftovers += 1
                self._learn(self._failed_at if self._suspect else None)
            if result == sdk.COMM_SUCCESS:
                self._suspect = False
            else:
                self._failed_at = started
                self._suspect = True
                self.drain(self.quiet_time, longest=2 * MAX_LATENESS, since=since)
        return result, value

    def retry(self, call: Callable[[], tuple[int, object]], *, answered: bool = True,
              tries: int | None = None, by_servo: bool = False) -> tuple[int, object]:
        """:meth:`attempt` ``call()`` (one packet exchange, returning ``(result, value)``), again
        after each failure, at most ``retries + 1`` times (``tries + 1`` when given; more while :attr:`patience`
        has not passed since the first). Returns the last ``(result, value)``:
        ``result`` is ``COMM_SUCCESS`` unless every try failed. When every try failed and one of them
        got a corrupt status packet, that is the result: a servo answered, on a noisy line or at
        another baud rate, even if a later try timed out (on a busy computer, the answer came late),
        and the message then points at the line, not at the servo's power or id.

        ``by_servo``: for an exchange with several servos (a SyncRead), whose failed tries' values are
        the servos they failed at. The servo that failed the most tries is the one reported (a servo that stays silent at
        every try is not hidden by one try that a late byte garbled at another servo), with a corrupt
        try of its own over its timeouts.
        """
        retries = self.retries if tries is None else tries
        failed, started = [], time.perf_counter()
        while True:
            result, value = self.attempt(call, answered=answered)
            if result == sdk.COMM_SUCCESS:
                return result, value
            failed.append((result, value))
            if len(failed) > retries and time.perf_counter() - started >= self.patience:
                break
            self.retried += 1
        self.tries_made = len(failed)
        return reported(failed, by_servo)

    def read(self, servo_id: int, address: int, size: int, *, tries: int | None = None) -> tuple[int, int, int]:
        """One READ with retries (``tries``: how many, default :attr:`retries`): ``(result, value,
        error byte)``; the value is unsigned."""

        def once():
            data, result, error = self.ph.readTxRx(self.port, servo_id, address, size)
            return result, (int.from_bytes(bytes(data), "little") if result == sdk.COMM_SUCCESS else 0, error)

        result, value = self.retry(once, tries=tries)
        value, error = value if value is not None else (0, 0)
        return result, value, error

    def write(self, servo_id: int, address: int, size: int, value: int, *,
              tries: int | None = None) -> tuple[int, int]:
        """One WRITE with retries (negative values written as two's complement): ``(result, error byte)``."""
        fn = {1: self.ph.write1ByteTxRx, 2: self.ph.write2ByteTxRx, 4: self.ph.write4ByteTxRx}[size]
        value = value & ((1 << 8 * size) - 1)
        return self.retry(lambda: fn(self.port, servo_id, address, value), tries=tries)

    def ping(self, servo_id: int) -> tuple[int, int, int]:
        """One PING with retries: ``(result, model number, error byte)``."""

        def once():
            model, result, error = self.ph.ping(self.port, servo_id)
            return result, (model, error)

        result, value = self.retry(once)
        model, error = value if value is not None else (0, 0)
        return result, model, error

    def reboot(self, servo_id: int) -> tuple[int, int]:
        """One REBOOT with retries: ``(result, error byte)``."""
        return self.retry(lambda: self.ph.reboot(self.port, servo_id))

    def ping_once(self, servo_id: int) -> int:
        """One PING, no retry (for waiting on a rebooting servo): the result."""
        def once():
            _, result, _ = self.ph.ping(self.port, servo_id)
            return result, None

        return self.attempt(once)[0]

    def close(self) -> None:
        if self.port.is_open:
            self.port.closePort()
