"""A message that points at a cell names it as a student finds it in JupyterLab (snakekit.cells.cell_name): by its
exercise, else as "code cell N" counting code cells only, with its first line; never by its index among all cells,
markdown ones included, which JupyterLab shows nowhere."""

from pathlib import Path

import pytest

from snakekit.cells import cell_name
from tests.conftest import need

ROOT = Path(__file__).resolve().parents[2]
LESSONS = sorted((ROOT / "notebooks").glob("0*.ipynb"))


def test_a_code_cell_after_markdown_is_counted_among_code_cells_and_shown_by_its_first_line():
    from nbformat.v4 import new_code_cell, new_markdown_cell

    cells = [new_markdown_cell("# Lesson"), new_code_cell("import numpy as np"), new_markdown_cell("## Part 2"),
             new_markdown_cell("Some text."), new_code_cell("\n# the demonstration\nrun = robot.run(sweep)")]
    assert cell_name(cells, 4) == "code cell 2 (the one that starts `# the demonstration`)"   # not "cell 5"
    assert cell_name(cells, 1) == "code cell 1 (the one that starts `import numpy as np`)"


def test_an_exercise_cell_is_named_by_its_exercise():
    from nbformat.v4 import new_code_cell, new_markdown_cell

    answer, check = new_code_cell("def f(x):\n    return x"), new_code_cell("ex.done()")
    answer.metadata["nbgrader"] = {"grade_id": "ex06_2_sweep_positions", "solution": True, "grade": False}
    check.metadata["nbgrader"] = {"grade_id": "ex06_2_sweep_positions_test", "solution": False, "grade": True}
    cells = [new_markdown_cell("### Exercise 6.2"), answer, check]
    assert (cell_name(cells, 1), cell_name(cells, 2)) == ("the answer cell of exercise 6.2", "the check cell of exercise 6.2")


@pytest.mark.parametrize("path", LESSONS, ids=lambda p: p.stem)
def test_every_code_cell_of_a_lesson_has_a_name_of_its_own(path):
    nb = need("nbformat").read(path, as_version=4)
    names = [cell_name(nb.cells, i) for i, c in enumerate(nb.cells) if c.cell_type == "code"]
    assert len(set(names)) == len(names), [n for n in names if names.count(n) > 1]
    code = 0
    for i, c in enumerate(nb.cells):
        code += c.cell_type == "code"
        if c.cell_type == "code" and not c.metadata.get("nbgrader", {}).get("grade_id"):
            assert cell_name(nb.cells, i).startswith(f"code cell {code} ("), (i, cell_name(nb.cells, i))
