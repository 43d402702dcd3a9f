"""The feedback notebook: the student's notebook made safe, with the grader's verdict per exercise.

Every autograded test cell shows only its visible part (the released source) and none of the
output of running it; the grader's message and, for trajectories, a plot of the student's run
against the reference take its place (:func:`build`); every other output goes through
:mod:`grader.feedback.scrub`. The TA's copy of the autograded notebook keeps the verdicts in its
metadata (:func:`annotate_notebook`, read back by :func:`recorded`), so a page can be built
again later.
"""

from __future__ import annotations

import base64
import html
import re

import nbformat

from grader.feedback.plot import verdict_plot
from grader.feedback.scrub import hidden_lines, machine_paths
from grader.feedback.scrub import scrub_cell as _scrub
from grader.markup import visible_part
from grader.scoring.rerun import rows_note
from grader.scoring.wording import points, title

#: The TA's note on the grading machine's load (:func:`grader.scoring.verdict.busy_machine`) in a result's detail: it
#: tells the TA to grade again, so a student's page leaves it out
LOAD_NOTE = re.compile(r"(?:; )?the grading machine's load was .*?\(`--student` for this one\)")


#: An error the grader quotes in a result's detail, "raised <type>: <its message>", up to where the grader's own
#: words go on: after a first run's fault (:mod:`grader.batch`), after the graded run's (``check_faults``), or at the
#: detail's end. The message is the TA's (the emulated arm's port, the servos' registers); a student's page names the
#: type
QUOTED_ERROR = re.compile(r"\braised (\w+): .*?(?=(?: at hidden case \d+)?(?: \(and \d+ more cell\(s\)\))?"
                          r"(?:\), which a busy machine causes| in the second run too| in the run graded)|$)")
#: A test cell's id in a result's detail ("ex07_2_recover_test"): a student's page names the exercise as the lesson does
GRADE_ID = re.compile(r"\bex\d+(?:_\d+)?_\w+?_test\b")


def for_student(detail: str, tests: dict[str, str] | None = None) -> str:
    """A result's detail as the student's page shows it: without the TA's note on the machine's load, each error the
    grader quotes by its type alone (its message holds the grading machine's port and registers), and each exercise
    by the name its lesson gives it (``tests``: the test cells' sources by grade id, :func:`title`).

    >>> for_student("graded on its second run: the first had a fault of the arm's bus (ex07_2_recover_test raised "
    ...             "CommunicationError: servo 3 did not answer on /dev/pts/4 (SyncRead). … at hidden case 2), which a "
    ...             "busy machine causes, so it ran once more from the start")
    "graded on its second run: the first had a fault of the arm's bus (exercise 7.2 recover raised CommunicationError at hidden case 2), which a busy machine causes, so it ran once more from the start"
    """
    text = LOAD_NOTE.sub("", detail or "")
    text = QUOTED_ERROR.sub(lambda m: f"raised {m[1]}", text)
    return GRADE_ID.sub(lambda m: f"exercise {title(m[0], (tests or {}).get(m[0], ''))}", text).strip("; ")


def page_head(assignment: str, student: str, score: float, max_score: float, status: str, detail: str, rows,
              tests: dict[str, str] | None = None, late: str = "") -> str:
    """A page's first cell: the score, the status unless ``graded``, ``late`` (what a late penalty took), the detail
    as the student reads it (:func:`for_student`), then a row per exercise, ``rows``: (its name, points, maximum,
    note)."""
    shown = for_student(detail, tests)
    return (f"# Feedback: {assignment}\n\nStudent: `{student}`. Score: **{points(score)} / {max_score:g}**"
            + (f" ({status})" if status != "graded" else "") + "\n\n" + late
            + (f"{shown}\n\n" if shown else "")
            + "| exercise | points | |\n|---|---|---|\n"
            + "".join(f"| {name} | {points(got)} / {most:g} | {note} |\n" for name, got, most, note in rows))


