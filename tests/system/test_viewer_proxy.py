"""The 3D view through the Jupyter server's own port, as on a hub, Binder or an SSH tunnel.

JupyterLab runs under a hub-like base URL (``/user/ana/``) and headless Chromium reaches it
through a TCP tunnel on another port, as ``ssh -L`` makes one: the browser may reach that
tunnel and nothing else (not even JupyterLab's own port): every other request is refused by
the browser's own routing, and every websocket it opens is recorded. Lesson 0's first cells (the viewer and the
control panel, as handed out) run in a small notebook; the view must draw the arm (pixels
against the same view with the arm hidden), follow a dragged slider, and play the move
Execute makes (pixels), all while the viewer's own port, open on the machine, is never asked.

The rules that choose the page's address (:mod:`snakekit.viewer.urls`) are tested without a
browser, and a page saved with ``save_html`` is opened from its file with the network off: it
still draws the arm by itself.
"""

import json
import socket
import socketserver
import threading
import time
import urllib.parse
import urllib.request
from pathlib import Path

import pytest

from tests.conftest import need, need_program
from tests.system.test_browser import (ARTIFACTS, CHROMIUM_FLAGS, KERNEL_IDLE, ROOT, JupyterLab, changed_fraction,
                                       drag_slider, pixels, port_open, steady_screenshot)

pytestmark = pytest.mark.system  # the 3D view through JupyterLab, in headless Chromium: not in `make test-quick`

BASE_URL = "/user/ana/"
NOTEBOOK = "proxied_view.ipynb"
# no name resolves: nothing beyond the loopback addresses the test gives (no CDN, no update check)
OFFLINE_FLAGS = ["--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1"]


def lesson0_cells() -> list[str]:
    """Lesson 0's first two code cells, as handed out: the robot, the viewer, the control panel."""
    nb = json.loads((ROOT / "notebooks" / "00_meet_the_arm.ipynb").read_text())
    code = ["".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "code"]
    assert "Viewer()" in code[0] and "ControlPanel(robot, viewer)" in code[1], code[:2]
    return code[:2]


def write_notebook(path: Path) -> None:
    import nbformat

    cells = lesson0_cells() + [
        'viewer.vis["snake"].set_property("visible", False)\nprint("arm hidden")',
        'viewer.vis["snake"].set_property("visible", True)\nprint("arm shown")',
    ]
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(c) for c in cells])
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nbformat.write(nb, path)


def changed_view(view, reference: bytes, *, timeout: float = 30.0, threshold: float = 0.002) -> bytes:
    """The view, steady, once it differs from ``reference`` in more than ``threshold`` of its pixels."""
    deadline = time.monotonic() + timeout
    while True:
        shot = view.screenshot()
        if changed_fraction(pixels(shot), pixels(reference)) > threshold:
            return steady_screenshot(view)
        if time.monotonic() > deadline:
            return shot   # the caller's assertion says what did not change
        time.sleep(0.3)


