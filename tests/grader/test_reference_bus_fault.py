"""The instructor notebook's run sets what every student is graded against. A fault of the arm's bus in it
(CommunicationError, PortLostError: a reply of the emulated servos came too late on a busy machine; BusWatchdogError:
the machine stalled a run past the servos' Bus Watchdog) used to
become an expected result: "must raise CommunicationError (the exercise asks for it there)", and every
student who computed that case right lost it (lesson 07, 7.2, 0.6 of 3 points in a run of the suite beside
other work). Such a run is made again, at most three times; still faulted, the batch stops with the case and
the error, and grades nobody. A student's run with such a fault is run once more from scratch, as one stopped
by a clock: the second run is graded, and the TA's line says why.

The fault is put into the run's own hand-in file after the sandbox wrote it (the test course does not run
the arm's bus), as the kit writes a raise: ``"<type>: <message>"`` at that case.
"""

from __future__ import annotations

import html

import pytest

from conftest import need_program
from grader_helpers import ASSIGNMENT, REFERENCES, make_course, submit

WRONG = {"ex1_tool_xy": "def tool_xy(q):\n    return np.array([0.3315, 0.0]) + 0 * q[:2]"}
GID = "ex1_tool_xy_test"
FAULTS = {"CommunicationError": "servo 3 did not answer (4 tries): is it powered and plugged in?",
          "PortLostError": "the port /dev/ttyUSB0 went away: was the cable pulled?",
          "BusWatchdogError": "during the run, the Bus Watchdog stopped servo(s) 1, 2, 3, 4, 5 on /dev/pts/0: they "
                              "heard nothing for more than 0.5 s, so they hold where they stopped and refuse goals. "
                              "Call robot.torque_on() to clear it and go on. The run as measured is kept on this "
                              "error's .run."}


def _class(course):
    submit(course, "alice")
    submit(course, "bob", WRONG)
    return course


def _grade(course, faulted_runs: int, error: str, monkeypatch, who=None, at=(1, 1, 1)):
    """Grade the class, the first ``faulted_runs`` runs of ``who`` (the instructor notebook unless told) given
    ``error`` at hidden case ``at[i]`` of GID in run i; (results, the runs of ``who`` made)."""
    from grader import batch
    from snakekit import errors
    from snakekit.handin import decode_results, encode_results

    real_run, runs = batch.Grader._sandboxed, []

    def run(self, student, src, nbs, tampered, **kw):
        work, outcome = real_run(self, student, src, nbs, tampered, **kw)
        if student == (who or batch.INSTRUCTOR):
            runs.append(work)
            if len(runs) <= faulted_runs:
                path = work / "handin" / f"{GID}.npz"
                results = decode_results(path.read_bytes())
                results[at[len(runs) - 1]] = getattr(errors, error)(FAULTS[error])
                path.write_bytes(encode_results(results))
        return work, outcome

    monkeypatch.setattr(batch.Grader, "_sandboxed", run)
    return batch.Grader(course, ASSIGNMENT, jobs=1, timeout=60, references=REFERENCES, seed=5).run(), runs


@pytest.fixture(scope="module")
def unfaulted(tmp_path_factory):
    need_program("unshare")
    from grader import batch

    course = _class(make_course(tmp_path_factory.mktemp("fresh")))
    return {r.student: (r.status, r.score, [(e.grade_id, e.score) for e in r.exercises]) for r in
            batch.Grader(course, ASSIGNMENT, jobs=1, timeout=60, references=REFERENCES, seed=5).run()}


