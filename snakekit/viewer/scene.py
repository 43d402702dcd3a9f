"""A 3D view of the arm in a notebook cell, on meshcat, served from this machine.

The arm is drawn from the visual boxes of the generated URDF (``snakekit/assets/snake.urdf``)
and posed with :func:`snakekit.kinematics.joint_frames`, so the picture always matches the
robot description.

meshcat's viewer is a web page (three.js) fed by a small server over a websocket; the server
is a thread of the kernel (:mod:`snakekit.viewer.server` starts and stops it). Here:

* the web server binds ``127.0.0.1`` unless told otherwise (``host="0.0.0.0"`` only to serve
  its own port to other machines), and the ZeroMQ socket always binds ``127.0.0.1``;
* in a notebook, the page and its websocket are reached through the Jupyter server's own
  URL, ``<base_url>proxy/<port>/`` (jupyter-server-proxy), so the view works wherever
  JupyterLab does (a hub, Binder, a container or an SSH tunnel with Jupyter's port alone);
  elsewhere on the viewer's own port. :mod:`.urls` says what decides it, and
  ``SNAKEKIT_VIEWER_URL`` overrides it;
* the environment may set the defaults: ``SNAKEKIT_VIEWER_HOST`` (the interface) and
  ``SNAKEKIT_VIEWER_PORTS`` (a range such as ``7000-7009``: the first free port in it is
  used);
* the page and its JavaScript come from the meshcat package itself: nothing is fetched from
  the internet;
* the server stops with :meth:`Viewer.close`, at the end of a ``with`` block, when the
  viewer is garbage collected, at interpreter exit, and with the kernel however it ends
  (``kill -9`` included), because it is part of it;
* no call waits for a browser: every request to the server times out with a
  :class:`ViewerError` instead of hanging a headless notebook run.

>>> from snakekit.viewer import Viewer
>>> with Viewer() as viewer:                       # doctest: +SKIP
...     viewer.show([0.3, -0.2, 0.4, 0.1, 0.0])
...     viewer                                      # the last line of a cell shows it
"""

from __future__ import annotations

import html
import os
import weakref
from pathlib import Path

import numpy as np

from ..errors import ConfigurationError, InputTypeError, ShapeError, ViewerError
from ..collision import Clearance, clearance
from ..kinematics import forward_kinematics, joint_frames, workspace_boundary
from ..model import SPEC, SnakeSpec, urdf
from ..robot import Run
from ..trajectory import Trajectory
from ..validate import as_configuration
from .server import LIVE, Window, start_in_range, start_server, stop_server
from .urls import viewer_root
from .urdf_visuals import visual_boxes

from .client import load as _load_meshcat

meshcat = _load_meshcat()  # meshcat's kernel side, without its (unused) server: see client.py
mg = meshcat.geometry
Animation = meshcat.animation.Animation
AnimationClip, AnimationTrack = meshcat.animation.AnimationClip, meshcat.animation.AnimationTrack


def _translation(x: float, y: float, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def _rot_z(a: float) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(a), np.sin(a)
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def _quaternions_xyzw(T: np.ndarray) -> np.ndarray:
    """The rotations of the poses ``T`` (N, 4, 4) as three.js quaternions (x, y, z, w), shape (N, 4):
    meshcat's ``quaternion_from_matrix`` (the eigenvector of the largest eigenvalue, w >= 0) for
    all the poses in one call, instead of one call per pose."""
    m = T[:, :3, :3]
    K = np.zeros((len(T), 4, 4))
    K[:, 0, 0] = m[:, 0, 0] - m[:, 1, 1] - m[:, 2, 2]
    K[:, 1, 0] = m[:, 0, 1] + m[:, 1, 0]
    K[:, 1, 1] = m[:, 1, 1] - m[:, 0, 0] - m[:, 2, 2]
    K[:, 2, 0] = m[:, 0, 2] + m[:, 2, 0]
    K[:, 2, 1] = m[:, 1, 2] + m[:, 2, 1]
    K[:, 2, 2] = m[:, 2, 2] - m[:, 0, 0] - m[:, 1, 1]
    K[:, 3, 0] = m[:, 2, 1] - m[:, 1, 2]
    K[:, 3, 1] = m[:, 0, 2] - m[:, 2, 0]
    K[:, 3, 2] = m[:, 1, 0] - m[:, 0, 1]
    K[:, 3, 3] = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    K /= 3.0
    w, V = np.linalg.eigh(K)   # the lower triangle, as meshcat's
    q = np.take_along_axis(V, np.argmax(w, axis=1)[:, None, None], axis=2)[:, :, 0]  # (x, y, z, w)
    return np.where(q[:, 3:] < 0.0, -q, q)


def _points3(points) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] not in (2, 3) or len(p) < 2:
        raise ShapeError("points", "(N, 2) or (N, 3) with N >= 2 [m]", p.shape)
    if p.shape[1] == 2:
        p = np.column_stack([p, np.zeros(len(p))])
    return p


