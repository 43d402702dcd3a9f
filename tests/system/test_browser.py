"""Lesson 0 in a real browser, as a student meets it: JupyterLab + headless Chromium.

Starts JupyterLab on a free loopback port over a temporary copy of ``notebooks/``, opens
lesson 0 (the student version, as handed out) in Chromium (Debian's, driven by Playwright)
and runs every cell: the run stops at exercise 0.1's check, which says the exercise is not
written yet. The student fills the exercise, runs its check and sees it pass, runs the rest;
then drags the joint 1 slider (the picture must change: screenshot pixels are compared) and
presses nbgrader's Validate button, which must report success. Screenshots are kept in
``artifacts/`` at the repository root.
Afterwards JupyterLab, its kernels (which serve the 3D view themselves) and Chromium must all be gone,
and the view's ports closed.
"""

import io
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import free_port, need, need_program

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.system  # JupyterLab in headless Chromium: not in `make test-quick`
ARTIFACTS = ROOT / "artifacts"
LESSON = "00_meet_the_arm.ipynb"
# What a student writes for exercise 0.1 (its answer cell, as handed out, raises NotImplementedError).
STUDENT_ANSWER = """def distance_mm(q, target):
    x, y, heading = snakekit.tool_pose_2d(q)
    return 1000 * np.hypot(x - target[0], y - target[1])"""
CHROMIUM_FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run"]


def port_open(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


class JupyterLab:
    """A JupyterLab server in its own session, with everything it starts tracked for cleanup."""

    def __init__(self, root: Path, home: Path, base_url: str = "/"):
        self.psutil = need("psutil")
        self.port = free_port()
        self.token = secrets.token_hex(16)
        env = dict(os.environ,
                   JUPYTER_CONFIG_DIR=str(home / "config"), JUPYTER_RUNTIME_DIR=str(home / "runtime"),
                   IPYTHONDIR=str(home / "ipython"), MPLBACKEND="module://matplotlib_inline.backend_inline",
                   JUPYTER_CONFIG_PATH=str(ROOT / "tools" / "student-lab"),   # the student's lab, as `make lab`
                   PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
        self.log = open(home / "jupyterlab.log", "wb")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "jupyter", "lab", "--no-browser", "--allow-root", "--ip=127.0.0.1",
             f"--port={self.port}", "--ServerApp.port_retries=0", f"--IdentityProvider.token={self.token}",
             f"--ServerApp.base_url={base_url}",
             f"--ServerApp.root_dir={root}", "--LabApp.expose_app_in_browser=True",
             f"--LabApp.workspaces_dir={home / 'workspaces'}", f"--LabApp.user_settings_dir={home / 'settings'}",
             "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate", "--LabApp.news_url=None"],
            cwd=root, env=env, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)
        self.seen: dict[int, str] = {}
        self.url = f"http://127.0.0.1:{self.port}{base_url.rstrip('/')}"
        deadline = time.monotonic() + 60
        while True:
            try:
                urllib.request.urlopen(f"{self.url}/api/status?token={self.token}", timeout=2)
                break
            except OSError:
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    self.stop()
                    raise RuntimeError(f"JupyterLab did not start; see {home / 'jupyterlab.log'}")
                time.sleep(0.3)

    def browser_context(self, browser, refused: list[str]):
        """A Chromium context logged in to this server (its token) with the network beyond the server off:
        a request to any other address is refused, and its URL added to ``refused``."""
        context = browser.new_context(viewport={"width": 1400, "height": 900},
                                      extra_http_headers={"Authorization": f"token {self.token}"})
        context.route("**/*", lambda route: route.continue_() if route.request.url.startswith(self.url + "/")
                      else (refused.append(route.request.url), route.abort()))
        return context

    def track(self) -> dict[int, str]:
        """Remember every process JupyterLab has started so far (kernels and what they started)."""
        try:
            for p in self.psutil.Process(self.proc.pid).children(recursive=True):
                try:
                    self.seen[p.pid] = " ".join(p.cmdline())
                except self.psutil.Error:
                    pass
        except self.psutil.Error:
            pass
        return self.seen

    def stop(self) -> None:
        """Shut down as a user would (kernels first), then make sure of it."""
        self.track()
        if self.proc.poll() is None:
            try:
                req = urllib.request.Request(f"{self.url}/api/shutdown", method="POST",
                                             headers={"Authorization": f"token {self.token}"})
                urllib.request.urlopen(req, timeout=10)
            except OSError:
                pass
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(timeout=10)
        self.log.close()

    def leftovers(self, timeout: float = 5.0) -> list[str]:
        """Tracked processes still alive after ``timeout`` seconds (zombies count as ended)."""
        deadline = time.monotonic() + timeout
        while True:
            alive = []
            for pid, cmd in self.seen.items():
                try:
                    if self.psutil.Process(pid).status() != self.psutil.STATUS_ZOMBIE:
                        alive.append(f"{pid}: {cmd[:200]}")
                except self.psutil.Error:
                    pass
            if not alive or time.monotonic() > deadline:
                return alive
            time.sleep(0.1)


