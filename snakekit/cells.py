"""A notebook's cell named as a student finds it in JupyterLab, in every message that points at one.

JupyterLab numbers no cell, and a notebook's list of cells holds its markdown cells too: "cell 17"
counted over all of them points a student at a cell they cannot find. A cell of an exercise is named
by the exercise (its nbgrader grade id: ``ex03_1_two_link_ik_test`` is exercise 3.1's check cell);
any other code cell as "code cell N", counting code cells only, with its first line to look for.

>>> cells = [{"cell_type": "markdown", "source": "# Lesson"},
...          {"cell_type": "code", "source": "import numpy as np\\nx = 1", "metadata": {}},
...          {"cell_type": "markdown", "source": "### Exercise 3.1"},
...          {"cell_type": "code", "source": "def f():\\n    pass",
...           "metadata": {"nbgrader": {"grade_id": "ex03_1_two_link_ik", "solution": True}}},
...          {"cell_type": "code", "source": "ex.done()",
...           "metadata": {"nbgrader": {"grade_id": "ex03_1_two_link_ik_test", "grade": True}}},
...          {"cell_type": "code", "source": "\\n\\nwhile True:\\n    pass", "metadata": {}}]
>>> for i in (1, 3, 4, 5):
...     print(cell_name(cells, i))
code cell 1 (the one that starts `import numpy as np`)
the answer cell of exercise 3.1
the check cell of exercise 3.1
code cell 4 (the one that starts `while True:`)
"""

from __future__ import annotations

import re

__all__ = ["cell_name"]

#: A grade id of the course (``ex03_1_two_link_ik``, ``ex03_1_two_link_ik_test``): the exercise's number.
EXERCISE_ID = re.compile(r"ex0*(\d+)_(\d+)_\w+$")


def _get(cell, key, default=None):
    return cell.get(key, default) if isinstance(cell, dict) else getattr(cell, key, default)


def cell_name(cells, index: int) -> str:
    """The cell at ``index`` of ``cells`` (a notebook's cells, markdown ones included), as a student finds it:
    its exercise's answer or check cell, a graded cell of another id by that id, else "code cell N" counting
    code cells only, with the first line it starts with."""
    cell = cells[index]
    meta = (_get(cell, "metadata") or {}).get("nbgrader", {}) or {}
    gid = meta.get("grade_id")
    if _get(cell, "cell_type") == "code" and isinstance(gid, str) and gid:
        m = EXERCISE_ID.match(gid)
        role = "check cell" if meta.get("grade") or gid.endswith("_test") else "answer cell"
        return f"the {role} of exercise {m.group(1)}.{m.group(2)}" if m else f"the {role} {gid}"
    if _get(cell, "cell_type") != "code":
        return f"the text cell before code cell {sum(_get(c, 'cell_type') == 'code' for c in cells[:index]) + 1}"
    number = sum(_get(c, "cell_type") == "code" for c in cells[:index + 1])
    source = _get(cell, "source") or ""
    source = "".join(source) if isinstance(source, list) else source
    first = next((line.strip() for line in source.splitlines() if line.strip()), "")
    if not first:
        return f"code cell {number} (an empty one)"
    return f"code cell {number} (the one that starts `{first[:60]}{'...' if len(first) > 60 else ''}`)"