@pytest.mark.parametrize("error", sorted(FAULTS))
@pytest.mark.parametrize("faulted_runs", [1, 2])
def test_a_reference_run_with_a_bus_fault_is_made_again_and_grades_as_without(faulted_runs, error, unfaulted, tmp_path,
                                                                                 monkeypatch, capfd):
    results, runs = _grade(_class(make_course(tmp_path)), faulted_runs, error, monkeypatch)
    got = {r.student: (r.status, r.score, [(e.grade_id, e.score) for e in r.exercises]) for r in results}
    assert got == unfaulted
    assert unfaulted["alice"][:2] == ("graded", 7.0)
    assert len(runs) == faulted_runs + 1
    said = [line for line in capfd.readouterr().err.splitlines() if "running it again" in line]
    assert len(said) == faulted_runs, said
    from grader.files import fitted

    said_of = fitted(f"{error}: {FAULTS[error]}")   # the grader's line keeps the raise's whole sentences that fit
    assert said_of.endswith("refuse goals. …") if error == "BusWatchdogError" else said_of == f"{error}: {FAULTS[error]}"
    assert all(f"{GID} raised {said_of} at hidden case 1" in line
               and "a fault of the arm's bus, not of the solution" in line for line in said), said


def test_a_reference_run_faulted_every_time_grades_nobody_and_says_why(tmp_path, monkeypatch):
    from grader.errors import GradingError

    course = _class(make_course(tmp_path))
    with pytest.raises(GradingError) as e:
        _grade(course, 3, "CommunicationError", monkeypatch)
    message = str(e.value)
    assert f"{GID} raised CommunicationError: {FAULTS['CommunicationError']} at hidden case 1, in each of its 3 runs" \
        in message, message
    assert "never an expected result" in message and message.endswith("nothing was graded")
    assert not (course / "feedback").exists() or not any((course / "feedback").rglob("*.html"))


@pytest.mark.parametrize("faulted", [(1,), (1, 1), (1, 0)], ids=["first run", "both at one case", "each at its own"])
def test_a_students_run_with_a_bus_fault_runs_once_more_and_the_second_is_graded(faulted, unfaulted, tmp_path,
                                                                                  monkeypatch):
    """A student's run whose hand-ins hold a fault of the arm's bus runs once more from scratch, and the second run
    is graded. A case that faults again in it, where the first run's did not, takes the first run's result (a busy
    machine strikes a case by chance: lesson 07's 7.2 lost 0.6 of 3 points so in a run of the suite beside other
    work); one that faults at the same case in both runs is lost, and only it."""
    results, runs = _grade(_class(make_course(tmp_path)), len(faulted), "CommunicationError", monkeypatch,
                           who="alice", at=faulted)
    got = {r.student: r for r in results}
    assert len(runs) == 2
    assert (got["bob"].status, got["bob"].score) == unfaulted["bob"][:2] and "second run" not in got["bob"].detail
    alice = got["alice"]
    assert alice.status == "graded"
    assert alice.detail.startswith(f"graded on its second run: the first had a fault of the arm's bus ({GID} raised "
                                   f"CommunicationError: {FAULTS['CommunicationError']} at hidden case 1), which a "
                                   "busy machine causes, so it ran once more from the start"), alice.detail
    scores = dict((e.grade_id, e.score) for e in alice.exercises)
    mended = f"{GID} at hidden case 0 had a fault of the arm's bus in the second run too, and took the first run's " \
             "result there"
    if faulted != (1, 1):   # the second run is the one graded, its faulted case from the first: all of it
        assert alice.score == 7.0 and scores == dict(unfaulted["alice"][2])
        assert (mended in alice.detail) == (faulted == (1, 0)), alice.detail
    else:                   # faulted again at the same case: that case is lost, and only it
        assert scores[GID] < 2.0 and {g: v for g, v in scores.items() if g != GID} == \
            {g: v for g, v in unfaulted["alice"][2] if g != GID}
        assert "took the first run's result" not in alice.detail, alice.detail


