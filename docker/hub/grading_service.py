"""Grading a collected assignment for the class's instructors and TAs, as a JupyterHub service.

A TA types ``snakekit grade 06_coded_sweep`` in a terminal of their hub server, in ``course/``:
their server cannot make the grader's sandboxes (a hub's servers keep Docker's seccomp profile
and /proc masking), so the command sends the request here (``grader.lms.hub_grading``), with the
server's hub token. This service, in the hub's container, asks the hub whose token it is: a
member of an instructors' group (SNAKEKIT_INSTRUCTOR_GROUPS) gets the grader's container run on
the course volume, as ``docker/hub/grade`` runs it (no network, read-only root, no
capabilities, 2 CPUs and 4 GB, the grader's own sandbox for each submission), and its output
streamed back; anyone else gets 403 and nothing runs. So no TA needs a shell on the hub's
machine or its Docker socket.

``POST api/grade/<assignment>`` with a JSON body of the options (all optional): ``students``
(a list of names), ``regenerate`` (bool), ``jobs``, ``timeout``, ``cell_timeout``,
``memory``, ``seed`` (numbers). The response is the grader's output, then one line
``MARK <exit code>``. One grading at a time: another request meanwhile gets 409. A closed
connection does not stop a grading: it runs to its end and writes the grades.

Run by the hub (``jupyterhub_config.py``'s services); settings in the environment:
SNAKEKIT_GRADING_PORT (10103), SNAKEKIT_GRADER_IMAGE, SNAKEKIT_COURSE_VOLUME (snakekit-course).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import time

import docker
from jupyterhub.services.auth import HubAuthenticated
from tornado import ioloop, iostream, web
from tornado.log import app_log

PREFIX = os.environ.get("JUPYTERHUB_SERVICE_PREFIX", "/services/grading/")
INSTRUCTORS = set(filter(None, os.environ.get("SNAKEKIT_INSTRUCTOR_GROUPS", "instructors").split(",")))
IMAGE = os.environ.get("SNAKEKIT_GRADER_IMAGE", "snakekit-grader:latest")
VOLUME = os.environ.get("SNAKEKIT_COURSE_VOLUME", "snakekit-course")
ASSIGNMENT = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,100}$")
STUDENT = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._@+-]{0,100}$")  # grader/files.py's student ids
#: The response's last line: MARK and the grader's exit code.
MARK = "grading-service: exit"
NUMBERS = {"jobs": int, "timeout": float, "cell_timeout": float, "memory": int, "seed": int}
running: dict[str, str] = {}  # the grading under way: who started it, which assignment, when


def grader_argv(assignment: str, options: dict) -> list[str]:
    """``snakekit grade`` in the grader's container, from the request's options (checked here)."""
    if not ASSIGNMENT.match(assignment):
        raise web.HTTPError(400, f"{assignment!r} is not an assignment name (letters, digits, _ . -)")
    unknown = set(options) - {"students", "regenerate", *NUMBERS}
    if unknown:
        raise web.HTTPError(400, f"unknown options {sorted(unknown)}: students, regenerate, {', '.join(NUMBERS)}")
    argv = ["snakekit", "grade", assignment, "--course", "/course", "--jobs", "2"]
    for key, kind in NUMBERS.items():
        value = options.get(key)
        if value is None:
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind is int and value != int(value)):
            raise web.HTTPError(400, f"{key} must be a number, got {value!r}")
        argv += [f"--{key.replace('_', '-')}", str(kind(value))]
    students = options.get("students") or []
    if not isinstance(students, list) or not all(isinstance(s, str) and STUDENT.match(s) for s in students):
        raise web.HTTPError(400, f"students must be a list of student names, got {students!r}")
    for s in students:
        argv += ["--student", s]
    if options.get("regenerate"):
        argv.append("--regenerate")
    return argv


class Grade(HubAuthenticated, web.RequestHandler):
    """``POST api/grade/<assignment>``: the grader's output, streamed, then MARK and its exit code."""

    def write_error(self, status_code, **kwargs):
        exc = kwargs.get("exc_info", (None, None))[1]
        message = getattr(exc, "log_message", None) or self._reason
        self.set_header("Content-Type", "application/json")
        self.finish(json.dumps({"status": status_code, "message": message}))

    @web.authenticated
    async def post(self, assignment: str):
        user = self.current_user
        name = user["name"]
        if not INSTRUCTORS & set(user.get("groups") or ()):
            raise web.HTTPError(403, f"{name} is not an instructor or TA of this hub: only they grade")
        try:
            options = json.loads(self.request.body or b"{}")
        except ValueError as e:
            raise web.HTTPError(400, f"the options are not JSON: {e}") from None
        if not isinstance(options, dict):
            raise web.HTTPError(400, "the options must be a JSON object")
        argv = grader_argv(assignment, options)
        if running:
            raise web.HTTPError(409, f"{running['who']} is grading {running['assignment']} (since "
                                     f"{running['since']}): one grading at a time; try again when it has finished")
        running.update(who=name, assignment=assignment, since=time.strftime("%H:%M:%S"))
        loop = asyncio.get_running_loop()
        container = None
        try:
            app_log.info("%s grades %s: %s", name, assignment, " ".join(argv))
            try:
                container = await loop.run_in_executor(None, start, argv)
            except docker.errors.DockerException as e:
                raise web.HTTPError(500, f"the grader's container ({IMAGE}) did not start: {e}; tell the hub's "
                                         "administrator (docker/hub/up builds the grader's image)") from None
            self.set_header("Content-Type", "text/plain; charset=utf-8")
            logs = container.logs(stream=True, follow=True)
            gone = False  # the TA's connection closed (Ctrl-C, a laptop asleep): grading goes on to its end
            while (chunk := await loop.run_in_executor(None, next, logs, None)) is not None:
                if not gone:
                    try:
                        self.write(chunk)
                        await self.flush()
                    except iostream.StreamClosedError:
                        gone = True
            code = (await loop.run_in_executor(None, container.wait))["StatusCode"]
            app_log.info("%s graded %s: exit %s", name, assignment, code)
        finally:
            running.clear()
            if container is not None:
                await loop.run_in_executor(None, lambda: container.remove(force=True))
        with contextlib.suppress(iostream.StreamClosedError):
            self.finish(f"\n{MARK} {code}\n")


def start(argv: list[str]):
    """The grader's container as docker/hub/grade runs it, started; the caller reads its output.

    ``docker run --security-opt systempaths=unconfined`` is the client's doing (no masked or
    read-only /proc paths); through the API it is those two lists, empty.
    """
    client = docker.from_env()
    host = client.api.create_host_config(
        network_mode="none", read_only=True, cap_drop=["ALL"],
        security_opt=["no-new-privileges:true", "seccomp=unconfined"],
        nano_cpus=2 * 10**9, mem_limit="4g", memswap_limit="4g", pids_limit=512,
        tmpfs={"/tmp": "exec", "/home/student": "uid=1000,gid=1000"}, binds={VOLUME: {"bind": "/course", "mode": "rw"}})
    host.update(MaskedPaths=[], ReadonlyPaths=[])
    made = client.api.create_container(IMAGE, argv, host_config=host, healthcheck={"test": ["NONE"]},
                                       labels={"snakekit.grading": "1"})
    container = client.containers.get(made["Id"])
    container.start()
    return container


def main() -> None:
    app = web.Application([(rf"{PREFIX}api/grade/([^/]+)/?", Grade)], cookie_secret=os.urandom(32))
    app.listen(int(os.environ.get("SNAKEKIT_GRADING_PORT", "10103")))
    ioloop.IOLoop.current().start()


if __name__ == "__main__":
    main()
