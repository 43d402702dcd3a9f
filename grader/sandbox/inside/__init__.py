"""What runs inside the sandbox beside the student's code: the standard library and nbgrader only
(tests/test_architecture.py), no course data and nothing of the grader outside this package."""
