"""The host side of the arm's serial port: the USB latency timer, and ``snakekit bridge``.

This one file needs only the Python standard library and pyserial, so a computer that
cannot run the kit (a Windows or macOS host whose lab runs in a container) can still serve
the arm::

    pip install pyserial
    python bridge.py /dev/ttyUSB0                  # or COM3, /dev/cu.usbserial-...
    python bridge.py /dev/ttyUSB0 --listen 0.0.0.0:7800

(``snakekit bridge PORT`` is the same, where the kit is installed.) The driver then opens
``socket://HOST:7800`` instead of the device: ``make_robot("hardware", port="socket://...")``.

The bridge holds the serial port exclusively, listens on 127.0.0.1 unless told otherwise
(the arm is not offered to the network by accident), serves one client at a time (a second
is disconnected at once, and the bridge says so) and says when a client connects or leaves,
and when the adapter disappears (then it disconnects the client and exits with status 1).

The USB latency timer: the arm's U2D2 adapter is an FTDI chip, which holds the bytes it
receives until its buffer fills or its latency timer (16 ms by default) expires, so every
read of the servos waits up to that long. On Linux the timer is a sysfs file;
:func:`check_latency_timer` reads it, sets it to 1 ms when it may, and otherwise warns
once with the udev rule that sets it for good. The driver calls it when it opens a port,
the bridge when it opens its own. (It lives here, not in :mod:`snakekit.hardware`, so
that this file runs alone.)
"""

from __future__ import annotations

import argparse
import os
import signal
import socket
import sys
import threading
import warnings
from dataclasses import dataclass
from pathlib import Path

try:
    import serial
except ImportError:  # pragma: no cover - the kit's environment has it
    serial = None

try:
    from termios import error as TermiosError
except ImportError:  # pragma: no cover - not on Windows
    class TermiosError(Exception):
        """Stands in for termios.error where there is no termios."""

#: what a serial port raises when its device goes away (pyserial's SerialException is an OSError)
PORT_ERRORS = (OSError, TermiosError, ValueError)

DEFAULT_LISTEN = ("127.0.0.1", 7800)
DEFAULT_BAUDRATE = 4_000_000

# --- the USB latency timer ----------------------------------------------------------------------

#: where Linux shows its devices; a test points this at a fake tree
SYSFS = "/sys"
#: the latency timer the kit wants [ms]
LATENCY_TARGET = 1
#: the udev rule that sets every FTDI adapter's latency timer to 1 ms when it is plugged in
UDEV_RULE = 'ACTION=="add", SUBSYSTEM=="usb-serial", DRIVER=="ftdi_sio", ATTR{latency_timer}="1"'
UDEV_FILE = "/etc/udev/rules.d/99-snakekit-ftdi.rules"
_WARNED: set[str] = set()


@dataclass(frozen=True)
class LatencyTimer:
    """An FTDI adapter's latency timer, as found and as left.

    Attributes:
        device: the tty the port resolves to (``ttyUSB0``).
        path: its sysfs ``latency_timer`` file.
        found: the timer as found [ms].
        now: the timer as left [ms] (``found`` when it could not be set).
        error: why it could not be set ("" when it was, or did not need to be).
    """

    device: str
    path: str
    found: int
    now: int
    error: str = ""

    def describe(self) -> str:
        """One line for a person.

        >>> LatencyTimer("ttyUSB0", "/sys/...", 16, 1).describe()
        'USB latency timer of ttyUSB0: 1 ms (was 16 ms; set by the kit)'
        """
        if self.now == self.found:
            return f"USB latency timer of {self.device}: {self.now} ms"
        return f"USB latency timer of {self.device}: {self.now} ms (was {self.found} ms; set by the kit)"


def is_url(port) -> bool:
    """Whether ``port`` is a pyserial URL (``socket://``, ``rfc2217://``...), not a device."""
    return "://" in str(port)


