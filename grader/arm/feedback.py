"""The lab's result in the student's feedback page.

``snakekit return`` hands back the page ``snakekit grade`` wrote
(``<course>/feedback/<student>/<a>/<notebook>.html``), and nothing else: nbgrader's exchange
carries one page per notebook. So the lab writes its result into that page, right after the
page's heading: the points and the message of a graded run with its plot (an inline PNG), a
refused job's reason, or a fault of the lab ("the lab's fault, not yours", no points). Each
time a job of the student is graded, refused or faults, the lab's part of the page is written
again in place (:func:`update_pages`); the rest of the page stays as it was. A page written
again later (``snakekit grade --student``, ``nbgrader generate_feedback``) gets the lab's part
back (:func:`with_lab`). A second ``snakekit return`` delivers the page with it.
"""

from __future__ import annotations

import base64
import html
import json
import re
from pathlib import Path

from grader.arm.jobs import Queue, lab_dir, settings, write_atomic
from grader.errors import LabError

#: The states a student hears of on the page (a queued or running job has nothing to tell yet).
SHOWN = ("graded", "refused", "lab fault")
_BEGIN, _END = "<!-- snakekit-lab:begin -->", "<!-- snakekit-lab:end -->"
_PART = re.compile(re.escape(_BEGIN) + ".*?" + re.escape(_END) + "\n?", re.S)
_SECOND_CELL = re.compile(r'<div[^>]*\bid="cell-id=cell-1"')


def section(course: Path, assignment: str, student: str) -> str:
    """The lab's part of the student's page (HTML), or ``""`` when the lab has nothing to tell them."""
    try:
        job = Queue.load(course, assignment).job(student)
    except LabError:
        return ""
    if job is None or job["state"] not in SHOWN:
        return ""
    title = f"Lab run of {html.escape(assignment)} on the arm"
    img = ""
    if job["state"] == "graded":
        d = lab_dir(course, assignment) / "results" / student
        try:
            report = json.loads((d / "report.json").read_text())
            png = (d / "plot.png").read_bytes()
        except (OSError, ValueError):
            return ""
        ok = report["points"] >= report["max_points"]
        head = (f"{title}: {report['points']:g} / {report['max_points']:g} points "
                f"<span style='font-weight:normal'>(a grade of its own, {html.escape(assignment)}-lab)</span>")
        words = html.escape(report["message"])
        colour = "#2a2" if ok else "#c33"
        img = ("<img alt='your sweep on the arm against the reference run and your simulated run, joint by joint' "
               f"style='max-width:100%' src='data:image/png;base64,{base64.b64encode(png).decode()}'>"
               "<div style='font-size:85%'>The reference run is the mean of the runs of the task's own sweep "
               "that the TA recorded on this arm to set the bands.</div>")
    elif job["state"] == "refused":
        head, colour = f"{title}: not run, no points", "#c33"
        words = html.escape(job["reason"])
    else:
        head, colour = f"{title}: not run yet, no points: a fault of the lab", "#999"
        words = html.escape(job["reason"])
    return (f"{_BEGIN}\n<div class='snakekit-lab' style='border-left:4px solid {colour};padding:4px 10px;"
            f"margin:10px 20px'><h2>Your sweep on the arm</h2><p><b>{head}</b></p><p>{words}</p>{img}"
            f"<div style='font-size:85%'>As of {html.escape(job['updated'].replace('T', ' ').replace('Z', ' UTC'))}."
            f"</div></div>\n{_END}\n")


def with_lab(page: str, part: str) -> str:
    """``page`` (a feedback page's HTML) with ``part`` as its lab part, in place of the one it had
    (``part`` empty: without one); the part stands after the page's heading."""
    page = _PART.sub("", page, count=1)
    if not part:
        return page
    m = _SECOND_CELL.search(page)
    at = m.start() if m else (page.rfind("</main>") if "</main>" in page else page.rfind("</body>"))
    return page[:at] + part + page[at:] if at >= 0 else page + part


def exercise_pages(course: Path, assignment: str, student: str) -> list[Path]:
    """The student's feedback pages of ``assignment`` that show the lab's exercise (the first page if none says)."""
    pages = sorted((Path(course) / "feedback" / student / assignment).glob("*.html"))
    try:
        gid = settings(course, assignment).exercise
    except LabError:
        return []
    shown = [p for p in pages if gid in p.read_text(encoding="utf-8", errors="replace")]
    return shown or pages[:1]


def add_to(page: str, course: Path, assignment: str, student: str) -> str:
    """``page``, a feedback page being written, with the lab's part when the lab has one for it."""
    if not (lab_dir(course, assignment) / "queue.json").is_file():
        return page
    try:
        gid = settings(course, assignment).exercise
    except LabError:
        return page
    return with_lab(page, section(course, assignment, student)) if gid in page else page


def update_pages(course: Path, assignment: str, student: str) -> list[Path]:
    """Write the lab's part into the student's feedback page(s) of ``assignment``; returns the pages written.

    Nothing happens when the lab has no queue for the assignment.
    """
    if not (lab_dir(course, assignment) / "queue.json").is_file():
        return []
    part = section(course, assignment, student)
    written = []
    for p in exercise_pages(course, assignment, student):
        old = p.read_text(encoding="utf-8")
        new = with_lab(old, part)
        if new != old:
            write_atomic(p, new)
            written.append(p)
    return written