def pixels(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)


def changed_fraction(a: np.ndarray, b: np.ndarray, threshold: int = 24) -> float:
    """Share of pixels whose colour moved by more than ``threshold`` (0..255) in any channel."""
    assert a.shape == b.shape
    return float((np.abs(a - b).max(axis=-1) > threshold).mean())


def steady_screenshot(element, *, timeout: float = 20.0) -> bytes:
    """A screenshot of ``element`` once two in a row, 0.5 s apart, are identical."""
    last = element.screenshot()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        time.sleep(0.5)
        shot = element.screenshot()
        if changed_fraction(pixels(shot), pixels(last), 0) == 0:
            return shot
        last = shot
    raise AssertionError(f"the 3D view kept changing for {timeout} s with nothing moving it")


#: true once the notebook in front has a kernel that is idle (JupyterLab exposed as window.jupyterapp)
KERNEL_IDLE = ("() => window.jupyterapp && window.jupyterapp.shell.currentWidget"
               " && window.jupyterapp.shell.currentWidget.sessionContext"
               " && window.jupyterapp.shell.currentWidget.sessionContext.session"
               " && window.jupyterapp.shell.currentWidget.sessionContext.session.kernel"
               " && window.jupyterapp.shell.currentWidget.sessionContext.session.kernel.status === 'idle'")


def drag_slider(page, label: str) -> tuple[float, float]:
    """Drag the slider labelled ``label`` 120 px left, 12 px at a time, as a hand does, and wait
    until its readout moved by more than 0.2; returns the readout before and after."""
    slider = page.locator(".widget-slider", has_text=label).first
    readout = slider.locator(".widget-readout")
    before = float(readout.inner_text().replace("\u2212", "-"))  # a real minus sign
    handle = slider.locator(".noUi-handle")
    handle.scroll_into_view_if_needed()
    box = handle.bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    for step in range(1, 11):
        page.mouse.move(x - 12 * step, y)
        time.sleep(0.03)
    page.mouse.up()
    page.wait_for_function(
        "([el, v]) => Math.abs(parseFloat(el.textContent.replace('\u2212', '-')) - v) > 0.2",
        arg=[readout.element_handle(), before], timeout=10_000)
    return before, float(readout.inner_text().replace("\u2212", "-"))


