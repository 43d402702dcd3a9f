"""The grader's entry points: ``snakekit grade`` (:mod:`.grade`), ``snakekit lab`` (:mod:`.lab`) and
nbgrader's plug-ins (:mod:`.nbgrader_plugins`, called from a course's ``nbgrader_config.py``).
Only this layer brings in the arm's lab (:mod:`grader.arm`)."""
