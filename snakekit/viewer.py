"""A 3D view of the arm in a notebook cell, on meshcat, served from this machine.

The arm is drawn from the visual boxes of the generated URDF (``snakekit/assets/snake.urdf``)
and posed with :func:`snakekit.kinematics.joint_frames`, so the picture always matches the
robot description.

meshcat's viewer is a web page (three.js) fed by a small server process over a websocket; the
kernel talks to that server over ZeroMQ. :class:`Viewer` starts the server itself rather
than through meshcat's launcher, because that launcher listens on every network interface
and leaves the server running when the kernel is killed. Here:

* the web server binds ``127.0.0.1`` unless told otherwise (``host="0.0.0.0"`` inside a
  container whose port is published), and the ZeroMQ socket always binds ``127.0.0.1``;
* the environment may set the defaults: ``SNAKEKIT_VIEWER_HOST`` (the interface) and
  ``SNAKEKIT_VIEWER_PORTS`` (a range such as ``7000-7009``: the first free port in it is
  used). The container image sets both, so the view is reachable on its published ports;
* the page and its JavaScript come from the meshcat package itself: nothing is fetched from
  the internet;
* the server stops with :meth:`Viewer.close`, at the end of a ``with`` block, when the
  viewer is garbage collected, at interpreter exit, and - if the kernel dies without any of
  those (``kill -9``) - on its own within a second, because it watches its parent;
* no call waits for a browser: every request to the server times out with a
  :class:`ViewerError` instead of hanging a headless notebook run.

>>> from snakekit.viewer import Viewer
>>> with Viewer() as viewer:                       # doctest: +SKIP
...     viewer.show([0.3, -0.2, 0.4, 0.1, 0.0])
...     viewer                                      # the last line of a cell shows it
"""

from __future__ import annotations

import atexit
import html
import os
import selectors
import socket
import subprocess
import sys
import time
import warnings
import weakref
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from .errors import SnakekitError
from .kinematics import as_configuration, forward_kinematics, joint_frames
from .model import SPEC, SnakeSpec, urdf
from .robot import Run
from .trajectory import Trajectory

try:
    import zmq

    with warnings.catch_warnings():  # meshcat 0.3 imports a pyzmq module deprecated since 17
        warnings.simplefilter("ignore", DeprecationWarning)
        import meshcat
        import meshcat.geometry as mg
        from meshcat.animation import Animation
        from meshcat.visualizer import ViewerWindow
except ImportError as _e:  # pragma: no cover - the kit's environment has meshcat
    raise ImportError(f"snakekit.viewer needs meshcat ({_e}); install the kit's environment "
                      "with tools/setup (or `pip install meshcat`)") from _e


class ViewerError(SnakekitError, RuntimeError):
    """The viewer's server could not be started, or stopped answering."""


# --- the server process -------------------------------------------------------------------

