"""The course folder: nbgrader's configuration and gradebook, an assignment's release, nbgrader's plug-ins."""
