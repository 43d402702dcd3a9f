"""The hidden cases: drawn per batch from a seed, served on a socket a sandbox can reach."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import need_program

CASES = '''
import numpy as np

TOLERANCES = {"ex_b_test": {"atol": 1e-6}}

def ex_a_test(rng, spec):
    return [(int(rng.integers(2, 800)), float(rng.uniform(1.0, 200.0))) for _ in range(4)]

def ex_b_test(rng, spec):
    return [(rng.uniform(-1, 1, spec.n_joints), "name", True) for _ in range(2)]

def _helper(rng, spec):
    return [(1,)]
'''


@pytest.fixture
def course(tmp_path):
    (tmp_path / "cases").mkdir()
    (tmp_path / "cases" / "t1.py").write_text(CASES)
    return tmp_path


def test_a_seed_draws_the_same_cases_again_and_another_seed_others(course):
    from grader.scoring.cases import draw

    a, b, c = draw(course, "t1", 7), draw(course, "t1", 7), draw(course, "t1", 8)
    assert sorted(a.cases) == ["ex_a_test", "ex_b_test"]          # _helper is not a grade id
    assert a.cases["ex_a_test"] == b.cases["ex_a_test"] != c.cases["ex_a_test"]
    assert np.array_equal(a.cases["ex_b_test"][1][0], b.cases["ex_b_test"][1][0])
    assert a.settings["ex_b_test"] == {"tolerances": {"atol": 1e-6}}
    fresh = {draw(course, "t1").seed for _ in range(3)}
    assert len(fresh) == 3                                           # os.urandom: a new seed each batch


def test_each_grade_id_draws_from_its_own_stream(course):
    """Adding a grade id to the module leaves the others' cases as they were."""
    from grader.scoring.cases import draw

    before = draw(course, "t1", 11).cases["ex_a_test"]
    (course / "cases" / "t1.py").write_text("def ex_0_test(rng, spec):\n    return [(rng.random(),)]\n" + CASES)
    assert draw(course, "t1", 11).cases["ex_a_test"] == before


@pytest.mark.parametrize("body, says", [
    ("def ex_a_test(rng, spec):\n    return [(object(),)]", "object is not numbers"),
    ("def ex_a_test(rng, spec):\n    return [1, 2]", "list of tuples"),
    ("def ex_a_test(rng, spec):\n    return []", "non-empty"),
    ("def ex_a_test(rng, spec):\n    raise KeyError('x')", "raised KeyError"),
    ("import no_such_module", "cannot be imported"),
    ("X = 1", "defines no case function"),
    ("TOLERANCES = {'ex_a_test': 1e-9}\ndef ex_a_test(rng, spec):\n    return [(1,)]", "must map grade ids to dicts"),
])
def test_a_broken_cases_module_is_refused_with_what_is_wrong(course, body, says):
    from grader.scoring.cases import draw
    from grader.errors import CasesError

    (course / "cases" / "t1.py").write_text(body)
    with pytest.raises(CasesError, match=says):
        draw(course, "t1", 1)


def test_no_cases_module_names_the_file_to_write(tmp_path):
    from grader.scoring.cases import draw
    from grader.errors import CasesError

    with pytest.raises(CasesError, match=r"cases/t9\.py does not exist"):
        draw(tmp_path, "t9", 1)


def test_the_server_answers_each_grade_id_with_its_cases(course, tmp_path):
    from grader.scoring.cases import CaseServer, draw
    from snakekit.handin import fetch_cases

    batch = draw(course, "t1", 3)
    with CaseServer(batch) as server:
        path = server.listen(tmp_path / "c.sock")
        got = fetch_cases(path, "ex_b_test")
        assert fetch_cases(path, "no_such_test") == []
        assert fetch_cases(path, "ex_a_test") == batch.cases["ex_a_test"]
    assert [a[1:] for a in got] == [("name", True)] * 2
    assert np.array_equal(got[0][0], batch.cases["ex_b_test"][0][0])
    assert not Path(path).exists()                                   # closed: the socket is gone


