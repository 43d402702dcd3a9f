"""The class's JupyterHub (docker/hub/up starts it; settings from the environment, defaults here).

- Students' servers: snakekit's image (``SNAKEKIT_IMAGE``), one per student, spawned by
  dockerspawner's SwarmSpawner as swarm services (``SNAKEKIT_SPAWNER=docker``: DockerSpawner,
  plain containers on this engine), on the overlay network ``SNAKEKIT_NETWORK``, with the
  student's own volume ``snakekit-<user>`` as ``~/work``, and memory and CPU limits.
- The exchange: the hub-managed service ``exchange`` (exchange_service.py), which knows
  students by their hub token; the image's nbgrader talks to it (grader.lms.hub_exchange).
- Instructors and TAs: the hub group ``instructors`` (``SNAKEKIT_INSTRUCTORS``, or the admin
  page / REST API later). Their servers run the grader's image (``SNAKEKIT_GRADER_IMAGE``: the
  same with the instructor's course, which students' image leaves out) and also mount the
  course volume ``snakekit-course`` at ``~/course`` (nbgrader's course folder, formgrader on
  it); students' servers never do.
- Idle servers are stopped by jupyterhub-idle-culler (``SNAKEKIT_CULL_TIMEOUT`` s); the
  student's volume stays, so nothing saved is lost.
- Login: ``SNAKEKIT_AUTH=native`` (the default: NativeAuthenticator, a password per person, in
  accounts that only the teacher makes: docker/hub/accounts; no sign-up page), or ``lti`` (an
  LMS course: lti_config.py). Roles come by name: ``SNAKEKIT_INSTRUCTORS``.
- The 3D view: each server's viewers listen on its container's loopback only
  (``SNAKEKIT_VIEWER_HOST=127.0.0.1``, over the image's 0.0.0.0), so the browser reaches them
  through the owner's Jupyter server (jupyter-server-proxy, ``/user/<name>/proxy/<port>/``)
  behind the hub's log-in, and no other container on the network reaches them.
"""

import os
import sys

env = os.environ.get
c = get_config()  # noqa: F821 (JupyterHub provides it)

DATA = env("SNAKEKIT_HUB_DATA", "/srv/data")
IMAGE = env("SNAKEKIT_IMAGE", "snakekit-lab:latest")
GRADER_IMAGE = env("SNAKEKIT_GRADER_IMAGE", "snakekit-grader:latest")  # docker/Dockerfile --target grader
NETWORK = env("SNAKEKIT_NETWORK", "snakekit-hub")
HUB_HOST = env("SNAKEKIT_HUB_HOST", "hub")  # the hub container's name on that network
INSTRUCTORS = [u for u in env("SNAKEKIT_INSTRUCTORS", "").split(",") if u]
EXCHANGE_PORT = 10102
GRADING_PORT = 10103

# --- the hub and its proxy (Debian's configurable-http-proxy, started by the hub) -------------
c.JupyterHub.ip = "0.0.0.0"
c.JupyterHub.port = 8000
c.JupyterHub.hub_ip = "0.0.0.0"
c.JupyterHub.hub_connect_ip = HUB_HOST
c.JupyterHub.db_url = f"sqlite:///{DATA}/jupyterhub.sqlite"
c.JupyterHub.cookie_secret_file = f"{DATA}/jupyterhub_cookie_secret"
c.ConfigurableHTTPProxy.pid_file = f"{DATA}/jupyterhub-proxy.pid"
c.JupyterHub.cleanup_servers = False  # a hub restart leaves the students' servers running
c.JupyterHub.default_url = "/hub/home"

