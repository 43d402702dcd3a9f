"""nbgrader configuration of the snakekit course (the course root is this folder).

Instructor versions live in source/<assignment>/<assignment>.ipynb; `make student` turns them
into the student versions in ../notebooks/ (see tools/generate_student and README.md).
"""

import os
import re

from nbgrader.preprocessors import (
    CheckCellMetadata, ClearHiddenTests, ClearMarkScheme, ClearOutput, ClearSolutions, ComputeChecksums,
    IncludeHeaderFooter, InstantiateTests, LockCells, NbGraderPreprocessor, SaveCells,
)

c = get_config()  # noqa: F821 (nbgrader provides it)

HERE = os.path.dirname(os.path.abspath(__file__))

c.CourseDirectory.root = HERE
c.CourseDirectory.course_id = "snakekit"
c.CourseDirectory.db_url = "sqlite:///" + os.path.join(HERE, "gradebook.db")

# A cell may run the simulator or the bus emulator for a few seconds; the default 30 s per
# cell leaves no margin on a busy machine.
c.ExecutePreprocessor.timeout = 120
c.Execute.timeout = 120


class ClearAnswers(NbGraderPreprocessor):
    """Remove the expected answers of "predict, then run" questions from the student version.

    In a markdown cell, everything between ``<!-- BEGIN ANSWER -->`` and ``<!-- END ANSWER -->``
    is for the instructor only.
    """

    pattern = re.compile(r"\n?<!-- BEGIN ANSWER -->.*?<!-- END ANSWER -->\n?", re.S)

    def preprocess_cell(self, cell, resources, index):
        if cell.cell_type == "markdown" and "BEGIN ANSWER" in cell.source:
            cell.source = self.pattern.sub("\n", cell.source).strip()
            if "<!-- BEGIN ANSWER" in cell.source or "<!-- END ANSWER" in cell.source:
                raise RuntimeError(f"unbalanced ANSWER markers in a markdown cell:\n{cell.source[:300]}")
        return cell, resources


class NameStubs(NbGraderPreprocessor):
    """Make each stub say which exercise it is: ``NotImplementedError("exercise 1.1: planar_fk")``.

    The exercise number comes from the grade id (``ex01_1_planar_fk`` -> 1.1), the name from
    the first ``def`` (or assignment) in the answer cell.
    """

    def preprocess_cell(self, cell, resources, index):
        meta = cell.metadata.get("nbgrader", {})
        if cell.cell_type == "code" and meta.get("solution") and "raise NotImplementedError()" in cell.source:
            m = re.match(r"ex(\d+)_(\d+)_", meta.get("grade_id", ""))
            name = re.search(r"^\s*def (\w+)|^(\w+)\s*=", cell.source, re.M)
            if m:
                label = f"exercise {int(m.group(1))}.{m.group(2)}"
                if name:
                    label += f": {name.group(1) or name.group(2)}"
                cell.source = cell.source.replace("raise NotImplementedError()", f'raise NotImplementedError("{label}")')
        return cell, resources


c.GenerateAssignment.preprocessors = [
    IncludeHeaderFooter, InstantiateTests, LockCells, ClearSolutions, NameStubs, ClearAnswers, ClearOutput,
    CheckCellMetadata, ComputeChecksums, SaveCells, ClearHiddenTests, ClearMarkScheme, ComputeChecksums,
    CheckCellMetadata,
]

# nbgrader's generate_feedback and formgrader's Generate Feedback and Autograde buttons give
# the grader's results: its safe pages and its sandboxed grading (see grader/README.md).
from grader.commands.nbgrader_plugins import use_safe_grading  # noqa: E402

use_safe_grading(c)

# What a run of an instructor notebook writes beside it (a 3D scene, a saved run, a plot, a
# table) is never released, nor part of what a reference was recorded from (grader/course/folder.py,
# source_hash): an instructor may run the notebook in its folder (lesson 8 records a bag there).
c.CourseDirectory.ignore = [".ipynb_checkpoints", "*.pyc", "__pycache__", "feedback", "*.html", "*.npz", "*.png", "*.csv",
                              "*.bag", "*.mcap"]
