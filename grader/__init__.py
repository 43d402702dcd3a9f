"""The autograder: nbgrader's autograde in parallel sandboxes, scored against reference runs.

Modules: :mod:`grader.compare` (trajectory and value checks), :mod:`grader.references`
(reference files), :mod:`grader.score` (a hand-in against its reference),
:mod:`grader.sandbox` (namespaces and limits), :mod:`grader.batch` (a class),
:mod:`grader.feedback` (HTML without hidden tests), :mod:`grader.cli` (``snakekit grade``).
See grader/README.md.
"""
