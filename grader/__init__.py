"""The autograder: nbgrader's autograde in parallel sandboxes, scored against reference runs.

Modules: :mod:`grader.scoring.compare` (trajectory and value checks), :mod:`grader.scoring.references`
(reference files), :mod:`grader.scoring.score` (a hand-in against its reference),
:mod:`grader.sandbox.namespaces` (namespaces and limits), :mod:`grader.batch` (a class),
:mod:`grader.feedback.report` (HTML without hidden tests), :mod:`grader.commands.grade` (``snakekit grade``).
See grader/README.md.
"""
