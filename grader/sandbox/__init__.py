"""Running a submission in a sandbox: namespaces and limits, the batch's runner, the warm fork server.

:mod:`grader.sandbox.inside` is what runs beside the student's code."""