def latency_timer_file(port: str, sysfs: str | os.PathLike | None = None) -> Path | None:
    """The sysfs ``latency_timer`` file of the USB serial adapter behind ``port``, or None.

    Symbolic links are followed (``/dev/serial/by-id/usb-FTDI_...`` -> ``/dev/ttyUSB0``).
    None for anything that is not a USB serial adapter with a latency timer: a URL, a
    pseudo-terminal, an ACM modem, or a system without sysfs.
    """
    if is_url(port):
        return None
    device = os.path.basename(os.path.realpath(os.fspath(port)))
    path = Path(SYSFS if sysfs is None else sysfs) / "bus" / "usb-serial" / "devices" / device / "latency_timer"
    return path if path.is_file() else None


def check_latency_timer(port: str, sysfs: str | os.PathLike | None = None, *, target: int = LATENCY_TARGET,
                        warn=None) -> LatencyTimer | None:
    """Read the latency timer of the adapter behind ``port``; set it to ``target`` [ms] if higher.

    When it cannot be set (not root, a read-only sysfs in a container), ``warn(message)``
    is called once per adapter (default: a :class:`UserWarning`) with the udev rule to install.

    Args:
        port: the serial port (a device path; URLs and non-USB ports have no timer).
        sysfs: the root of sysfs (default :data:`SYSFS`, ``/sys``).
        target: the latency timer wanted [ms].
        warn: called with the warning's text (default :func:`warnings.warn`).

    Returns:
        The timer as found and left, or None when ``port`` has no latency timer.
    """
    path = latency_timer_file(port, sysfs)
    if path is None:
        return None
    device = path.parent.name
    try:
        found = int(path.read_text().strip())
    except (OSError, ValueError):
        return None
    if found <= target:
        return LatencyTimer(device, str(path), found, found)
    try:
        path.write_text(f"{target}\n")
        now = int(path.read_text().strip())
        error = "" if now <= target else f"it still reads {now} ms after writing {target}"
    except (OSError, ValueError) as e:
        now, error = found, (getattr(e, "strerror", None) or str(e))
    timer = LatencyTimer(device, str(path), found, now, error)
    if error and str(path) not in _WARNED:
        _WARNED.add(str(path))
        message = (
            f"the USB adapter of {port} ({device}) has its latency timer at {found} ms, so every read of the "
            f"servos waits up to {found} ms (about {1000 // (found + 1)} cycles a second at most); the kit could "
            f"not set it to {target} ms ({error}). Install the udev rule once, as root, then plug the adapter "
            f"in again:\n"
            f"    echo '{UDEV_RULE}' | sudo tee {UDEV_FILE}\n"
            f"    sudo udevadm control --reload-rules && sudo udevadm trigger\n"
            f"(docs/hardware.md, 'The USB latency timer'; the kit ships the rule as tools/99-snakekit-ftdi.rules)")
        if warn is None:
            warnings.warn(message, UserWarning, stacklevel=3)
        else:
            warn(message)
    return timer


# --- the bridge -----------------------------------------------------------------------------

try:  # inside the kit: its error tree; run alone (no kit, or no numpy), a class of its own
    from snakekit.errors import BridgeError
except ImportError:
    class BridgeError(Exception):
        """The bridge could not start: the port or the address is not usable (the message says why)."""


def parse_listen(text: str | None) -> tuple[str, int]:
    """``HOST:PORT``, ``PORT`` or ``:PORT`` as ``(host, port)``; the host defaults to 127.0.0.1.

    >>> parse_listen(None), parse_listen("7900"), parse_listen("0.0.0.0:7900")
    (('127.0.0.1', 7800), ('127.0.0.1', 7900), ('0.0.0.0', 7900))
    """
    if text is None:
        return DEFAULT_LISTEN
    host, sep, port = str(text).strip().rpartition(":")
    host = host.strip("[]") if sep else ""
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 <= number <= 65535:
        shown = f"{text[:80]!r}{'...' if len(text) > 80 else ''}"  # a short excerpt of a long argument
        raise BridgeError(f"--listen takes HOST:PORT or PORT (e.g. 127.0.0.1:7800), got {shown}")
    return host or DEFAULT_LISTEN[0], number


