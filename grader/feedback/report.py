"""Per-student feedback: the student's notebook as HTML, with the grader's verdict per exercise.

What the student must not see is taken out here, not trusted to nbgrader (whose feedback
keeps the hidden tests, its issue #917): every autograded test cell shows only its visible
part (the released source) and none of the output of running it; the grader's message and,
for trajectories, a plot of the student's run against the reference take its place. Any other
output that repeats a line of hidden test code is removed too.

A page works offline and as it is: it loads nothing (no require.js, MathJax or mermaid from a
CDN; math is turned into MathML when the page is written, which browsers typeset themselves),
an interactive widget becomes one line saying what it was, and the grading machine's paths in
tracebacks and outputs (the sandbox's folder, the Python installation, the kit, the home
folder) are replaced by neutral names.
"""

from __future__ import annotations

import base64
import functools
import hashlib
import html
import io
import os
import re
import sys
import sysconfig
import threading
from collections import OrderedDict
from pathlib import Path

import nbformat
import numpy as np

from grader.feedback.page import html_page
from grader.markup import HIDDEN, first_hidden_line, visible_part

REMOVED = "[output removed by the grader: it showed hidden test code]"

_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def cell_error(cell) -> tuple[str, str, str] | None:
    """How an executed test cell failed: ``(exception name, message, where)``; None if it did not.

    ``where`` is ``"visible"`` when the traceback shows the statement that raised standing
    before the cell's hidden tests (a visible check, which the student can run in their own
    notebook), ``"hidden"`` when it stands in or after them, ``"unknown"`` when the traceback
    names no line of the cell (the course's checks print a one-line message, no traceback).

    >>> from nbformat.v4 import new_code_cell, new_output
    >>> c = new_code_cell("check(f)\\n### BEGIN HIDDEN TESTS\\nsecret(f)\\n### END HIDDEN TESTS\\n", execution_count=7)
    >>> c.outputs = [new_output("error", ename="CheckFailed", evalue="f is not written yet",
    ...                         traceback=["Cell In[7], line 1", "..."])]
    >>> cell_error(c)
    ('CheckFailed', 'f is not written yet', 'visible')
    >>> c.outputs[0]["traceback"] = ["Cell In[7], line 3", "..."]
    >>> cell_error(c)[2], cell_error(new_code_cell("x = 1")) is None
    ('hidden', True)
    """
    err = next((o for o in cell.get("outputs", []) if o.get("output_type") == "error"), None)
    if err is None:
        return None
    ename = str(err.get("ename", "an error"))[:80]
    evalue = _ANSI.sub("", str(err.get("evalue", "")))[:600]
    lines = str(cell.get("source", "")).splitlines()
    first_hidden = first_hidden_line(lines)
    tb = _ANSI.sub("", "\n".join(map(str, err.get("traceback", []))))
    count = cell.get("execution_count")
    m = re.search(rf"Cell In\[{count}\], line (\d+)", tb) if count else None
    if not m:
        return ename, evalue, "unknown"
    return ename, evalue, "visible" if int(m.group(1)) < first_hidden else "hidden"


def hidden_lines(sources) -> set[str]:
    """The non-trivial lines of the hidden regions of ``sources`` (to spot them in outputs)."""
    out = set()
    for s in sources:
        for block in HIDDEN.findall(s):
            for line in block.splitlines()[1:-1]:
                line = line.strip()
                if len(line) >= 12 and not line.startswith("#"):
                    out.add(line)
    return out


_plots: OrderedDict[bytes, bytes] = OrderedDict()  # recent plots by a digest of what they draw
_plots_lock = threading.Lock()
PLOT_CACHE = 16  # plots kept; each is a few hundred kB


def plot_png(curves: dict, title: str) -> bytes:
    """The student's run against the reference, one row per joint, as PNG bytes.

    Left: the whole run. Right: 5 s around the largest difference between the student's
    curve and the reference (or the start, when they agree), where one can see it. The
    reference is drawn wide and grey underneath, the student's curves in colour on top.

    The simulator repeats a run bit for bit, so every student whose sweep is right hands in
    the same curves: a plot of the same title and arrays is drawn once and its bytes reused.
    """
    digest = hashlib.blake2b(title.encode(), digest_size=20)
    for name in sorted(curves):
        for a in curves[name]:
            a = np.ascontiguousarray(a)
            digest.update(f"{name}|{a.dtype.str}|{a.shape}|".encode())
            digest.update(a.data)
    key = digest.digest()
    with _plots_lock:
        if key in _plots:
            _plots.move_to_end(key)
            return _plots[key]
    png = _draw(curves, title)
    with _plots_lock:
        _plots[key] = png
        while len(_plots) > PLOT_CACHE:
            _plots.popitem(last=False)
    return png