# --- the students' servers ----------------------------------------------------------------------
if env("SNAKEKIT_SPAWNER", "swarm") == "swarm":
    from docker.types import Mount
    from dockerspawner import SwarmSpawner

    class ClassSwarmSpawner(SwarmSpawner):
        """SwarmSpawner, with named volumes: it mounts every volume as a bind of a host folder."""

        @property
        def mounts(self):
            return [Mount(target=v["bind"], source=src, type="bind" if src.startswith("/") else "volume",
                          read_only=v["mode"] == "ro", driver_config=self.mount_driver_config)
                    for src, v in self.volume_binds.items()]

    c.JupyterHub.spawner_class = ClassSwarmSpawner
    # Each server is reached at its task's address (DNS round robin): a service's virtual IP
    # needs the engine's iptables rules (IPVS), which an engine without iptables does not have.
    c.SwarmSpawner.extra_endpoint_spec = {"mode": "dnsrr"}
    # The hub checks that a server answers; the image's own health check would only delay the
    # server's name in the swarm's DNS until it first passes (up to its 5 s interval).
    c.SwarmSpawner.extra_container_spec = {"healthcheck": {"Test": ["NONE"]}}
    c.SwarmSpawner.mem_guarantee = env("SNAKEKIT_MEM_GUARANTEE", "256M")
    c.SwarmSpawner.cpu_guarantee = float(env("SNAKEKIT_CPU_GUARANTEE", "0.05"))
else:
    c.JupyterHub.spawner_class = "dockerspawner.DockerSpawner"
    c.DockerSpawner.remove = True  # the container goes when the server stops; the volume stays
c.DockerSpawner.image = IMAGE
c.DockerSpawner.pull_policy = "never"  # the image is built or loaded on each node beforehand
c.DockerSpawner.network_name = NETWORK
c.DockerSpawner.use_internal_ip = True
c.DockerSpawner.name_template = "snakekit-lab-{username}"
c.DockerSpawner.notebook_dir = "/home/student/work"
c.DockerSpawner.volumes = {"snakekit-{username}": "/home/student/work"}
c.DockerSpawner.mem_limit = env("SNAKEKIT_MEM_LIMIT", "1G")
c.DockerSpawner.cpu_limit = float(env("SNAKEKIT_CPU_LIMIT", "1"))
# a class arriving at once on a small machine: JupyterLab starts slower when many start together
c.DockerSpawner.start_timeout = int(env("SNAKEKIT_START_TIMEOUT", "300"))
c.DockerSpawner.http_timeout = int(env("SNAKEKIT_HTTP_TIMEOUT", "180"))  # from the container's start to JupyterLab answering
c.DockerSpawner.environment = {
    "SNAKEKIT_EXCHANGE_URL": f"http://{HUB_HOST}:{EXCHANGE_PORT}/services/exchange/",
    # the 3D view's servers on the container's loopback: reached only through the owner's Jupyter
    # server (its proxy, behind the hub's log-in), never by another container on the network
    "SNAKEKIT_VIEWER_HOST": "127.0.0.1",
}
# What a server's own token ($JUPYTERHUB_API_TOKEN) may do: its activity, its own server, and
# tell the exchange who it is (name and groups); nothing of anyone else.
# (The grading service, too: it grades only for the instructors' group and refuses the rest.)
c.Spawner.server_token_scopes = ["users:activity!user", "access:servers!server", "access:services!service=exchange",
                                 "access:services!service=grading", "read:users:name!user", "read:users:groups!user"]


def course_for_instructors(spawner):
    """Instructors and TAs get the grader's image (with the course), the course volume and nbgrader's teacher tools."""
    if any(g.name == "instructors" for g in spawner.user.groups):
        spawner.image = GRADER_IMAGE
        spawner.volumes = {**spawner.volumes, "snakekit-course": "/home/student/course"}
        # `snakekit grade` in their terminal asks the hub's grading service (grading_service.py)
        spawner.environment = {**spawner.environment, "SNAKEKIT_ROLE": "instructor",
                               "SNAKEKIT_GRADING_URL": f"http://{HUB_HOST}:{GRADING_PORT}/services/grading/",
                               "SNAKEKIT_HUB_COURSE": "/home/student/course"}


