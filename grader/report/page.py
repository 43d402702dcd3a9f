"""The class report as one self-contained page and a CSV per table.

The page is a notebook of tables and pictures rendered by the feedback pages' exporter
(:func:`grader.feedback.exporter.write_html`: its template loads nothing, its plots are inline PNG),
so it opens offline and holds no address and no path of the machine. Each table is also a CSV (for
the LMS or a spreadsheet) in the same folder.
"""

from __future__ import annotations

import csv
import html
import io
import os
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook, new_output

from grader.feedback.exporter import write_html
from grader.report.standing import ClassStanding, exercise_name

__all__ = ["tables", "write_report", "PAGE"]

#: The page's file name in the report's folder.
PAGE = "report.html"
#: Students named in a table cell before "and N more".
NAMES = 6
#: Pairs shown on the page, the most alike first (all of them are in the CSVs).
SHOWN = 100


def _names(students, limit: int = NAMES) -> str:
    students = list(students)
    more = f" and {len(students) - limit} more" if len(students) > limit else ""
    return ", ".join(students[:limit]) + more


def tables(s: ClassStanding, code: list, trajectories: list) -> dict[str, tuple[list[str], list[list]]]:
    """Every table of the report: name -> (columns, rows)."""
    return {
        "exercises": (["exercise", "grade_id", "points", "full", "partial", "zero"],
                      [[e.name, e.grade_id, e.max_score, e.full, e.partial, e.zero] for e in s.exercises]),
        "cases": (["exercise", "case_kind", "cases", "passed", "pass_rate"],
                  [[exercise_name(c.grade_id), c.kind, c.cases, c.passed, round(c.rate, 4)] for c in s.case_kinds]),
        "totals": (["student", "score", "max_score", "late", "resubmitted", "hours_before_due"],
                   [[st, score, s.max_score, st in s.late, st in s.resubmitted, s.hours_before_due.get(st, "")]
                    for st, score in s.totals.items()]),
        "failures": (["exercise", "mistake", "kind", "count", "examples", "students", "example_message"],
                     [[exercise_name(f.grade_id), f.text, _kind(f), f.count, ", ".join(f.students[:2]),
                       " ".join(f.students), f.example] for f in s.failures]),
        "alike": (["first", "second", "similarity", "cells"],
                  [[p.first, p.second, p.similarity, " ".join(f"{gid}:{sim:g}" for gid, _, _, sim in p.cells)]
                   for p in code]),
        "trajectories": (["first", "second", "exercise", "largest_difference"],
                         [[p.first, p.second, exercise_name(p.grade_id), p.diff] for p in trajectories]),
    }


def _kind(f) -> str:
    return "hint" if f.hinted else "not written" if f.unwritten else "no hint"


#: A cell of text or code, as it is read: from the left, from the top (JupyterLab's tables right-align).
LEFT = 'style="text-align: left; vertical-align: top"'


