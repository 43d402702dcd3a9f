"""The adversarial corpus, graded in one batch: every kind gets its stated verdict, none stops the batch.

The host-side facts are checked here too: nothing was written outside the submissions' copies,
the gradebook survived, no connection reached the host, the feedback carries no hidden test.
"""

from __future__ import annotations

import os
import shutil
import socket
import sqlite3
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import pytest

from conftest import IN_CI, need_program
from grader_corpus import CASES, PWNED
from grader_helpers import ASSIGNMENT, REFERENCES, make_course, read_csv

REPO = Path(__file__).resolve().parents[2]
# Bounds for a hang, not for speed: a submission of the corpus that ends needs under 12 s (its
# longest cell, the 4 MB of output, under 2 s) on a quiet machine, and at least 5x that is given
# (10x a cell's: the longest took over 10 s at a load of 10 on 2 cores).
TIMEOUT = 60  # a notebook's wall clock [s]
CELL_TIMEOUT = 20  # a cell's: a cell that hangs is interrupted and the exercises after it are still graded


def _host_ip() -> str:
    out = subprocess.run(["ip", "-4", "-o", "addr", "show", "scope", "global"], capture_output=True, text=True).stdout
    for line in out.splitlines():
        return line.split()[3].split("/")[0]
    return "127.0.0.1"


class _Listener:
    """A TCP server on every host interface that records who connected."""

    def __init__(self):
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind(("0.0.0.0", 0))
        self.sock.listen()
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.seen: list = []
        self.stop = False
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self):
        while not self.stop:
            try:
                conn, addr = self.sock.accept()
            except OSError:
                continue
            self.seen.append(addr)
            conn.close()

    def close(self):
        self.stop = True
        self.thread.join()
        self.sock.close()


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    need_program("unshare")
    if os.geteuid() != 0:
        if IN_CI:
            pytest.fail("the adversarial corpus runs as root under CI=true (the sandbox's own user needs it)")
        pytest.skip("the full sandbox (separate user) is tested as root, as in CI")
    tmp = tmp_path_factory.mktemp("adversarial")
    course = make_course(tmp)
    # the batch's working folder (its TMPDIR): short, so the cases' Unix socket path fits (107 bytes)
    # under any pytest folder, xdist's worker folders included
    work = Path(tempfile.mkdtemp(prefix="adv-"))
    listener = _Listener()
    ctx = {
        "secrets": [f"{course}/gradebook.db", f"{course}/source/**/*.ipynb", f"{course}/submitted/good/**/*.ipynb",
                    f"{REFERENCES}/*.npz", f"{REPO}/course/references/*.npz", f"{REPO}/tests/grader/grader_course/**/*.ipynb",
                    f"{work}/*/*/course/autograded/good/**/*.ipynb", "/root/**/*.ipynb", f"{course}/cases/*.py",
                    f"{REPO}/tests/grader/grader_course/cases/*.py", f"{REPO}/course/cases/*.py", f"{work}/*/.*.gate"],
        "targets": [f"/tmp/{PWNED}", f"{course}/{PWNED}", f"{REPO}/{PWNED}", f"{work}/{PWNED}", f"{tmp}/{PWNED}"],
        "gradebook": str(course / "gradebook.db"),
        "port": listener.port, "host_ip": _host_ip(), "pwned": PWNED,
    }
    for case in CASES:
        case.make(course, case.student, ctx)
    csv = tmp / "grades.csv"
    r = subprocess.run([sys.executable, "-m", "grader.commands.grade", ASSIGNMENT, "--course", str(course), "--jobs", "2",
                        "--timeout", str(TIMEOUT), "--cell-timeout", str(CELL_TIMEOUT), "--memory", "1536", "--csv", str(csv),
                        "--references", str(REFERENCES)],
                       capture_output=True, text=True, timeout=900, cwd=REPO,
                       env={**os.environ, "TMPDIR": str(work)})
    listener.close()
    yield {"course": course, "run": r, "rows": read_csv(csv) if csv.exists() else {}, "ctx": ctx,
           "listener": listener, "tmp": tmp}
    for t in ctx["targets"]:
        Path(t).unlink(missing_ok=True)
    shutil.rmtree(work, ignore_errors=True)


def test_the_batch_completes_with_exit_code_0(batch):
    r = batch["run"]
    assert r.returncode == 0, r.stderr[-3000:]
    assert set(batch["rows"]) == {c.student for c in CASES}
    assert f"done {len(CASES)}, left 0" in r.stderr