c.Spawner.pre_spawn_hook = course_for_instructors

# --- who may log in -------------------------------------------------------------------------------
AUTH = env("SNAKEKIT_AUTH", "native")
if AUTH == "lti":
    exec(open(os.path.join(os.path.dirname(__file__), "lti_config.py")).read())  # noqa: S102 (our own file)
elif AUTH == "native":
    c.JupyterHub.authenticator_class = "native"
    # Accounts are made by the teacher only (docker/hub/accounts: a first password each): no
    # sign-up page, so no name can be claimed by whoever comes first.
    c.NativeAuthenticator.enable_signup = False
    # a password a student chooses at /hub/change-password: not short, not a common one
    c.NativeAuthenticator.minimum_password_length = 10
    c.NativeAuthenticator.check_common_password = True
    # guessing: ten wrong passwords for a name, then a minute's wait for it
    c.NativeAuthenticator.allowed_failed_logins = 10
    c.NativeAuthenticator.seconds_before_next_try = 60
    # NativeAuthenticator lets in only its own authorized accounts with their password: every
    # account may log in (JupyterHub 5 lets no one in unless told)
    c.Authenticator.allow_all = True
else:
    raise SystemExit(f"hub: SNAKEKIT_AUTH={AUTH!r} is not a log-in this hub has: native (the default: a password "
                     "per person, docker/hub/accounts) or lti (an LMS course)")
c.Authenticator.admin_users = set(INSTRUCTORS[:1])  # the first instructor administers the hub
c.JupyterHub.load_groups = {"instructors": {"users": INSTRUCTORS}}

# --- services: the exchange, grading and the idle culler ---------------------------------------
c.JupyterHub.services = [
    {
        "name": "exchange",
        "url": f"http://{HUB_HOST}:{EXCHANGE_PORT}",
        "command": [sys.executable, os.path.join(os.path.dirname(__file__), "exchange_service.py")],
        "environment": {
            "SNAKEKIT_EXCHANGE_DIR": f"{DATA}/exchange",
            "SNAKEKIT_EXCHANGE_PORT": str(EXCHANGE_PORT),
            "SNAKEKIT_SUBMIT_LIMIT_MB": env("SNAKEKIT_SUBMIT_LIMIT_MB", "20"),
            "SNAKEKIT_EXCHANGE_QUOTA_MB": env("SNAKEKIT_EXCHANGE_QUOTA_MB", "2000"),
            "SNAKEKIT_INSTRUCTOR_GROUPS": "instructors",
        },
    },
    {
        # grading for the instructors' group: the grader's container on the course volume (the
        # engine's socket is the hub's, as for the spawner); a student gets 403
        "name": "grading",
        "url": f"http://{HUB_HOST}:{GRADING_PORT}",
        "command": [sys.executable, os.path.join(os.path.dirname(__file__), "grading_service.py")],
        "environment": {
            "SNAKEKIT_GRADING_PORT": str(GRADING_PORT),
            "SNAKEKIT_GRADER_IMAGE": GRADER_IMAGE,
            "SNAKEKIT_COURSE_VOLUME": "snakekit-course",
            "SNAKEKIT_INSTRUCTOR_GROUPS": "instructors",
        },
    },
    {
        "name": "idle-culler",
        "command": [sys.executable, "-m", "jupyterhub_idle_culler", f"--timeout={env('SNAKEKIT_CULL_TIMEOUT', '3600')}",
                    f"--cull-every={env('SNAKEKIT_CULL_EVERY', '300')}"],
    },
]
c.JupyterHub.load_roles = [
    # every user may reach the exchange (it decides what each may do there) and the grading
    # service (it grades for the instructors' group only)
    {"name": "user", "scopes": ["self", "access:services!service=exchange", "access:services!service=grading"]},
    {"name": "idle-culler", "services": ["idle-culler"],
     "scopes": ["list:users", "read:users:activity", "read:servers", "delete:servers"]},
]