def _html_table(columns, rows) -> str:
    """A table whose numbers stand right, as usual, and whose text reads from the left."""
    def cell(v):
        return f"<td>{v}</td>" if isinstance(v, int | float) else f"<td {LEFT}>{html.escape(str(v))}</td>"

    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in columns)
    body = "".join("<tr>" + "".join(cell(v) for v in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _shown(html_text: str = "", png: bytes | None = None, alt: str = ""):
    cell = new_code_cell("", metadata={"tags": ["grader-verdict"]})
    data = {"text/html": html_text} if html_text else {}
    if png is not None:
        import base64

        data = {"image/png": base64.b64encode(png).decode(), "text/plain": alt}
    cell.outputs = [new_output("display_data", data=data)]
    return cell


def _bars(labels, series: dict, title: str, xlabel: str, *, stacked: bool = True) -> bytes:
    """A bar chart as PNG: ``series`` name -> one value per label."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 0.45 * len(labels) + 1.4), dpi=72)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    left = [0.0] * len(labels)
    for i, (name, values) in enumerate(series.items()):
        ax.barh(range(len(labels)), values, left=left if stacked else None, label=name, color=f"C{i}")
        if stacked:
            left = [a + b for a, b in zip(left, values)]
    ax.set_yticks(range(len(labels)), labels)
    ax.invert_yaxis()
    ax.set_xlabel(xlabel)
    ax.set_title(title)
    if len(series) > 1:
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0))   # beside the bars, never over them
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def _histogram(values, max_score: float) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 3), dpi=72)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.hist(list(values), bins=min(20, max(5, int(max_score) + 1)), range=(0, max_score), color="C0", edgecolor="white")
    ax.set_xlabel(f"total [points of {max_score:g}]")
    ax.set_ylabel("students")
    ax.set_title("Distribution of totals")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def _side_by_side(pair) -> str:
    rows = "".join(f"<tr><th colspan=2 {LEFT}>{html.escape(gid)}: {sim:.0%} alike</th></tr>"
                   f"<tr><td {LEFT}><pre {LEFT}>{html.escape(a)}</pre></td>"
                   f"<td {LEFT}><pre {LEFT}>{html.escape(b)}</pre></td></tr>"
                   for gid, a, b, sim in pair.cells)
    return (f"<h4>{html.escape(pair.first)} and {html.escape(pair.second)}: {pair.similarity:.0%} alike</h4>"
            f"<table><thead><tr><th {LEFT}>{html.escape(pair.first)}</th><th {LEFT}>{html.escape(pair.second)}</th>"
            f"</tr></thead><tbody>{rows}</tbody></table>")


def notebook(s: ClassStanding, code: list, trajectories: list, threshold: float):
    """The report as a notebook (rendered by :func:`write_report`)."""
    t = tables(s, code, trajectories)
    n, totals = len(s.totals), list(s.totals.values())
    mean = sum(totals) / n
    hours = sorted(s.hours_before_due.values())
    md = [f"# {s.assignment}: the class's report",
          f"{n} submissions graded; mean total {mean:.2f} of {s.max_score:g}; {len(s.late)} late, "
          f"{len(s.resubmitted)} resubmitted." + (f" Handed in: median {_due(hours[len(hours) // 2])} "
                                                  f"(earliest {_due(hours[-1])}, latest {_due(hours[0])})."
                                                  if hours else " The gradebook has no due date or no hand-in times.")
          + (f" Without the grader's verdicts (a notebook that never ran): {_names(s.unrecorded)}." if s.unrecorded else "")]
    cells = [new_markdown_cell("\n\n".join(md)), new_markdown_cell("## Where the class stands")]
    labels = [e.name for e in s.exercises]
    cells.append(_shown(png=_bars(labels, {"full": [e.full for e in s.exercises],
                                           "partial": [e.partial for e in s.exercises],
                                           "zero": [e.zero for e in s.exercises]},
                                  "Marks per exercise", "submissions"), alt="marks per exercise: full, partial, zero"))
    cells.append(_shown(_html_table(*t["exercises"])))
    if s.case_kinds:
        cells.append(new_markdown_cell("### Hidden cases, by kind"))
        cells.append(_shown(png=_bars([f"{exercise_name(c.grade_id)}: {c.kind}" for c in s.case_kinds],
                                      {"pass rate": [c.rate for c in s.case_kinds]}, "Hidden cases right in full",
                                      "share of cases"), alt="pass rate per kind of hidden case"))
        cells.append(_shown(_html_table(*t["cases"])))
    cells.append(new_markdown_cell("### Totals"))
    cells.append(_shown(png=_histogram(totals, s.max_score), alt="distribution of totals"))
    cells.append(new_markdown_cell("## Why they fail\n\nThe same mistake at other cases counts once: grouped by the hint "
                                   "that fired, else by the message with its numbers taken out (`#`)."))
    for kind, title in (("hint", "### Mistakes a hint recognised"),
                        ("no hint", "### Mistakes no hint recognised (candidates for the next hint)"),
                        ("not written", "### Not written (the hand-out's stub still raised)")):
        rows = [[exercise_name(f.grade_id), f.shown, f.count, _names(f.students, 2), f.example]
                for f in s.failures if _kind(f) == kind]
        cells.append(new_markdown_cell(title))
        cells.append(_shown(_html_table(["exercise", "mistake", "count", "examples", "one student's message"], rows))
                     if rows else new_markdown_cell("None."))
    cells.append(new_markdown_cell(f"## Too alike to be chance\n\nA screen for a TA to read; it changes no grade. "
                                   f"Answer cells without the hand-out's and the solution's code, at least "
                                   f"{threshold:.0%} alike ({len(code)} pairs):"))
    cells.append(_shown("".join(_side_by_side(p) for p in code[:SHOWN])) if code else new_markdown_cell("None."))
    cells.append(new_markdown_cell(f"The same wrong trajectory, equal within float noise ({len(trajectories)} pairs):"))
    columns, rows = t["trajectories"]
    cells.append(_shown(_html_table(columns, rows[:SHOWN])) if trajectories else new_markdown_cell("None."))
    if len(code) > SHOWN or len(trajectories) > SHOWN:
        cells.append(new_markdown_cell(f"The first {SHOWN} pairs of each are shown; all of them are in `alike.csv` "
                                       "and `trajectories.csv`."))
    for i, cell in enumerate(cells):   # ids of their own, not random ones: the same class, the same page
        cell.id = f"report-{i}"
    nb = new_notebook(cells=cells)
    nb.metadata["language_info"] = {"name": "python"}
    nb.metadata["title"] = f"{s.assignment}: the class's report"   # the page's <title>
    return nb


def _due(hours_before: float) -> str:
    """Hours before the due date in words: "3.8 h before the due date", "10.3 h after it".

    >>> _due(3.84), _due(-10.27)
    ('3.8 h before the due date', '10.3 h after the due date')
    """
    return f"{abs(hours_before):.1f} h {'before' if hours_before >= 0 else 'after'} the due date"


def _write_csv(path: Path, columns, rows) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(columns)
        w.writerows(rows)
    os.replace(tmp, path)


def write_report(folder: Path, s: ClassStanding, code: list, trajectories: list, threshold: float) -> list[Path]:
    """Write the page and the CSVs into ``folder``; returns the files written, the page first."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = [write_html(nbformat.from_dict(notebook(s, code, trajectories, threshold)), folder / PAGE)]
    for name, (columns, rows) in tables(s, code, trajectories).items():
        _write_csv(folder / f"{name}.csv", columns, rows)
        written.append(folder / f"{name}.csv")
    return written
