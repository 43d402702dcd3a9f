"""The course folder: nbgrader's configuration and gradebook, an assignment's release and its test cells."""

from .schema import install as _install_schema

_install_schema()  # a new gradebook's schema version read in this process (grader.course.schema)
