"""The servo bus through the unmodified dynamixel-sdk: the port, packets, and one retry loop.

The driver (:mod:`snakekit.hardware.driver`) asks this layer for reads, writes, pings and
group packets; lost or corrupt packets are sent again here, in :meth:`Bus.retry`, the only
retry loop of the hardware backend.
"""

from __future__ import annotations

import select
import threading
import time
from contextlib import contextmanager
from typing import Callable

from ..errors import BackendError, MissingDependencyError

try:
    import dynamixel_sdk as sdk
    import serial
except ImportError as e:  # pragma: no cover - the kit's environment has it
    raise MissingDependencyError("the hardware backend needs dynamixel-sdk: install the kit's environment "
                                 "with tools/setup (or `pip install dynamixel-sdk`)") from e

COMM_RESULTS = {
    sdk.COMM_PORT_BUSY: "port busy", sdk.COMM_TX_FAIL: "could not send the packet",
    sdk.COMM_RX_FAIL: "no status packet", sdk.COMM_TX_ERROR: "malformed instruction packet",
    sdk.COMM_RX_WAITING: "status packet incomplete", sdk.COMM_RX_TIMEOUT: "timed out",
    sdk.COMM_RX_CORRUPT: "corrupt status packet", sdk.COMM_NOT_AVAILABLE: "not available",
}
SUPPORTED_BAUD_RATES = "57600, 1000000, 2000000, 3000000 or 4000000"


def describe(result: int) -> str:
    """The SDK's communication result in words.

    >>> describe(sdk.COMM_RX_TIMEOUT)
    'timed out'
    """
    return COMM_RESULTS.get(result, str(result))


class Port(sdk.PortHandler):
    """The SDK's port handler, waiting in ``select`` for the first byte instead of spinning.

    The SDK polls the port with a zero timeout until a status packet arrives or its packet
    timeout passes. Polling a moment, then sleeping in ``select`` until a byte arrives,
    gives the same timing without burning a CPU core (and without holding Python's lock
    for long, which an emulator in the same process needs to answer).
    """

    #: how long to poll before sleeping in select [s]: a fast answer is caught without the
    #: cost of a wake-up, a slow one costs no CPU
    spin = 3e-4

    def setupPort(self, cflag_baud):
        """The SDK's port set-up, opening the port exclusively (a second program, or a second
        robot object, can't share the bus and undo this one's settings)."""
        if self.is_open:
            self.closePort()
        self.ser = serial.Serial(port=self.port_name, baudrate=self.baudrate, bytesize=serial.EIGHTBITS,
                                 timeout=0, exclusive=True)
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True

    def readPort(self, length):
        ser = self.ser
        data = ser.read(length)  # what the SDK does: a read that never waits
        if data:
            return data
        end = time.perf_counter() + self.spin
        while time.perf_counter() < end:
            data = ser.read(length)
            if data:
                return data
        left = (self.packet_timeout - self.getTimeSinceStart()) / 1000.0  # ms -> s
        if left > 0:
            select.select([ser.fileno()], [], [], min(left, 0.05))
        return ser.read(length)


class SyncRead(sdk.GroupSyncRead):
    """The SDK's SyncRead, keeping each status packet's error byte (the SDK drops it)."""

    def __init__(self, *args):
        super().__init__(*args)
        self.errors: dict[int, int] = {}
        self.failed_id: int | None = None

    def rxPacket(self):
        self.last_result = False
        self.failed_id = None
        result = sdk.COMM_RX_FAIL
        for dxl_id in self.data_dict:
            self.data_dict[dxl_id], result, self.errors[dxl_id] = self.ph.readRx(self.port, dxl_id, self.data_length)
            if result == sdk.COMM_SUCCESS and len(self.data_dict[dxl_id]) != self.data_length:
                result = sdk.COMM_RX_CORRUPT  # a late status packet of another request
            if result != sdk.COMM_SUCCESS:
                self.failed_id = dxl_id
                return result
        self.last_result = True
        return result

    def exchange(self) -> tuple[int, None]:
        """One SyncRead, for :meth:`Bus.retry`: corrupt unless every servo's whole block arrived."""
        result = self.txRxPacket()
        if result == sdk.COMM_SUCCESS and not all(self.isAvailable(i, self.start_address, self.data_length)
                                                  for i in self.data_dict):
            result = sdk.COMM_RX_CORRUPT
        return result, None


