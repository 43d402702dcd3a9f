"""The course folder: nbgrader's configuration and gradebook, an assignment's release and its test cells."""