def test_clients_that_never_ask_cost_only_their_own_socket(course, tmp_path):
    """A kernel that opens connections and sends nothing holds its own socket's few slots; once
    they go, its socket answers again, and another sandbox's socket answers all along."""
    import socket

    from grader.scoring.cases import CaseServer, draw
    from snakekit.handin import fetch_cases

    with CaseServer(draw(course, "t1", 3), timeout=30) as server:
        mine, other = server.listen(tmp_path / "a.sock"), server.listen(tmp_path / "b.sock")
        idle = [socket.socket(socket.AF_UNIX) for _ in range(6)]
        for s in idle:
            s.connect(mine)
        assert len(fetch_cases(other, "ex_a_test", timeout=5)) == 4
        for s in idle:
            s.close()
        # once the server has seen them go (its threads read their end: on a busy machine, a moment later; a
        # connection before that is turned away, as one past the slots is), its socket answers again
        deadline = time.monotonic() + 30
        while True:
            try:
                assert len(fetch_cases(mine, "ex_a_test", timeout=5)) == 4
                break
            except ConnectionError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)


def test_the_socket_is_reached_from_inside_a_sandbox(course, tmp_path):
    need_program("unshare")
    from grader.sandbox import namespaces as sandbox
    from grader.scoring.cases import CaseServer, draw

    batch = draw(course, "t1", 5)
    work = tmp_path / "work"
    work.mkdir()
    script = textwrap.dedent("""
        import os
        from snakekit.handin import fetch_cases
        cases = fetch_cases(os.environ["SNAKEKIT_CASES"], "ex_a_test")
        print("cases:", cases, "uid", os.getuid())
    """)
    with CaseServer(batch) as server, open(tmp_path / "out.txt", "w") as out:
        server.listen(work / "cases.sock")
        outcome = sandbox.run([sys.executable, "-c", script], workdir=work, limits=sandbox.Limits(wall=60),
                              env={"PATH": "/usr/bin:/bin", "SNAKEKIT_CASES": str(work / "cases.sock"),
                                   "PYTHONPATH": str(sandbox.PACKAGE_ROOT)},
                              stdout=out, stderr=subprocess.STDOUT)
    text = (tmp_path / "out.txt").read_text()
    assert outcome.returncode == 0, text
    assert f"cases: {batch.cases['ex_a_test']}" in text