def open_serial(port: str, baudrate: int = DEFAULT_BAUDRATE, timeout: float = 0.05):
    """``port`` opened exclusively with pyserial (a device path or a URL), or a BridgeError that says why."""
    if serial is None:
        raise BridgeError("the bridge needs pyserial: pip install pyserial")
    try:
        return serial.serial_for_url(port, baudrate=baudrate, timeout=timeout, exclusive=True)
    except PORT_ERRORS as e:
        busy = "exclusive" in str(e).lower() or "lock" in str(e).lower()
        hint = ("another program holds it (a notebook kernel, another bridge?): stop that first" if busy else
                "check the name (Linux: /dev/ttyUSB0, macOS: /dev/cu.usbserial-..., Windows: COM3), that the "
                "adapter is plugged in, and that you may use it (Linux: the 'dialout' group)")
        raise BridgeError(f"could not open the serial port {port}: {e}; {hint}") from None


def no_delay(sock: socket.socket) -> None:
    """Send small packets at once: a status packet must not wait for the last one's TCP acknowledgement."""
    try:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    except OSError:
        pass


def hang_up(sock: socket.socket | None) -> None:
    """Close a client's connection both ways (its reads end at once)."""
    if sock is not None:
        try:
            sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        sock.close()


class Bridge:
    """A serial port served over TCP to one client at a time.

    Args:
        port: the serial port (``/dev/ttyUSB0``, ``COM3``, or any pyserial URL).
        listen: ``HOST:PORT`` to listen on (default ``127.0.0.1:7800``; port 0 picks a free one).
        baudrate: the bus speed [baud] (the servos' Baud Rate register).
        log: called with each line the bridge has to say (default: print to standard error).
        latency: check the adapter's USB latency timer (:func:`check_latency_timer`).

    Raises:
        BridgeError: the port cannot be opened (missing, in use) or the address bound.
    """

    def __init__(self, port: str, listen: str | None = None, *, baudrate: int = DEFAULT_BAUDRATE,
                 log=None, latency: bool = True):
        self.port_name = str(port)
        self.log = log or (lambda line: print(f"bridge: {line}", file=sys.stderr, flush=True))
        host, number = parse_listen(listen)
        self.timer = check_latency_timer(self.port_name, warn=self.log) if latency else None
        self.serial = open_serial(self.port_name, baudrate)
        try:
            self.server = socket.create_server((host, number))
        except OSError as e:
            self.serial.close()
            raise BridgeError(f"could not listen on {host}:{number}: {e.strerror or e}; "
                              "choose another port with --listen HOST:PORT") from None
        self.server.settimeout(0.1)
        self.address = self.server.getsockname()[:2]
        #: why the bridge stopped: "" (asked to), or the adapter's error
        self.gone = ""
        #: clients served and refused, since start
        self.served = self.refused = 0
        self._client: socket.socket | None = None
        self._client_name = ""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    @property
    def url(self) -> str:
        """What a client opens: ``socket://HOST:PORT``."""
        return f"socket://{self.address[0]}:{self.address[1]}"

    def describe(self) -> str:
        return f"serving {self.port_name} on {self.address[0]}:{self.address[1]} (open {self.url})"

    # --- running ------------------------------------------------------------------------------

    def start(self) -> "Bridge":
        """Serve in background threads; returns self."""
        if not self._threads:
            for target, name in ((self._accept, "accept"), (self._from_port, "port to client")):
                t = threading.Thread(target=target, name=f"bridge {name} {self.port_name}", daemon=True)
                t.start()
                self._threads.append(t)
        return self

    def serve(self) -> int:
        """Serve until :meth:`stop`, Ctrl-C or the adapter going away: 0, or 1 when the adapter went away."""
        self.start()
        try:
            while not self._stop.wait(0.2):
                pass
        finally:
            self.stop()
        return 1 if self.gone else 0

    def stop(self) -> None:
        """Disconnect the client, stop listening and release the port. Safe to call twice."""
        self._stop.set()
        self._drop_client()
        try:
            self.server.close()
        except OSError:
            pass
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(timeout=2)
        try:
            self.serial.close()
        except PORT_ERRORS:
            pass

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
        return False

    # --- the threads ---------------------------------------------------------------------------

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                sock, peer = self.server.accept()
            except socket.timeout:
                continue
            except OSError:
                return  # closed by stop()
            name = f"{peer[0]}:{peer[1]}"
            with self._lock:
                busy = self._client is not None
                if not busy:
                    self._client, self._client_name = sock, name
            if busy:
                self.refused += 1
                self.log(f"refused {name}: {self._client_name} is connected (one client at a time)")
                sock.close()
                continue
            no_delay(sock)
            try:
                self.serial.reset_input_buffer()  # nothing left over from the last client
            except PORT_ERRORS as e:
                self._adapter_gone(e)
                return
            self.served += 1
            self.log(f"client {name} connected")
            t = threading.Thread(target=self._from_client, args=(sock, name), name=f"bridge client {name}", daemon=True)
            t.start()

    def _from_client(self, sock: socket.socket, name: str) -> None:
        """Client -> port, until the client leaves."""
        while not self._stop.is_set():
            try:
                data = sock.recv(65536)
            except OSError:
                data = b""
            if not data:
                break
            try:
                self.serial.write(data)
            except PORT_ERRORS as e:
                self._adapter_gone(e)
                return
        with self._lock:
            mine = self._client is sock
            if mine:
                self._client = None
        sock.close()
        if mine and not self._stop.is_set():
            self.log(f"client {name} left")

    def _from_port(self) -> None:
        """Port -> client (bytes with no client are dropped, as on an open bus)."""
        ser = self.serial
        while not self._stop.is_set():
            try:
                data = ser.read(1)  # waits at most the port's timeout
                if data:
                    waiting = ser.in_waiting
                    if waiting:
                        data += ser.read(waiting)
            except PORT_ERRORS as e:
                if not self._stop.is_set():
                    self._adapter_gone(e)
                return
            client = self._client
            if data and client is not None:
                try:
                    client.sendall(data)
                except OSError:
                    pass  # the client is leaving: its thread says so

    def _adapter_gone(self, error: Exception) -> None:
        if self._stop.is_set():
            return
        self.gone = str(error) or type(error).__name__
        had = self._client_name if self._client is not None else ""
        self.log(f"the adapter on {self.port_name} is gone ({self.gone}); "
                 + (f"client {had} disconnected; " if had else "")
                 + "plug it in again and start the bridge again")
        self._stop.set()
        self._drop_client()

    def _drop_client(self) -> None:
        with self._lock:
            client, self._client = self._client, None
        hang_up(client)