class Tunnel(socketserver.ThreadingTCPServer):
    """A TCP tunnel from a free loopback port to ``127.0.0.1:<port>``, as ``ssh -L`` makes one."""

    daemon_threads = True

    def __init__(self, port: int):
        self.target = port

        class Relay(socketserver.BaseRequestHandler):
            def handle(self):
                with socket.create_connection(("127.0.0.1", self.server.target)) as far:
                    back = threading.Thread(target=self.pipe, args=(far, self.request), daemon=True)
                    back.start()
                    self.pipe(self.request, far)
                    back.join()

            @staticmethod
            def pipe(src, dst):
                try:
                    while data := src.recv(65536):
                        dst.sendall(data)
                except OSError:
                    pass
                finally:
                    try:
                        dst.shutdown(socket.SHUT_WR)
                    except OSError:
                        pass

        super().__init__(("127.0.0.1", 0), Relay)
        self.port = self.server_address[1]
        threading.Thread(target=self.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.shutdown()
        self.server_close()


def run_next_cell(page, expect: str | None = None, timeout: float = 120_000) -> None:
    page.keyboard.press("Shift+Enter")
    if expect:
        page.locator(".jp-OutputArea-output", has_text=expect).first.wait_for(timeout=timeout)


def test_view_and_panel_work_through_the_jupyter_port_alone_under_a_hub_base_url(tmp_path):
    sync_api = need("playwright.sync_api")
    need("jupyterlab")
    need("meshcat")
    need("nbformat")
    need("jupyter_server_proxy")
    chromium = need_program("chromium")
    ARTIFACTS.mkdir(exist_ok=True)
    root = tmp_path / "notebooks"
    root.mkdir()
    write_notebook(root / NOTEBOOK)
    home = tmp_path / "home"
    home.mkdir()

    lab = JupyterLab(root, home, base_url=BASE_URL)
    tunnel = Tunnel(lab.port)
    jupyter = f"127.0.0.1:{tunnel.port}"   # all the browser may reach
    refused: list[str] = []
    asked: list[str] = []
    sockets: list[str] = []
    viewer_port = None

    def only_jupyter(route):
        url = route.request.url
        asked.append(url)
        if urllib.parse.urlsplit(url).netloc == jupyter:
            route.continue_()
        else:
            refused.append(url)
            route.abort("addressunreachable")

    try:
        with sync_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_FLAGS + OFFLINE_FLAGS)
            try:
                context = browser.new_context(viewport={"width": 1400, "height": 1100})
                context.route("**/*", only_jupyter)
                page = context.new_page()
                page.on("websocket", lambda ws: sockets.append(ws.url))
                page.goto(f"http://{jupyter}{BASE_URL}lab/tree/{NOTEBOOK}?token={lab.token}")
                page.wait_for_function(KERNEL_IDLE, timeout=90_000)
                cells = page.locator(".jp-Notebook .jp-Cell")
                cells.first.locator(".cm-content").click()
                page.keyboard.press("Escape")                  # command mode on the first cell
                run_next_cell(page, "snakekit Viewer serving")  # the lesson's print(viewer)
                shown = page.locator(".jp-OutputArea-output", has_text="snakekit Viewer serving").first.inner_text()
                run_next_cell(page)                             # the control panel
                view = page.locator("iframe[title='snakekit 3D view']").first
                view.wait_for(timeout=120_000)
                src = view.get_attribute("src")
                assert src.startswith(f"{BASE_URL}proxy/") and src.endswith("/static/"), src
                assert src in shown, shown                       # what print(viewer) tells the student
                viewer_port = int(src.split("/")[-3])
                view.content_frame.locator("canvas").first.wait_for(state="visible", timeout=60_000)
                view.scroll_into_view_if_needed()
                page.locator(".widget-button", has_text="Execute").first.wait_for(timeout=30_000)
                drawn = steady_screenshot(view)
                (ARTIFACTS / "proxy_view_drawn.png").write_bytes(drawn)

                # the same view with every arm hidden: the blank canvas the drawing is compared with
                run_next_cell(page, "arm hidden")
                blank = changed_view(view, drawn)
                (ARTIFACTS / "proxy_view_blank.png").write_bytes(blank)
                arm = changed_fraction(pixels(drawn), pixels(blank))
                assert arm > 0.01, f"the view drew no arm through the proxy ({arm:.3%} of its pixels are the arm's)"
                run_next_cell(page, "arm shown")
                again = changed_view(view, blank)
                back = changed_fraction(pixels(again), pixels(drawn))
                assert back < 0.001, f"shown again, the arm is not where it was drawn ({back:.3%} of pixels differ)"

                # a slider dragged: the goal arm follows in the view
                drag_slider(page, "joint 1 [rad]")
                view.scroll_into_view_if_needed()
                goal = changed_view(view, again)
                (ARTIFACTS / "proxy_view_goal.png").write_bytes(goal)
                moved = changed_fraction(pixels(again), pixels(goal))
                assert 0.002 < moved < 0.5, f"the goal arm did not follow the slider ({moved:.3%} of pixels changed)"

                # Execute: the robot moves to the goal and the view plays the move
                button = page.locator(".widget-button", has_text="Execute").first
                button.scroll_into_view_if_needed()
                button.click()
                page.locator(".jp-RenderedImage img[src^='data:image/png']").first.wait_for(timeout=120_000)
                view.scroll_into_view_if_needed()
                executed = changed_view(view, goal, timeout=60)
                (ARTIFACTS / "proxy_view_executed.png").write_bytes(executed)
                page.screenshot(path=str(ARTIFACTS / "proxy_page.png"))
                went = changed_fraction(pixels(goal), pixels(executed))
                assert 0.002 < went < 0.5, f"Execute did not move the arm in the view ({went:.3%} of pixels changed)"

                # the viewer's own port was open all along, and the browser never asked it
                page_direct = urllib.request.urlopen(f"http://127.0.0.1:{viewer_port}/static/", timeout=10).read()
                assert b"viewer.connect(" in page_direct
            finally:
                browser.close()
    finally:
        lab.stop()
        tunnel.close()
    assert refused == [], f"the browser asked beyond the tunnel to Jupyter's port: {refused[:5]}"
    assert asked and all(urllib.parse.urlsplit(u).netloc == jupyter for u in asked)
    assert any(u.startswith(f"{BASE_URL}proxy/{viewer_port}/static/", len(f"http://{jupyter}")) for u in asked), asked
    view_sockets = [u for u in sockets if "/proxy/" in u]
    assert view_sockets and set(view_sockets) == {f"ws://{jupyter}{BASE_URL}proxy/{viewer_port}/"}, sockets
    assert all(urllib.parse.urlsplit(u).netloc == jupyter for u in sockets), sockets
    assert not port_open(viewer_port), "the viewer's port is still open after JupyterLab shut down"


