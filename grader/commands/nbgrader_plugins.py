"""nbgrader's own commands and formgrader's buttons, made to give the grader's results.

A course's ``nbgrader_config.py`` calls :func:`use_safe_grading` (``course/nbgrader_config.py``
does). Then:

* ``nbgrader generate_feedback``, and formgrader's Generate Feedback buttons, write the
  grader's safe pages (:mod:`grader.feedback.notebook`, :mod:`grader.feedback.exporter`: no hidden
  tests, nothing loaded from the network), never nbgrader's own (which keep the hidden tests, its
  issue #917). The pages are built from the gradebook's scores (:mod:`grader.feedback.scores`),
  so a score or comment a TA entered in formgrader and the late penalty are on the page, beside
  the grader's verdict (kept in the autograded notebook by the grader), and the lab's result
  when ``snakekit lab`` ran the student's sweep (docs/lab.md).
* saving a score, extra credit or comment in formgrader sets that student's late penalty again from
  the score saved (a penalty in percent of the score, or capped at it, follows it) and writes the
  student's pages and the class CSV again from the gradebook at once: the page, the CSV,
  ``snakekit export`` and formgrader show the same score.
* formgrader's pages and API give each submission's score after the late penalty, and say the
  penalty (:mod:`grader.commands.formgrader_scores`), as the page, the CSV and the export do.
* formgrader's Autograde button grades the submission with ``snakekit grade ASSIGNMENT
  --student STUDENT`` (the sandbox, the out-of-kernel scoring, the feedback), not with
  nbgrader's in-kernel autograde. Its options come from the config's ``SnakekitGrade``
  section (``references``, ``timeout``, ``cell_timeout``, ``memory``).
* formgrader's menu has "Class reports": each assignment's ``snakekit report`` page, behind formgrader's
  own login (:mod:`grader.commands.formgrader_report`).
* formgrader's grading page loads MathJax from the Jupyter server (``jupyter_server_mathjax``)
  instead of a CDN (template ``grader/templates/snakekit_formgrade``), so every formgrader page
  works with no network beyond the server.

formgrader reads the config again for each request, so the button is replaced whenever the
course's config is in force; plain ``nbgrader autograde`` on the command line is left as it is.
"""

from __future__ import annotations

import asyncio
import json
import os
import sys
from pathlib import Path

from nbconvert.exporters import HTMLExporter

from grader.commands import formgrader_report, formgrader_scores
from grader.feedback import exporter, scores
from grader.arm import feedback as lab_feedback

#: where formgrader's request handlers live (imported only by a server that runs formgrader)
FORMGRADER = "nbgrader.server_extensions.formgrader.apihandlers"


def use_safe_grading(c) -> None:
    """Make nbgrader's feedback and formgrader's Autograde button the grader's (call from ``nbgrader_config.py``)."""
    c.GenerateFeedback.exporter_class = f"{__name__}.SafeFeedbackExporter"
    c.GenerateFeedback.preprocessors = []  # nbgrader's GetGrades and CSS header: the page is built below
    handlers = sys.modules.get(FORMGRADER)
    if handlers is not None:
        handlers.AutogradeHandler.post = _autograde_post(handlers)
        saved_in_formgrader(handlers)
        formgrader_scores.install(handlers)
        formgrader_report.install(handlers)
        math_from_the_server(c)


def math_from_the_server(c) -> None:
    """formgrader's grading page ("formgrade") with MathJax from the Jupyter server, not a CDN: nbgrader's
    template, whose MathJax macro ``grader/templates/snakekit_formgrade`` replaces."""
    from nbgrader.server_extensions.formgrader.handlers import template_path

    c.HTMLExporter.template_name = "snakekit_formgrade"
    c.HTMLExporter.extra_template_basedirs = [str(exporter.TEMPLATES), template_path]


class SafeFeedbackExporter(HTMLExporter):
    """nbgrader's feedback exporter, writing the grader's page for one autograded notebook."""

    @property
    def file_extension(self):
        return ".html"

    def from_notebook_node(self, nb, resources=None, **kw):
        info = (resources or {}).get("nbgrader") or {}
        student, assignment, notebook = info.get("student"), info.get("assignment"), info.get("notebook")
        course_id = getattr(getattr(self.parent, "coursedir", None), "course_id", None) or "default_course"
        root = getattr(getattr(self.parent, "coursedir", None), "root", None)
        body = safe_page(nb, root=root, student=student, assignment=assignment, notebook=notebook,
                         db_url=info.get("db_url"), course_id=course_id)
        resources = dict(resources or {})
        resources["output_extension"] = ".html"
        return body, resources


