"""The meshcat server: a thread of the kernel, bound to one host, gone with the kernel.

meshcat's viewer is a web page (three.js) fed over a websocket by a small server (meshcat's
own ``ZMQWebSocketBridge``, on tornado); the kernel sends it drawing commands over ZeroMQ.
meshcat's launcher runs that server as a separate Python process, listening on every network
interface and left running when the kernel is killed. Here it runs in a thread of the kernel
itself, on its own event loop:

* no second Python process: a kernel with a viewer is 30-35 MB smaller (a Python process with
  tornado and ZeroMQ is about 31 MB resident), and starting a viewer starts no interpreter;
* the web server binds the host asked for (``127.0.0.1`` by default), and the ZeroMQ socket
  always binds ``127.0.0.1``;
* the server stops when :func:`stop_server` is called, at interpreter exit (for the viewers
  registered in :data:`LIVE`), and with the kernel however it ends (``kill -9`` included),
  because it is part of it; a cell's Ctrl-C does not reach it (only the main thread gets
  KeyboardInterrupt);
* the kernel's busy cells do not stop it: Python hands the thread the interpreter lock every
  few milliseconds, and while a cell waits (a real-time move, ``time.sleep``) it runs freely;
* no request waits for a browser: every request times out with a
  :class:`~snakekit.errors.ViewerError` instead of hanging a headless notebook run;
* the page connects its websocket beside its own address, not to the root of its host, so
  it works on the server's own port and through jupyter-server-proxy alike
  (``<base_url>proxy/<port>/static/`` and its websocket ``<base_url>proxy/<port>/``).
"""

from __future__ import annotations

import atexit
import socket
import threading
import weakref
from pathlib import Path

from ..errors import MissingDependencyError, ViewerError

try:
    import zmq

    from .client import load as _load_meshcat
    from .client import server_module as _server_module

    ViewerWindow = _load_meshcat().visualizer.ViewerWindow
except ImportError as _e:  # pragma: no cover - the kit's environment has meshcat
    raise MissingDependencyError(f"snakekit.viewer needs meshcat ({_e}); install the kit's environment "
                      "with tools/setup (or `pip install meshcat`)") from _e

#: the open viewers (anything with a close()), closed at interpreter exit
LIVE: weakref.WeakSet = weakref.WeakSet()


#: meshcat's page connects its websocket to ``ws://<host>/``, the root of the host it came from;
#: through a proxy its websocket is beside its own address instead (``.../proxy/7001/`` for a page
#: at ``.../proxy/7001/static/``), so the page is served with this call in place of meshcat's
CONNECT = 'viewer.connect(new URL("..", location.href).href.replace(/^http/, "ws"));'


def _page(meshcat_server) -> str:
    """meshcat's viewer page, connecting its websocket beside its own address (:data:`CONNECT`)."""
    text = (Path(meshcat_server.VIEWER_ROOT) / meshcat_server.VIEWER_HTML).read_text(encoding="utf-8")
    if text.count("viewer.connect();") != 1:
        raise ViewerError(f"meshcat's page {meshcat_server.VIEWER_HTML} no longer calls viewer.connect() once, "
                          "so the kit cannot point its websocket through Jupyter's proxy: install the meshcat "
                          "version of environment.lock (tools/setup)")
    return text.replace("viewer.connect();", CONNECT)


def _bridge_class():
    """meshcat's bridge, listening on the host asked for only (meshcat's own listen() binds
    every interface), remembering its HTTP server so that it can be stopped, and quiet: in
    the kernel, anything it printed would land in a notebook cell."""
    import tornado.httpserver
    import tornado.netutil
    import tornado.web
    import tornado.websocket

    meshcat_server = _server_module()
    page = _page(meshcat_server)

    class Page(tornado.web.RequestHandler):
        def get(self):
            self.set_header("Content-Type", "text/html; charset=UTF-8")
            self.set_header("Cache-Control", "no-store")
            self.write(page)

    class PageSocket(meshcat_server.WebSocketHandler):
        def open(self):  # meshcat's, without printing "opened: <handler>"
            self.bridge.websocket_pool.add(self)
            self.bridge.send_scene(self)

        def on_close(self):  # meshcat's, without printing "closed: <handler>"
            self.bridge.websocket_pool.discard(self)

    class Bridge(meshcat_server.ZMQWebSocketBridge):
        def make_app(self):
            app = tornado.web.Application([  # meshcat's two routes, the page and its websocket, and ours
                (r"/static/(?:index\.html)?", Page),
                (r"/static/(.*)", meshcat_server.StaticFileHandlerNoCache,
                 {"path": meshcat_server.VIEWER_ROOT, "default_filename": meshcat_server.VIEWER_HTML}),
                (r"/", PageSocket, {"bridge": self}),
            ], log_function=lambda handler: None)  # no access log

            def listen(port, **kwargs):
                sockets = tornado.netutil.bind_sockets(port, address=self.host)
                self.http_server = tornado.httpserver.HTTPServer(app)
                self.http_server.add_sockets(sockets)
                self.bound_port = sockets[0].getsockname()[1]

            app.listen = listen
            return app

        def forward_to_websockets(self, frames):  # meshcat's, skipping a page that just left
            for page in list(self.websocket_pool):
                try:
                    page.write_message(frames[2], binary=True)
                except tornado.websocket.WebSocketClosedError:
                    self.websocket_pool.discard(page)

    return Bridge


