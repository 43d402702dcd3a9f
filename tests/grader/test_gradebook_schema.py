"""A new gradebook carries nbgrader's own schema version, read in the grader's process.

grader.course.schema has nbgrader stamp a new gradebook with the head of its migrations read by
alembic in this process, where nbgrader runs ``alembic heads`` in a new one. Checked against
nbgrader's own answer (its function, run where the grader is not imported), on a gradebook a TA's
first command makes, and against ``alembic``'s own view of that gradebook.
"""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

from tests.conftest import copy_course

REPO = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}


def nbgraders_own_head() -> str:
    """nbgrader's get_alembic_version as nbgrader runs it (``alembic heads`` in a new process)."""
    r = subprocess.run([sys.executable, "-c", "from nbgrader.api import get_alembic_version; "
                        "print(get_alembic_version())"], capture_output=True, text=True, env=ENV, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    return r.stdout.strip()


def stamped(db: Path) -> list:
    con = sqlite3.connect(db)
    try:
        return con.execute("SELECT version_num FROM alembic_version").fetchall()
    finally:
        con.close()


def test_the_head_read_in_process_is_nbgraders_own():
    from grader.course.schema import alembic_head

    own = nbgraders_own_head()
    assert len(own) == 12 and all(c in "0123456789abcdef" for c in own), own
    assert alembic_head() == own


def test_nbgrader_imported_after_the_grader_stamps_with_it_whatever_imports_it_first(tmp_path):
    code = ("import grader.course, sys\n"
            "assert 'nbgrader.api' not in sys.modules\n"     # installing the hook imports no nbgrader
            "from nbgrader.api import Gradebook\n"
            "import nbgrader.api\n"
            "from grader.course.schema import alembic_head\n"
            "assert nbgrader.api.get_alembic_version is alembic_head\n"
            f"Gradebook('sqlite:///{tmp_path / 'g.db'}').close()\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert stamped(tmp_path / "g.db") == [(nbgraders_own_head(),)]


def test_a_tas_first_command_in_a_new_course_makes_a_gradebook_alembic_sees_as_current(tmp_path):
    course = copy_course(tmp_path / "course")
    assert not (course / "gradebook.db").exists()
    r = subprocess.run([sys.executable, "-m", "snakekit.cli", "release", "00_meet_the_arm", "--course", str(course)],
                       capture_output=True, text=True, env=ENV, cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert stamped(course / "gradebook.db") == [(nbgraders_own_head(),)]
    # alembic itself, on that gradebook, with nbgrader's migrations: at the head, nothing to upgrade
    from nbgrader.dbutil import _temp_alembic_ini

    with _temp_alembic_ini(f"sqlite:///{course / 'gradebook.db'}") as ini:
        current = subprocess.run(["alembic", "-c", ini, "current"], capture_output=True, text=True, env=ENV,
                                 timeout=300)
    assert current.returncode == 0, current.stderr[-2000:]
    assert f"{nbgraders_own_head()} (head)" in current.stdout, current.stdout
