"""The meshcat server process: started by the kernel, bound to one host, gone with the kernel.

meshcat's viewer is a web page (three.js) fed by a small server process over a websocket; the
kernel talks to that server over ZeroMQ. The server is started here rather than through
meshcat's launcher, because that launcher listens on every network interface and leaves the
server running when the kernel is killed. Here:

* the web server binds the host asked for (``127.0.0.1`` by default), and the ZeroMQ socket
  always binds ``127.0.0.1``;
* the server stops when :func:`stop_server` is called, at interpreter exit (for the viewers
  registered in :data:`LIVE`), and - if the kernel dies without either (``kill -9``) - on its
  own within a second, because it watches its parent and its stdin;
* no request waits for a browser: every request times out with a
  :class:`~snakekit.errors.ViewerError` instead of hanging a headless notebook run.
"""

from __future__ import annotations

import atexit
import os
import selectors
import socket
import subprocess
import sys
import time
import warnings
import weakref

from ..errors import MissingDependencyError, ViewerError

try:
    import zmq

    from .client import load as _load_meshcat

    ViewerWindow = _load_meshcat().visualizer.ViewerWindow
except ImportError as _e:  # pragma: no cover - the kit's environment has meshcat
    raise MissingDependencyError(f"snakekit.viewer needs meshcat ({_e}); install the kit's environment "
                      "with tools/setup (or `pip install meshcat`)") from _e


# Run with ``python -c`` so the server process imports meshcat's server module, tornado and
# ZeroMQ only (not Pinocchio or MuJoCo): it stays small. The ``meshcat`` package's own
# __init__ is not run: it loads the kernel side (numpy, IPython, PIL, the geometry and
# visualizer modules), which the server never uses - that halves the server's memory
# (53 MB -> 31 MB resident). Arguments: host, port (0 = any free one).
_SERVER = r'''
import importlib.util, os, sys, threading, time, types
spec = importlib.util.find_spec("meshcat")
package = types.ModuleType("meshcat")
package.__path__ = list(spec.submodule_search_locations)
sys.modules["meshcat"] = package  # the package without its __init__: only the server is used
import tornado.httpserver, tornado.netutil, zmq
from meshcat.servers.zmqserver import ZMQWebSocketBridge

host, port = sys.argv[1], int(sys.argv[2])
parent = os.getppid()

def watch_stdin():
    # The kernel holds the other end of stdin: EOF means it is gone, however it ended.
    while sys.stdin.buffer.read(4096):
        pass
    os._exit(0)

def watch_parent():
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(0)

class Bridge(ZMQWebSocketBridge):
    def make_app(self):
        app = super().make_app()
        def listen(port, **kwargs):
            # meshcat's own listen() binds every interface; bind only the host asked for.
            sockets = tornado.netutil.bind_sockets(port, address=self.host)
            tornado.httpserver.HTTPServer(app).add_sockets(sockets)
            self.bound_port = sockets[0].getsockname()[1]
        app.listen = listen
        return app

threading.Thread(target=watch_stdin, daemon=True).start()
threading.Thread(target=watch_parent, daemon=True).start()
bridge = Bridge(zmq_url="tcp://127.0.0.1:*", host=host, port=port)
endpoint = bridge.zmq_socket.getsockopt(zmq.LAST_ENDPOINT).decode()
print(f"zmq_url={endpoint}", flush=True)
print(f"web_port={bridge.bound_port}", flush=True)
null = os.open(os.devnull, os.O_WRONLY)
os.dup2(null, 1)
os.dup2(null, 2)
bridge.run()
'''

#: the open viewers (anything with a close()), closed at interpreter exit
LIVE: weakref.WeakSet = weakref.WeakSet()


def stop_server(proc: subprocess.Popen, socket) -> None:
    """Close the ZeroMQ socket and end the server process (wait for it, so no zombie stays)."""
    try:
        socket.close(linger=0)
    except Exception:
        pass
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=3)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=3)
    for f in (proc.stdin, proc.stdout, proc.stderr):
        if f is not None:
            try:
                f.close()
            except Exception:
                pass


@atexit.register
def _close_all() -> None:
    for viewer in list(LIVE):
        viewer.close()