def test_lesson0_student_fills_exercise_moves_view_and_validates(tmp_path):
    sync_api = need("playwright.sync_api")
    need("jupyterlab")
    need("meshcat")
    chromium = need_program("chromium")
    ARTIFACTS.mkdir(exist_ok=True)
    root = tmp_path / "notebooks"
    shutil.copytree(ROOT / "notebooks", root, ignore=shutil.ignore_patterns(".ipynb_checkpoints", "*.html"))
    home = tmp_path / "home"
    home.mkdir()

    lab = JupyterLab(root, home)
    browser_pids: list[int] = []
    meshcat_ports: list[int] = []
    try:
        with sync_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_FLAGS)
            try:
                page = browser.new_page(viewport={"width": 1400, "height": 1000})
                page.goto(f"{lab.url}/lab/tree/{LESSON}?token={lab.token}")
                page.wait_for_function(KERNEL_IDLE, timeout=90_000)
                cells = page.locator(".jp-Notebook .jp-Cell")
                # as handed out: running everything stops at the exercise's check, which says why
                page.evaluate("() => window.jupyterapp.commands.execute('notebook:run-all-cells')")
                check = page.locator(".jp-OutputArea-output", has_text="Check failed: exercise 0.1").first
                check.wait_for(timeout=120_000)
                shown = check.inner_text()
                assert "distance_mm` is not written yet" in shown, shown
                assert "Traceback" not in shown and "checks.py" not in shown, shown   # the message, not the stack
                assert page.locator("text=saved meet_the_arm.html").count() == 0   # run-all stopped there

                # the student fills exercise 0.1 in its answer cell (pasted, as from an editor) ...
                answer = cells.filter(has_text='NotImplementedError("exercise 0.1').first
                answer.locator(".cm-content").click()
                page.keyboard.press("Control+a")
                page.keyboard.insert_text(STUDENT_ANSWER)
                page.keyboard.press("Shift+Enter")          # runs the answer cell, moves to its check
                test_cell = cells.filter(has_text='checks.Exercise("0.1"').first
                test_cell.locator(".cm-content").click()
                page.keyboard.press("Shift+Enter")          # ... runs the check and sees it pass
                passed = test_cell.locator(".jp-OutputArea-output", has_text="exercise 0.1 distance_mm: 2 check(s) passed")
                passed.wait_for(timeout=60_000)
                assert test_cell.locator(".jp-OutputArea-output[data-mime-type='application/vnd.jupyter.stderr']").count() == 0
                test_cell.scroll_into_view_if_needed()
                page.screenshot(path=str(ARTIFACTS / "browser_lesson0_exercise_passed.png"))

                # ... and runs the rest of the lesson
                page.evaluate("() => window.jupyterapp.commands.execute('notebook:run-all-below')")
                page.wait_for_selector("text=saved meet_the_arm.html", timeout=120_000)
                lab.track()
                errors = page.locator(".jp-OutputArea-output[data-mime-type='application/vnd.jupyter.stderr']")
                tracebacks = [t for t in errors.all_text_contents() if "Traceback" in t or "Error" in t]
                assert tracebacks == []
                moves = page.locator(".jp-OutputArea-output", has_text="mm from its target").first.inner_text()
                assert moves.count("mm from its target") == 3, moves   # the demonstration after the exercise ran
                # the panel's plot after Execute arrives as a picture, not as "<Figure size ...>"
                assert page.locator(".jp-RenderedImage img[src^='data:image/png']").count() >= 1
                assert page.locator("text=<Figure size").count() == 0

                view = page.locator("iframe[title='snakekit 3D view']").first
                view.scroll_into_view_if_needed()
                src = view.get_attribute("src")
                assert src.startswith("/proxy/") and src.endswith("/static/"), src   # through Jupyter's own port
                meshcat_ports.append(int(src.split("/")[2]))
                view.content_frame.locator("canvas").first.wait_for(state="visible", timeout=30_000)

                before = steady_screenshot(view)  # the last move's playback has ended
                (ARTIFACTS / "browser_lesson0_before.png").write_bytes(before)
                page.screenshot(path=str(ARTIFACTS / "browser_lesson0_page.png"))

                value_before, value_after = drag_slider(page, "joint 1 [rad]")

                view.scroll_into_view_if_needed()
                after = steady_screenshot(view)
                (ARTIFACTS / "browser_lesson0_after.png").write_bytes(after)
                diff = np.abs(pixels(after) - pixels(before)).max(axis=-1) > 24
                from PIL import Image

                Image.fromarray((diff * 255).astype(np.uint8)).save(ARTIFACTS / "browser_lesson0_diff.png")
                frac = changed_fraction(pixels(before), pixels(after))
                assert value_after < value_before - 0.2
                assert frac > 0.002, f"the view did not change after the slider moved ({frac:.4%} of pixels)"
                assert frac < 0.5, f"the whole view changed ({frac:.1%}): not just the arm moving"

                # nbgrader's Validate button (its JupyterLab extension) runs the saved notebook in a
                # fresh kernel and reports the checks: the filled exercise passes
                button = page.locator(".jp-NotebookPanel-toolbar .validate-button").first
                button.wait_for(timeout=10_000)
                button.click()
                dialog = page.locator(".jp-Dialog")
                dialog.wait_for(timeout=240_000)   # after the saved notebook ran in a fresh kernel
                result = dialog.locator(".validation-success, .validation-failed, .validation-error, "
                                        ".validation-unchanged, .validation-changed")
                result.first.wait_for(timeout=240_000)
                lab.track()   # the validation kernel
                page.screenshot(path=str(ARTIFACTS / "browser_lesson0_validate.png"))
                report = dialog.inner_text()
                assert "Success! Your notebook passes all the tests." in report, report
                dialog.locator("button", has_text="OK").first.click()
            finally:
                browser_pids += [p.pid for p in lab.psutil.Process().children(recursive=True)
                                 if "chrom" in p.name().lower()]
                browser.close()
    finally:
        lab.stop()
    assert browser_pids, "no Chromium process was seen"
    for pid in browser_pids:
        lab.seen[pid] = "chromium"
    left = lab.leftovers()
    assert left == [], f"processes left after JupyterLab shut down: {left}"
    kinds = [c[:80] for c in lab.seen.values()]
    assert any("ipykernel" in c for c in lab.seen.values()), kinds
    assert not any("meshcat" in c for c in lab.seen.values()), kinds  # the kernel serves the view: no server process
    assert not port_open(lab.port)
    for port in meshcat_ports:
        assert not port_open(port), f"meshcat port {port} still open"
