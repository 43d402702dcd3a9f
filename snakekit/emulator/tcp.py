"""The lines an emulated bus can be reached on (a pseudo-terminal, or a TCP port), and the USB
adapter's FTDI chip between the servos and the host.

A line gives the emulator's packet loop what to wait on (:meth:`readers`), the bytes a
client sent (:meth:`receive`), and a way to send bytes back (:meth:`write`). The TCP line
serves one client at a time, like ``snakekit bridge``: a client opens ``socket://HOST:PORT``
with pyserial (or ``make_robot("hardware", port=...)``) exactly as it would reach a real
arm through the bridge, and no pseudo-terminal is needed.
"""

from __future__ import annotations

import collections
import math
import os
import socket
import time

from ..bridge import BridgeError, hang_up, no_delay, parse_listen
from ..errors import ConfigurationError


#: bytes an FTDI FT232H (the U2D2's chip) sends the host in one USB packet (512, less 2 status bytes)
CHIP_PACKET = 510


class FtdiChip:
    """The U2D2's FTDI chip, in front of a line: it holds what the servos send and passes it on
    when its buffer fills (:data:`CHIP_PACKET` bytes) or its latency timer expires. The timer
    restarts at every USB transfer, and an idle chip makes one each period, so a reply waits
    for the next expiry of that period.

    Args:
        line: where the bytes go (a :class:`PtyLine` or :class:`TcpLine`).
        latency_timer: the chip's latency timer [ms].
    """

    def __init__(self, line, latency_timer: int):
        self.line = line
        self.period = latency_timer / 1000
        self.held = bytearray()
        self.tick = time.perf_counter()  # the last USB transfer
        self.flush_at = math.inf
        #: how long each reply the chip took with an empty buffer was to be held [s], newest last
        self.holds: collections.deque[float] = collections.deque(maxlen=10_000)

    def write(self, data: bytes) -> None:
        """Bytes from the servos: held, and sent on when the buffer is full."""
        now = time.perf_counter()
        if not self.held:  # the next expiry of the timer, which restarts at every transfer
            self.flush_at = self.tick + self.period * max(1, math.ceil((now - self.tick) / self.period))
            self.holds.append(self.flush_at - now)
        self.held += data
        while len(self.held) >= CHIP_PACKET:  # a full buffer leaves at once
            self._transfer(CHIP_PACKET)

    def wait(self, longest: float) -> float:
        """How long the emulator may wait for packets [s] before the chip has something to send."""
        return max(0.0, min(longest, self.flush_at - time.perf_counter())) if self.held else longest

    def poll(self) -> None:
        """Send what is held if the timer expired."""
        if self.held and time.perf_counter() >= self.flush_at:
            self._transfer(len(self.held))

    def _transfer(self, size: int) -> None:
        chunk = bytes(self.held[:size])
        del self.held[:size]
        self.tick = time.perf_counter()
        self.flush_at = self.tick + self.period if self.held else math.inf
        self.line.write(chunk)


class PtyLine:
    """A pseudo-terminal: clients open :attr:`port` (``/dev/pts/N``) as a serial port."""

    def __init__(self):
        import tty  # POSIX only: imported when a pty is asked for

        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.port = os.ttyname(self.slave)

    def readers(self) -> list:
        return [self.master]

    def receive(self, ready) -> bytes | None:
        """What arrived (b"" for nothing), or None when the line broke."""
        if self.master not in ready:
            return b""
        try:
            return os.read(self.master, 65536)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            return None

    def write(self, data: bytes) -> None:
        try:
            os.write(self.master, data)
        except OSError:
            pass  # nobody reads the port: the bytes are lost, as on an open bus

    def close(self) -> None:
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


class TcpLine:
    """A listening TCP socket, one client at a time; clients open :attr:`port` (``socket://HOST:PORT``).

    Args:
        listen: ``HOST:PORT`` or ``PORT`` (host 127.0.0.1; port 0 picks a free one).
    """

    def __init__(self, listen: str):
        try:
            host, number = parse_listen(listen)
        except BridgeError as e:
            raise ConfigurationError(str(e).replace("--listen", "the emulator's TCP address")) from None
        try:
            self.server = socket.create_server((host, number))
        except OSError as e:
            raise ConfigurationError(f"the emulator could not listen on {host}:{number}: {e.strerror or e}; "
                                     "choose another port") from None
        self.server.setblocking(False)
        self.address = self.server.getsockname()[:2]
        self.port = f"socket://{self.address[0]}:{self.address[1]}"
        self.client: socket.socket | None = None
        #: clients refused because another was connected
        self.refused = 0

    def readers(self) -> list:
        return [self.server] if self.client is None else [self.server, self.client]

    def receive(self, ready) -> bytes | None:
        if self.server in ready:
            self._accept()
        client = self.client
        if client is None or client not in ready:
            return b""
        try:
            data = client.recv(65536)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:
            data = b""
        if not data:  # the client left: wait for the next one
            self._drop()
        return data

    def _accept(self) -> None:
        try:
            sock, _ = self.server.accept()
        except OSError:
            return
        if self.client is not None:
            self.refused += 1
            sock.close()  # one client at a time, like the bridge
            return
        no_delay(sock)
        sock.setblocking(True)
        self.client = sock

    def _drop(self) -> None:
        client, self.client = self.client, None
        hang_up(client)

    def write(self, data: bytes) -> None:
        client = self.client
        if client is not None:
            try:
                client.sendall(data)
            except OSError:
                pass  # the client is leaving; the next receive() notices

    def close(self) -> None:
        self._drop()
        try:
            self.server.close()
        except OSError:
            pass