# Run with ``python -c`` so the server process imports meshcat and tornado only (not
# Pinocchio or MuJoCo): it stays small. Arguments: host, port (0 = any free one).
_SERVER = r'''
import os, sys, threading, time
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

_LIVE: "weakref.WeakSet[Viewer]" = weakref.WeakSet()


def _stop_server(proc: subprocess.Popen, socket) -> None:
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
    for viewer in list(_LIVE):
        viewer.close()


def _start_server(host: str, port: int, timeout: float) -> tuple[subprocess.Popen, str, int]:
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


def _start_in_range(host: str, ports: str, timeout: float) -> tuple[subprocess.Popen, str, int]:
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
            return _start_server(host, candidate, timeout)
        except ViewerError as e:
            if "in use" not in str(e):
                raise
    raise ViewerError(f"every viewer port in {low}-{high} (SNAKEKIT_VIEWER_PORTS) is in use: close a viewer "
                      "(viewer.close(), or restart its kernel) and make a new one")


class _Window(ViewerWindow):
    """meshcat's window on a server started by :func:`_start_server`, with request timeouts."""

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


# --- geometry from the robot description ----------------------------------------------------


@dataclass(frozen=True)
class VisualBox:
    """One visual box of the URDF.

    Attributes:
        link: the link it belongs to (``base_link``, ``link1``...).
        name: the visual's name in the URDF.
        origin: box centre in the link frame [m].
        size: edge lengths (x, y, z) [m].
        color: RGB colour as 0xRRGGBB.
    """

    link: str
    name: str
    origin: tuple[float, float, float]
    size: tuple[float, float, float]
    color: int


def _rgb_hex(rgba: str) -> int:
    r, g, b = (min(max(float(c), 0.0), 1.0) for c in rgba.split()[:3])
    return (round(r * 255) << 16) | (round(g * 255) << 8) | round(b * 255)


def visual_boxes(urdf_text: str) -> list[VisualBox]:
    """The box visuals of a URDF, in document order.

    >>> from snakekit.model import urdf
    >>> boxes = visual_boxes(urdf())
    >>> sorted({b.link for b in boxes})
    ['base_link', 'link1', 'link2', 'link3', 'link4', 'link5']
    """
    root = ET.fromstring(urdf_text)
    colors = {m.get("name"): _rgb_hex(m.find("color").get("rgba"))
              for m in root.findall("material") if m.find("color") is not None}
    out = []
    for link in root.findall("link"):
        for vis in link.findall("visual"):
            box = vis.find("geometry/box")
            if box is None:
                continue
            origin = vis.find("origin")
            xyz = origin.get("xyz", "0 0 0") if origin is not None else "0 0 0"
            mat = vis.find("material")
            color = 0xAAAAAA
            if mat is not None:
                inline = mat.find("color")
                color = _rgb_hex(inline.get("rgba")) if inline is not None else colors.get(mat.get("name"), color)
            out.append(VisualBox(link.get("name"), vis.get("name", ""), tuple(map(float, xyz.split())),
                                 tuple(map(float, box.get("size").split())), color))
    return out


def workspace_boundary(*, bins: int = 120, samples: int = 20000, refine: int = 60, seed: int = 0,
                       spec: SnakeSpec = SPEC) -> np.ndarray:
    """Outer boundary of the tool's reachable points, as a closed polygon (bins, 2) [m].

    See :func:`boundary_configurations` for how it is found.
    """
    return boundary_configurations(bins=bins, samples=samples, refine=refine, seed=seed, spec=spec)[0].copy()


@lru_cache(maxsize=8)
def boundary_configurations(*, bins: int = 120, samples: int = 20000, refine: int = 60, seed: int = 0,
                            spec: SnakeSpec = SPEC) -> tuple[np.ndarray, np.ndarray]:
    """Outer boundary of the tool's reachable points, as a closed polygon (bins, 2) [m].

    For each of ``bins`` directions around joint 1 it keeps the farthest tool point found
    among ``samples`` random configurations and the evenly curled ones (joints 2..n bent
    alike), then pushes each direction's best configuration outwards with ``refine`` small
    random steps (a step that lands in another direction improves that one). Every vertex
    is a reachable tool point.

    Returns:
        the boundary points (M, 2) [m] and the joint angles (M, n_joints) [rad] reaching
        them (cached; read-only arrays).
    """
    rng = np.random.default_rng(seed)
    n = spec.n_joints
    grid = np.linspace(spec.lower, spec.upper, 61)
    curled = np.array([[a] + [b] * (n - 1) for a in grid for b in grid])
    qs = np.vstack([rng.uniform(spec.lower, spec.upper, (samples, n)), curled])
    pts = np.array([forward_kinematics(q, spec=spec)[:2, 3] for q in qs])

    def bin_of(p):
        a = np.arctan2(p[..., 1], p[..., 0])
        return np.minimum(((a + np.pi) / (2 * np.pi) * bins).astype(int), bins - 1)

    idx, rad = bin_of(pts), np.hypot(pts[:, 0], pts[:, 1])
    best_r = np.full(bins, -1.0)
    best_q = np.zeros((bins, n))
    best_p = np.zeros((bins, 2))
    for i in np.argsort(rad):  # ascending: the farthest point of each bin is written last
        best_r[idx[i]], best_q[idx[i]], best_p[idx[i]] = rad[i], qs[i], pts[i]
    for step in np.geomspace(0.3, 0.01, refine):
        for b in np.flatnonzero(best_r > 0):
            q = np.clip(best_q[b] + rng.normal(0, step, n), spec.lower, spec.upper)
            p = forward_kinematics(q, spec=spec)[:2, 3]
            r, k = float(np.hypot(*p)), int(bin_of(p))
            if r > best_r[k]:  # a farther point for whichever direction it lands in
                best_r[k], best_q[k], best_p[k] = r, q, p
    keep = best_r > 0
    points, configurations = best_p[keep], best_q[keep]
    points.setflags(write=False)
    configurations.setflags(write=False)
    return points, configurations


def _translation(x: float, y: float, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _rot_z(a: float) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(a), np.sin(a)
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def _points3(points) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] not in (2, 3) or len(p) < 2:
        raise ValueError(f"points must have shape (N, 2) or (N, 3) with N >= 2 [m], got shape {p.shape}")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    return p


# --- the viewer ---------------------------------------------------------------------------

ROBOT = "snake/robot"
GOAL = "snake/goal"
MARKS = "snake/marks"


class Viewer:
    """The arm in a meshcat scene, shown in a notebook cell.

    Args:
        host: interface the web server listens on. Keep ``"127.0.0.1"`` unless the browser
            runs on another machine (``"0.0.0.0"`` inside a container with a published port).
            Default: ``$SNAKEKIT_VIEWER_HOST``, else ``"127.0.0.1"``.
        port: web server port (default: the first free one in ``$SNAKEKIT_VIEWER_PORTS``,
            e.g. ``7000-7009``, else any free port).
        url_host: host name the browser uses to reach the server (default: ``host``, or
            ``localhost`` when listening on every interface).
        height: height of the view in a notebook cell [px].
        timeout: longest wait for the server to start or to answer a request [s].
        spec: the arm to draw.

    Raises:
        ViewerError: the server could not start (port in use, meshcat missing).
    """

    def __init__(self, *, host: str | None = None, port: int | None = None, url_host: str | None = None,
                 height: int = 420, timeout: float = 10.0, spec: SnakeSpec = SPEC):
        if port is not None and not (isinstance(port, int) and 0 <= port < 65536):
            raise ValueError(f"port must be an integer in 0..65535 (or None for any free port), got {port!r}")
        self.spec = spec
        if host is None:
            host = os.environ.get("SNAKEKIT_VIEWER_HOST") or "127.0.0.1"
        self.host = host
        self.height = int(height)
        if port is None and os.environ.get("SNAKEKIT_VIEWER_PORTS"):
            self._proc, zmq_url, self.port = _start_in_range(host, os.environ["SNAKEKIT_VIEWER_PORTS"], timeout)
        else:
            self._proc, zmq_url, self.port = _start_server(host, port or 0, timeout)
        shown = url_host or ("localhost" if host in ("0.0.0.0", "", "::") else host)
        if ":" in shown and not shown.startswith("["):
            shown = f"[{shown}]"
        self.url = f"http://{shown}:{self.port}/static/"
        self._window = _Window(zmq_url, self.url, self._proc, timeout)
        self._finalizer = weakref.finalize(self, _stop_server, self._proc, self._window.zmq_socket)
        _LIVE.add(self)
        self.vis = meshcat.Visualizer(window=self._window)
        self._boxes = visual_boxes(urdf(spec))
        self._links = ["base_link"] + [f"link{i + 1}" for i in range(spec.n_joints)]
        self._goal_drawn = False
        self._setup_scene()
        self.q = spec.home.copy()
        self.show(self.q)

    # --- life cycle ------------------------------------------------------------------------

    @property
    def server_pid(self) -> int:
        """Process id of the meshcat server."""
        return self._proc.pid

    @property
    def closed(self) -> bool:
        return not self._finalizer.alive

    def close(self) -> None:
        """Stop the server. Safe to call more than once; the view in the page goes blank."""
        self._finalizer()
        _LIVE.discard(self)

    def __enter__(self) -> "Viewer":
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def _check_open(self) -> None:
        if self.closed:
            raise ViewerError("this viewer is closed; make a new one with snakekit.viewer.Viewer()")

    def __repr__(self) -> str:
        state = "closed" if self.closed else f"serving {self.url} (server pid {self.server_pid})"
        return f"<snakekit Viewer {state}>"

    # --- notebook display ------------------------------------------------------------------

    def iframe(self, height: int | None = None) -> str:
        """HTML of an iframe showing the live scene (what a notebook cell displays)."""
        h = self.height if height is None else int(height)
        return (f'<div class="snakekit-viewer" style="height:{h}px;width:100%;resize:vertical;overflow:hidden">'
                f'<iframe src="{html.escape(self.url)}" title="snakekit 3D view" '
                f'style="width:100%;height:100%;border:none"></iframe></div>')

    def _repr_html_(self) -> str:
        if self.closed:
            return "<p>snakekit viewer (closed)</p>"
        return self.iframe()

    # --- scene -----------------------------------------------------------------------------

    def _setup_scene(self) -> None:
        v = self.vis
        v["/Background"].set_property("visible", False)  # plain white
        v["/Axes"].set_property("visible", False)
        # meshcat's grid is 20 m in 0.5 m squares: make it 1 m in 25 mm squares, under the base.
        floor = min(b.origin[2] - b.size[2] / 2 for b in self._boxes)
        grid = np.diag([0.05, 0.05, 0.05, 1.0])
        grid[2, 3] = floor
        v["/Grid"].set_transform(grid)
        # The default camera sits 3 m away; bring it to the 0.33 m arm. Camera coordinates
        # are meshcat's y-up frame: (x, y, z)_camera = (x, z, -y)_world.
        v["/Cameras/default/rotated/<object>"].set_property("position", [-0.05, 0.32, 0.30])
        self._draw_arm(ROBOT, opacity=1.0)

    def _draw_arm(self, root: str, *, opacity: float) -> None:
        for b in self._boxes:
            node = self.vis[f"{root}/{b.link}/{b.name}"]
            color = b.color if opacity == 1.0 else 0x2E86DE
            node.set_object(mg.Box(b.size), mg.MeshLambertMaterial(color=color, opacity=opacity))
            node.set_transform(_translation(*b.origin))

    def _pose(self, root: str, q: np.ndarray) -> None:
        frames = joint_frames(q, spec=self.spec)
        for i, link in enumerate(self._links[1:]):
            self.vis[f"{root}/{link}"].set_transform(frames[i])

    def show(self, q) -> None:
        """Pose the arm at joint angles ``q`` [rad] (one per joint, base to tip)."""
        self._check_open()
        q = as_configuration(q, self.spec)
        self._pose(ROBOT, q)
        self.q = q.copy()

    def show_goal(self, q) -> None:
        """Show a translucent blue arm at ``q`` [rad]: where the next move will go."""
        self._check_open()
        q = as_configuration(q, self.spec, "goal q")
        if not self._goal_drawn:
            self._draw_arm(GOAL, opacity=0.35)
            self._goal_drawn = True
        self.vis[GOAL].set_property("visible", True)
        self._pose(GOAL, q)

    def hide_goal(self) -> None:
        """Hide the goal arm."""
        self._check_open()
        if self._goal_drawn:
            self.vis[GOAL].set_property("visible", False)

    # --- marks -----------------------------------------------------------------------------

    def draw_target(self, x: float, y: float, heading: float | None = None, *,
                    closest: tuple[float, float] | None = None, name: str = "target") -> None:
        """Mark a tool target at (``x``, ``y``) [m], with an arrow along ``heading`` [rad].

        A reachable target is green. Give ``closest`` (the closest reachable point [m]) for
        an unreachable one: the target turns red and an orange dot on the closest point is
        joined to it by a line.
        """
        self._check_open()
        root = self.vis[f"{MARKS}/{name}"]
        root.delete()
        bad = closest is not None
        color = 0xD62728 if bad else 0x2CA02C
        root["point"].set_object(mg.Sphere(0.007), mg.MeshLambertMaterial(color=color))
        root["point"].set_transform(_translation(x, y))
        if heading is not None:
            length = 0.03
            root["heading"].set_object(mg.Box([length, 0.003, 0.003]), mg.MeshLambertMaterial(color=color))
            root["heading"].set_transform(_translation(x, y) @ _rot_z(heading) @ _translation(length / 2, 0))
        if bad:
            cx, cy = closest
            root["closest"].set_object(mg.Sphere(0.006), mg.MeshLambertMaterial(color=0xFF7F0E))
            root["closest"].set_transform(_translation(cx, cy))
            gap = _points3([[cx, cy], [x, y]]).T
            root["gap"].set_object(mg.Line(mg.PointsGeometry(gap), mg.LineBasicMaterial(color=0xD62728)))

    def draw_path(self, path, *, name: str = "path", color: int = 0x1F77B4) -> np.ndarray:
        """Draw a tool path: points (N, 2) or (N, 3) [m], or the tool path of a trajectory or run.

        For a :class:`~snakekit.robot.Run` the measured motion is drawn. Returns the points
        drawn (N, 3) [m].
        """
        self._check_open()
        if isinstance(path, Run):
            path = path.measured
        if isinstance(path, Trajectory):
            pts = np.array([forward_kinematics(q, spec=self.spec)[:3, 3] for q in path.positions])
        else:
            pts = _points3(path)
        self.vis[f"{MARKS}/{name}"].set_object(
            mg.Line(mg.PointsGeometry(pts.T), mg.LineBasicMaterial(color=color, linewidth=2)))
        return pts

    def draw_workspace(self, *, name: str = "workspace", color: int = 0x7F7F7F) -> np.ndarray:
        """Draw the outer boundary of the tool's workspace; returns it (N, 2) [m]."""
        self._check_open()
        boundary = workspace_boundary(spec=self.spec)
        pts = _points3(boundary)
        self.vis[f"{MARKS}/{name}"].set_object(
            mg.LineLoop(mg.PointsGeometry(pts.T), mg.LineBasicMaterial(color=color)))
        return boundary

    def clear(self, name: str | None = None) -> None:
        """Remove one mark (by name), or all marks."""
        self._check_open()
        self.vis[MARKS if name is None else f"{MARKS}/{name}"].delete()

    # --- playback --------------------------------------------------------------------------

    def animate(self, motion, *, fps: float = 30.0, play: bool = True, repetitions: int = 1,
                path: bool = True) -> int:
        """Play a trajectory or a run back in the view, with meshcat's animation controls.

        The controls (play, pause, reset, time scrubber, speed) are in the view's
        "Open Controls" menu under "Animations". A run plays its measured motion.

        Args:
            motion: a :class:`~snakekit.trajectory.Trajectory` or :class:`~snakekit.robot.Run`.
            fps: frames per second of the animation [Hz]; the motion plays at real speed.
            play: start playing at once.
            repetitions: how many times to play it.
            path: also draw the tool path (mark ``"path"``).

        Returns:
            the number of frames.
        """
        self._check_open()
        traj = motion.measured if isinstance(motion, Run) else motion
        if not isinstance(traj, Trajectory):
            raise TypeError(f"animate() takes a snakekit Trajectory or Run, got {type(motion).__name__}")
        if not fps > 0:
            raise ValueError(f"fps must be > 0 [Hz], got {fps}")
        count = int(np.ceil(traj.duration * fps - 1e-9)) + 1  # the last frame holds the end pose
        times = traj.times[0] + np.arange(count) / fps
        qs = traj.sample(times)
        anim = Animation(default_framerate=fps)
        for frame, q in enumerate(qs):
            frames = joint_frames(q, spec=self.spec)
            with anim.at_frame(self.vis, frame) as f:
                for i, link in enumerate(self._links[1:]):
                    f[f"{ROBOT}/{link}"].set_transform(frames[i])
        self.vis.set_animation(anim, play=play, repetitions=repetitions)
        if path:
            self.draw_path(traj)
        # Where the arm ends is where later show() calls start from.
        self.q = np.array(qs[-1])
        return count

    # --- export ----------------------------------------------------------------------------

    def static_html(self) -> str:
        """The scene as one self-contained HTML page (meshcat's JavaScript inlined)."""
        self._check_open()
        return self.vis.static_html()

    def save_html(self, path) -> Path:
        """Write :meth:`static_html` to ``path`` (opens offline, e.g. in grading feedback)."""
        path = Path(path)
        path.write_text(self.static_html(), encoding="utf-8")
        return path
