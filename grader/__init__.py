"""The trajectory autograder (not built yet; see grader/README.md)."""