@pytest.mark.parametrize("case", CASES, ids=[c.student for c in CASES])
def test_each_kind_gets_its_verdict(batch, case):
    row = batch["rows"][case.student]
    if case.at_most:
        assert (row["status"], float(row["max_score"])) == (case.status, 7.0) and float(row["score"]) <= case.score, row
    else:
        assert (row["status"], float(row["score"]), float(row["max_score"])) == (case.status, case.score, 7.0), row
    if case.reason:
        html = (batch["course"] / "feedback" / case.student / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()
        assert case.reason in row["detail"] or case.reason in html, (row, case.reason)


def test_nothing_was_written_outside_the_copies(batch):
    for t in batch["ctx"]["targets"]:
        assert not Path(t).exists(), t
    con = sqlite3.connect(batch["course"] / "gradebook.db")
    assert con.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    students = {s for (s,) in con.execute("SELECT student_id FROM submitted_assignment")}
    assert students == {c.student for c in CASES}
    graded = con.execute("SELECT COUNT(*) FROM grade WHERE auto_score IS NOT NULL").fetchone()[0]
    assert graded == 3 * len(CASES)


def test_no_connection_reached_the_host(batch):
    assert batch["listener"].seen == []


def test_secrets_were_not_readable(batch):
    """The student printed what it could open; the feedback shows the empty list."""
    html = (batch["course"] / "feedback" / "read_secrets" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()
    assert "found []" in html
    html = (batch["course"] / "feedback" / "network" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()
    assert "reached []" in html
    html = (batch["course"] / "feedback" / "write_outside" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()
    assert f"written ['/tmp/{PWNED}']" in html  # only its private /tmp, gone with the sandbox


def test_the_kernel_ran_as_the_sandbox_user_with_its_limits(batch):
    """As root, the grader runs each submission as `snakekit-grader`, no_new_privs, with rlimits."""
    import pwd

    uid = pwd.getpwnam("snakekit-grader").pw_uid
    assert uid != 0
    html = (batch["course"] / "feedback" / "write_outside" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()
    # --memory 1536 (MB); CPU seconds: 2 x the notebook's timeout + 30
    assert f"who {uid} {uid} nonewprivs 1 memory 1536 cpu {2 * TIMEOUT + 30}" in html


def _instructor_only_lines(course) -> list[str]:
    """Lines of the instructor's solutions that no student of the corpus wrote, and the cases module's."""
    import nbformat

    from grader_helpers import GOOD

    src = nbformat.read(course / "source" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb", as_version=4)
    mine = {line.strip() for v in GOOD.values() for line in v.splitlines()}
    lines = [line.strip() for c in src.cells if c.metadata.get("nbgrader", {}).get("solution")
             for line in c.source.splitlines() if line.strip() and line.strip() not in mine
             and not line.strip().startswith(("def ", '"""', "return snakekit"))]
    lines += [line.strip() for line in (course / "cases" / f"{ASSIGNMENT}.py").read_text().splitlines()
              if line.strip().startswith(("def ", "return", "points", "rate", "sweeps", "amplitude"))]
    return lines


def _readable(html: str) -> str:
    """The page's text and every base64 run in it, decoded."""
    import base64
    import html as html_lib
    import re

    text = html_lib.unescape(html)
    decoded = []
    for run in re.findall(r"[A-Za-z0-9+/]{64,}={0,2}", text):
        try:
            decoded.append(base64.b64decode(run + "=" * (-len(run) % 4)).decode("utf-8", "replace"))
        except ValueError:
            pass
    return text + "\n".join(decoded)


def test_no_feedback_carries_the_solution_the_cases_or_a_classmates_work(batch):
    """Nothing a submission can read holds the instructor's solution, the cases module, the
    references or another student's notebook: whatever it prints, plain or base64, shows none."""
    secret = _instructor_only_lines(batch["course"])
    assert len(secret) >= 6 and any("t / (t[-1] / sweeps)" in line for line in secret)
    for case in CASES:
        page = _readable((batch["course"] / "feedback" / case.student / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text())
        assert not [line for line in secret if line in page], case.student
        assert "BEGIN SOLUTION" not in page and "cases_hash" not in page and "source_hash" not in page
        if case.student != "classmate":
            assert "classmate-marker-7c1f" not in page, case.student
    dumped = _readable((batch["course"] / "feedback" / "print_secrets" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text())
    assert "FILE" in dumped and "gradebook.db" in dumped   # it did read its own copy of the gradebook
    assert "SQLite format 3" in dumped                     # ... and printed it, base64-decoded here


def test_asking_for_the_cases_ahead_gets_none(batch):
    page = (batch["course"] / "feedback" / "peek_cases" / ASSIGNMENT / f"{ASSIGNMENT}.html").read_text()
    assert "asked ahead: 0 cases" in page


def test_megabytes_of_output_stay_bounded(batch):
    html = batch["course"] / "feedback" / "big_output" / ASSIGNMENT / f"{ASSIGNMENT}.html"
    # 4 MB printed; the page keeps a bounded part of it (a page without the output is about 0.5 MB)
    assert html.stat().st_size < 1_000_000