def _in_kernel() -> bool:
    """Whether this runs inside an IPython kernel or shell (a notebook)."""
    import sys

    shell = sys.modules.get("IPython.core.interactiveshell")
    return bool(shell and shell.InteractiveShell.initialized())


#: the longest wait for the server to start and report its address [s]
STARTUP_TIMEOUT = 10.0


# --- the viewer ---------------------------------------------------------------------------

ROBOT = "snake/robot"
GOAL = "snake/goal"
MARKS = "snake/marks"
#: colours of the goal arm: one the robots take, and one that folds the arm onto itself
GOAL_OK, GOAL_FOLDED = 0x2E86DE, 0xD62728


class Viewer:
    """The arm in a meshcat scene, shown in a notebook cell.

    Args:
        host: interface the web server listens on. Keep ``"127.0.0.1"``: a browser on
            another machine reaches the view through the Jupyter server's port; ``"0.0.0.0"``
            only for its own port to be reached from elsewhere.
            Default: ``$SNAKEKIT_VIEWER_HOST``, else ``"127.0.0.1"``.
        port: web server port (default: the first free one in ``$SNAKEKIT_VIEWER_PORTS``,
            e.g. ``7000-7009``, else any free port).
        url_host: host name the browser uses to reach the server's own port; given, the
            page is not proxied (default: in a notebook, through the Jupyter server,
            ``<base_url>proxy/<port>/static/``, or ``$SNAKEKIT_VIEWER_URL``; elsewhere
            ``host``, or ``localhost`` when listening on every interface).
        height: height of the view in a notebook cell [px].
        timeout: longest wait for the server to answer a request [s]; starting it may take
            up to ``max(timeout, STARTUP_TIMEOUT)`` (a busy machine can be slow).
        spec: the arm to draw.
        replace: close the viewers made before in this process first. The default is yes
            inside a notebook kernel, so running a cell again replaces its view instead of
            leaving another server behind, and no elsewhere (scripts, tests).

    Raises:
        ViewerError: the server could not start (port in use, meshcat missing).
        ConfigurationError: ``SNAKEKIT_VIEWER_URL`` is not an address with ``{port}``.
    """

    def __init__(self, *, host: str | None = None, port: int | None = None, url_host: str | None = None,
                 height: int = 420, timeout: float = 10.0, spec: SnakeSpec = SPEC,
                 replace: bool | None = None):
        if port is not None and not (isinstance(port, int) and 0 <= port < 65536):
            raise ConfigurationError(f"port must be an integer in 0..65535 (or None for any free port), got {port!r}")
        if replace is None:
            replace = _in_kernel()
        if replace:
            for old in list(LIVE):
                old.close()
        self.spec = spec
        if host is None:
            host = os.environ.get("SNAKEKIT_VIEWER_HOST") or "127.0.0.1"
        self.host = host
        self.height = int(height)
        if port is None and os.environ.get("SNAKEKIT_VIEWER_PORTS"):
            self._server = start_in_range(host, os.environ["SNAKEKIT_VIEWER_PORTS"], max(timeout, STARTUP_TIMEOUT))
        else:
            self._server = start_server(host, port or 0, max(timeout, STARTUP_TIMEOUT))
        self.port = self._server.port
        try:
            root = viewer_root(self.port, host, in_kernel=_in_kernel(), url_host=url_host)
        except ConfigurationError:
            self._server.stop()
            raise
        self.url = f"{root}static/"
        self._window = Window(self.url, self._server, timeout)
        self._finalizer = weakref.finalize(self, stop_server, self._server, self._window.zmq_socket)
        LIVE.add(self)
        self.vis = meshcat.Visualizer(window=self._window)
        self._boxes = visual_boxes(urdf(spec))
        self._links = ["base_link"] + [f"link{i + 1}" for i in range(spec.n_joints)]
        self._goal_drawn = False
        self._setup_scene()
        self.q = spec.home.copy()
        self.show(self.q)

    # --- life cycle ------------------------------------------------------------------------

    @property
    def zmq_url(self) -> str:
        """Where the kernel sends the server its drawing commands (ZeroMQ, on 127.0.0.1)."""
        return self._server.zmq_url

    @property
    def closed(self) -> bool:
        return not self._finalizer.alive

    def close(self) -> None:
        """Stop the server. Safe to call more than once; the view in the page goes blank."""
        self._finalizer()
        LIVE.discard(self)

    def __enter__(self) -> "Viewer":
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def _check_open(self) -> None:
        if self.closed:
            raise ViewerError("this viewer is closed; make a new one with snakekit.viewer.Viewer()")

    def __repr__(self) -> str:
        state = "closed" if self.closed else f"serving {self.url}"
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
        # Frame the workspace: meshcat's grid is 20 m in 0.5 m squares; scale it to the arm's
        # reach (a square of side 2.4 x reach, under the base, so the reach circle sits on it), and look
        # at the arm from above and in front, close enough that the reach fills the view.
        reach = float(self.spec.reach)
        floor = min(b.origin[2] - b.size[2] / 2 for b in self._boxes)
        k = 2.4 * reach / 20
        grid = np.diag([k, k, k, 1.0])
        grid[2, 3] = floor
        v["/Grid"].set_transform(grid)
        # Camera coordinates are meshcat's y-up frame: (x, y, z)_camera = (x, z, -y)_world;
        # the camera looks at the world origin (joint 1).
        v["/Cameras/default/rotated/<object>"].set_property("position", [0.0, 1.45 * reach, 0.85 * reach])
        self._draw_arm(ROBOT, opacity=1.0)

    def _draw_arm(self, root: str, *, opacity: float, color: int | None = None) -> None:
        for b in self._boxes:
            node = self.vis[f"{root}/{b.link}/{b.name}"]
            node.set_object(mg.Box(b.size), mg.MeshLambertMaterial(color=b.color if color is None else color,
                                                                    opacity=opacity))
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

    def show_goal(self, q) -> Clearance:
        """Show a translucent arm at ``q`` [rad]: where the next move will go.

        The goal arm is blue, or red when it folds onto itself (two links that are not
        neighbours closer than ``spec.collision_margin``: a goal every robot refuses).
        Returns the goal's :class:`~snakekit.collision.Clearance` (the closest pair of links).
        """
        self._check_open()
        q = as_configuration(q, self.spec, "goal q")
        c = clearance(q, spec=self.spec)
        color = GOAL_FOLDED if c.distance < self.spec.collision_margin else GOAL_OK
        if self._goal_drawn != color:
            self._draw_arm(GOAL, opacity=0.35, color=color)
            self._goal_drawn = color
        self.vis[GOAL].set_property("visible", True)
        self._pose(GOAL, q)
        return c

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

    def play(self, motion, *, fps: float = 30.0, play: bool = True, repetitions: int = 1,
             path: bool = True) -> int:
        """Play a run or a trajectory back in the view, with meshcat's animation controls.

        The motion becomes a meshcat animation (every frame's link poses, by forward kinematics),
        kept in the scene: replayed from the view's "Open Controls" menu under "Animations"
        (play, pause, reset, time scrubber, speed), and in a page saved with :meth:`save_html`.
        A run plays its measured motion, a trajectory its goals.

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
            raise InputTypeError(f"play() takes a snakekit Run or Trajectory (what robot.run, robot.move_to or "
                                 f"snakekit.joint_trajectory give), got {type(motion).__name__}")
        if not fps > 0:
            raise ConfigurationError(f"fps must be > 0 [Hz], got {fps}")
        count = int(np.ceil(traj.duration * fps - 1e-9)) + 1  # the last frame holds the end pose
        times = traj.times[0] + np.arange(count) / fps
        qs = traj.sample(times)
        poses = np.stack([joint_frames(q, spec=self.spec) for q in qs])  # (frame, link, 4, 4)
        anim = Animation(default_framerate=fps)
        keys = list(range(count))
        for i, link in enumerate(self._links[1:]):
            # the tracks meshcat's set_transform writes frame by frame, written whole
            anim.clips[self.vis.path.append(f"{ROBOT}/{link}")] = AnimationClip(tracks={
                "position": AnimationTrack("position", "vector3", list(keys), poses[:, i, :3, 3].tolist()),
                "quaternion": AnimationTrack("quaternion", "quaternion", list(keys),
                                             _quaternions_xyzw(poses[:, i]).tolist())}, fps=fps)
        self.vis.set_animation(anim, play=play, repetitions=repetitions)
        if path:
            self.draw_path(traj)
        # Where the arm ends is where later show() calls start from.
        self.q = np.array(qs[-1])
        return count

    animate = play   # its earlier name

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
