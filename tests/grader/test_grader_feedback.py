"""What a student and a TA see after grading: the notebook's deadline, offline pages, nbgrader's own buttons.

One small batch of the test course (a good submission, an edited test cell, an infinite loop,
a widget and a library error) graded in-process; then nbgrader's ``generate_feedback`` on it,
a lesson's page opened in headless Chromium with the network off, and formgrader's Autograde
and Generate Feedback buttons pressed in Chromium on a tampered submission.
"""

from __future__ import annotations

import copy
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

from conftest import need, need_program, without_data
from grader_corpus import _edit
from grader_helpers import ASSIGNMENT, FIXTURE, GOOD, REFERENCES, make_course, submit, use_safe_grading
from tests.system.test_browser import CHROMIUM_FLAGS, JupyterLab

REPO = Path(__file__).resolve().parents[2]
ARTIFACTS = REPO / "artifacts"
TIMEOUT = 20  # each notebook's wall clock [s]: a bound for a hang, 5x what one of these notebooks needs
#: an endless loop that waits for something that never comes (the corpus's busy ``while True: pass``, which burns a
#: core until it is stopped, is tests/grader/test_grader_adversarial.py's; the clock stops both alike)
LOOP = {"ex1_tool_xy": 'print("before the loop")\n' + GOOD["ex1_tool_xy"],
        "ex2_sweep": "import time\nwhile True:\n    time.sleep(0.05)"}
#: what a kernel's shell sets up as it imports a module (matplotlib's inline backend, the widgets' comm target, the
#: kit's note on a missing name), printed where nothing has imported a widget yet and again after one was shown
KERNEL_FACTS = """import json as _json, sys as _sys, matplotlib as _mpl
_ip = get_ipython()
def _facts():
    return {"backend": _mpl.get_backend(), "png_formatter": bool(_ip.display_formatter.formatters["image/png"].type_printers),
            "ipywidgets_loaded": "ipywidgets" in _sys.modules, "name_error_note": NameError in _ip.custom_exceptions,
            "widget_target": "jupyter.widget" in _ip.kernel.comm_manager.targets, "cwd_on_path": "" in _sys.path}
print("facts", _json.dumps(_facts()))
"""
EXTRAS = {"ex1_tool_xy": KERNEL_FACTS + "import ipywidgets\n"
                         "display(ipywidgets.VBox([ipywidgets.IntSlider(description='q1')]))\n"
                         'print("facts", _json.dumps(_facts()))\n' + GOOD["ex1_tool_xy"],
          # an answer that stops with an error, so its check cell meets a NameError
          "ex3_peak_speed": "import numpy\nnumpy.linalg.inv(numpy.zeros((2, 2)))"}


