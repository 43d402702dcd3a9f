"""formgrader's scores after the late penalty, as the page, the class CSV and ``snakekit export`` give them.

nbgrader's formgrader adds up the cells' points (``Grade.score``) and leaves nbgrader's own late
penalty (``SubmittedNotebook.late_submission_penalty``) out of every score it shows. With the
course's config (:func:`grader.commands.nbgrader_plugins.use_safe_grading`), formgrader's server
asks :class:`LateAwareAPI` instead of nbgrader's ``NbGraderAPI`` for what its pages show, so every
score of a submission (manage submissions, a student's assignments and notebooks, the students'
overall scores, the gradebook's submissions and averages) is the score after the penalty, with the
penalty beside it (``late_penalty`` in the API's answer; the pages say "(late: -3)" in the score's
cell). A cell's points in the grading view stay the cell's: a penalty belongs to the submission.
"""

from __future__ import annotations

import functools
import sys
from collections import defaultdict

#: What each of formgrader's score pages runs after nbgrader's own script: each row whose submission has a
#: late penalty says it beside the score (the score itself is the API's, after the penalty).
LATE_SCRIPT = """<script>
(function () {
  ["StudentUI", "StudentSubmissionUI", "SubmissionUI", "StudentSubmittedNotebookUI", "SubmittedNotebookUI"]
    .forEach(function (name) {
      var view = window[name];
      if (!view) return;
      var render = view.prototype.render;
      view.prototype.render = function () {
        var out = render.apply(this, arguments);
        var late = this.model.get("late_penalty");
        if (late && this.$score) {
          this.$score.append(" ").append($("<span/>").addClass("snakekit-late text-warning")
            .attr("title", "late penalty: the score is after it")
            .text("(late: -" + roundToPrecision(late, 2) + ")"));
        }
        return out;
      };
    });
})();
</script>
"""
#: formgrader's pages that show a submission's score.
SCORE_PAGES = {"manage_students.tpl", "manage_students_assignments.tpl", "manage_submissions.tpl",
               "manage_students_notebook_submissions.tpl", "gradebook_notebook_submissions.tpl"}


def late_penalties(gb) -> dict[tuple[str, str, str], float]:
    """Every late penalty in the gradebook ``gb``: (assignment, student, notebook) -> points off."""
    from nbgrader.api import Assignment, Notebook, SubmittedAssignment, SubmittedNotebook

    rows = (gb.db.query(Assignment.name, SubmittedAssignment.student_id, Notebook.name,
                        SubmittedNotebook.late_submission_penalty)
            .select_from(SubmittedNotebook)
            .join(SubmittedAssignment, SubmittedNotebook.assignment_id == SubmittedAssignment.id)
            .join(Notebook, SubmittedNotebook.notebook_id == Notebook.id)
            .join(Assignment, Notebook.assignment_id == Assignment.id)
            .filter(SubmittedNotebook.late_submission_penalty > 0))
    return {(a, s, nb): float(p) for a, s, nb, p in rows}


def _after(row: dict, penalty: float, key: str = "score") -> dict:
    """``row`` (one of formgrader's answers) with ``key`` after ``penalty`` and the penalty said (a score
    rounded as :attr:`grader.course.gradebook.SubmissionScores.score` is, an average not)."""
    if "late_penalty" not in row:  # once: a row nbgrader's API builds from another is not taken off twice
        after = float(row.get(key) or 0.0) - penalty
        row[key] = round(after, 4) if key == "score" else after
        row["late_penalty"] = round(penalty, 4) if key == "score" else penalty
    return row


def late_aware(api_class):
    """``api_class`` (nbgrader's ``NbGraderAPI``) with every score it answers after the late penalty."""

    class LateAwareAPI(api_class):
        """nbgrader's API for formgrader, its scores after nbgrader's late penalty."""

        def _late(self):
            with self.gradebook as gb:
                return late_penalties(gb)

        def _summed(self, *fields):
            out = defaultdict(float)
            for key, p in self._late().items():
                out[tuple(key[i] for i in fields)] += p
            return out

        def get_submission(self, assignment_id, student_id, ungraded=None, students=None):
            row = super().get_submission(assignment_id, student_id, ungraded=ungraded, students=students)
            if row and row.get("autograded"):
                _after(row, self._summed(0, 1).get((assignment_id, student_id), 0.0))
            return row

        def get_submissions(self, assignment_id):
            late = self._summed(0, 1)
            return [_after(r, late.get((assignment_id, r["student"]), 0.0)) if r.get("autograded") else r
                    for r in super().get_submissions(assignment_id)]

        def get_student_notebook_submissions(self, student_id, assignment_id):
            late = self._late()
            return [_after(r, late.get((assignment_id, student_id, r["name"]), 0.0)) if r.get("id") else r
                    for r in super().get_student_notebook_submissions(student_id, assignment_id)]

        def get_notebook_submissions(self, assignment_id, notebook_id):
            late = self._late()
            return [_after(r, late.get((assignment_id, r["student"], notebook_id), 0.0))
                    for r in super().get_notebook_submissions(assignment_id, notebook_id)]

        def get_student(self, student_id, submitted=None):
            row = super().get_student(student_id, submitted=submitted)
            return row and _after(row, self._summed(1).get((student_id,), 0.0))

        def get_students(self):
            late = self._summed(1)
            return [_after(r, late.get((r["id"],), 0.0)) for r in super().get_students()]

        def get_assignment(self, assignment_id, released=None):
            row = super().get_assignment(assignment_id, released=released)
            if row and row.get("id"):
                with self.gradebook as gb:
                    n = gb.find_assignment(assignment_id).num_submissions
                total = self._summed(0).get((assignment_id,), 0.0)
                _after(row, total / n if n else 0.0, "average_score")
            return row

        def get_notebooks(self, assignment_id):
            late = self._summed(0, 2)
            return [_after(r, late.get((assignment_id, r["name"]), 0.0) / r["num_submissions"]
                           if r.get("num_submissions") else 0.0, "average_score")
                    for r in super().get_notebooks(assignment_id)]

    LateAwareAPI._snakekit = True
    return LateAwareAPI


def _render_with_late(render):
    """formgrader's page rendering, the score pages with :data:`LATE_SCRIPT` after nbgrader's own script."""

    @functools.wraps(render)   # keeps the marks of the wrappers inside it: each wraps formgrader once
    def rendered(self, name, **ns):
        html = render(self, name, **ns)
        return html.replace("</head>", LATE_SCRIPT + "</head>", 1) if name in SCORE_PAGES else html

    rendered._snakekit = True
    return rendered


def install(handlers) -> None:
    """formgrader's server (``handlers``: its API handlers' module) answering and showing scores after the late
    penalty: its API is :func:`late_aware`, its score pages say the penalty. Installing twice changes nothing."""
    base = sys.modules[handlers.__name__.rsplit(".", 1)[0] + ".base"]
    if not getattr(base.NbGraderAPI, "_snakekit", False):
        base.NbGraderAPI = late_aware(base.NbGraderAPI)
    if not getattr(base.BaseHandler.render, "_snakekit", False):
        base.BaseHandler.render = _render_with_late(base.BaseHandler.render)
