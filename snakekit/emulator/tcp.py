"""The lines an emulated bus can be reached on: a pseudo-terminal, or a TCP port.

A line gives the emulator's packet loop what to wait on (:meth:`readers`), the bytes a
client sent (:meth:`receive`), and a way to send bytes back (:meth:`write`). The TCP line
serves one client at a time, like ``snakekit bridge``: a client opens ``socket://HOST:PORT``
with pyserial (or ``make_robot("hardware", port=...)``) exactly as it would reach a real
arm through the bridge, and no pseudo-terminal is needed.
"""

from __future__ import annotations

import os
import socket

from ..bridge import BridgeError, hang_up, no_delay, parse_listen
from ..errors import ConfigurationError


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
