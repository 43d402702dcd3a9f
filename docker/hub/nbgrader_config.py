"""nbgrader in snakekit's image (/etc/jupyter/nbgrader_config.py): on a hub's server, the
class's course id and the exchange through the hub's exchange service, which knows each user
by their hub token (grader/lms/hub_exchange.py). Outside a hub (no JUPYTERHUB_API_TOKEN in the
environment) it changes nothing."""
import os

c = get_config()  # noqa: F821 (nbgrader provides it)
if os.environ.get("JUPYTERHUB_API_TOKEN"):
    from grader.lms.hub_exchange import use_hub_exchange

    c.CourseDirectory.course_id = os.environ.get("SNAKEKIT_COURSE_ID", "snakekit")
    if os.environ.get("SNAKEKIT_ROLE") != "instructor":
        # a student is who the hub says (every server runs as the same unix user, "student");
        # the exchange service checks it against the token anyway
        c.CourseDirectory.student_id = os.environ.get("JUPYTERHUB_USER", "")
    # what was submitted (and its secret, which finds the feedback) stays in the student's
    # volume, not in the container that goes when the server stops
    c.Exchange.cache = os.path.join(os.path.expanduser("~/work"), ".nbgrader_cache")
    use_hub_exchange(c)
