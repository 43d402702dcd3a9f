"""formgrader with no network beyond its server, as a TA on a hub meets it: names from the roster, math typeset.

Two students of the test course collected with a roster (names and e-mails), alice's notebook
graded; it holds math in a markdown cell she wrote and in her answer's output. JupyterLab runs in the
course folder under a hub's base URL (``/user/ta/``), and headless Chromium (Debian's, driven by
Playwright) opens each of formgrader's pages with every request outside that server refused and
recorded. No request may leave the server, none may fail, no script may fail, the students' page
lists the roster's names and e-mails, and the grading page lays each formula out as MathJax's
output. A screenshot of the grading page is kept in ``artifacts/``.
"""

from __future__ import annotations

import re

import nbformat
import pytest

from tests.conftest import need, need_program
from tests.grader.grader_helpers import ASSIGNMENT, REFERENCES, good_notebook, make_course, use_safe_grading
from tests.system.test_browser import ARTIFACTS, CHROMIUM_FLAGS, JupyterLab

pytestmark = pytest.mark.system  # JupyterLab in headless Chromium: not in `make test-quick`
TIMEOUT = 60  # each notebook's wall clock [s]: a bound for a hang, over 5x what one of these notebooks needs
ROSTER = "student,name,email\nalice,Alice Smith,alice@uni.test\nbob,Bob Jones,bob@uni.test\n"
#: what alice writes beside her answers: a markdown cell, and her answer to exercise 3 shown as math
NOTE = r"My sweep's peak speed $\omega = \max_i |\dot q_i|$, from $$\dot q_i \approx \frac{q_{i+1} - q_i}{\Delta t}$$"
SHOWN = "from IPython.display import Math\ndisplay(Math(rf'\\omega = {peak_speed:.3f}\\ \\mathrm{{rad/s}}'))"


def _alices_notebook(course) -> bytes:
    nb = nbformat.reads(good_notebook(course, "alice").decode(), as_version=4)
    answer = next(i for i, c in enumerate(nb.cells) if c.metadata.get("nbgrader", {}).get("grade_id") == "ex3_peak_speed")
    nb.cells[answer].source += "\n" + SHOWN
    nb.cells.insert(answer + 1, nbformat.v4.new_markdown_cell(NOTE))
    return nbformat.writes(nb).encode()


def test_formgraders_pages_load_nothing_from_the_network_and_show_names_and_math(tmp_path):
    need_program("unshare")
    sync_api = need("playwright.sync_api")
    chromium = need_program("chromium")
    from grader.batch import Grader
    from grader.lms import collect

    ARTIFACTS.mkdir(exist_ok=True)
    course = make_course(tmp_path)
    use_safe_grading(course, TIMEOUT)
    download = tmp_path / "download"
    download.mkdir()
    (download / "alice.ipynb").write_bytes(_alices_notebook(course))
    (download / "bob.ipynb").write_bytes(good_notebook(course, "bob"))
    (course / "roster.csv").write_text(ROSTER)
    assert collect.main([ASSIGNMENT, "--from", str(download), "--course", str(course),
                         "--roster", str(course / "roster.csv")]) == 0
    # alice graded; bob collected only (formgrader lists him by name all the same)
    (alice,) = Grader(course, ASSIGNMENT, jobs=2, timeout=TIMEOUT, references=REFERENCES).run(["alice"])
    assert (alice.status, alice.score) == ("graded", alice.max_score), f"{alice.status}: {alice.detail}"   # whole

    home = tmp_path / "home"
    home.mkdir()
    server = JupyterLab(course, home, base_url="/user/ta/")  # in the course folder, as a TA starts it, under a hub's URL
    left, failed, errors = [], [], []
    try:
        with sync_api.sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium, headless=True, args=CHROMIUM_FLAGS)
            try:
                page = server.browser_context(browser, left).new_page()
                page.on("response", lambda r: failed.append(f"{r.status} {r.url}") if r.status >= 400 else None)
                page.on("pageerror", lambda e: errors.append(f"{page.url}: {e}"))
                fg = f"{server.url}/formgrader"

                def visit(path: str, *shown: str) -> str:
                    """The page at ``path``, once its scripts filled it with every text of ``shown``."""
                    page.goto(f"{fg}/{path}")
                    page.wait_for_function("texts => texts.every(t => document.body.innerText.includes(t))",
                                           arg=list(shown), timeout=30_000)
                    return page.evaluate("() => document.body.innerText")

                visit("manage_assignments", ASSIGNMENT)
                visit("gradebook", ASSIGNMENT)
                visit(f"gradebook/{ASSIGNMENT}", ASSIGNMENT)  # the assignment's notebooks
                visit(f"gradebook/{ASSIGNMENT}/{ASSIGNMENT}", "Submission #1")
                visit(f"manage_submissions/{ASSIGNMENT}", "Smith, Alice")
                students = visit("manage_students", "Smith, Alice", "Jones, Bob")
                assert "alice@uni.test" in students and "bob@uni.test" in students, students
                visit("manage_students/alice", ASSIGNMENT)
                visit(f"manage_students/alice/{ASSIGNMENT}", ASSIGNMENT)
                subs = page.evaluate("async a => (await (await fetch(`${base_url}/formgrader/api/submitted_notebooks/"
                                     "${a}/${a}`)).json()).map(s => [s.student, s.id])", ASSIGNMENT)
                visit(f"submissions/{dict(subs)['alice']}/", "Student's answer")  # the names hidden, as formgrader starts
                try:  # formgrader's own script marks the end of MathJax's typesetting
                    page.wait_for_function("() => window.MathJax && MathJax.loaded === true", timeout=60_000)
                except sync_api.TimeoutError:
                    pass  # no MathJax: what was asked of other hosts, and what was typeset, say why (below)
                shown = page.evaluate("""() => [...document.querySelectorAll('#notebook-container span.MathJax')]
                    .map(m => { const r = m.getBoundingClientRect(); return [r.width, r.height]; })""")
                text = page.evaluate("() => [...document.querySelectorAll('#notebook-container .text_cell_render, "
                                     "#notebook-container .output_subarea')].map(e => e.innerText).join('\\n')")
                if shown:
                    page.locator("#notebook-container span.MathJax").first.scroll_into_view_if_needed()
                page.screenshot(path=str(ARTIFACTS / "formgrader_offline_math.png"))
            finally:
                browser.close()
    finally:
        server.stop()
    assert left == [], left     # nothing asked of any other host (a CDN's MathJax would be here)
    assert failed == [], failed  # and nothing missing on the server (MathJax's own files, its fonts)
    assert errors == [], errors
    formulas = len(re.findall(r"\$\$.+?\$\$|\$[^$]+\$", NOTE)) + 1  # the two in her note, the one her answer shows
    assert len(shown) == formulas == 3 and all(w > 0 and h > 0 for w, h in shown), shown  # each laid out as math
    assert "$" not in text and "\\frac" not in text and "\\omega" not in text  # no TeX left as text