def test_run_command_prints_each_case_and_what_was_handed_in(course, tmp_path):
    import nbformat

    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell(textwrap.dedent("""
        import numpy as np
        from snakekit import checks
        def a(points, rate):
            return np.arange(points)[:3] / rate
        def b(q, name, flag):
            if flag:
                raise ValueError(f"no {name}")
        checks.Exercise("1", "a").hand_in("ex_a_test", a)
        checks.Exercise("2", "b").hand_in("ex_b_test", b)
    """))]
    nbformat.write(nb, tmp_path / "t1.ipynb")
    r = subprocess.run([sys.executable, "-m", "grader.scoring.cases", "run", str(tmp_path / "t1.ipynb"), "--course",
                        str(course), "--seed", "4"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    from grader.scoring.cases import draw

    n, rate = draw(course, "t1", 4).cases["ex_a_test"][0]
    assert "t1: cases drawn with seed 4" in r.stdout
    assert f"case 0: args ({n}, {rate!r})" in r.stdout
    assert f"-> value = [0.      , {1 / rate:.6f}," in r.stdout.replace("0.00", "0.00")
    assert "-> ValueError: no name" in r.stdout


def test_behind_a_gate_only_the_running_test_cells_cases_are_answered(course, tmp_path):
    """The worker says which test cell runs; a kernel asking at any other moment gets no cases."""
    import socket

    from grader.scoring.cases import CaseServer, draw
    from snakekit.handin import fetch_cases

    with CaseServer(draw(course, "t1", 3)) as server:
        path = server.listen(tmp_path / "c.sock", gate=tmp_path / "gate")
        assert oct((tmp_path / "gate").stat().st_mode & 0o777) == "0o600"     # root's only
        worker = socket.socket(socket.AF_UNIX)
        worker.connect(str(tmp_path / "gate"))
        line = worker.makefile("rwb", buffering=0)
        assert fetch_cases(path, "ex_a_test") == []                          # no test cell runs: nothing
        line.write(b"open ex_a_test\n")
        assert line.readline() == b"ok\n"
        assert len(fetch_cases(path, "ex_a_test")) == 4
        assert fetch_cases(path, "ex_b_test") == []                          # another exercise's: nothing
        line.write(b"close\n")
        assert line.readline() == b"ok\n"
        assert fetch_cases(path, "ex_a_test") == []
        assert server.refused == [(path, "ex_a_test"), (path, "ex_b_test"), (path, "ex_a_test")]
        worker.close()
    assert not (tmp_path / "gate").exists()


def test_a_sandbox_has_pseudo_terminals_of_its_own(tmp_path):
    """Lesson 07's bus emulator serves the arm on a pty: a sandbox can open one (a private devpts
    instance), and it does not see the host's terminals."""
    need_program("unshare")
    from grader.sandbox import namespaces as sandbox

    work = tmp_path / "work"
    work.mkdir()
    script = textwrap.dedent("""
        import os
        master, slave = os.openpty()
        os.write(master, b"ping\\n")
        print("read:", os.read(slave, 5), "name:", os.ttyname(slave), "others:", sorted(os.listdir("/dev/pts")))
    """)
    with open(tmp_path / "out.txt", "w") as out:
        outcome = sandbox.run([sys.executable, "-c", script], workdir=work, limits=sandbox.Limits(wall=60),
                              env={"PATH": "/usr/bin:/bin"}, stdout=out, stderr=subprocess.STDOUT)
    text = (tmp_path / "out.txt").read_text()
    assert outcome.returncode == 0, text
    assert "read: b'ping\\n' name: /dev/pts/0 others: ['0', 'ptmx']" in text, text


def test_an_instructor_run_that_only_raises_stops_the_batch(course):
    """A solution that raised at every case (a device missing on the grading machine, say) would make
    every student who raises the same score full marks: the batch refuses it."""
    from grader.scoring.cases import draw
    from grader.scoring.references import expected
    from grader.errors import InstructorReferenceError

    batch = draw(course, "t1", 5)
    gid = "ex_a_test"
    ref = type("Ref", (), {"exercises": {gid: {"kind": "values", "outputs": ["value"], "tolerances": {}}}})()
    batch = dataclasses.replace(batch, cases={gid: batch.cases[gid]})
    errors = ["OSError: out of pty devices"] * len(batch.cases[gid])
    with pytest.raises(InstructorReferenceError, match=r"ex_a_test raised at every one of its 4 hidden cases .*OSError: out of pty"):
        expected(ref, batch, {gid: errors})


def test_lesson_06s_sweeps_catch_a_sweep_that_ignores_its_rate_at_every_seed():
    """6.3's sweeps inside the limits are inside them (the library's own side_sweep passes
    check_limits), and at every seed a sweep that sends 10 Hz whatever its rate is wrong in at
    least two of them: one draw in 27 once had all three at 10 Hz, and such a slip got 6.3 in full."""
    from grader.scoring.cases import draw
    from snakekit import LimitError, side_sweep

    course = Path(__file__).resolve().parents[2] / "course"
    for seed in range(300):
        *inside, beyond, task2 = draw(course, "06_coded_sweep", seed).cases["ex06_3_task2_test"]
        assert task2 == ()
        for points, rate, sweeps, amplitude in inside:      # side_sweep raises LimitError beyond them
            assert len(side_sweep(points=points, rate=rate, sweeps=sweeps, amplitude=amplitude)) == points
        assert sum(rate != 10.0 for _, rate, _, _ in inside) >= 2, f"seed {seed}: {inside}"
        points, rate, sweeps, amplitude = beyond
        with pytest.raises(LimitError):
            side_sweep(points=points, rate=rate, sweeps=sweeps, amplitude=amplitude).check_limits()