@pytest.mark.parametrize("where", ["check", "demonstration"])
def test_a_students_check_stopped_by_a_bus_fault_runs_once_more_and_the_second_is_graded(where, unfaulted, tmp_path,
                                                                                        monkeypatch):
    """The check cell of an exercise stopped on a fault of the arm's bus (lesson 07's 7.2 in a run of the suite: "servo
    1 ... did not answer the SyncRead of the joint state (timed out, 4 tries)"): the student's page would show that
    where the check's own hint belongs, whatever the answer. So does any other cell (a Bus Watchdog stop in one of
    lesson 07's demonstrations, and the errors it left in the cells after it, on the page of a student graded 8 of
    8). The run is made once more from scratch, as one whose hand-ins hold such a fault, and the second one is
    graded. The fault is put into the first run's graded notebook, as the kernel writes an error."""
    import nbformat

    from grader import batch

    real_run, runs, said = batch.Grader._sandboxed, [], []

    def run(self, student, src, nbs, tampered, **kw):
        work, outcome = real_run(self, student, src, nbs, tampered, **kw)
        if student == "alice":
            runs.append(work)
            if len(runs) == 1:
                path = work / "course" / "autograded" / "alice" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb"
                nb = nbformat.read(path, as_version=4)
                n, cell = next((n, c) for n, c in enumerate(nb.cells, 1) if c.cell_type == "code" and (
                    c.metadata.get("nbgrader", {}).get("grade_id") == GID if where == "check"
                    else not c.metadata.get("nbgrader", {}).get("grade")))
                cell.outputs.append(nbformat.v4.new_output("error", ename="CommunicationError",
                                                           evalue=FAULTS["CommunicationError"], traceback=[]))
                said.append(f"{GID}'s check" if where == "check" else f"cell {n}")
                nbformat.write(nb, path)
        return work, outcome

    monkeypatch.setattr(batch.Grader, "_sandboxed", run)
    results = batch.Grader(_class(make_course(tmp_path)), ASSIGNMENT, jobs=1, timeout=60, references=REFERENCES,
                           seed=5).run()
    got = {r.student: r for r in results}
    assert len(runs) == 2
    assert got["alice"].detail.startswith(
        f"graded on its second run: the first had a fault of the arm's bus ({said[0]} raised CommunicationError: "
        f"{FAULTS['CommunicationError']}), which a busy machine causes, so it ran once more from the start"), \
        got["alice"].detail
    assert (got["alice"].status, got["alice"].score) == ("graded", 7.0)
    assert [(e.grade_id, e.score) for e in got["alice"].exercises] == unfaulted["alice"][2]
    # her page says it in the grader's words: the fault by its type, its message (the machine's port) the TA's
    (page,) = (tmp_path / "course" / "feedback" / "alice").rglob("*.html")
    text = html.unescape(page.read_text())
    assert "raised CommunicationError), which a busy machine causes, so it ran once more from the start" in text
    assert FAULTS["CommunicationError"][:30] not in text and "/dev/" not in text
    assert (got["bob"].status, got["bob"].score) == unfaulted["bob"][:2] and "second run" not in got["bob"].detail


def test_the_tas_terminal_names_who_was_graded_on_a_second_run(tmp_path, monkeypatch, capsys):
    """`snakekit grade` run as a TA runs it: a student graded on a second run is "graded" in the list, and the line
    after it names them and points at the CSV's detail (the terminal said nothing of it before)."""
    from grader import batch
    from snakekit import errors
    from snakekit.cli import main
    from snakekit.handin import decode_results, encode_results

    course = _class(make_course(tmp_path))
    real_run, runs = batch.Grader._sandboxed, []

    def run(self, student, src, nbs, tampered, **kw):
        work, outcome = real_run(self, student, src, nbs, tampered, **kw)
        if student == "alice":
            runs.append(work)
            if len(runs) == 1:
                path = work / "handin" / f"{GID}.npz"
                results = decode_results(path.read_bytes())
                results[1] = errors.BusWatchdogError(FAULTS["BusWatchdogError"])
                path.write_bytes(encode_results(results))
        return work, outcome

    monkeypatch.setattr(batch.Grader, "_sandboxed", run)
    capsys.readouterr()
    code = main(["grade", ASSIGNMENT, "--course", str(course), "--references", str(REFERENCES), "--jobs", "1",
                 "--seed", "5"])
    out = capsys.readouterr().out
    assert code == 0 and len(runs) == 2, out
    assert "1 graded on a second run (alice): the CSV's detail says why" in out, out
    assert "graded 2 submission(s) of" in out and "0 with problems" in out, out