def _draw(curves: dict, title: str) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    n = next(iter(curves.values()))[1].shape[1]
    height = 1.45 * n + 1.0
    fig = Figure(figsize=(10, height), dpi=72)  # fixed margins: a layout engine would double the drawing time
    fig.subplots_adjust(left=0.07, right=0.99, bottom=0.5 / height, top=1 - 0.75 / height, wspace=0.04, hspace=0.15)
    FigureCanvasAgg(fig)
    # shared axes: the inner rows draw no tick labels (most of a panel's drawing time is its ticks)
    axes = np.atleast_2d(fig.subplots(n, 2, sharex="col", sharey="row", width_ratios=(2, 1)))
    styles = {"reference measured": dict(color="0.7", lw=3.5, zorder=1),
              "reference commanded": dict(color="0.35", lw=1, ls=":", zorder=2),
              "commanded": dict(color="C0", lw=1, ls="--", zorder=3),
              "measured": dict(color="C1", lw=1.2, zorder=4)}
    centre, worst = 0.0, ""
    for mine, ref in (("measured", "reference measured"), ("commanded", "reference commanded")):
        if mine in curves and ref in curves:
            (ts, qs), (tr, qr) = curves[mine], curves[ref]
            ts, tr = ts - ts[0], tr - tr[0]
            grid = ts[(ts >= 0) & (ts <= tr[-1])]
            if len(grid):
                diff = np.abs(qs[: len(grid)] - np.column_stack([np.interp(grid, tr, qr[:, j]) for j in range(n)]))
                if diff.max() > 1e-9:
                    i, j = np.unravel_index(int(np.argmax(diff)), diff.shape)
                    centre, worst = float(grid[i]), f"largest difference: {mine} joint {j + 1} at t={grid[i]:.1f} s"
                    break
    lo = max(centre - 2.5, 0.0)
    for name in sorted(curves, key=lambda k: styles.get(k, {}).get("zorder", 5)):
        t, q = curves[name]
        t = t - t[0]
        every = max(1, len(t) // 2000)  # the whole run: at most ~2000 points a curve (the panel is ~600 px wide)
        for j in range(n):
            for col, keep in ((0, slice(None, None, every)), (1, (t >= lo) & (t <= lo + 5))):
                axes[j, col].plot(t[keep], q[keep, j], label=name if (j, col) == (0, 0) else None,
                                  **styles.get(name, {}))
    for j in range(n):
        axes[j, 0].set_ylabel(f"joint {j + 1} [rad]", fontsize=8)
        for col in (0, 1):
            axes[j, col].grid(alpha=0.3)
            axes[j, col].tick_params(labelsize=7)
        axes[j, 0].yaxis.set_major_locator(MaxNLocator(4, steps=[1, 2, 5, 10]))
    axes[-1, 0].set_xlabel("time from the first point [s]", fontsize=8)
    axes[-1, 1].set_xlabel(f"zoom: {lo:.1f} to {lo + 5:.1f} s", fontsize=8)
    axes[0, 1].set_title(worst or "your curves match the reference", fontsize=8)
    fig.legend(loc="upper right", bbox_to_anchor=(0.99, 1.0), fontsize=8, ncols=4, frameon=False)
    fig.suptitle(title, fontsize=10, x=0.01, ha="left")
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()


def verdict_plot(ex) -> bytes | None:
    """The plot of a trajectory exercise's run against the reference (None for other exercises)."""
    return plot_png(ex.curves, f"{ex.grade_id}: your run (colour) and the reference (grey)") if ex.curves else None


def _verdict_cell(ex, label: str, png: bytes | None = None):
    png = png or verdict_plot(ex)
    rows = "".join(f"<tr><td>{html.escape(c.name)}</td><td>{c.fraction * c.weight:.2f} / {c.weight:g}</td>"
                   f"<td>{html.escape(c.message)}</td></tr>" for c in ex.checks) if png else ""
    body = (f"<div class='grader-verdict' style='border-left:4px solid {'#2a2' if ex.score >= ex.max_score else '#c33'};"
            f"padding:4px 10px;margin:6px 0'><b>Grader: {html.escape(label)}: {ex.score:g} / {ex.max_score:g} points"
            f"</b><br>{html.escape(ex.message)}"
            + (f"<table style='font-size:90%'>{rows}</table>" if rows else "") + "</div>")
    outputs = [nbformat.v4.new_output("display_data", data={"text/html": body})]
    if png:
        outputs.append(nbformat.v4.new_output("display_data", data={"image/png": base64.b64encode(png).decode()}))
    cell = nbformat.v4.new_code_cell("", metadata={"tags": ["grader-verdict"]})
    cell.outputs = outputs
    return cell


WIDGET = "application/vnd.jupyter.widget-view+json"
TEMPLATES = Path(__file__).resolve().parents[1] / "templates"


def machine_paths(extra: dict[str, str] | None = None) -> list[tuple[str, str]]:
    """The grading machine's paths and the neutral names a page shows instead, longest first."""
    kit = Path(__file__).resolve().parents[2]
    names = {sysconfig.get_paths()["purelib"]: "<site-packages>", sysconfig.get_paths()["platlib"]: "<site-packages>",
             sys.prefix: "<python>", sys.base_prefix: "<python>", sys.exec_prefix: "<python>",
             str(kit): "<snakekit>", os.path.expanduser("~"): "~", **(extra or {})}
    pairs = {}
    for path, name in names.items():
        if path and len(path) > 1:
            pairs[path] = name
            pairs[os.path.realpath(path)] = name
    return sorted(pairs.items(), key=lambda kv: -len(kv[0]))


def neutral(text: str, paths: list[tuple[str, str]]) -> str:
    """``text`` with every machine path in ``paths`` replaced by its neutral name.

    >>> neutral("File /opt/venv/lib/x.py, line 3", [("/opt/venv", "<python>")])
    'File <python>/lib/x.py, line 3'
    """
    for path, name in paths:
        if path in text:
            text = text.replace(path, name)
    return text


def _neutral_output(out, paths):
    if "text" in out:
        out["text"] = neutral("".join(out["text"]) if isinstance(out["text"], list) else out["text"], paths)
    if "traceback" in out:
        out["traceback"] = [neutral(str(line), paths) for line in out["traceback"]]
    if "evalue" in out:
        out["evalue"] = neutral(str(out["evalue"]), paths)
    for mime, v in list(out.get("data", {}).items()):
        if mime.startswith("text/") and isinstance(v, str | list):
            out["data"][mime] = neutral("".join(v) if isinstance(v, list) else v, paths)
    return out


def _widget_line(out):
    """One line in place of an interactive widget (its model lives only in a running kernel)."""
    plain = out.get("data", {}).get("text/plain", "")
    plain = "".join(plain) if isinstance(plain, list) else str(plain)
    m = re.match(r"\s*([A-Za-z_]\w*)\(", plain)
    kind = f" ({m.group(1)})" if m else ""
    return nbformat.v4.new_output("stream", name="stdout",
                                  text=f"[an interactive widget{kind}: it works in the running notebook, not in this page]\n")


def _scrub(cell, secret: set[str], paths=()) -> None:
    """A code cell's outputs made fit for the page: hidden test code, widgets, machine paths, TeX."""
    if cell.cell_type != "code":
        return
    keep = []
    for out in cell.get("outputs", []):
        text = "".join(out.get("text", "")) + "".join(out.get("traceback", []))
        for v in out.get("data", {}).values():
            text += v if isinstance(v, str) else "".join(v) if isinstance(v, list) else ""
        if any(line in text for line in secret):
            keep.append(nbformat.v4.new_output("stream", name="stdout", text=REMOVED + "\n"))
            continue
        data = out.get("data", {})
        if WIDGET in data:
            keep.append(_widget_line(out))
            continue
        if "text/latex" in data and not {"text/html", "image/png", "image/svg+xml"} & set(data):
            latex = "".join(data["text/latex"]) if isinstance(data["text/latex"], list) else str(data["text/latex"])
            out = nbformat.from_dict(dict(out))
            out["data"] = {"text/html": math_html(latex)}
        keep.append(_neutral_output(nbformat.from_dict(dict(out)), paths) if paths else out)
    cell.outputs = keep


# --- math, typeset when the page is written ---------------------------------------------------

_MATH = re.compile(r"\$\$(.+?)\$\$|\\\[(.+?)\\\]|\$(.+?)\$|\\\((.+?)\\\)", re.S)


@functools.lru_cache(maxsize=4096)
def tex_to_mathml(tex: str, display: bool = False) -> str:
    """TeX as a MathML element (browsers typeset MathML without any script); on TeX it cannot
    read, the TeX itself in a ``<code>``.

    >>> tex_to_mathml("q_1")
    '<math display="inline"><mrow><msub><mi>q</mi><mn>1</mn></msub></mrow></math>'
    """
    from latex2mathml.converter import convert

    clean = re.sub(r"\\\\\[[^\]]*\]", r"\\\\", tex.strip())  # a row break's extra space (\\[2mm]) is not MathML's
    try:
        out = convert(clean, display="block" if display else "inline")
    except Exception:  # noqa: BLE001 - anything latex2mathml cannot read stays readable TeX
        return f"<code class='grader-tex'>{html.escape(tex)}</code>"
    return out.replace(' xmlns="http://www.w3.org/1998/Math/MathML"', "")


def math_html(latex: str) -> str:
    """A ``text/latex`` output (``$...$``, ``$$...$$``, ``\\[...\\]``) as HTML with MathML."""
    parts, last = [], 0
    for m in _MATH.finditer(latex):
        parts.append(html.escape(latex[last:m.start()]))
        block = m.group(1) is not None or m.group(2) is not None
        parts.append(tex_to_mathml(next(g for g in m.groups() if g is not None), block))
        last = m.end()
    if not parts:
        return tex_to_mathml(latex, True)
    parts.append(html.escape(latex[last:]))
    return "".join(parts)


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
                cells.append(_verdict_cell(by_id[gid], gid, plots.get(gid)))
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
            cells.append(nbformat.v4.new_markdown_cell(f"**Test cell `{gid}` was missing from your notebook.**"))
            cells.append(_verdict_cell(ex, gid, plots.get(gid)))
    head = head or (f"# Feedback: {assignment}\n\nStudent: `{student}`. Score: **{result.score:g} / {result.max_score:g}**"
            + (f" ({result.status})" if result.status != "graded" else "") + "\n\n"
            + (f"{result.detail}\n\n" if result.detail else "")
            + "| exercise | points | |\n|---|---|---|\n"
            + "".join(f"| `{e.grade_id}` | {e.score:g} / {e.max_score:g} | {'ok' if e.score >= e.max_score else 'see below'} |\n"
                      for e in result.exercises))
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
                                  "plot": base64.b64encode(png).decode() if png else ""}
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
                                               f" ({html.escape(result.detail)})</div>")
            shown["metadata"] = {RECORD: True}
            cell.outputs.append(shown)
    return nb


