"""The old dotted name of :mod:`grader.commands.nbgrader_plugins`, kept for course folders made
before the grader's sub-packages: their ``nbgrader_config.py`` says
``from grader.nbgrader_plugins import use_safe_grading``. New course folders use the new name."""

from grader.commands.nbgrader_plugins import use_safe_grading  # noqa: F401