# --- the command ----------------------------------------------------------------------------

def parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(
        prog="snakekit bridge",
        description="Serve the arm's USB serial port over TCP, so the kit can reach the arm from another "
                    "computer or from a container: make_robot('hardware', port='socket://HOST:PORT'). "
                    "One client at a time; Ctrl-C stops.")
    ap.add_argument("port", help="the serial port of the U2D2 adapter (/dev/ttyUSB0, /dev/cu.usbserial-..., COM3)")
    ap.add_argument("--listen", metavar="HOST:PORT", default=None,
                    help="address to listen on (default 127.0.0.1:7800: this computer only; "
                         "0.0.0.0:7800 offers the arm to the network)")
    ap.add_argument("--baud", type=int, default=DEFAULT_BAUDRATE,
                    help=f"bus speed [baud] (default {DEFAULT_BAUDRATE}, the kit's)")
    return ap


def main(argv: list[str] | None = None) -> int:
    """``snakekit bridge``: 0 after Ctrl-C or SIGTERM, 1 when the adapter went away, 2 when it could not start."""
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        args = parser().parse_args(argv)
    except SystemExit as e:
        return int(e.code or 0)
    try:
        bridge = Bridge(args.port, args.listen, baudrate=args.baud)
    except BridgeError as e:
        print(f"snakekit bridge: {e}", file=sys.stderr)
        return 2

    def terminate(signum, frame):
        raise KeyboardInterrupt

    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, terminate) if in_main else None
    try:
        if bridge.timer is not None:
            bridge.log(bridge.timer.describe())
        bridge.log(f"{bridge.describe()}; one client at a time; Ctrl-C stops")
        code = bridge.serve()
    except KeyboardInterrupt:
        code = 0
    finally:
        bridge.stop()
        if in_main:
            signal.signal(signal.SIGTERM, previous)
    if not bridge.gone:
        bridge.log(f"stopped ({bridge.served} client(s) served)")
    return code


if __name__ == "__main__":
    sys.exit(main())
