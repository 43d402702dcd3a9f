"""The lab: graded runs of the students' Task 2 on the real arm (``snakekit lab``).

:mod:`.jobs` (the course's lab settings, the queue in ``<course>/lab/<a>/queue.json``),
:mod:`.gate` (each trajectory checked in the simulator, outside the student's code),
:mod:`.session` (calibration, the runs on the arm, the grades and result folders),
:mod:`.feedback` (the lab's result in the student's feedback page),
:mod:`.lock` (one session per course and per arm),
The command is :mod:`grader.commands.lab`. docs/lab.md is the TA's guide.
"""
