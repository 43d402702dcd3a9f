"""Every line of a check's message reaches the student whole: through nbgrader's Validate (its
validator cuts a line longer than its width, 90 columns less indent, and ends it with "...") and
through ``snakekit check`` (its rows and its "also failed" lines).

The messages are each lesson's longest: the longest message text and the longest hint its
check cells hold (the literal text of ``ex.fail``/``ex.true``/``ex.close``/``ex.raises`` and of
the ``mistakes`` hints, an f-string's fields filled with a number). One notebook carries them
all, each in a graded cell as the lesson's exercise would raise it, and once more in a
demonstration cell that waits for the exercise (the "also failed" lines of ``snakekit check``).
"""

from __future__ import annotations

import ast
import io
import json
import os
import re
import sys
from pathlib import Path

import pytest

from tests.conftest import need

ROOT = Path(__file__).resolve().parents[2]
LESSONS = sorted(p.name for p in (ROOT / "course" / "source").iterdir() if (p / f"{p.name}.ipynb").exists())
ANSI = re.compile(r"\x1b\[[0-9;]*m")


def _text(node) -> str | None:
    """The text of a string literal (an f-string's fields as a number), else None."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(v.value if isinstance(v, ast.Constant) else "0.1234" for v in node.values)
    return None


def longest_messages(name: str) -> tuple[str, str, str]:
    """(exercise number, the longest message, the longest hint) of the check cells of lesson ``name``."""
    nb = json.loads((ROOT / "course" / "source" / name / f"{name}.ipynb").read_text())
    messages, hints, number = [""], [""], None
    for cell in nb["cells"]:
        meta = cell.get("metadata", {}).get("nbgrader", {})
        if cell["cell_type"] != "code" or not meta.get("grade"):
            continue
        m = re.match(r"ex(\d+)_(\d+)_", meta["grade_id"])
        number = number or f"{int(m.group(1))}.{m.group(2)}"
        source = "\n".join(line for line in "".join(cell["source"]).splitlines() if not line.lstrip().startswith("%"))
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and \
                    node.func.attr in ("fail", "true", "close", "raises"):
                texts = [t for t in map(_text, node.args) if t]
                if node.func.attr == "fail" and texts:
                    messages.append(texts[0])
                    hints += texts[1:]
                elif node.func.attr == "true" and len(node.args) >= 2:
                    messages += [t for t in [_text(node.args[1])] if t]
                    hints += [t for t in map(_text, node.args[2:]) if t]
                kws = {kw.arg: _text(kw.value) for kw in node.keywords}
                if node.func.attr == "close":   # the message close() builds, in its shape
                    unit = kws.get("unit") or "m"
                    where = f" at {kws['where']}" if kws.get("where") else ""
                    messages.append(f"{kws.get('what') or 'value'}{where} is 0.1234 {unit}, expected 0.1234 {unit}: "
                                    f"off by 1.234 {unit} (tolerance 0.1234 {unit}: "
                                    f"{kws.get('why') or 'exact math, 1e-9 relative'}).")
                if node.func.attr == "raises":  # the message raises() builds when nothing is raised
                    messages.append(f"`name` returned a result when called with {kws.get('where') or '0.1234'}, raising nothing; "
                                    f"{kws.get('why') or ''}: raise a ValueError there (`raise ValueError(\"...\")`, "
                                    "saying why).")
                for kw in node.keywords:
                    if kw.arg == "mistakes" and isinstance(kw.value, ast.Dict):
                        hints += [t for t in map(_text, kw.value.keys) if t]
            if isinstance(node, ast.Dict):   # hint tables built before the call
                hints += [t for t in map(_text, node.keys) if t and len(t) > 40]
    return number, max(messages, key=len), max(hints, key=len)


def words(text: str) -> str:
    return " ".join(ANSI.sub("", text).split())


@pytest.fixture(scope="module")
def notebook(tmp_path_factory):
    """A notebook whose graded cells fail with each lesson's longest message and hint, and whose
    demonstration cells stop with them (what ``snakekit check`` lists as "also failed")."""
    nbformat = need("nbformat")
    folder = tmp_path_factory.mktemp("whole")
    # the messages come from a file, so that the cells' own sources stay short (Validate shows them too)
    cells, expected, said = [nbformat.v4.new_code_cell("import json\nfrom snakekit import checks\n"
                                                       "SAID = json.load(open('said.json'))")], {}, {}
    for name in LESSONS:
        number, message, hint = longest_messages(name)
        expected[name] = (f"exercise {number} {name}: {message}", hint)
        said[name] = [number, message, hint]
        cell = nbformat.v4.new_code_cell(f"n, m, h = SAID[{name!r}]\nchecks.Exercise(n, {name!r}).fail(m, h)")
        gid = f"ex{number.replace('.', '_')}_{name}_test"
        cell.metadata["nbgrader"] = {"grade": True, "grade_id": gid, "points": 1, "solution": False,
                                     "locked": True, "schema_version": 3}
        cells.append(cell)
        cells.append(nbformat.v4.new_code_cell(f"n, m, h = SAID[{name!r}]\nwith checks.waiting_for(n):\n"
                                               "    raise ValueError(m + ' ' + h)"))
    (folder / "said.json").write_text(json.dumps(said))
    nb = nbformat.v4.new_notebook(cells=cells)
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    path = folder / "messages.ipynb"
    nbformat.write(nb, path)
    return path, expected


def test_the_longest_messages_are_long_enough_to_be_cut():
    """Each lesson's longest message and hint are found, and are longer than nbgrader's line."""
    for name in LESSONS:
        number, message, hint = longest_messages(name)
        assert re.fullmatch(r"\d\.\d", number), name
        assert len(message) > 90 and len(hint) > 60, (name, message, hint)


def test_validate_shows_every_line_of_each_lessons_longest_message_whole(notebook, monkeypatch):
    need("nbgrader")
    from nbgrader.validator import Validator

    path, expected = notebook
    monkeypatch.setenv("PATH", f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
    out = io.StringIO()
    validator = Validator()
    validator.stream = out
    validator.validate_and_print(str(path))
    shown = out.getvalue()
    assert f"VALIDATION FAILED ON {len(LESSONS)} CELL(S)" in words(shown), shown[:2000]
    cut = [line for line in shown.splitlines() if line.endswith("...")]
    assert cut == [], "nbgrader cut these lines:\n" + "\n".join(cut)
    for name, (message, hint) in expected.items():
        assert words(f"Check failed: {message} Hint: {hint}") in words(shown), (name, message, shown[:3000])


def test_snakekit_check_shows_every_line_of_each_lessons_longest_message_whole(notebook):
    from snakekit.notebook_check import check_notebook

    path, expected = notebook
    out = io.StringIO()
    assert check_notebook(path, out=out) == 1
    shown = out.getvalue()
    assert f"0 of {len(LESSONS)} exercises passed" in shown, shown
    for name, (message, hint) in expected.items():
        rows = shown.split("also failed")[0]
        assert words(f"{message} Hint: {hint}") in words(rows), (name, message, shown)
        # the demonstration cell that waits for the exercise: its whole message, not 120 characters of it
        number = message.split()[1]
        also = [block for block in shown.split("  also failed: ")[1:] if f"exercise {number}," in block]
        assert len(also) == 1 and words(f"{message.split(': ', 1)[1]} {hint}") in words(also[0]), (name, shown)
