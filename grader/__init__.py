"""The autograder: nbgrader's autograde in parallel sandboxes, scored against reference runs.

Sub-packages, along the pipeline: :mod:`grader.commands` (``snakekit grade``, ``snakekit lab``,
nbgrader's plug-ins), :mod:`grader.lms` (roster, collect, export, return, the hub's exchange),
:mod:`grader.course` (the course folder, an assignment, the gradebook), :mod:`grader.sandbox`
(with :mod:`grader.sandbox.inside`, what runs beside the student's code), :mod:`grader.scoring`
(cases, comparisons, rules, references, verdicts), :mod:`grader.feedback` (what a student sees),
:mod:`grader.report` (the teacher's view of a graded class) and :mod:`grader.arm` (the arm's lab). :mod:`grader.batch` grades a class; :mod:`grader.errors`
holds every exception. docs/architecture.md maps every module; see grader/README.md.
"""