def _verdict_cell(ex, label: str, png: bytes | None = None):
    """The grader's box under a test cell: its points, its message, and (with a plot) a row per check, each
    detail said once: in its row, not again in the message above."""
    png = png or verdict_plot(ex)
    message = ex.message
    rows = ""
    if png and ex.checks:
        for c in ex.checks:
            message = message.replace(c.message, "")
        message = " ".join(re.sub(r"(^|\s)[.;,](?=\s|$)", " ", message).split())   # no stop left of a line moved
        note = rows_note(ex.message)
        said = [c.message for c in ex.checks]
        rows = (f"<tr><td colspan='3'><i>{html.escape(note)}</i></td></tr>" if note else "") + "".join(
            f"<tr><td>{html.escape(c.name)}</td><td>{c.fraction * c.weight:.2f} / {c.weight:g}</td>"
            f"<td>{html.escape(c.message if c.message not in said[:k] else 'as above.')}</td></tr>"
            for k, c in enumerate(ex.checks))
    body = (f"<div class='grader-verdict' style='border-left:4px solid {'#2a2' if ex.score >= ex.max_score else '#c33'};"
            f"padding:4px 10px;margin:6px 0'><b>Grader: {html.escape(label)}: {points(ex.score)} / {ex.max_score:g} points"
            f"</b><br>{html.escape(message)}"
            + (f"<table style='font-size:90%'>{rows}</table>" if rows else "") + "</div>")
    outputs = [nbformat.v4.new_output("display_data", data={"text/html": body})]
    if png:
        outputs.append(nbformat.v4.new_output("display_data", data={"image/png": base64.b64encode(png).decode()}))
    cell = nbformat.v4.new_code_cell("", metadata={"tags": ["grader-verdict"]})
    cell.outputs = outputs
    return cell


def _stopped_cell(timeout: float | None):
    note = STOPPED.format(timeout=timeout or 0)
    cell = nbformat.v4.new_code_cell("", metadata={"tags": ["grader-verdict"]})
    cell.outputs = [nbformat.v4.new_output("display_data", data={"text/html": (
        "<div class='grader-stopped' style='border-left:4px solid #c33;padding:4px 10px;margin:6px 0'>"
        f"<b>{html.escape(note)}</b>: this cell was interrupted, and the cells after it did not run.</div>")})]
    return cell


STOPPED = "stopped here: the notebook ran longer than {timeout:g} s"  # as grader.sandbox.inside.worker's note


def build(nb, *, student: str, assignment: str, result, test_sources: dict[str, str], stopped: int | None = None,
          timeout: float | None = None, hide_paths: dict[str, str] | None = None, plots: dict | None = None,
          comments: dict[str, str] | None = None, head: str | None = None):
    """The feedback notebook: ``nb`` (executed or as submitted) made safe, with verdicts.

    ``test_sources`` maps each test cell's grade id to its instructor source (with hidden tests).
    ``stopped``: the index of the cell at which the notebook's time (``timeout`` s) ran out; it
    gets a note. ``hide_paths`` adds machine paths (path -> neutral name) to :func:`machine_paths`.
    ``plots``: a trajectory exercise's plot (PNG bytes) by grade id, when its curves are gone;
    ``comments``: the teacher's comment on a cell, by grade id; ``head``: the first cell's markdown
    (default: the score and exercises of ``result``; pages use the gradebook's, :func:`grader.feedback.scores.head`).
    """
    plots, comments = plots or {}, comments or {}
    secret = hidden_lines(test_sources.values())
    paths = machine_paths(hide_paths)
    by_id = {ex.grade_id: ex for ex in result.exercises}
    seen = set()
    cells = []
    note = STOPPED.format(timeout=timeout or 0)
    for index, cell in enumerate(nb.cells):
        meta = cell.get("metadata", {}).get("nbgrader", {})
        gid = meta.get("grade_id")
        if gid in test_sources:
            if gid in seen:
                continue  # a duplicated test cell is shown once
            seen.add(gid)
            cell = nbformat.v4.new_code_cell(visible_part(test_sources[gid]))
            cells.append(cell)
            if index == stopped:
                cells.append(_stopped_cell(timeout))
            if gid in by_id:
                cells.append(_verdict_cell(by_id[gid], title(gid, test_sources[gid]), plots.get(gid)))
            continue
        cell = nbformat.from_dict(dict(cell))
        if cell.cell_type == "code":
            cell.outputs = [o for o in cell.get("outputs", [])
                            if not (index == stopped and o.get("output_type") == "stream" and note in o.get("text", ""))]
            _scrub(cell, secret, paths)
            cell.metadata = {k: v for k, v in cell.metadata.items() if k in ("tags",)}
        cells.append(cell)
        if index == stopped:
            cells.append(_stopped_cell(timeout))
        if gid in comments:
            cells.append(nbformat.v4.new_markdown_cell(f"**Comment from your teacher:** {html.escape(comments[gid])}"))
    for gid, ex in by_id.items():
        if gid not in seen:
            name = title(gid, test_sources.get(gid, ""))
            cells.append(nbformat.v4.new_markdown_cell(f"**The test cell of exercise {name} was missing from your "
                                                       "notebook.**"))
            cells.append(_verdict_cell(ex, name, plots.get(gid)))
    head = head or page_head(assignment, student, result.score, result.max_score, result.status, result.detail,
                             [(title(e.grade_id, test_sources.get(e.grade_id, "")), e.score, e.max_score,
                               "ok" if e.score >= e.max_score else "see below") for e in result.exercises],
                             test_sources)
    out = nbformat.v4.new_notebook(cells=[nbformat.v4.new_markdown_cell(head)] + cells)
    for i, cell in enumerate(out.cells):  # the same page whenever it is written again
        cell["id"] = f"cell-{i}"
    out.metadata = {"language_info": {"name": "python"}}
    kernelspec = nb.get("metadata", {}).get("kernelspec")
    if isinstance(kernelspec, dict) and {"name", "display_name"} <= set(kernelspec):
        out.metadata["kernelspec"] = kernelspec
    return out