# --- the address rules, without a browser -------------------------------------------------------

def server_file(runtime: Path, pid: int, base_url: str) -> Path:
    runtime.mkdir(exist_ok=True)
    path = runtime / f"jpserver-{pid}.json"
    path.write_text(json.dumps({"base_url": base_url, "pid": pid, "port": 8888, "url": f"http://127.0.0.1:8888{base_url}"}))
    return path


def test_a_kernel_of_a_jupyter_server_proxies_under_that_servers_base_url(tmp_path):
    from snakekit.viewer.urls import viewer_root

    server_file(tmp_path, 4242, "/user/ana/")
    env = {"JPY_PARENT_PID": "4242"}
    assert viewer_root(7003, "127.0.0.1", in_kernel=True, environ=env, runtime_dir=tmp_path) == "/user/ana/proxy/7003/"
    server_file(tmp_path, 4242, "/")
    assert viewer_root(7003, "127.0.0.1", in_kernel=True, environ=env, runtime_dir=tmp_path) == "/proxy/7003/"
    # the server's file wins over a hub's prefix (they agree on a hub; the file is the server itself)
    env["JUPYTERHUB_SERVICE_PREFIX"] = "/user/bob/"
    assert viewer_root(7003, "127.0.0.1", in_kernel=True, environ=env, runtime_dir=tmp_path) == "/proxy/7003/"


def test_a_kernel_on_a_hub_without_its_servers_file_proxies_under_the_hub_prefix(tmp_path):
    from snakekit.viewer.urls import viewer_root

    env = {"JPY_PARENT_PID": "4243", "JUPYTERHUB_SERVICE_PREFIX": "/user/ana"}
    assert viewer_root(7000, "0.0.0.0", in_kernel=True, environ=env, runtime_dir=tmp_path) == "/user/ana/proxy/7000/"


def test_scripts_and_kernels_no_server_started_use_the_viewers_own_port(tmp_path):
    from snakekit.viewer.urls import viewer_root

    server_file(tmp_path, 4244, "/user/ana/")
    hub = {"JPY_PARENT_PID": "4244", "JUPYTERHUB_SERVICE_PREFIX": "/user/ana/"}
    assert viewer_root(7000, "127.0.0.1", in_kernel=False, environ=hub, runtime_dir=tmp_path) == "http://127.0.0.1:7000/"
    # a headless notebook run: the kernel's parent is no Jupyter server
    assert viewer_root(7000, "0.0.0.0", in_kernel=True, environ={"JPY_PARENT_PID": "1"},
                       runtime_dir=tmp_path) == "http://localhost:7000/"
    assert viewer_root(7000, "::1", in_kernel=True, environ={}, runtime_dir=tmp_path) == "http://[::1]:7000/"
    # a host name asked for: the viewer's own port, proxy or not
    assert viewer_root(7000, "0.0.0.0", in_kernel=True, url_host="lab.local", environ=hub,
                       runtime_dir=tmp_path) == "http://lab.local:7000/"


def test_snakekit_viewer_url_overrides_the_address_everywhere(tmp_path):
    from snakekit.viewer.urls import viewer_root

    server_file(tmp_path, 4245, "/user/ana/")
    env = {"JPY_PARENT_PID": "4245", "SNAKEKIT_VIEWER_URL": "https://lab.example.org/ana/proxy/{port}"}
    assert viewer_root(7002, "127.0.0.1", in_kernel=True, environ=env,
                       runtime_dir=tmp_path) == "https://lab.example.org/ana/proxy/7002/"
    env["SNAKEKIT_VIEWER_URL"] = "http://localhost:{port}/"
    assert viewer_root(7002, "127.0.0.1", in_kernel=False, environ=env, runtime_dir=tmp_path) == "http://localhost:7002/"