def recorded(nb):
    """What :func:`record` kept in ``nb``: ``(status, detail, stopped, timeout, exercises, plots)``, or None.

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
            exercises.append(ExerciseScore(str(gid), float(e["score"]), float(e["max_score"]), str(e["status"]),
                                           str(e["message"]), checks))
            if e["plot"]:
                plots[str(gid)] = base64.b64decode(e["plot"])
        stopped = rec.get("stopped")
        return (str(rec["status"]), str(rec["detail"]), stopped if isinstance(stopped, int) else None,
                float(rec["timeout"]) if rec.get("timeout") is not None else None, exercises, plots)
    except (TypeError, KeyError, ValueError, AttributeError):
        return None


_exporters = threading.local()


def _memo(fn, size: int = 4096):
    """``fn`` of strings with its recent results kept (each feedback page repeats the lesson's cells)."""
    import functools

    cached = functools.lru_cache(maxsize=size)(lambda args, kw: fn(*args, **dict(kw)))

    def call(*args, **kw):
        key = tuple(sorted((k, _frozen(v)) for k, v in kw.items()))
        try:
            hash((args, key))
        except TypeError:  # an argument that cannot be a key
            return fn(*args, **kw)
        return cached(args, key)
    return call


def _frozen(v):
    if isinstance(v, dict):
        return tuple(sorted((k, _frozen(x)) for k, x in v.items()))
    if isinstance(v, list | set):
        return tuple(_frozen(x) for x in v)
    return v


def exporter_config():
    """nbconvert's settings for a feedback page: the verdict cells show their output only, no prompts,
    and the page template loads nothing from the network."""
    from traitlets.config import Config

    c = Config()
    c.HTMLExporter.extra_template_basedirs = [str(TEMPLATES)]
    c.HTMLExporter.template_name = "snakekit_feedback"
    c.TagRemovePreprocessor.remove_input_tags = {"grader-verdict"}
    c.TagRemovePreprocessor.enabled = True
    c.HTMLExporter.exclude_input_prompt = True
    c.HTMLExporter.exclude_output_prompt = True
    c.HTMLExporter.optimistic_validation = True  # the notebook validated once, not after each of a dozen steps
    return c


def exporter_class():
    """nbconvert's HTML exporter, with the math of markdown cells written as MathML."""
    from jinja2 import pass_context
    from nbconvert import HTMLExporter
    from nbconvert.filters.markdown_mistune import IPythonRenderer, MarkdownWithMath

    class MathMLRenderer(IPythonRenderer):
        def block_math(self, body: str) -> str:
            return tex_to_mathml(body, True)

        def inline_math(self, body: str) -> str:
            return tex_to_mathml(body, False)

        def latex_environment(self, name: str, body: str) -> str:
            return tex_to_mathml(f"\\begin{{{name}}}{body}\\end{{{name}}}", True)

    class FeedbackPageExporter(HTMLExporter):
        @pass_context
        def markdown2html(self, context, source):
            cell = context.get("cell", {})
            attachments = cell.get("attachments", {})
            path = context.get("resources", {}).get("metadata", {}).get("path", "")
            # every page of a class repeats the lesson's text: each cell is rendered once
            key = (source, path, repr(_frozen(attachments)))
            memo = self.__dict__.setdefault("_markdown_memo", OrderedDict())
            if key in memo:
                memo.move_to_end(key)
                return memo[key]
            renderer = MathMLRenderer(
                escape=False, attachments=attachments, embed_images=self.embed_images, path=path,
                anchor_link_text=self.anchor_link_text, exclude_anchor_links=self.exclude_anchor_links,
                **self.lexer_options)
            memo[key] = out = MarkdownWithMath(renderer=renderer).render(source)
            if len(memo) > 2048:
                memo.popitem(last=False)
            return out

        def from_notebook_node(self, nb, resources=None, **kw):
            body, resources = html_page(self, nb, resources, **kw)
            # the page's style sheets credit web pages in comments; a page with no address in it is simpler to check
            return _STYLE.sub(lambda m: _CSS_COMMENT.sub(lambda c: "" if "http" in c.group(0) else c.group(0),
                                                         m.group(0)), body), resources

    return FeedbackPageExporter


_STYLE = re.compile(r"<style[^>]*>.*?</style>", re.S)
_CSS_COMMENT = re.compile(r"/\*.*?\*/", re.S)


def page_exporter():
    """One HTML exporter per thread (its templates load once; an exporter is not shared between threads).

    Every page of a class shows the same lesson text and test cells, so the exporter keeps
    the results of its per-cell filters (syntax highlighting, HTML sanitising, markdown) for reuse.
    """
    if not hasattr(_exporters, "html"):
        from nbconvert.filters.highlight import Highlight2HTML

        class FeedbackExporter(exporter_class()):
            def default_filters(self):
                for name, fn in super().default_filters():
                    yield name, (_memo(fn) if name == "clean_html" else fn)

        exporter = FeedbackExporter(config=exporter_config())
        # the feedback notebook's language is Python (build() sets it), so one highlighter serves every page
        exporter.filters = {**exporter.filters, "highlight_code": _memo(Highlight2HTML(pygments_lexer="python",
                                                                                      parent=exporter))}
        _exporters.html = exporter
    return _exporters.html


def write_html(nb, path: Path) -> Path:
    """Render the feedback notebook to one self-contained HTML file (images inline)."""
    body, _ = page_exporter().from_notebook_node(nb)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(body, encoding="utf-8")
    return path
