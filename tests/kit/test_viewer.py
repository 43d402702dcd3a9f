"""The 3D viewer: geometry from the URDF, poses from kinematics, a server that never lingers.

The scene is checked where meshcat keeps it: the server's scene tree, read back through
``static_html()`` (msgpack commands, base64 in the page) and decoded here.
"""

import base64
import os
import re
import signal
import socket
import subprocess
import sys
import textwrap
import time
import urllib.request
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from tests.conftest import free_port, need, notebook_client

need("meshcat")
psutil = need("psutil")
umsgpack = need("umsgpack")

import snakekit  # noqa: E402
from snakekit.model import SPEC, urdf  # noqa: E402
from snakekit.viewer import Viewer, ViewerError, boundary_configurations, visual_boxes  # noqa: E402


def scene_commands(viewer: Viewer) -> list[dict]:
    """The drawing commands the server holds, decoded."""
    page = viewer.static_html()
    blobs = re.findall(r'data:application/octet-binary;base64,([A-Za-z0-9+/=]+)"', page)
    return [umsgpack.unpackb(base64.b64decode(b)) for b in blobs]


def transform_of(viewer: Viewer, path: str) -> np.ndarray:
    matrices = [c["matrix"] for c in scene_commands(viewer)
                if c["type"] == "set_transform" and c["path"] == f"/meshcat/{path}"]
    assert matrices, f"no transform for {path}"
    return np.array(matrices[-1], dtype=float).reshape(4, 4).T  # three.js is column-major


def listening(*ports: int) -> list[tuple[str, int]]:
    """The listening sockets of this machine on ``ports``, as (address, port)."""
    return sorted((c.laddr.ip, c.laddr.port) for c in psutil.net_connections("inet")
                  if c.status == psutil.CONN_LISTEN and c.laddr.port in ports)


def zmq_port(viewer: Viewer) -> int:
    return int(viewer.zmq_url.rsplit(":", 1)[1])


def port_open(port: int, host: str = "127.0.0.1") -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex((host, port)) == 0


