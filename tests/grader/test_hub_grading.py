"""The hub's grading service (docker/hub/grading_service.py) and `snakekit grade` on a hub's
server (grader/lms/hub_grading.py): a TA's request runs the grader's container with the options
given, and its output and exit code come back to the TA's terminal; a student's is refused
(403) and nothing runs; a bad option is refused before anything runs; one grading at a time.

The service runs here in-process on loopback, with the hub's answer to "whose token is this"
and the engine's container stood in for (the hub test runs the real ones: docker/hub/test.sh).
"""

from __future__ import annotations

import asyncio
import importlib.util
import io
import json
import threading
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from grader.commands.grade import build_parser
from grader.lms.hub_grading import MARK, grade_on_hub
from tests.conftest import free_port

REPO = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("grading_service", REPO / "docker/hub/grading_service.py")
service = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(service)

USERS = {"ta-token": {"name": "ta", "groups": ["instructors"]}, "s01-token": {"name": "s01", "groups": []}}
A = "06_coded_sweep"


class FakeContainer:
    """The grader's container: prints its lines, then exits with ``code`` (after ``hold`` is set)."""

    def __init__(self, lines: list[bytes], code: int, hold: threading.Event):
        self.lines, self.code, self.hold, self.removed = lines, code, hold, False

    def logs(self, stream, follow):
        yield from self.lines
        self.hold.wait(60)

    def wait(self):
        return {"StatusCode": self.code}

    def remove(self, force):
        self.removed = True


@pytest.fixture
def hub(monkeypatch):
    """The service on a free loopback port; ``started`` records each container's argv."""
    started, hold = [], threading.Event()
    hold.set()
    state = {"code": 0, "hold": hold}

    def start(argv):
        started.append(argv)
        c = FakeContainer([b"snakekit grade: 2 submission(s)\n", b"graded s01, s02\n"], state["code"], state["hold"])
        state["container"] = c
        return c

    monkeypatch.setattr(service, "start", start)
    monkeypatch.setattr(service.Grade, "get_current_user",
                        lambda self: USERS.get(self.request.headers.get("Authorization", "").removeprefix("token ")))
    port = free_port()
    loop = asyncio.new_event_loop()
    ready = threading.Event()

    def serve():
        asyncio.set_event_loop(loop)
        app = service.web.Application([(rf"{service.PREFIX}api/grade/([^/]+)/?", service.Grade)], cookie_secret=b"x")
        app.listen(port, address="127.0.0.1")
        ready.set()
        loop.run_forever()

    threading.Thread(target=serve, daemon=True).start()
    ready.wait(30)
    url = f"http://127.0.0.1:{port}{service.PREFIX}"
    yield url, started, state
    hold.set()
    loop.call_soon_threadsafe(loop.stop)


def post(url: str, token: str, assignment: str = A, options: dict | None = None) -> tuple[int, str]:
    req = urllib.request.Request(f"{url}api/grade/{assignment}", data=json.dumps(options or {}).encode(), method="POST",
                                 headers={"Authorization": f"token {token}"})
    try:
        with urllib.request.urlopen(req, timeout=60) as r:
            return r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())["message"]


def test_a_ta_gets_the_graders_output_and_its_exit_code(hub):
    url, started, state = hub
    status, body = post(url, "ta-token", options={"students": ["s01", "s02"], "regenerate": True, "timeout": 60})
    assert status == 200
    assert body == f"snakekit grade: 2 submission(s)\ngraded s01, s02\n\n{MARK} 0\n"
    assert started == [["snakekit", "grade", A, "--course", "/course", "--jobs", "2", "--timeout", "60.0",
                        "--student", "s01", "--student", "s02", "--regenerate"]]
    assert state["container"].removed


def test_a_student_is_refused_and_nothing_runs(hub):
    url, started, _ = hub
    assert post(url, "s01-token") == (403, "s01 is not an instructor or TA of this hub: only they grade")
    assert started == []


@pytest.mark.parametrize("assignment, options, message", [
    ("..", {}, "'..' is not an assignment name"),
    (A, {"students": ["../etc"]}, "students must be a list of student names"),
    (A, {"students": "s01"}, "students must be a list of student names"),
    (A, {"course": "/"}, "unknown options ['course']"),
    *[(A, {key: "1; rm -rf /"}, f"{key} must be a number") for key in service.NUMBERS],
    (A, {"jobs": 1.5}, "jobs must be a number"),
    (A, {"seed": True}, "seed must be a number"),
], ids=lambda v: str(v)[:30])
def test_a_bad_request_is_refused_before_anything_runs(hub, assignment, options, message):
    url, started, _ = hub
    status, text = post(url, "ta-token", assignment, options)
    assert status == 400 and text.startswith(message), text
    assert started == []


