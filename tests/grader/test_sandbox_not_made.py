"""A sandbox that cannot be made (its mounts refused for a moment, on a machine short of something) ran
nothing of the notebook: it is made again, and it never costs a student a point. Made three times in vain,
the student's row says "grader error" with the sandbox's own words, and the reference run's failure names
them too, where it used to say only "its sandbox ended with 125".

The failures are real: the sandbox is asked to bind a host path that does not exist, so its first process
stops on the refused mount and exits with :data:`grader.sandbox.namespaces.NOT_MADE`.
"""

from __future__ import annotations

import itertools

import pytest

from conftest import need_program
from grader_helpers import ASSIGNMENT, REFERENCES, make_course, submit

WRONG = {"ex1_tool_xy": "def tool_xy(q):\n    return np.array([0.3315, 0.0]) + 0 * q[:2]"}
MISSING = "/snakekit-no-such-folder-to-bind"


def _class(course):
    submit(course, "alice")
    submit(course, "bob", WRONG)
    return course


def _grade(course, fail, monkeypatch):
    """Grade the class with the sandboxes of the runs that ``fail(who)`` says made unmakeable; (results, stderr
    lines, each run's student in order)."""
    from grader import batch
    from grader.sandbox import namespaces, runner

    real_execute, real_binds, runs = runner.Runner.execute, namespaces.default_binds, []

    def execute(self, work, student, **kw):
        runs.append(student)
        if fail(student, runs.count(student)):
            monkeypatch.setattr(namespaces, "default_binds", lambda: [*real_binds(), MISSING])
        try:
            return real_execute(self, work, student, **kw)
        finally:
            monkeypatch.setattr(namespaces, "default_binds", real_binds)

    monkeypatch.setattr(runner.Runner, "execute", execute)
    try:
        return batch.Grader(course, ASSIGNMENT, jobs=1, timeout=60, references=REFERENCES, seed=5).run(), runs
    finally:
        monkeypatch.setattr(runner.Runner, "execute", real_execute)


@pytest.fixture(scope="module")
def unfailed(tmp_path_factory):
    """The grades of the class when every sandbox is made."""
    need_program("unshare")
    from grader import batch

    course = _class(make_course(tmp_path_factory.mktemp("fresh")))
    return {r.student: (r.status, r.score) for r in
            batch.Grader(course, ASSIGNMENT, jobs=1, timeout=60, references=REFERENCES, seed=5).run()}


# every run of the batch (the reference's, each student's) refused once or twice, alone or all together
WHO = ["instructor", "alice", "bob"]
CASES = [(set(who), times) for n in (1, 3) for who in itertools.combinations(WHO, n) for times in (1, 2)]


@pytest.mark.parametrize("who, times", CASES, ids=[f"{'+'.join(sorted(w))}-{t}x" for w, t in CASES])
def test_a_sandbox_not_made_is_made_again_and_costs_no_point(who, times, unfailed, tmp_path, monkeypatch, capfd):
    from grader.batch import INSTRUCTOR

    names = {"instructor": INSTRUCTOR}
    failing = {names.get(w, w) for w in who}
    results, runs = _grade(_class(make_course(tmp_path)), lambda s, k: s in failing and k <= times, monkeypatch)
    assert {r.student: (r.status, r.score) for r in results} == unfailed
    assert unfailed["alice"] == ("graded", 7.0) and unfailed["bob"][0] == "graded"
    for s in failing:
        assert runs.count(s) == times + 1, runs
    err = capfd.readouterr().err
    said = [line for line in err.splitlines() if "the sandbox could not be made" in line]
    assert len(said) == times * len(failing), err
    assert all(f"mount {MISSING}" in line and line.endswith("; making it again") for line in said), said


