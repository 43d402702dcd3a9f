"""nbgrader's own commands and formgrader's buttons, made to give the grader's results.

A course's ``nbgrader_config.py`` calls :func:`use_safe_grading` (``course/nbgrader_config.py``
does). Then:

* ``nbgrader generate_feedback``, and formgrader's Generate Feedback buttons, write the
  grader's safe pages (:mod:`grader.feedback.report`: no hidden tests, nothing loaded from the
  network), never nbgrader's own (which keep the hidden tests, its issue #917). The pages are
  built from the gradebook's scores, so a score or comment a TA entered in formgrader is on
  the page, beside the grader's verdict (kept in the autograded notebook by the grader), and
  the lab's result when ``snakekit lab`` ran the student's sweep (docs/lab.md).
* formgrader's Autograde button grades the submission with ``snakekit grade ASSIGNMENT
  --student STUDENT`` (the sandbox, the out-of-kernel scoring, the feedback), not with
  nbgrader's in-kernel autograde. Its options come from the config's ``SnakekitGrade``
  section (``references``, ``timeout``, ``cell_timeout``, ``memory``).

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

from grader.feedback import report as feedback
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


class SafeFeedbackExporter(HTMLExporter):
    """nbgrader's feedback exporter, writing the grader's page for one autograded notebook."""

    @property
    def file_extension(self):
        return ".html"

    def from_notebook_node(self, nb, resources=None, **kw):
        info = (resources or {}).get("nbgrader") or {}
        student, assignment, notebook = info.get("student"), info.get("assignment"), info.get("notebook")
        course_id = getattr(getattr(self.parent, "coursedir", None), "course_id", None) or "default_course"
        page = regenerate(nb, student=student, assignment=assignment, notebook=notebook,
                          db_url=info.get("db_url"), course_id=course_id)
        body, _ = feedback.page_exporter().from_notebook_node(page)
        root = getattr(getattr(self.parent, "coursedir", None), "root", None)
        if root and student and assignment:  # the lab's result, when the lab ran the student's sweep
            body = lab_feedback.add_to(body, Path(root), assignment, student)
        resources = dict(resources or {})
        resources["output_extension"] = ".html"
        return body, resources


def regenerate(nb, *, student: str, assignment: str, notebook: str, db_url: str, course_id: str):
    """The feedback notebook of an autograded notebook, with the gradebook's scores and comments.

    A score the TA set by hand replaces the grader's (the verdict says so); a TA's comment on
    a cell follows that cell. A notebook the grader did not autograde (no verdicts kept in it)
    gets the gradebook's points with no messages, never its own test cells' output.
    """
    from nbgrader.api import Gradebook, MissingEntry

    from grader.scoring.verdict import SubmissionResult

    kept = feedback.recorded(nb)
    status, detail, stopped, timeout, exercises, plots = kept or ("graded", "", None, None, [], {})
    by_id = {e.grade_id: e for e in exercises}
    with Gradebook(db_url, course_id) as gb:
        source = gb.find_notebook(notebook, assignment)
        solution = {c.name for c in source.solution_cells}
        sources = {c.name: c.source for c in source.source_cells}
        tests = {g.name: sources[g.name] for g in source.grade_cells if g.cell_type == "code" and g.name not in solution}
        final, comments = [], {}
        for gid in tests:
            try:
                grade = gb.find_grade(gid, notebook, assignment, student)
            except MissingEntry:
                continue
            mine = by_id.get(gid)
            score = float(grade.score or 0.0)
            if mine is None:
                from grader.scoring.score import ExerciseScore

                mine = ExerciseScore(gid, score, float(grade.max_score), "scored", "")
            if grade.manual_score is not None and abs(grade.manual_score - mine.score) > 1e-9:
                mine = type(mine)(gid, score, mine.max_score, mine.status,
                                  f"Your teacher set the points to {score:g} (the grader gave {mine.score:g}). "
                                  + mine.message, mine.checks)
            final.append(mine)
        for name in solution | {c.name for c in source.task_cells}:
            try:
                comment = gb.find_comment(name, notebook, assignment, student)
            except MissingEntry:
                continue
            if comment.manual_comment:
                comments[name] = comment.manual_comment
        sub = gb.find_submission(assignment, student)
        total, max_total = float(sub.score), float(sub.max_score)
        late = float(sub.late_submission_penalty or 0.0)
    if late:
        detail = f"{detail}; " if detail else ""
        detail += f"late submission: {late:g} points taken off"
    result = SubmissionResult(student, assignment, total - late, max_total, status, detail, tuple(final))
    return feedback.build(nb, student=student, assignment=assignment, result=result, test_sources=tests,
                          stopped=stopped, timeout=timeout, plots=plots, comments=comments)


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