def wait_closed(*ports: int, timeout: float = 10.0) -> bool:
    """True once nothing listens on ``ports`` any more (``timeout``: a bound for a hang [s])."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not any(port_open(p) for p in ports):
            return True
        time.sleep(0.05)
    return False


@pytest.fixture(scope="module")
def viewer():
    with Viewer() as v:
        yield v


# --- geometry -------------------------------------------------------------------------------


def test_boxes_are_the_urdf_visuals():
    text = urdf()
    boxes = visual_boxes(text)
    assert len(boxes) == len(ET.fromstring(text).findall("link/visual"))
    servos = [b for b in boxes if b.name.startswith("servo")]
    assert len(servos) == SPEC.n_joints
    for b in servos:
        assert b.size == pytest.approx(SPEC.servo.size)
    tip = next(b for b in boxes if b.name == "tool_tip")
    assert tip.link == "link5" and tip.color == 0xD91A1A


def test_scene_holds_every_urdf_box_at_its_origin(viewer):
    sets = {c["path"] for c in scene_commands(viewer) if c["type"] == "set_object"}
    for b in visual_boxes(urdf()):
        path = f"snake/robot/{b.link}/{b.name}"
        assert f"/meshcat/{path}" in sets
        assert transform_of(viewer, path)[:3, 3] == pytest.approx(b.origin)


def test_show_poses_every_link_by_forward_kinematics(viewer):
    q = np.array([0.4, -0.3, 0.7, -0.2, 0.5])
    viewer.show(q)
    frames = snakekit.joint_frames(q)
    for i in range(SPEC.n_joints):
        assert transform_of(viewer, f"snake/robot/link{i + 1}") == pytest.approx(frames[i], abs=1e-6)
    tool = transform_of(viewer, "snake/robot/link5") @ np.array([SPEC.tool_offset, 0, 0, 1])
    assert tool[:3] == pytest.approx(snakekit.forward_kinematics(q)[:3, 3], abs=1e-6)


def test_show_rejects_a_wrong_configuration(viewer):
    with pytest.raises(snakekit.ShapeError, match=r"shape \(5,\)"):
        viewer.show([0.1, 0.2])


def test_goal_arm_is_translucent_and_separate(viewer):
    viewer.show([0, 0, 0, 0, 0])
    viewer.show_goal([1.0, 0, 0, 0, 0])
    goal = [c for c in scene_commands(viewer) if c["type"] == "set_object"
            and c["path"].startswith("/meshcat/snake/goal/")]
    assert goal and all(c["object"]["materials"][0]["opacity"] < 1 for c in goal)
    assert transform_of(viewer, "snake/goal/link1") == pytest.approx(snakekit.joint_frames([1.0, 0, 0, 0, 0])[0])
    assert transform_of(viewer, "snake/robot/link1") == pytest.approx(np.eye(4))


def test_a_goal_that_folds_the_arm_turns_red_and_back(viewer):
    from snakekit.viewer.scene import GOAL_FOLDED, GOAL_OK

    def goal_colors():
        last = {}
        for c in scene_commands(viewer):
            if c["type"] == "set_object" and c["path"].startswith("/meshcat/snake/goal/"):
                last[c["path"]] = c["object"]["materials"][0]["color"]
        return set(last.values())

    c = viewer.show_goal([1.57, 1.57, 1.57, 1.57, 0])
    assert c.distance < SPEC.collision_margin and c.links == ("base_link", "link4")
    assert goal_colors() == {GOAL_FOLDED}
    c = viewer.show_goal([0.3, 0.2, 0, 0, 0])
    assert c.distance >= SPEC.collision_margin
    assert goal_colors() == {GOAL_OK}


def test_animation_replays_the_motion_at_real_speed(viewer):
    tr = snakekit.joint_trajectory(np.zeros(5), [0.6, -0.4, 0.3, 0.2, -0.1], 2.0)
    frames = viewer.animate(tr, fps=30)
    assert frames == 61
    anim = [c for c in scene_commands(viewer) if c["type"] == "set_animation"][-1]
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    clip = clips["/meshcat/snake/robot/link5"]
    assert clip["fps"] == 30
    pos = next(t for t in clip["tracks"] if t["name"] == ".position")
    assert len(pos["keys"]) == 61 and pos["keys"][-1]["time"] == 60
    final = snakekit.joint_frames(tr.positions[-1])[4]
    assert pos["keys"][-1]["value"] == pytest.approx(final[:3, 3], abs=1e-6)
    assert viewer.q == pytest.approx(tr.positions[-1])


def test_play_holds_every_frame_of_a_run_at_its_time_in_the_saved_page(viewer, tmp_path):
    """Each frame k of the animation is the run's measured pose at t0 + k / fps: every link where
    forward kinematics puts it, turned as meshcat's own ``quaternion_from_matrix`` turns it (what
    its ``set_transform`` writes frame by frame), read back from the page save_html writes."""
    from meshcat.transformations import quaternion_from_matrix

    with snakekit.make_robot("sim") as robot:
        run = robot.move_to([0.5, 0.2, -0.3, 0.0, 0.1], duration=1.0)
    fps = 20.0
    frames = viewer.play(run, fps=fps)
    m = run.measured
    assert frames == int(np.ceil(m.duration * fps - 1e-9)) + 1
    page = viewer.save_html(tmp_path / "run.html").read_text()
    blobs = re.findall(r'data:application/octet-binary;base64,([A-Za-z0-9+/=]+)"', page)
    anim = [c for c in map(lambda b: umsgpack.unpackb(base64.b64decode(b)), blobs) if c["type"] == "set_animation"][-1]
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    times = m.times[0] + np.arange(frames) / fps
    # the measured angles at those times, interpolated here joint by joint (not by the kit's sampling)
    q = np.column_stack([np.interp(times, m.times, m.positions[:, j]) for j in range(5)])
    for i in range(5):
        clip = clips[f"/meshcat/snake/robot/link{i + 1}"]
        assert clip["fps"] == fps
        keys = next(t for t in clip["tracks"] if t["name"] == ".position")["keys"]
        assert [k["time"] for k in keys] == list(range(frames))
        poses = [snakekit.joint_frames(qk)[i] for qk in q]
        want = np.array([T[:3, 3] for T in poses])
        assert np.abs(np.array([k["value"] for k in keys]) - want).max() < 1e-9, f"link{i + 1}"
        turns = next(t for t in clip["tracks"] if t["name"] == ".quaternion")["keys"]
        assert [k["time"] for k in turns] == list(range(frames))
        want = np.array([np.roll(quaternion_from_matrix(T), -1) for T in poses])   # (w, x, y, z) -> three.js's (x, y, z, w)
        assert np.abs(np.array([k["value"] for k in turns]) - want).max() < 1e-9, f"link{i + 1}"
    assert viewer.q == pytest.approx(m.positions[-1])


def test_play_says_what_it_takes(viewer):
    with pytest.raises(snakekit.SnakekitError, match=r"play\(\) takes a snakekit Run or Trajectory .*got ndarray"):
        viewer.play(np.zeros((10, 5)))


def test_animate_a_run_draws_its_measured_tool_path(viewer):
    with snakekit.make_robot("sim") as robot:
        run = robot.move_to([0.5, 0.2, -0.3, 0.0, 0.1])
    viewer.animate(run)
    line = [c for c in scene_commands(viewer) if c["type"] == "set_object"
            and c["path"] == "/meshcat/snake/marks/path"][-1]
    array = line["object"]["geometries"][0]["data"]["attributes"]["position"]["array"]
    pts = np.frombuffer(array.data, dtype=np.float32).reshape(-1, 3)  # a msgpack Float32Array
    assert len(pts) == len(run.measured)
    assert pts[-1] == pytest.approx(snakekit.forward_kinematics(run.measured.positions[-1])[:3, 3], abs=1e-5)


def test_unreachable_target_marks_the_closest_point(viewer):
    viewer.draw_target(0.45, 0.0, 0.3, closest=(0.3315, 0.0))
    paths = {c["path"] for c in scene_commands(viewer) if c["type"] == "set_object"}
    assert {"/meshcat/snake/marks/target/point", "/meshcat/snake/marks/target/closest",
            "/meshcat/snake/marks/target/gap", "/meshcat/snake/marks/target/heading"} <= paths
    assert transform_of(viewer, "snake/marks/target/closest")[:2, 3] == pytest.approx([0.3315, 0.0])
    viewer.draw_target(0.2, 0.1)  # reachable: no closest mark left behind
    paths = {c["path"] for c in scene_commands(viewer) if c["type"] == "set_object"}
    assert "/meshcat/snake/marks/target/closest" not in paths


def test_workspace_boundary_is_reachable_and_encloses_the_samples():
    points, qs = boundary_configurations()
    for p, q in zip(points[::10], qs[::10]):
        assert snakekit.tool_pose_2d(q)[:2] == pytest.approx(p, abs=1e-9)
        assert np.all(np.abs(q) <= SPEC.upper)
    radius = np.hypot(*points.T)
    assert radius.max() == pytest.approx(SPEC.reach, abs=1e-3)
    # random reachable points lie within the boundary's radius in their direction (+2 mm)
    samples = snakekit.workspace_points(3000, seed=7)
    ang_b = np.arctan2(points[:, 1], points[:, 0])
    for s in samples[::15]:
        a = np.arctan2(s[1], s[0])
        nearest = np.argmin(np.abs(np.angle(np.exp(1j * (ang_b - a)))))
        assert np.hypot(*s) <= radius[nearest] + 0.004


def test_save_html_is_self_contained(viewer, tmp_path):
    viewer.draw_workspace()
    path = viewer.save_html(tmp_path / "scene.html")
    page = path.read_text()
    assert "MeshCat.Viewer" in page and len(page) > 500_000  # meshcat's JS is inlined
    assert not re.search(r"<script[^>]+src=", page)
    assert "http://" not in page.split("<script>")[0]
    assert "/meshcat/snake/marks/workspace" in str(scene_commands(viewer))


# --- the server -----------------------------------------------------------------------------


def test_server_listens_on_loopback_only(viewer):
    addrs = listening(viewer.port, zmq_port(viewer))
    assert addrs == sorted([("127.0.0.1", viewer.port), ("127.0.0.1", zmq_port(viewer))])  # page+websocket, ZeroMQ
    assert viewer.url == f"http://127.0.0.1:{viewer.port}/static/"


def test_the_server_is_a_thread_of_the_kernel_not_another_process(viewer):
    import threading

    # no process of the viewer's (the grader's warm fork server, kept by a test process that graded a batch, and the
    # suite's kernel server, kept by one that ran a notebook (tests/kernel_zygote.py), are none)
    assert [p for p in psutil.Process().children()
            if not {"grader.sandbox.forkserver", "tests.kernel_zygote"} & set(p.cmdline())] == []
    assert [t.name for t in threading.enumerate() if t.name.startswith("snakekit viewer server")] != []
    assert "serving http://127.0.0.1:" in repr(viewer)


def test_page_and_javascript_are_served_locally(viewer):
    page = urllib.request.urlopen(viewer.url, timeout=5).read().decode()
    assert 'src="main.min.js"' in page
    js = urllib.request.urlopen(viewer.url + "main.min.js", timeout=5).read()
    assert len(js) > 500_000 and b"MeshCat" in js
    assert viewer.url in viewer.iframe() and "<iframe" in viewer._repr_html_()


def test_all_interfaces_only_when_asked():
    with Viewer(host="0.0.0.0") as v:
        addrs = listening(v.port, zmq_port(v))
        assert addrs == sorted([("0.0.0.0", v.port), ("127.0.0.1", zmq_port(v))])  # ZeroMQ stays local
        assert v.url == f"http://localhost:{v.port}/static/"


def test_port_is_configurable():
    port = free_port()
    with Viewer(port=port) as v:
        assert v.port == port and f":{port}/" in v.url
        assert port_open(port)


def test_port_in_use_is_reported():
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(ViewerError, match=rf"{port}.*in use.*choose another port="):
            Viewer(port=port)


def test_close_stops_the_server_and_frees_the_port():
    import threading

    v = Viewer()
    ports = v.port, zmq_port(v)
    before = set(threading.enumerate())
    assert port_open(ports[0])
    v.close()
    v.close()  # twice is fine
    assert wait_closed(*ports)
    gone = [t for t in before if t.name.startswith("snakekit viewer server") and not t.is_alive()]
    assert len(gone) == 1, "the viewer's server thread did not end"
    with pytest.raises(ViewerError, match="closed"):
        v.show(np.zeros(5))


def test_closing_a_viewer_with_a_page_open_closes_the_page_connection():
    websocket = need("tornado.websocket")
    import asyncio

    v = Viewer()

    async def page_socket_closed() -> bool:
        ws = await websocket.websocket_connect(f"ws://127.0.0.1:{v.port}/", connect_timeout=5)
        v.close()  # from the kernel's thread, while the page is connected
        while (message := await asyncio.wait_for(ws.read_message(), 5)) is not None:
            assert isinstance(message, bytes)  # the scene, sent on connecting
        return True  # None: the server closed the connection

    assert asyncio.run(page_socket_closed())
    assert wait_closed(v.port)


def test_context_manager_stops_the_server():
    with Viewer() as v:
        port = v.port
    assert v.closed and wait_closed(port)


def test_a_stuck_server_raises_instead_of_hanging():
    import threading

    v = Viewer(timeout=0.5)
    release, freed = threading.Event(), threading.Event()

    def busy():  # the server's loop held until the test lets go (a bound of 60 s for a hang)
        release.wait(60.0)
        freed.set()

    try:
        v._server.loop.add_callback(busy)
        with pytest.raises(ViewerError, match=r"did not answer within 0.5 s \(it is still running\)"):
            v.show(np.zeros(5))
        assert not freed.is_set(), "show() waited for the stuck loop instead of raising"
    finally:
        release.set()
        v.close()


CHILD = textwrap.dedent("""
    import os, signal, sys
    from snakekit.viewer import Viewer
    v = Viewer()
    print(v.port, v.zmq_url.rsplit(":", 1)[1], flush=True)
    if sys.argv[1] == "kill":
        os.kill(os.getpid(), signal.SIGKILL)   # no atexit, no finalizer: like a killed kernel
    sys.exit(0)                                # a normal exit without close(): atexit