class Bus:
    """One open Dynamixel bus: the SDK port and packet handler, a lock, and the retry loop.

    Args:
        port: serial port name (``/dev/ttyUSB0``, or the emulator's pseudo-terminal).
        baudrate: bus speed [baud].
        retries: how many times a lost or corrupt packet is sent again.

    Raises:
        BackendError: the port can't be opened, or the SDK does not support ``baudrate``.
    """

    def __init__(self, port: str, baudrate: int, retries: int):
        self.name = str(port)
        self.retries = int(retries)
        #: packets sent again after a loss or corruption, since the bus was opened
        self.retried = 0
        #: when the bus last carried a packet (time.perf_counter() [s])
        self.last_used = time.perf_counter()
        self._lock = threading.RLock()
        self.port = Port(self.name)
        self.ph = sdk.PacketHandler(2.0)
        try:
            opened = self.port.openPort()
        except Exception as e:  # pyserial raises SerialException (an OSError) for a bad path
            if "exclusive" in str(e).lower() or "lock" in str(e).lower():
                raise BackendError(f"the servo bus at {self.name} is in use by another program (another "
                                   "notebook kernel or snakekit command?); close the robot there first "
                                   "(robot.close()) or stop that program") from e
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

    def drain(self, quiet: float, longest: float = 0.5) -> None:
        """Throw away bytes until the line has been quiet for ``quiet`` [s] (at most ``longest`` [s]):
        a status packet that arrives after the SDK gave up must not be taken as the next answer."""
        ser = self.port.ser
        end = time.perf_counter() + longest
        while time.perf_counter() < end:
            if not select.select([ser.fileno()], [], [], quiet)[0]:
                return
            ser.read(4096)

    def retry(self, call: Callable[[], tuple[int, object]]) -> tuple[int, object]:
        """Run ``call()`` (one packet exchange, returning ``(result, value)``) with the bus held,
        again after each failure, at most ``retries + 1`` times. Returns the last
        ``(result, value)``: ``result`` is ``COMM_SUCCESS`` unless every try failed.
        """
        for attempt in range(self.retries + 1):
            with self.hold():
                self.port.clearPort()  # nothing left over from an earlier, failed exchange
                try:
                    result, value = call()
                except IndexError:  # the SDK read a stale, shorter status packet as the answer
                    result, value = sdk.COMM_RX_CORRUPT, None
                if result != sdk.COMM_SUCCESS:
                    self.drain(max(2 * self.port.packet_timeout, 50.0) / 1000.0)  # ms -> s
            if result == sdk.COMM_SUCCESS:
                break
            if attempt < self.retries:
                self.retried += 1
        return result, value

    def read(self, servo_id: int, address: int, size: int) -> tuple[int, int, int]:
        """One READ with retries: ``(result, value, error byte)``; the value is unsigned."""

        def once():
            data, result, error = self.ph.readTxRx(self.port, servo_id, address, size)
            if result == sdk.COMM_SUCCESS and len(data) != size:
                result = sdk.COMM_RX_CORRUPT  # the status of another request, arriving late
            return result, (int.from_bytes(bytes(data), "little") if result == sdk.COMM_SUCCESS else 0, error)

        result, value = self.retry(once)
        value, error = value if value is not None else (0, 0)
        return result, value, error

    def write(self, servo_id: int, address: int, size: int, value: int) -> tuple[int, int]:
        """One WRITE with retries (negative values written as two's complement): ``(result, error byte)``."""
        fn = {1: self.ph.write1ByteTxRx, 2: self.ph.write2ByteTxRx, 4: self.ph.write4ByteTxRx}[size]
        value = value & ((1 << 8 * size) - 1)
        return self.retry(lambda: fn(self.port, servo_id, address, value))

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
        with self.hold():
            _, result, _ = self.ph.ping(self.port, servo_id)
        return result

    def close(self) -> None:
        if self.port.is_open:
            self.port.closePort()