@pytest.mark.parametrize("bad", ["/user/ana/proxy/7000/", "/proxy/{port}/{user}/", "/proxy/{0}/"])
def test_a_snakekit_viewer_url_without_its_port_field_is_refused_with_examples(bad, monkeypatch):
    need("meshcat")
    from snakekit.errors import ConfigurationError
    from snakekit.viewer import Viewer
    from snakekit.viewer.server import LIVE

    monkeypatch.setenv("SNAKEKIT_VIEWER_URL", bad)
    before = set(LIVE)
    with pytest.raises(ConfigurationError, match=r"SNAKEKIT_VIEWER_URL must be the viewer's address with \{port\}.*"
                                                 r"/user/ana/proxy/\{port\}/ or http://localhost:\{port\}/"):
        Viewer(replace=False)
    assert set(LIVE) == before


def test_the_viewer_in_a_kernel_of_jupyter_gives_the_proxied_page(tmp_path, monkeypatch):
    """A Viewer made in a kernel that a Jupyter server (pid in JPY_PARENT_PID) started."""
    need("meshcat")
    import snakekit.viewer.scene as scene
    from snakekit.viewer import Viewer

    server_file(tmp_path, 4246, "/user/ana/")
    monkeypatch.setenv("JUPYTER_RUNTIME_DIR", str(tmp_path))
    monkeypatch.setenv("JPY_PARENT_PID", "4246")
    monkeypatch.delenv("SNAKEKIT_VIEWER_URL", raising=False)
    monkeypatch.setattr(scene, "_in_kernel", lambda: True)
    with Viewer(replace=False) as viewer:
        assert viewer.url == f"/user/ana/proxy/{viewer.port}/static/"
        assert f'src="/user/ana/proxy/{viewer.port}/static/"' in viewer.iframe()
        # the page it names (on the viewer's own port here, as jupyter-server-proxy asks it)
        page = urllib.request.urlopen(f"http://127.0.0.1:{viewer.port}/static/", timeout=10).read().decode()
        assert 'viewer.connect(new URL("..", location.href).href.replace(/^http/, "ws"));' in page
        assert "viewer.connect();" not in page
        assert urllib.request.urlopen(f"http://127.0.0.1:{viewer.port}/static/index.html", timeout=10).read().decode() == page


def test_a_saved_page_draws_the_arm_in_chromium_with_the_network_off(tmp_path):
    """save_html stays self-contained: opened from a file with the network off, it draws the arm."""
    sync_api = need("playwright.sync_api")
    need("meshcat")
    chromium = need_program("chromium")
    from snakekit.viewer import Viewer

    with Viewer(replace=False) as viewer:
        viewer.show([0.6, -0.4, 0.8, -0.5, 0.3])
        viewer.draw_workspace()
        drawn = viewer.save_html(tmp_path / "drawn.html")
        viewer.vis["snake/robot"].set_property("visible", False)
        blank = viewer.save_html(tmp_path / "blank.html")
    asked: list[str] = []
    shots = {}
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_FLAGS + OFFLINE_FLAGS)
        try:
            context = browser.new_context(offline=True, viewport={"width": 900, "height": 700})
            context.on("request", lambda request: asked.append(request.url))
            page = context.new_page()
            for name, path in (("drawn", drawn), ("blank", blank)):
                page.goto(path.as_uri())
                canvas = page.locator("canvas").first
                canvas.wait_for(state="visible", timeout=30_000)
                shots[name] = steady_screenshot(canvas)
                (ARTIFACTS / f"saved_view_{name}.png").write_bytes(shots[name])
        finally:
            browser.close()
    assert {urllib.parse.urlsplit(u).scheme for u in asked} <= {"file", "data", "blob"}, asked
    arm = changed_fraction(pixels(shots["drawn"]), pixels(shots["blank"]))
    assert arm > 0.01, f"the saved page drew no arm offline ({arm:.3%} of its pixels are the arm's)"


def test_a_meshcat_page_that_no_longer_connects_once_is_refused_clearly(tmp_path):
    need("meshcat")
    from types import SimpleNamespace

    from snakekit.errors import ViewerError
    from snakekit.viewer.server import _page

    (tmp_path / "index.html").write_text("<script>var viewer = new MeshCat.Viewer(pane); viewer.connect(url);</script>")
    changed = SimpleNamespace(VIEWER_ROOT=str(tmp_path), VIEWER_HTML="index.html")
    with pytest.raises(ViewerError, match=r"no longer calls viewer.connect\(\) once.*install the meshcat version "
                                          r"of environment.lock"):
        _page(changed)