""")


@pytest.mark.parametrize("how", ["exit", "kill"])
def test_server_never_outlives_its_process(how):
    proc = subprocess.Popen([sys.executable, "-c", CHILD, how], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == (-signal.SIGKILL if how == "kill" else 0), err
    ports = [int(p) for p in out.split()]
    assert wait_closed(*ports), f"the viewer's ports {ports} outlived their process ({how})"
    leftover = [p for p in psutil.process_iter(["pid"]) if _session(p) == proc.pid]
    assert leftover == [], f"processes left behind by the kernel: {leftover}"


def _session(p) -> int | None:
    try:
        return os.getsid(p.pid)
    except OSError:
        return None


def test_running_the_viewer_cell_twice_in_a_kernel_leaves_one_server(tmp_path):
    """In a notebook, a new Viewer replaces the one made before: no server is left behind."""
    nbformat = need("nbformat")
    need("nbclient")
    cell = "from snakekit.viewer import Viewer\nviewer = Viewer()\nviewer"
    nb = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell(cell),
        nbformat.v4.new_code_cell("first = viewer.port, viewer.zmq_url"),
        nbformat.v4.new_code_cell(cell),  # the same cell, run again
        nbformat.v4.new_code_cell(
            "import os, threading\n"
            "servers = [t for t in threading.enumerate() if t.name.startswith('snakekit viewer server')]\n"
            "print(first[0], first[1].rsplit(':', 1)[1], viewer.port, len(servers), os.getpid())"),
    ])
    client = notebook_client(nb, timeout=60, kernel_name="python3",
                             resources={"metadata": {"path": str(tmp_path)}})
    with client.setup_kernel():
        for i in range(4):
            client.execute_cell(nb.cells[i], i)
        old_port, old_zmq, new_port, servers, kernel_pid = map(int, nb.cells[3].outputs[0]["text"].split())
        assert new_port != old_port
        assert wait_closed(old_port, old_zmq), "the first viewer's server is still listening"
        assert port_open(new_port)
        assert servers == 1
        assert psutil.Process(kernel_pid).children() == []  # no server process either


# --- meshcat's kernel side, imported without its server --------------------------------------

def _python(code: str) -> str:
    r = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_importing_the_viewer_imports_no_web_server_and_meshcat_still_works_as_documented():
    out = _python("""
        import os, sys
        from snakekit.viewer import Viewer
        print(sorted(m for m in ("tornado", "tornado.web", "asyncio", "ssl", "meshcat.servers.tree") if m in sys.modules))
        import meshcat, meshcat.geometry
        print(meshcat.Visualizer is meshcat.visualizer.Visualizer)
        print(sorted(os.listdir(os.path.join(meshcat.viewer_assets_path(), "dist"))))
        from meshcat.servers.zmqserver import ZMQWebSocketBridge  # a user's own server: the real module
        print(ZMQWebSocketBridge.__module__, "tornado.web" in sys.modules)
        print(sys.modules["meshcat.servers.zmqserver"].start_zmq_server_as_subprocess.__module__)
    """).splitlines()
    assert out[0] == "[]", "importing the viewer imported a web server: " + out[0]  # only Viewer() does
    assert out[1] == "True"
    assert "'index.html'" in out[2] and "'main.min.js'" in out[2], out[2]
    assert out[3] == "meshcat.servers.zmqserver True"
    assert out[4] == "meshcat.servers.zmqserver"


def test_meshcats_own_launcher_still_starts_its_server_from_a_kernel_with_the_viewer():
    out = _python("""
        import subprocess
        import snakekit.viewer
        import meshcat.visualizer as mv
        calls = []
        import io
        class Proc:  # the real launcher runs; only the server process it starts is replaced
            def __init__(self, args, **kw):
                calls.append(args)
                self.stdout = io.BytesIO(b"zmq_url=tcp://127.0.0.1:1\\nweb_url=http://127.0.0.1:2/static/\\n")
            poll = kill = wait = lambda self: None
        subprocess.Popen = Proc
        print(mv.start_zmq_server_as_subprocess(server_args=[])[1:])
        print(calls[0][-2:] == ["-m", "meshcat.servers.zmqserver"])
    """).splitlines()
    assert out == ["('tcp://127.0.0.1:1', 'http://127.0.0.1:2/static/')", "True"], out


def test_a_meshcat_imported_before_the_viewer_is_used_as_it_is():
    out = _python("""
        import meshcat
        full = meshcat
        from snakekit.viewer import Viewer
        import sys
        print(sys.modules["meshcat"] is full, hasattr(full, "__file__"))
    """)
    assert out.split() == ["True", "True"]
