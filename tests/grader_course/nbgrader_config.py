c = get_config()
c.CourseDirectory.course_id = "snakekit-test-course"

# What a run of an instructor notebook writes beside it (a 3D scene, a saved run, a plot, a
# table) is never released, nor part of what a reference was recorded from (grader/course/folder.py,
# source_hash): an instructor may run the notebook in its folder.
c.CourseDirectory.ignore = [".ipynb_checkpoints", "*.pyc", "__pycache__", "feedback", "*.html", "*.npz", "*.png", "*.csv"]