# --- the grader's verdicts, kept in the TA's copy of the notebook --------------------------------

RECORD = "snakekit_grader"  # the autograded notebook's metadata key; set by the grader only


def annotate_notebook(nb, result, *, stopped: int | None = None, timeout: float | None = None):
    """The autograded notebook ``nb`` (the TA's copy) with the grader's verdicts in it.

    Its metadata keeps what a feedback page is built from (status, every exercise's points,
    message and checks, the plots), so pages can be written again later from the gradebook's
    scores (:mod:`grader.commands.nbgrader_plugins`); each test cell also shows its verdict as an output,
    where formgrader shows it to the TA. Whatever the submission put under that key is dropped.
    """
    nb = nbformat.from_dict(dict(nb))
    nb.metadata = {k: v for k, v in nb.get("metadata", {}).items() if k != RECORD}
    exercises = {}
    for ex in result.exercises:
        png = verdict_plot(ex)
        exercises[ex.grade_id] = {"score": ex.score, "max_score": ex.max_score, "status": ex.status,
                                  "message": ex.message,
                                  "checks": [[c.name, c.fraction, c.weight, c.message] for c in ex.checks] if png else [],
                                  "plot": base64.b64encode(png).decode() if png else "",
                                  "cases": [[kind, fraction] for kind, fraction in ex.cases]}
    nb.metadata[RECORD] = {"status": result.status, "detail": result.detail, "stopped": stopped, "timeout": timeout,
                           "exercises": exercises}
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        cell.outputs = [o for o in cell.get("outputs", []) if RECORD not in o.get("metadata", {})]
        gid = cell.get("metadata", {}).get("nbgrader", {}).get("grade_id")
        ex = next((e for e in result.exercises if e.grade_id == gid), None)
        if ex is not None:
            shown = _verdict_cell(ex, gid, verdict_plot(ex)).outputs[0]
            if result.status != "graded":
                shown["data"]["text/html"] += (f"<div><b>Submission: {html.escape(result.status)}</b>"
                                               f" ({html.escape(for_student(result.detail))})</div>")
            shown["metadata"] = {RECORD: True}
            cell.outputs.append(shown)
    return nb


def recorded(nb):
    """What :func:`annotate_notebook` kept in ``nb``: ``(status, detail, stopped, timeout, exercises, plots)``, or None.

    ``exercises`` are :class:`grader.scoring.score.ExerciseScore` (checks as ``grader.scoring.compare.Check``);
    values of the wrong type are not trusted and give None.
    """
    from grader.scoring.compare import Check
    from grader.scoring.score import ExerciseScore

    rec = nb.get("metadata", {}).get(RECORD)
    try:
        exercises, plots = [], {}
        for gid, e in rec["exercises"].items():
            checks = tuple(Check(str(n), float(f), str(m), float(w)) for n, f, w, m in e["checks"])
            cases = tuple((str(k), float(f)) for k, f in e.get("cases", ()))
            exercises.append(ExerciseScore(str(gid), float(e["score"]), float(e["max_score"]), str(e["status"]),
                                           str(e["message"]), checks, cases=cases))
            if e["plot"]:
                plots[str(gid)] = base64.b64decode(e["plot"])
        stopped = rec.get("stopped")
        return (str(rec["status"]), str(rec["detail"]), stopped if isinstance(stopped, int) else None,
                float(rec["timeout"]) if rec.get("timeout") is not None else None, exercises, plots)
    except (TypeError, KeyError, ValueError, AttributeError):
        return None