def safe_page(nb, *, root, student: str, assignment: str, notebook: str, db_url: str, course_id: str) -> str:
    """The grader's page of an autograded notebook, from the gradebook's scores and comments (and
    the lab's result, when the lab ran the student's sweep)."""
    page, numbers = regenerate(nb, student=student, assignment=assignment, notebook=notebook, db_url=db_url,
                               course_id=course_id, root=root)
    body = scores.html(page, numbers)
    if root and student and assignment:
        body = lab_feedback.add_to(body, Path(root), assignment, student)
    return body


def rewrite_stale(course: Path, assignment: str, out) -> list[str]:
    """The feedback pages whose numbers are no longer the gradebook's (a score or comment set in formgrader,
    a late penalty) written again, and the class CSV with them (:func:`grader.feedback.scores.refresh`), so
    the page ``snakekit return`` hands back says the score the student gets."""
    from grader.arm.keep import HOOKS

    students = scores.refresh(course, assignment, after=HOOKS.pages)
    if students:
        print(f"feedback pages written again with the gradebook's scores: {', '.join(students)}", file=out)
    return students


def return_main(argv: list[str] | None = None, out=None) -> int:
    """``snakekit return``: :func:`grader.lms.export.return_main`, the stale pages written again first."""
    from grader.lms.export import return_main as hand_back

    return hand_back(argv, out, before=rewrite_stale)


def regenerate(nb, *, student: str, assignment: str, notebook: str, db_url: str, course_id: str, root=None):
    """The feedback notebook of an autograded notebook, with the gradebook's scores and comments
    (:func:`grader.feedback.scores.page`), and those numbers."""
    from nbgrader.api import Gradebook

    from grader.course.gradebook import cell_order, submission_scores

    with Gradebook(db_url, course_id) as gb:
        numbers = submission_scores(gb, gb.find_submission(assignment, student),
                                    cell_order(Path(root), assignment) if root else None)
        tests = scores.test_sources(gb, assignment, notebook)
    return scores.page(nb, numbers, notebook, tests), numbers


def saved_in_formgrader(handlers) -> None:
    """formgrader's saving of a score or comment, followed by the student's late penalty set again from the
    score saved (nbgrader's ``AssignLatePenalties``, as grading sets it) and the student's pages and the
    class CSV written again from the gradebook (:func:`grader.feedback.scores.refresh`)."""
    from grader.arm.keep import HOOKS
    from grader.course.gradebook import late_penalties

    for name, find in (("GradeHandler", "find_grade_by_id"), ("CommentHandler", "find_comment_by_id")):
        cls = getattr(handlers, name)
        if getattr(cls.put, "_snakekit", False):
            continue
        saved = cls.put

        def put(self, item_id, _saved=saved, _find=find):
            _saved(self, item_id)
            sub = getattr(self.gradebook, _find)(item_id).notebook.assignment
            course, assignment, student = Path(self.coursedir.root), sub.assignment.name, sub.student.id
            self.gradebook.db.commit()  # formgrader's own session ends here: the penalty is written beside it
            # a penalty that is a share of the score (per-day:10%), or capped at it, follows the score just saved
            late_penalties(course, assignment, student)
            scores.refresh(course, assignment, {student}, after=HOOKS.pages)

        put.__wrapped__ = saved  # inspect.unwrap reaches formgrader's own handler through it
        put._snakekit = True
        cls.put = put


def _autograde_post(handlers):
    """formgrader's Autograde request, graded by ``snakekit grade --student`` in a separate process."""
    from tornado import web

    base = sys.modules[handlers.__name__.rsplit(".", 1)[0] + ".base"]

    @web.authenticated
    @base.check_xsrf
    @base.check_notebook_dir
    async def post(self, assignment_id, student_id):
        root = Path(self.coursedir.root)
        opts = self.coursedir.parent.config.get("SnakekitGrade", {})
        cmd = [sys.executable, "-m", "grader.commands.grade", assignment_id, "--course", str(root), "--student", student_id]
        for key, flag in (("references", "--references"), ("timeout", "--timeout"),
                          ("cell_timeout", "--cell-timeout"), ("memory", "--memory")):
            if key in opts:
                cmd += [flag, str(opts[key])]
        env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
        proc = await asyncio.create_subprocess_exec(*cmd, cwd=str(root), env=env, stdout=asyncio.subprocess.PIPE,
                                                    stderr=asyncio.subprocess.STDOUT)
        out, _ = await proc.communicate()
        log = out.decode(errors="replace")[-8000:]
        ok = proc.returncode == 0
        self.write(json.dumps({"success": ok, "log": log, "error": "" if ok else log}))

    return post
