"""What a student must not see, taken out of a feedback notebook's outputs.

Not trusted to nbgrader (whose feedback keeps the hidden tests, its issue #917): an output that
repeats a line of hidden test code is replaced by one line saying so (:func:`scrub_cell`); an
interactive widget, and an output that would load an address when the page opens (the live
3D view's iframe, served by the kernel that graded it), become one line saying what they were
(they live only in a running kernel); the grading machine's paths in tracebacks and outputs (the sandbox's folder, the Python
installation, the kit, the home folder) are replaced by neutral names (:func:`neutral`); a TeX
output becomes MathML (:mod:`grader.feedback.mathml`). A failed test cell is said to have failed
in its visible or its hidden part, never where in the hidden part (:func:`cell_error`).

This module draws nothing: the plots are :mod:`grader.feedback.plot`'s.
"""

from __future__ import annotations

import os
import re
import sys
import sysconfig
from pathlib import Path

import nbformat

from snakekit.errors import whole_sentences

from grader.feedback.mathml import math_html
from grader.markup import HIDDEN, first_hidden_line

REMOVED = "[output removed by the grader: it showed hidden test code]"

#: An element that loads an address when the page opens (a page loads nothing: it works offline)
LOADS = re.compile(r"<(script|link|iframe|img)[^>]+(src|href)=[\"'](?!data:)", re.IGNORECASE)

_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def strip_ansi(text: str) -> str:
    """``text`` without the terminal colours of a traceback.

    >>> strip_ansi("\x1b[0;31mKeyboardInterrupt\x1b[0m: ")
    'KeyboardInterrupt: '
    """
    return _ANSI.sub("", text)


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
    evalue = whole_sentences(_ANSI.sub("", str(err.get("evalue", ""))))
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


WIDGET = "application/vnd.jupyter.widget-view+json"


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


#: The file a kernel gives a cell's code in a traceback (``/tmp/ipykernel_4242/3140725618.py``), and a folder
#: made by ``tempfile`` (``/tmp/tmpk2_x9q0a``): the grading machine's, wherever its temporary folder is
KERNEL_CELL = re.compile(r"(?:/[\w.-]+)*/ipykernel_\d+/\d+\.py")
TEMP_FOLDER = re.compile(r"(?:/[\w.-]+)*/tmp[a-z0-9_]{8}(?![\w.-])")


def neutral(text: str, paths: list[tuple[str, str]]) -> str:
    """``text`` with every machine path in ``paths`` replaced by its neutral name, a cell's file by
    ``<notebook cell>`` and a temporary folder by ``<temporary folder>``.

    >>> neutral("File /opt/venv/lib/x.py, line 3", [("/opt/venv", "<python>")])
    'File <python>/lib/x.py, line 3'
    >>> neutral("File /tmp/ipykernel_4242/3140725618.py:7, in read_joint_states(path)", [])
    'File <notebook cell>:7, in read_joint_states(path)'
    >>> neutral("/var/tmp/tmpk2_x9q0a/recorded.bag holds no /joint_states messages", [])
    '<temporary folder>/recorded.bag holds no /joint_states messages'
    """
    for path, name in paths:
        if path in text:
            text = text.replace(path, name)
    return TEMP_FOLDER.sub("<temporary folder>", KERNEL_CELL.sub("<notebook cell>", text))


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


def _loading_line(html: str):
    """One line in place of an output that would load an address (the live 3D view's iframe)."""
    what = "the 3D view" if "snakekit 3D view" in html else "an output that loads an address"
    return nbformat.v4.new_output("stream", name="stdout",
                                  text=f"[{what}: it works in the running notebook, not in this page]\n")


#: The one line of a run's summary (:meth:`snakekit.Run.summary`) that is not a fact of the submission: how long
#: the grading machine took. A page shows the line without it, so a regrade writes the same page.
WALL_TIME = re.compile(r"^(wall time:\s*)\d[\d.]* s \([\d.]+x real time\)$", re.MULTILINE)
WALL_TIME_SAID = r"\1(left out of this page: it is the grading machine's, and differs from run to run)"


def steady(text: str) -> str:
    r"""``text`` without what differs each time the same notebook runs (:data:`WALL_TIME`).

    >>> steady("robot time:         49.90 s\nwall time:          0.73 s (68.4x real time)\n")
    "robot time:         49.90 s\nwall time:          (left out of this page: it is the grading machine's, and differs from run to run)\n"
    """
    return WALL_TIME.sub(WALL_TIME_SAID, text)


def scrub_cell(cell, secret: set[str], paths=()) -> None:
    """A code cell's outputs made fit for the page: hidden test code, widgets, machine paths, TeX, the
    grading machine's timing (:func:`steady`)."""
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
        html = data.get("text/html", "")
        html = "".join(html) if isinstance(html, list) else str(html)
        if LOADS.search(html):
            keep.append(_loading_line(html))
            continue
        if "text/latex" in data and not {"text/html", "image/png", "image/svg+xml"} & set(data):
            latex = "".join(data["text/latex"]) if isinstance(data["text/latex"], list) else str(data["text/latex"])
            out = nbformat.from_dict(dict(out))
            out["data"] = {"text/html": math_html(latex)}
        if out.get("output_type") == "stream":
            text = "".join(out["text"]) if isinstance(out.get("text"), list) else str(out.get("text", ""))
            if WALL_TIME.search(text):
                out = nbformat.from_dict({**dict(out), "text": steady(text)})
        keep.append(_neutral_output(nbformat.from_dict(dict(out)), paths))
    cell.outputs = keep