def test_a_student_whose_sandbox_is_never_made_gets_a_grader_error_with_its_words(tmp_path, monkeypatch, capfd):
    need_program("unshare")
    results, runs = _grade(_class(make_course(tmp_path)), lambda s, k: s == "bob", monkeypatch)
    got = {r.student: r for r in results}
    assert runs.count("bob") == 3
    assert (got["alice"].status, got["alice"].score) == ("graded", 7.0)
    bob = got["bob"]
    assert bob.status == "grader error", (bob.status, bob.detail)
    assert bob.detail.startswith("the grader could not make the sandbox to run the notebook in, three times (sandbox: ")
    assert bob.detail.count("sandbox: ") == 1, bob.detail   # each of the sandbox's words once, not once a try
    assert f"mount {MISSING}" in bob.detail and bob.detail.endswith("so this is no score of the student's; grade the "
                                                                     "student again")


def test_a_reference_run_whose_sandbox_is_never_made_names_the_sandboxs_words(tmp_path, monkeypatch):
    need_program("unshare")
    from grader.batch import INSTRUCTOR
    from grader.errors import GradingError

    with pytest.raises(GradingError) as e:
        _grade(_class(make_course(tmp_path)), lambda s, k: s == INSTRUCTOR, monkeypatch)
    message = str(e.value)
    assert "its sandbox could not be made, three times: sandbox: " in message and f"mount {MISSING}" in message
    assert "nothing of the notebook ran: grade the batch again); nothing was graded" in message


def test_the_fork_server_tries_again_while_the_machine_refuses_a_fork_for_now(monkeypatch):
    """A busy machine at its process limit refuses a fork for a moment (EAGAIN, "Resource temporarily
    unavailable"): the fork server ended on it, and the batch with it. It now tries again, and gives up only
    after FORK_WAIT."""
    from grader.sandbox import forkserver

    refusals = []

    def fork(n):
        def refused():
            refusals.append(1)
            if len(refusals) <= n:
                raise BlockingIOError(11, "Resource temporarily unavailable")
            return 4242
        return refused

    monkeypatch.setattr(forkserver.os, "fork", fork(3))
    assert forkserver._fork(wait=5.0) == 4242 and len(refusals) == 4
    refusals.clear()
    monkeypatch.setattr(forkserver.os, "fork", fork(10 ** 6))
    assert forkserver._fork(wait=0.3) is None and len(refusals) >= 3


def test_a_sandbox_the_server_could_not_fork_is_reported_not_made_with_why(tmp_path):
    """What the grader reads of it: exit 125 (made again, never a score) and the sandbox's words in its log."""
    import json
    import socket

    from grader.sandbox import forkserver, namespaces

    log = tmp_path / "sandbox.log"
    mine, theirs = socket.socketpair()
    forkserver._not_made(json.dumps({"log": str(log)}).encode(), theirs.detach(), "fork: refused, still after 20 s")
    assert mine.recv(100) == f"exit {namespaces.NOT_MADE}\n".encode() and mine.recv(100) == b""
    assert log.read_text() == "sandbox: fork: refused, still after 20 s\n"


@pytest.mark.parametrize("never_made", [None, "bob"])
def test_a_grader_process_with_a_default_socket_timeout_grades_as_any(never_made, unfailed, tmp_path, monkeypatch):
    """A library or a TA's script may set ``socket.setdefaulttimeout`` in the grader's process. Its sockets are
    then non-blocking: the fork server's control socket (its first wait for a request raised BlockingIOError
    and ended it, "the grader's fork server ended ... did not start again") and the hidden cases' listeners
    (their wait for the next sandbox ended after the timeout). The class is graded as without it."""
    import socket

    before = socket.getdefaulttimeout()
    socket.setdefaulttimeout(1.0)
    try:
        results, _ = _grade(_class(make_course(tmp_path)), lambda s, k: s == never_made, monkeypatch)
    finally:
        socket.setdefaulttimeout(before)
    got = {r.student: (r.status, r.score) for r in results}
    if never_made is None:
        assert got == unfailed
    else:
        assert got["alice"] == unfailed["alice"] and got["bob"][0] == "grader error"
        assert f"mount {MISSING}" in next(r.detail for r in results if r.student == "bob")