def test_one_grading_at_a_time(hub):
    url, started, state = hub
    state["hold"] = threading.Event()
    first = threading.Thread(target=post, args=(url, "ta-token"))
    first.start()
    for _ in range(600):
        if started:
            break
        threading.Event().wait(0.05)
    status, text = post(url, "ta-token")
    state["hold"].set()
    first.join(60)
    assert status == 409 and text.startswith(f"ta is grading {A} (since "), text
    assert len(started) == 1


def hub_args(argv: list[str], course: Path):
    return build_parser().parse_args([*argv, "--course", str(course)])


@pytest.fixture
def server(hub, monkeypatch, tmp_path):
    """A TA's server's environment: the service's URL, its token, the course volume at tmp_path."""
    url, started, state = hub
    monkeypatch.setenv("SNAKEKIT_GRADING_URL", url)
    monkeypatch.setenv("SNAKEKIT_HUB_COURSE", str(tmp_path))
    monkeypatch.setenv("JUPYTERHUB_API_TOKEN", "ta-token")
    return tmp_path, started, state


def test_snakekit_grade_on_the_hub_prints_the_output_and_returns_the_graders_code(server, capsys):
    course, started, state = server
    state["code"] = 3
    out = io.StringIO()
    assert grade_on_hub(hub_args([A, "--student", "s02"], course), out) == 3
    assert out.getvalue() == (f"snakekit grade: {A} graded by the hub's grading service (the grader's sandboxes, on "
                              "the course folder)\nsnakekit grade: 2 submission(s)\ngraded s01, s02\n\n")
    assert started[0][-2:] == ["--student", "s02"]


def test_snakekit_grade_on_the_hub_as_a_student_says_it_was_refused(server, monkeypatch, capsys):
    course, started, _ = server
    monkeypatch.setenv("JUPYTERHUB_API_TOKEN", "s01-token")
    assert grade_on_hub(hub_args([A], course), io.StringIO()) == 2
    assert capsys.readouterr().err == ("snakekit grade: the hub's grading service refused (403): s01 is not an "
                                       "instructor or TA of this hub: only they grade\n")
    assert started == []


@pytest.mark.parametrize("extra, message", [
    (["--csv", "grades.csv"], "leave out --csv"),
    (["--references", "/tmp"], "leave out --references"),
])
def test_snakekit_grade_on_the_hub_refuses_what_the_service_cannot_do(server, capsys, extra, message):
    course, started, _ = server
    assert grade_on_hub(hub_args([A, *extra], course), io.StringIO()) == 2
    assert message in capsys.readouterr().err
    assert started == []


def test_snakekit_grade_on_the_hub_grades_only_the_course_volume(server, capsys, tmp_path_factory):
    course, started, _ = server
    elsewhere = tmp_path_factory.mktemp("other")
    assert grade_on_hub(build_parser().parse_args([A, "--course", str(elsewhere)]), io.StringIO()) == 2
    assert capsys.readouterr().err == (f"snakekit grade: on the hub, grading runs on the class's course folder {course}, "
                                       f"not {elsewhere}: `cd {course}` and run the command again\n")
    assert started == []



def test_snakekit_grade_on_the_hub_names_the_files_in_the_tas_own_course_folder(server, monkeypatch):
    """The service grades in a container with the course at /course; the TA reads the lines in their
    own server, where the course is ~/course: every such path is theirs, and no other is touched."""
    course, started, state = server
    lines = [b"wrote /course/grades-06_coded_sweep.csv\n", b"feedback: /course/feedback/s01/06_coded_sweep/a.html\n",
             b"course /course: 2 graded; kept /coursework and /data/course/x as they are\n"]
    monkeypatch.setattr(service, "start", lambda argv: started.append(argv) or FakeContainer(lines, 0, state["hold"]))
    out = io.StringIO()
    assert grade_on_hub(hub_args([A], course), out) == 0
    assert out.getvalue().splitlines()[1:4] == [
        f"wrote {course}/grades-06_coded_sweep.csv", f"feedback: {course}/feedback/s01/06_coded_sweep/a.html",
        f"course {course}: 2 graded; kept /coursework and /data/course/x as they are"]