def _page(course: Path, student: str) -> str:
    return (course / "feedback" / student / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()


def _secret_lines() -> set[str]:
    """What no page may show: the instructor's solution lines that no student here wrote (there
    are no hidden tests any more), and the lines of the hidden cases' module."""
    src = nbformat.read(FIXTURE / "source" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)
    written = {line.strip() for v in GOOD.values() for line in v.splitlines()}
    lines = {line.strip() for c in src.cells if c.metadata.get("nbgrader", {}).get("solution")
             for line in c.source.splitlines() if "=" in line and line.strip() not in written}
    lines |= {line.strip() for line in (FIXTURE / "cases" / f"{ASSIGNMENT}.py").read_text().splitlines()
              if line.strip().startswith(("def ", "rate =", "points =", "return"))}
    assert "angle = amplitude * np.sin(2 * np.pi * t / (t[-1] / sweeps))" in lines
    return lines


def _loads_nothing(page: str) -> None:
    assert "http" not in without_data(page)  # no address at all: nothing to load, nothing to follow
    assert not re.search(r"<(script|link|iframe|img)[^>]+(src|href)=[\"'](?!data:)", page)


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    need_program("unshare")
    from grader.batch import INSTRUCTOR, Grader
    from grader.sandbox.runner import Runner

    course = make_course(tmp_path_factory.mktemp("feedback"))
    use_safe_grading(course, TIMEOUT)
    submit(course, "alice")
    submit(course, "edited", edit=_edit)
    submit(course, "loop", LOOP)
    submit(course, "extras", EXTRAS)
    submit(course, "flaky")  # a right submission whose first run the machine stalls (below)
    # one cell may take the notebook's whole time here, so the notebook's own clock is what stops the loop
    grader = Grader(course, ASSIGNMENT, jobs=2, timeout=TIMEOUT, references=REFERENCES, cell_timeout=TIMEOUT)
    stage, first = Runner.stage, set()

    def stalled_once(self, student, src, nbs, tampered):
        """flaky's first run, and the instructor notebook's, stall in their first answer cell as a
        stuck machine would; their second runs go as handed in."""
        work = stage(self, student, src, nbs, tampered)
        if student in ("flaky", INSTRUCTOR) and student not in first:
            first.add(student)
            for name, nb in nbs.items():
                nb = nbformat.from_dict(copy.deepcopy(nb))
                cell = next(c for c in nb.cells if c.metadata.get("nbgrader", {}).get("solution"))
                cell.source = "import time\ntime.sleep(10**6)\n" + cell.source
                nbformat.write(nb, work / "course" / "submitted" / student / ASSIGNMENT / f"{name}.ipynb")
        return work

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(Runner, "stage", stalled_once)
        results = {r.student: r for r in grader.run()}
    assert first == {"flaky", INSTRUCTOR}, first

    return course, results


def test_an_infinite_loop_costs_the_batch_only_twice_the_notebooks_timeout(graded):
    _, results = graded
    loop = results["loop"]
    nb = nbformat.read(graded[0] / "submitted" / "loop" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", 4)
    # named as the student finds it (markdown cells come before it: an index counting them is no cell they can find)
    assert any(c.cell_type == "markdown" for c in nb.cells[:next(i for i, c in enumerate(nb.cells) if "while True" in c.source)])
    assert (loop.status, loop.detail) == ("timeout", f"the notebook ran longer than {TIMEOUT} s and was stopped in the answer "
                                          "cell ex2_sweep (run twice, so that a busy grading machine is not the cause, and "
                                          "stopped both times)")
    # each of its two sandboxes was stopped by the notebook's clock (the detail above says so; the
    # backstop, TIMEOUT + 30 s, or one limit per cell would say otherwise): at least TIMEOUT s each
    assert loop.wall >= 2 * TIMEOUT, loop.wall
    assert [(e.grade_id, e.score) for e in loop.exercises] == [
        ("ex1_tool_xy_test", 2.0), ("ex2_sweep_test", 0.0), ("ex3_peak_speed_test", 0.0)]


def test_a_notebook_the_machine_stalled_once_is_graded_on_its_second_run(graded):
    """(The instructor notebook's first run, which gives the batch its expected results, stalled too.)"""
    course, results = graded
    flaky, alice = results["flaky"], results["alice"]
    assert (flaky.status, flaky.score) == ("graded", alice.score) and alice.score == alice.max_score
    assert flaky.detail == "graded on its second run: the first was stopped by the clock, so it ran once more from the start"
    assert flaky.wall >= TIMEOUT, flaky.wall   # the stalled run, then the right one
    page = re.sub(r"<[^>]+>", "", _page(course, "flaky"))
    assert "graded on its second run" in page and "stopped here" not in page and "time.sleep" not in page


def test_a_stopped_notebooks_page_keeps_its_outputs_up_to_the_stopped_cell(graded):
    course, _ = graded
    page = _page(course, "loop")
    text = re.sub(r"<[^>]+>", "", page)  # as read (the code is highlighted span by span)
    before = text.index("before the loop")  # printed by the cell before the loop
    note = text.index(f"stopped here: the notebook ran longer than {TIMEOUT} s")
    loop_cell = text.index("while True")
    assert before < loop_cell < note  # the note follows the cell that was stopped
    assert page.count("stopped here") == 1
    assert "Grader: 1 tool_xy: 2 / 2 points" in page
    # the test cell after it never ran: the student is told why
    assert "Grader: 2 my_sweep: 0 / 4 points" in page and "nothing was handed in" in page
    ran = nbformat.read(course / "autograded" / "loop" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)
    stopped = [i for i, c in enumerate(ran.cells) if c.cell_type == "code" and "while True" in c.source][0]
    after = [c for c in ran.cells[stopped + 1:] if c.cell_type == "code"]
    assert after and all(c.get("execution_count") is None for c in after)
    # nothing of the kernel's after the stop: only the grader's verdicts, which the TA's copy shows at each test cell
    assert all("snakekit_grader" in o.get("metadata", {}) for c in after for o in c.get("outputs", []))


def test_no_feedback_page_loads_anything_from_the_network(graded):
    course, _ = graded
    pages = sorted((course / "feedback").glob(f"*/{ASSIGNMENT}/*.html"))
    assert len(pages) == 5
    for page in pages:
        _loads_nothing(page.read_text())


def test_a_widget_is_one_line_and_no_machine_path_is_shown(graded):
    course, _ = graded
    page = _page(course, "extras")
    assert "[an interactive widget (VBox): it works in the running notebook, not in this page]" in page
    assert "VBox(children" not in page and "IntSlider(" not in page
    assert "LinAlgError" in page and "&lt;site-packages&gt;/numpy/linalg/" in page  # the traceback, neutral paths
    for path in (sys.prefix, str(REPO), "/tmp/snakekit-grade-", str(course), os.path.expanduser("~") + "/"):
        assert path not in page, path


def test_a_graded_kernel_sets_up_its_shell_as_a_students_kernel_does(graded, tmp_path):
    """The grader forks its kernels from a process that imported the libraries already. A module that sets up the
    shell that imports it (matplotlib's inline backend, the widgets' comm target, the kit's note on a missing name)
    must still do so in a graded kernel, as in the student's own: the same facts in both, and the note on the page."""
    from jupyter_client.manager import AsyncKernelManager

    from tests.conftest import notebook_client

    course, _ = graded
    graded_nb = nbformat.read(course / "autograded" / "extras" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", 4)
    cell = next(c for c in graded_nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") == "ex1_tool_xy")
    printed = "".join(o.get("text", "") for o in cell.outputs if o["output_type"] == "stream")
    in_grader = [json.loads(line[6:]) for line in printed.splitlines() if line.startswith("facts ")]

    # the same cells in a student's kernel (a fresh one, as JupyterLab starts it)
    setup = next(c.source for c in graded_nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") == "setup")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(setup), nbformat.v4.new_code_cell(cell.source)])
    notebook_client(nb, timeout=120, kernel_name="python3", kernel_manager_class=AsyncKernelManager,
                    resources={"metadata": {"path": str(tmp_path)}}).execute()
    printed = "".join(o.get("text", "") for o in nb.cells[1].outputs if o["output_type"] == "stream")
    in_lab = [json.loads(line[6:]) for line in printed.splitlines() if line.startswith("facts ")]

    assert len(in_lab) == 2 and in_lab[0]["ipywidgets_loaded"] is False and in_lab[1]["widget_target"] is True
    assert in_lab[0]["backend"].endswith("backend_inline") and in_lab[0]["name_error_note"] is True
    assert in_grader == in_lab
    page = _page(course, "extras")
    assert "is not defined: the cell that defines `peak_speed` has not run yet" in page, re.findall(r"NameError.{300}", page)


def test_the_live_3d_view_is_one_line_on_the_page():
    """A lesson's cell that shows the 3D view outputs an iframe to the kernel's own viewer server,
    which is gone when the page is read: one line says what it was, and the picture beside it stays."""
    from types import SimpleNamespace

    from grader.feedback.scrub import scrub_cell
    from snakekit.viewer import Viewer

    view = Viewer.iframe(SimpleNamespace(url="http://127.0.0.1:43881/static/", height=420))
    cell = nbformat.v4.new_code_cell("viewer")
    cell.outputs = [nbformat.v4.new_output("execute_result", execution_count=3,
                                           data={"text/html": view, "text/plain": "<snakekit Viewer>"}),
                    nbformat.v4.new_output("display_data", data={"image/png": "iVBORw0KGgo="})]
    scrub_cell(cell, set())
    assert cell.outputs[0] == nbformat.v4.new_output(
        "stream", name="stdout", text="[the 3D view: it works in the running notebook, not in this page]\n")
    assert cell.outputs[1]["data"] == {"image/png": "iVBORw0KGgo="}


def test_nbgrader_generate_feedback_writes_the_graders_pages_with_the_tas_scores(graded):
    course, _ = graded
    from nbgrader.api import Gradebook

    written = {s: _page(course, s) for s in ("alice", "edited", "loop", "extras")}
    r = subprocess.run([sys.executable, "-m", "nbgrader", "generate_feedback", ASSIGNMENT, "--force"], cwd=course,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    assert {s: _page(course, s) for s in written} == written  # nbgrader's command writes the same safe pages

    # a TA corrects a score and comments in the gradebook (as formgrader does), then regenerates
    with Gradebook(f"sqlite:///{course / 'gradebook.db'}", "snakekit-test-course") as gb:
        gb.find_grade("ex2_sweep_test", ASSIGNMENT, ASSIGNMENT, "edited").manual_score = 1.5
        gb.find_comment("ex2_sweep", ASSIGNMENT, ASSIGNMENT, "edited").manual_comment = "Put the check back."
        gb.db.commit()
    r = subprocess.run([sys.executable, "-m", "nbgrader", "generate_feedback", ASSIGNMENT, "--student", "edited",
                        "--force"], cwd=course, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    page = _page(course, "edited")
    assert "Score: <strong>4.5 / 7</strong> (tests restored)" in page  # 3 from the grader + 1.5 by hand
    assert "Grader: 2 my_sweep: 1.5 / 4 points" in page
    assert "Your teacher set the points to 1.5 (the grader gave 4)" in page
    assert "Comment from your teacher:</strong> Put the check back." in page
    assert "BEGIN HIDDEN TESTS" not in page and not [line for line in _secret_lines() if line in page]
    _loads_nothing(page)


def test_a_page_opened_offline_in_chromium_shows_typeset_math():
    sync_api = need("playwright.sync_api")
    chromium = need_program("chromium")
    from grader.feedback.exporter import write_html
    from grader.feedback.notebook import build
    from grader.scoring.verdict import SubmissionResult

    ARTIFACTS.mkdir(exist_ok=True)
    lesson = "01_forward_kinematics"
    nb = nbformat.read(REPO / "course" / "source" / lesson / f"{lesson}.ipynb", as_version=4)
    tex = [m for c in nb.cells if c.cell_type == "markdown" for m in re.findall(r"\$\$.+?\$\$|\$[^$\n]+\$", c.source)]
    assert len(tex) > 20
    result = SubmissionResult("ann", lesson, 8.0, 8.0, "graded")
    path = write_html(build(nb, student="ann", assignment=lesson, result=result, test_sources={}),
                      ARTIFACTS / "feedback_offline_math.html")
    _loads_nothing(path.read_text())
    requested = []
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_FLAGS)
        try:
            context = browser.new_context(offline=True, viewport={"width": 1200, "height": 900})
            context.route("**/*", lambda route: (requested.append(route.request.url),
                                                 route.continue_() if route.request.url.startswith(("file:", "data:"))
                                                 else route.abort()))
            page = context.new_page()
            page.goto(path.as_uri(), wait_until="load")
            sizes = page.evaluate("() => [...document.querySelectorAll('.jp-MarkdownCell math')].map(m => {"
                                  " const r = m.getBoundingClientRect(); return [r.width, r.height]; })")
            text = page.evaluate("() => document.body.innerText")
            page.locator("math[display='block']").first.scroll_into_view_if_needed()
            page.screenshot(path=str(ARTIFACTS / "feedback_offline_math.png"))
        finally:
            browser.close()
    assert [u for u in requested if not u.startswith(("file:", "data:"))] == []
    assert len(sizes) == len(tex), (len(sizes), len(tex))
    assert all(w > 0 and h > 0 for w, h in sizes)  # laid out as math by the browser
    assert "$" not in text and "\\frac" not in text and "\\sum" not in text  # no raw TeX left


# --- formgrader's buttons, pressed in Chromium ------------------------------------------------


def _press(page, student: str, button: str, done: str):
    row = page.locator("table tbody tr", has=page.locator("td.student-id", has_text=student))
    row.locator(f"td.{button} a").click()
    modal = page.locator("#success-modal, #error-modal").first
    modal.wait_for(state="visible", timeout=300_000)
    text = modal.text_content()  # the log too, folded away in the dialog
    assert modal.get_attribute("id") == "success-modal", text
    assert done in text, text
    modal.locator(".modal-footer button").first.click()
    modal.wait_for(state="detached", timeout=10_000)
    return text


def test_formgraders_autograde_and_feedback_buttons_give_the_graders_results(tmp_path):
    need_program("unshare")
    sync_api = need("playwright.sync_api")
    chromium = need_program("chromium")
    from nbgrader.api import Gradebook

    course = make_course(tmp_path)
    use_safe_grading(course, TIMEOUT)
    submit(course, "edited", edit=_edit)  # ex2's test cell replaced: it runs as released, and the TA is told
    home = tmp_path / "home"
    home.mkdir()
    server = JupyterLab(course, home)  # in the course folder, as a TA starts it: formgrader reads its config
    blocked = []
    try:
        with sync_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_FLAGS)
            try:
                page = server.browser_context(browser, blocked).new_page()
                page.goto(f"{server.url}/formgrader/manage_submissions/{ASSIGNMENT}")
                page.locator("td.student-id", has_text="edited").wait_for(timeout=60_000)
                log = _press(page, "edited", "autograde", f"Successfully autograded '{ASSIGNMENT}' for student 'edited'")
                assert "tests restored" in log
                score = page.locator("table tbody tr", has=page.locator("td.student-id", has_text="edited"))
                page.wait_for_function("() => [...document.querySelectorAll('td.score')].some(td => "
                                       "td.textContent.trim() === '7 / 7')", timeout=30_000)
                assert score.locator("td.score").inner_text().strip() == "7 / 7"
                page.screenshot(path=str(tmp_path / "formgrader_autograded.png"))

                # the TA sets a score by hand in formgrader (its grade API, as its score box does)
                page.evaluate("""async ([assignment]) => {
                    const headers = {'Content-Type': 'application/json'};  // the token header authenticates
                    const nbs = await (await fetch(base_url + '/formgrader/api/submitted_notebooks/' + assignment + '/'
                                                   + assignment, {headers})).json();
                    const nb = nbs.find(n => n.student === 'edited');
                    const grades = await (await fetch(base_url + '/formgrader/api/grades?submission_id=' + nb.id,
                                                      {headers})).json();
                    const g = grades.find(g => g.name === 'ex2_sweep_test');
                    await fetch(base_url + '/formgrader/api/grade/' + g.id,
                                {method: 'PUT', headers, body: JSON.stringify({manual_score: 2})});
                }""", [ASSIGNMENT])
                _press(page, "edited", "generate-feedback",
                       f"Successfully generated feedback for '{ASSIGNMENT}' for student 'edited'")
            finally:
                browser.close()
    finally:
        server.stop()
    assert blocked == []
    with Gradebook(f"sqlite:///{course / 'gradebook.db'}", "snakekit-test-course") as gb:
        sub = gb.find_submission(ASSIGNMENT, "edited")
        assert sub.score == 5.0  # the grader's 3 for ex1 and ex3 + the TA's 2 for ex2 (the grader gave 4)
        assert gb.find_grade("ex2_sweep_test", ASSIGNMENT, ASSIGNMENT, "edited").auto_score == 4.0
        assert sub.notebooks[0].flagged  # formgrader shows the flag: this one is not plainly "graded"
    ran = nbformat.read(course / "autograded" / "edited" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)
    test = next(c for c in ran.cells if c.metadata.get("nbgrader", {}).get("grade_id") == "ex2_sweep_test")
    shown = [o["data"]["text/html"] for o in test.outputs if "snakekit_grader" in o.get("metadata", {})]
    assert len(shown) == 1 and "tests restored" in shown[0] and "edited: run as released" in shown[0]  # at the cell
    assert "the check is gone" not in test.source   # the TA sees the released test, which ran
    page = _page(course, "edited")
    assert "Score: <strong>5 / 7</strong> (tests restored)" in page
    assert "Grader: 2 my_sweep: 2 / 4 points" in page and "Your teacher set the points to 2" in page
    assert "BEGIN HIDDEN TESTS" not in page and not [line for line in _secret_lines() if line in page]
    _loads_nothing(page)
