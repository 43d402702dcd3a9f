"""The serial port under the SDK: any pyserial port or URL, waiting without spinning, and a port that
goes away turned into one clear error (:class:`~snakekit.errors.PortLostError`)."""

from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Callable

import dynamixel_sdk as sdk
import serial

from ..bridge import PORT_ERRORS, is_url, no_delay
from ..errors import PortLostError

SYNC_WRITE = 0x83  # the instruction byte of a SYNC_WRITE packet


class Port(sdk.PortHandler):
    """The SDK's port handler on any pyserial port, waiting with pyserial's timeout, never spinning.

    The port may be a device (``/dev/ttyUSB0``, ``COM3``) or a pyserial URL
    (``socket://host:7800`` for ``snakekit bridge``, ``rfc2217://host:port``): it is opened
    with ``serial.serial_for_url``. The SDK polls the port with a zero timeout until a status
    packet arrives or its packet timeout passes; here each read waits for the bytes the SDK
    asks for with pyserial's own timeout (at most :attr:`slice` at a time), which works on
    every pyserial port and system and costs no CPU while waiting.

    A port that goes away (the adapter unplugged, the bridge or the emulator stopped) raises
    :class:`~snakekit.errors.PortLostError`, saying what the arm was last told
    (:attr:`last_told`), from then on at every use.
    """

    #: the longest one read waits [s]: a missing reply is noticed within this of its timeout
    #: (and pyserial on Windows counts its timeout in whole milliseconds)
    slice = 0.002

    def __init__(self, port_name):
        super().__init__(port_name)
        self.ser = None
        #: called (no arguments) for the words that say what the arm was last told, when the port is lost
        self.last_told: Callable[[], str] | None = None
        #: the PortLostError, once the port went away
        self.lost: PortLostError | None = None
        #: the last SYNC_WRITE that left the port: ``(time.perf_counter() [s], packet)``, or None
        self.last_sync_write: tuple[float, bytes] | None = None

    def setupPort(self, cflag_baud):
        """Open the port exclusively (a second program, or a second robot object, can't share
        the bus and undo this one's settings); an open port only changes its baud rate."""
        if self.is_open and self.ser is not None:
            with self._guard():
                self.ser.baudrate = self.baudrate
            return True
        self.ser = serial.serial_for_url(self.port_name, baudrate=self.baudrate, bytesize=serial.EIGHTBITS,
                                         timeout=self.slice, exclusive=True)
        sock = getattr(self.ser, "_socket", None)  # socket://: send each packet at once (no Nagle)
        if sock is not None:
            no_delay(sock)
        self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True

    @contextmanager
    def _guard(self):
        """Turn the port's going away into a PortLostError (once lost, it stays lost)."""
        if self.lost is not None:
            raise self._again()
        try:
            yield
        except PORT_ERRORS as e:
            self.lost = PortLostError(port_lost_message(self.port_name, e, self.last_told))
            raise self._again() from e

    def _again(self) -> PortLostError:
        return PortLostError(*self.lost.args)

    def readPort(self, length):
        """Up to ``length`` bytes: waits until they are all there, the packet timeout passed, or :attr:`slice`."""
        with self._guard():
            return self.ser.read(length)

    def read_within(self, size: int) -> bytes:
        """What arrives within :attr:`slice` [s] (up to ``size`` bytes)."""
        with self._guard():
            return self.ser.read(size)

    def writePort(self, packet):
        with self._guard():
            written = self.ser.write(packet)
        if len(packet) > 12 and packet[7] == SYNC_WRITE:
            self.last_sync_write = (time.perf_counter(), bytes(packet))
        return written

    def clearPort(self):
        with self._guard():
            self.ser.flush()

    def getBytesAvailable(self):
        with self._guard():
            return self.ser.in_waiting

    def closePort(self):
        if self.ser is not None:
            try:
                self.ser.close()
            except PORT_ERRORS:
                pass  # already gone
        self.is_open = False


def port_lost_message(port: str, error: Exception, last_told: Callable[[], str] | None = None) -> str:
    """Why the port at ``port`` is gone, what the arm was last told, and what to do."""
    args = getattr(error, "args", ())
    error = args[1] if len(args) == 2 and isinstance(args[1], str) else (str(error) or type(error).__name__)
    if is_url(port):
        where = (f"the connection to the servo bus at {port} was lost ({error}): the bridge stopped, its "
                 "adapter was unplugged, or it serves another client (one at a time)")
        fix = "start the bridge again (snakekit bridge PORT) with the adapter plugged in"
    else:
        where = f"the servo bus at {port} is gone ({error}): the USB adapter was unplugged or lost power"
        fix = "plug the adapter in again"
    told = ""
    if last_told is not None:
        try:
            told = " " + last_told()
        except Exception:  # the words must never hide the loss
            told = ""
    return f"{where}.{told} Then robot.close() and make the robot again: {fix}."
