"""The 3D viewer: geometry from the URDF, poses from kinematics, a server that never lingers.

The scene is checked where meshcat keeps it: the server's scene tree, read back through
``static_html()`` (msgpack commands, base64 in the page) and decoded here.
"""

import base64
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

from tests.conftest import free_port, need

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


def listening(pid: int) -> list[tuple[str, int]]:
    return sorted((c.laddr.ip, c.laddr.port) for c in psutil.Process(pid).net_connections("inet")
                  if c.status == psutil.CONN_LISTEN)


def port_open(port: int, host: str = "127.0.0.1") -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex((host, port)) == 0


def wait_gone(pid: int, port: int, timeout: float = 5.0) -> bool:
    """True once the process has ended (a zombie waiting for init counts) and the port is closed.

    A process that ends from a worker thread shows as a zombie before its last threads
    have closed its sockets, hence the port check.
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        ended = not psutil.pid_exists(pid) or psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
        if ended and not port_open(port):
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
    addrs = listening(viewer.server_pid)
    assert len(addrs) == 2  # the web page + websocket, and ZeroMQ
    assert {ip for ip, _ in addrs} == {"127.0.0.1"}
    assert viewer.url == f"http://127.0.0.1:{viewer.port}/static/"


def test_page_and_javascript_are_served_locally(viewer):
    page = urllib.request.urlopen(viewer.url, timeout=5).read().decode()
    assert 'src="main.min.js"' in page
    js = urllib.request.urlopen(viewer.url + "main.min.js", timeout=5).read()
    assert len(js) > 500_000 and b"MeshCat" in js
    assert viewer.url in viewer.iframe() and "<iframe" in viewer._repr_html_()


def test_all_interfaces_only_when_asked():
    with Viewer(host="0.0.0.0") as v:
        addrs = listening(v.server_pid)
        assert ("0.0.0.0", v.port) in addrs
        assert all(ip == "127.0.0.1" for ip, port in addrs if port != v.port)  # ZeroMQ stays local
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
        with pytest.raises(ViewerError, match=rf"{port}.*in use"):
            Viewer(port=port)


def test_close_stops_the_server_and_frees_the_port():
    v = Viewer()
    pid, port = v.server_pid, v.port
    assert port_open(port)
    v.close()
    v.close()  # twice is fine
    assert wait_gone(pid, port, 1.0)
    with pytest.raises(ViewerError, match="closed"):
        v.show(np.zeros(5))


def test_context_manager_stops_the_server():
    with Viewer() as v:
        pid, port = v.server_pid, v.port
    assert v.closed and wait_gone(pid, port, 1.0)


def test_a_stuck_server_raises_instead_of_hanging():
    v = Viewer(timeout=0.5)
    try:
        psutil.Process(v.server_pid).suspend()
        t0 = time.monotonic()
        with pytest.raises(ViewerError, match="did not answer within 0.5 s"):
            v.show(np.zeros(5))
        assert time.monotonic() - t0 < 2.0
    finally:
        psutil.Process(v.server_pid).resume()
        v.close()


CHILD = textwrap.dedent("""
    import os, signal, sys
    from snakekit.viewer import Viewer
    v = Viewer()
    print(v.server_pid, v.port, flush=True)
    if sys.argv[1] == "kill":
        os.kill(os.getpid(), signal.SIGKILL)   # no atexit, no finalizer: like a killed kernel
    sys.exit(0)                                # a normal exit without close(): atexit
""")


@pytest.mark.parametrize("how", ["exit", "kill"])
def test_server_never_outlives_its_process(how):
    proc = subprocess.run([sys.executable, "-c", CHILD, how], capture_output=True, text=True, timeout=60)
    assert proc.returncode == (-signal.SIGKILL if how == "kill" else 0), proc.stderr
    pid, port = map(int, proc.stdout.split())
    assert wait_gone(pid, port, 5.0), f"meshcat server {pid} outlived its parent ({how})"


def test_running_the_viewer_cell_twice_in_a_kernel_leaves_one_server(tmp_path):
    """In a notebook, a new Viewer replaces the one made before: no server is left behind."""
    nbformat = need("nbformat")
    nbclient = need("nbclient")
    cell = "from snakekit.viewer import Viewer\nviewer = Viewer()\nviewer"
    nb = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell(cell),
        nbformat.v4.new_code_cell("first = viewer.server_pid, viewer.port"),
        nbformat.v4.new_code_cell(cell),  # the same cell, run again
        nbformat.v4.new_code_cell("import os\nprint(first[0], first[1], viewer.server_pid, os.getpid())"),
    ])
    client = nbclient.NotebookClient(nb, timeout=60, kernel_name="python3",
                                     resources={"metadata": {"path": str(tmp_path)}})
    with client.setup_kernel():
        client.execute_cell(nb.cells[0], 0)
        client.execute_cell(nb.cells[1], 1)
        client.execute_cell(nb.cells[2], 2)
        client.execute_cell(nb.cells[3], 3)
        old_pid, old_port, new_pid, kernel_pid = map(int, nb.cells[3].outputs[0]["text"].split())
        assert new_pid != old_pid
        assert wait_gone(old_pid, old_port), "the first viewer's server is still running"
        assert psutil.pid_exists(new_pid)
        servers = [p for p in psutil.Process(kernel_pid).children() if p.pid in (old_pid, new_pid)]
        assert [p.pid for p in servers] == [new_pid]


# --- meshcat's kernel side, imported without its server --------------------------------------

def _python(code: str) -> str:
    r = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return r.stdout


def test_the_kernel_does_not_import_meshcats_web_server_but_meshcat_still_works_as_documented():
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
    assert out[0] == "[]", "importing the viewer imported meshcat's server: " + out[0]
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