def start_server(host: str, port: int, timeout: float) -> tuple[subprocess.Popen, str, int]:
    """Start the server; return the process, its ZeroMQ address and its web port."""
    proc = subprocess.Popen([sys.executable, "-u", "-c", _SERVER, host, str(port)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)  # a cell's Ctrl-C must not reach it
    lines: dict[str, str] = {}
    buf = b""
    deadline = time.monotonic() + timeout
    with selectors.DefaultSelector() as sel:
        sel.register(proc.stdout, selectors.EVENT_READ)
        while len(lines) < 2:
            left = deadline - time.monotonic()
            if left <= 0 or proc.poll() is not None:
                break
            if sel.select(timeout=min(left, 0.2)):
                chunk = os.read(proc.stdout.fileno(), 4096)
                if not chunk:
                    break
                buf += chunk
                *done, buf = buf.split(b"\n")
                for line in done:
                    key, _, value = line.decode().strip().partition("=")
                    if key in ("zmq_url", "web_port"):
                        lines[key] = value
    if len(lines) < 2:
        running = proc.poll() is None
        if running:
            proc.kill()
        proc.wait()
        err = proc.stderr.read().decode(errors="replace").strip().splitlines()
        for f in (proc.stdin, proc.stdout, proc.stderr):
            f.close()
        why = (f"it did not report its address within {timeout:g} s" if running
               else f"it exited with code {proc.returncode}: {err[-1] if err else 'no message'}")
        hint = (f"Port {port} may be in use: choose another port= or leave it unset for a free one."
                if port and any("in use" in e for e in err) else
                "Check that meshcat is installed in this environment (tools/setup).")
        raise ViewerError(f"the meshcat server could not start on {host}:{port or 'any port'}: {why}. {hint}")
    return proc, lines["zmq_url"], int(lines["web_port"])


def start_in_range(host: str, ports: str, timeout: float) -> tuple[subprocess.Popen, str, int]:
    """Start the server on the first free port of a range ``"LOW-HIGH"`` (or one port)."""
    low, _, high = ports.partition("-")
    try:
        low, high = int(low), int(high or low)
    except ValueError:
        raise ViewerError(f"SNAKEKIT_VIEWER_PORTS must be a port range such as 7000-7009, got {ports!r}") from None
    if not 0 < low <= high < 65536:
        raise ViewerError(f"SNAKEKIT_VIEWER_PORTS must be a port range such as 7000-7009, got {ports!r}")
    for candidate in range(low, high + 1):
        with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
            try:
                s.bind((host, candidate))
            except OSError:
                continue  # taken (another viewer): try the next one
        try:
            return start_server(host, candidate, timeout)
        except ViewerError as e:
            if "in use" not in str(e):
                raise
    raise ViewerError(f"every viewer port in {low}-{high} (SNAKEKIT_VIEWER_PORTS) is in use: close a viewer "
                      "(viewer.close(), or restart its kernel) and make a new one")


class Window(ViewerWindow):
    """meshcat's window on a server started by :func:`start_server`, with request timeouts."""

    def __init__(self, zmq_url: str, web_url: str, proc: subprocess.Popen, timeout: float):
        self.server_proc = proc
        self.zmq_url = zmq_url
        self.web_url = web_url
        self.timeout_ms = int(timeout * 1000)
        self.connect_zmq()

    def connect_zmq(self):
        self.zmq_socket = self.context.socket(zmq.REQ)
        self.zmq_socket.setsockopt(zmq.LINGER, 0)
        self.zmq_socket.setsockopt(zmq.RCVTIMEO, self.timeout_ms)
        self.zmq_socket.setsockopt(zmq.SNDTIMEO, self.timeout_ms)
        self.zmq_socket.connect(self.zmq_url)

    def _request(self, frames: list[bytes]) -> bytes:
        try:
            self.zmq_socket.send_multipart(frames)
            return self.zmq_socket.recv()
        except zmq.Again as e:
            # A REQ socket that missed its answer cannot be reused: start over.
            self.zmq_socket.close(linger=0)
            self.connect_zmq()
            alive = self.server_proc.poll() is None
            raise ViewerError(
                f"the meshcat server did not answer within {self.timeout_ms / 1000:g} s "
                f"({'it is still running' if alive else f'it exited with code {self.server_proc.returncode}'}). "
                "Close this viewer and make a new one with snakekit.viewer.Viewer().") from e

    def send(self, command):
        import umsgpack  # meshcat's own dependency

        data = command.lower()
        self._request([data["type"].encode(), data["path"].encode(), umsgpack.packb(data)])

    def get_scene(self) -> str:
        return self._request([b"get_scene"]).decode("utf-8")