class Server:
    """meshcat's bridge served by a daemon thread of this process, on its own event loop.

    After :meth:`start`: ``zmq_url`` (where the kernel sends commands) and ``port`` (the web
    page's). ``alive`` tells whether it still serves, ``error`` why it stopped if it failed.
    """

    def __init__(self, host: str, port: int):
        self.host, self.requested_port = host, port
        self.zmq_url, self.port = "", 0
        self.error: BaseException | None = None
        self.loop = None  # the bridge's tornado IOLoop, once started
        self._bridge = None
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"snakekit viewer server ({host}:{port})",
                                        daemon=True)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive() and self.error is None

    def start(self, timeout: float) -> "Server":
        self._thread.start()
        if not self._ready.wait(timeout):
            raise ViewerError(f"the meshcat server could not start on {self.host}:{self.requested_port or 'any port'}: "
                              f"it did not report its address within {timeout:g} s. Make a new viewer; if this "
                              "repeats, restart the kernel.")
        if self.error is not None:
            why = f"{type(self.error).__name__}: {self.error}"
            hint = (f"Port {self.requested_port} may be in use: choose another port= or leave it unset for a free one."
                    if self.requested_port and "in use" in str(self.error) else
                    "Check that meshcat is installed in this environment (tools/setup).")
            raise ViewerError(f"the meshcat server could not start on {self.host}:{self.requested_port or 'any port'}: "
                              f"{why}. {hint}")
        return self

    def _run(self) -> None:
        import asyncio  # with tornado, only once a viewer is made: importing the module costs nothing

        asyncio.set_event_loop(asyncio.new_event_loop())
        try:
            bridge = _bridge_class()(zmq_url="tcp://127.0.0.1:*", host=self.host, port=self.requested_port)
            self.zmq_url = bridge.zmq_socket.getsockopt(zmq.LAST_ENDPOINT).decode()
            self.port = bridge.bound_port
        except BaseException as e:  # reported by start(), in the kernel's thread
            self.error = e
            asyncio.get_event_loop().close()
            self._ready.set()
            return
        self._bridge, self.loop = bridge, bridge.ioloop
        self._ready.set()
        try:
            bridge.ioloop.start()
        except BaseException as e:  # pragma: no cover - tornado's loop does not raise
            self.error = e
        finally:
            bridge.zmq_stream.close(linger=0)
            bridge.ioloop.close(all_fds=True)  # the listening sockets and every connection

    def _shutdown(self) -> None:
        """On the server's own loop: stop listening, say goodbye to the pages, stop the loop."""
        bridge = self._bridge
        server = getattr(bridge, "http_server", None)
        if server is not None:
            server.stop()
        for ws in list(bridge.websocket_pool):
            ws.close()
        self.loop.stop()

    def stop(self, timeout: float = 3.0) -> None:
        if self._thread.is_alive() and self.loop is not None:
            try:
                self.loop.add_callback(self._shutdown)
            except RuntimeError:  # the loop is already closed
                pass
            self._thread.join(timeout)


def stop_server(server: Server, socket) -> None:
    """Close the kernel's ZeroMQ socket and stop the server (its port is free on return)."""
    try:
        socket.close(linger=0)
    except Exception:
        pass
    server.stop()


@atexit.register
def _close_all() -> None:
    for viewer in list(LIVE):
        viewer.close()


def start_server(host: str, port: int, timeout: float) -> Server:
    """Start the server on ``host``:``port`` (0: any free port); it serves once this returns."""
    return Server(host, port).start(timeout)


def start_in_range(host: str, ports: str, timeout: float) -> Server:
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

    def __init__(self, web_url: str, server: Server, timeout: float):
        self.server = server
        self.zmq_url = server.zmq_url
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
            state = ("it is still running" if self.server.alive else
                     f"it stopped: {self.server.error}" if self.server.error else "it stopped")
            raise ViewerError(
                f"the meshcat server did not answer within {self.timeout_ms / 1000:g} s ({state}). "
                "Close this viewer and make a new one with snakekit.viewer.Viewer().") from e

    def send(self, command):
        import umsgpack  # meshcat's own dependency

        data = command.lower()
        self._request([data["type"].encode(), data["path"].encode(), umsgpack.packb(data)])

    def get_scene(self) -> str:
        return self._request([b"get_scene"]).decode("utf-8")


