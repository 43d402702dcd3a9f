"""``snakekit release ASSIGNMENT --solutions``: the worked solution reaches the students after the due date.

The test course's instructor notebook is given a hidden test (the real lessons have none today) and
the outputs of a run at drawn cases; the solution is released to nbgrader's exchange and fetched as a
student fetches an assignment. It runs and passes its visible checks, and holds neither the hidden
test nor the outputs. For every lesson of the course, the solution holds no line of the lesson's
cases module that the student's notebook does not already show, even when its check cells carry
the cases module in hidden tests. Each refusal says what to do, in one line.
"""

from __future__ import annotations

import datetime as dt
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

from conftest import need, notebook_client
from grader_helpers import ASSIGNMENT, make_course, snakekit
from test_grader_files import one_line_error, run, tree

A = ASSIGNMENT
S = f"{A}-solutions"
REPO = Path(__file__).resolve().parents[2]
COURSE = REPO / "course"
LESSONS = sorted(p.name for p in (COURSE / "source").iterdir() if p.is_dir())
#: A hidden test's line, and a case drawn at grading as an instructor's run may have printed it.
SECRET = "assert np.allclose(tool_xy(np.full(5, 0.4321)), [0.0618, 0.2599], atol=1e-4)  # hidden"
DRAWN = "drawn case: q = [0.918273, -1.2736, 0.5463, 0.0192, -0.8877]"
NOW = dt.datetime.now(dt.timezone.utc).replace(tzinfo=None, microsecond=0)


def hide(nb, lines: list[str]) -> None:
    """Append a hidden-test region holding ``lines`` to each graded test cell of ``nb``, as nbgrader writes it."""
    for cell in nb.cells:
        if cell.metadata.get("nbgrader", {}).get("grade"):
            cell.source += "\n### BEGIN HIDDEN TESTS\n" + "\n".join(lines) + "\n### END HIDDEN TESTS\n"


def set_due(course: Path, due: dt.datetime | None) -> None:
    from grader.course.folder import gradebook

    with gradebook(course) as gb:
        gb.update_or_create_assignment(A, duedate=due)


@pytest.fixture(scope="module")
def released(tmp_path_factory):
    """The test course released with a hidden test in its source and outputs of an instructor's run."""
    from grader.course.folder import generate

    course = make_course(tmp_path_factory.mktemp("solutions"))
    path = course / "source" / A / f"{A}.ipynb"
    nb = nbformat.read(path, as_version=4)
    hide(nb, [SECRET])
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text=DRAWN + "\n")]
            cell.execution_count = 1
            cell.metadata["execution"] = {"iopub.execute_input": "2026-03-03T10:00:00Z"}
    nbformat.write(nb, path)
    generate(course, course, A)
    set_due(course, NOW - dt.timedelta(days=1))
    (course / "draws").mkdir()
    (course / "draws" / f"{A}.json").write_text('{"alice": {"seed": 8399502073383157944, "attempt": "ab"}}\n')
    return course


@pytest.fixture
def course(released, tmp_path):
    course = tmp_path / "course"
    shutil.copytree(released, course)
    return course


def texts(folder: Path) -> str:
    return "\n".join(p.read_text(errors="replace") for p in sorted(folder.rglob("*")) if p.is_file())


def visible(nb) -> list[tuple[str, str]]:
    """(grade id, source) of each cell, the solution markers' lines dropped, blank ends stripped."""
    return [(c.metadata.get("nbgrader", {}).get("grade_id", ""),
             re.sub(r"(?m)^[ \t]*### (BEGIN|END) SOLUTION[ \t]*\n?", "", c.source).strip()) for c in nb.cells]


def test_a_student_fetches_the_solution_and_it_passes_its_visible_checks(course, tmp_path, monkeypatch):
    need("nbclient")
    exchange, home = tmp_path / "exchange", tmp_path / "erin"
    exchange.mkdir(), home.mkdir()
    r = snakekit("release", A, "--solutions", "--course", course, "--exchange", exchange)
    assert r.returncode == 0, r.stdout + r.stderr
    assert f"{S}: released to the exchange (students fetch it with the Assignments tab or " \
           f"`nbgrader fetch_assignment {S}`)" in r.stdout
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}",
           "USER": "erin", "LOGNAME": "erin", "HOME": str(home)}
    f = subprocess.run([str(Path(sys.executable).parent / "nbgrader"), "fetch_assignment", S,
                        f"--Exchange.root={exchange}", "--CourseDirectory.course_id=snakekit-test-course",
                        "--student=erin"], capture_output=True, text=True, cwd=home, env=env, timeout=300)
    assert f.returncode == 0, f.stdout + f.stderr
    assert sorted(p.name for p in (home / S).iterdir()) == [f"{S}.ipynb"]
    got = nbformat.read(home / S / f"{S}.ipynb", as_version=4)
    text = (home / S / f"{S}.ipynb").read_text()
    for secret in (SECRET, "BEGIN HIDDEN", "END HIDDEN", DRAWN, "8399502073383157944", "iopub.execute_input"):
        assert secret not in text
    assert got.cells[0].source.startswith(f"**Worked solution of {A}** (due {NOW - dt.timedelta(days=1):%Y-%m-%d %H:%M} UTC): ")
    # Every cell as the instructor wrote it, except the hidden test nbgrader's release took out of
    # the students' version: the test cells are the students' (nbgrader's ClearHiddenTests), the rest the source's.
    source = nbformat.read(course / "source" / A / f"{A}.ipynb", as_version=4)
    student = nbformat.read(course / "release" / A / f"{A}.ipynb", as_version=4)
    want = [s if s[0].endswith("_test") else i for i, s in zip(visible(source), visible(student))]
    assert visible(got)[1:] == want
    assert "def tool_xy(q):" in got.cells[4].source and "phi = np.cumsum(q)" in got.cells[4].source
    assert all(c.outputs == [] and c.execution_count is None for c in got.cells if c.cell_type == "code")

    monkeypatch.setenv("SNAKEKIT_TEST", "1")
    notebook_client(got, timeout=300, kernel_name="python3", allow_errors=True,
                    resources={"metadata": {"path": str(home / S)}}).execute()
    errors = {c.metadata.get("nbgrader", {}).get("grade_id"): "".join(o.get("evalue", "") for o in c.outputs
              if o.output_type == "error") for c in got.cells if c.cell_type == "code"}
    assert {k: v for k, v in errors.items() if v} == {}
    assert {k for k in errors if (k or "").endswith("_test")} == {"ex1_tool_xy_test", "ex2_sweep_test",
                                                                  "ex3_peak_speed_test"}


def test_released_again_the_solution_replaces_the_one_in_the_exchange(course, tmp_path, capsys):
    exchange = tmp_path / "exchange"
    exchange.mkdir()
    for _ in range(2):
        r = run(capsys, "release", A, "--solutions", "--course", course, "--exchange", exchange)
        assert r.returncode == 0, r.stdout + r.stderr
    outbound = exchange / "snakekit-test-course" / "outbound" / S
    assert tree(outbound) == tree(course / "release" / S)


def test_without_the_exchange_the_solution_waits_in_the_release_folder(course, capsys):
    r = run(capsys, "release", A, "--solutions", "--course", course)
    assert r.returncode == 0, r.stderr
    assert f"{A}: its worked solution {S}.ipynb is in {course.resolve()}/release/{S}/" in r.stdout
    assert "upload it to the LMS, or add --exchange" in r.stdout
    assert sorted(tree(course / "release" / S)) == [f"{S}.ipynb"]


@pytest.mark.parametrize("lesson", LESSONS)
def test_no_hidden_test_nor_case_reaches_the_lesson_s_solution(lesson, tmp_path):
    """The course's lesson, with its cases module in hidden tests of every check cell too."""
    from grader.course import solutions

    cases = [line.strip() for line in (COURSE / "cases" / f"{lesson}.py").read_text().splitlines() if line.strip()]
    shown = {line.strip() for c in nbformat.read(REPO / "notebooks" / f"{lesson}.ipynb", as_version=4).cells
             for line in c.source.splitlines()}
    # what the solution adds to the student's notebook: the answers (a loop of the answer may share a line with
    # a helper of the cases module: `return q`)
    source = (COURSE / "source" / lesson / f"{lesson}.ipynb").read_text()
    answers = {line.strip() for c in nbformat.reads(source, as_version=4).cells
               for part in re.findall(r"BEGIN (SOLUTION|ANSWER)(.*?)END \1", c.source, re.S)
               for line in part[1].splitlines()}
    for hidden in ([], cases):
        course = tmp_path / ("hidden" if hidden else "as-is")
        shutil.copytree(COURSE / "source" / lesson, course / "source" / lesson)
        path = course / "source" / lesson / f"{lesson}.ipynb"
        nb = nbformat.read(path, as_version=4)
        if hidden:
            hide(nb, hidden)
        nbformat.write(nb, path)
        (course / "release" / lesson).mkdir(parents=True)
        shutil.copyfile(REPO / "notebooks" / f"{lesson}.ipynb", course / "release" / lesson / f"{lesson}.ipynb")
        folder = solutions.write(course, lesson, None)
        assert sorted(tree(folder)) == [f"{lesson}-solutions.ipynb"]
        text = (folder / f"{lesson}-solutions.ipynb").read_text()
        got = nbformat.read(folder / f"{lesson}-solutions.ipynb", as_version=4)
        lines = {line.strip() for c in got.cells for line in c.source.splitlines()}
        assert "HIDDEN TESTS" not in text and "BEGIN SOLUTION" not in text
        assert sorted(lines & set(cases) - shown - answers) == []
        assert all(c.outputs == [] for c in got.cells if c.cell_type == "code")
        # the answers are there: no answer cell is the student's stub
        solved = [c.source for c in got.cells if c.metadata.get("nbgrader", {}).get("solution")]
        assert solved and not [a for a in solved if "NotImplementedError(\"exercise" in a]
    # the lesson's code as the suite runs it in the instructor's notebook (tests/lessons/test_course.py, full
    # marks): the same code cells, the solution markers' lines the only difference
    source_code = [c.source for c in nbformat.read(COURSE / "source" / lesson / f"{lesson}.ipynb", as_version=4).cells
                   if c.cell_type == "code"]
    got = nbformat.read(tmp_path / "as-is" / "release" / f"{lesson}-solutions" / f"{lesson}-solutions.ipynb",
                        as_version=4)
    assert [c.source for c in got.cells if c.cell_type == "code"] == \
        [re.sub(r"(?m)^[ \t]*### (BEGIN|END) SOLUTION[ \t]*\n?", "", s) for s in source_code]


def test_before_the_due_date_it_is_refused_saying_when_and_how_to_override(course, capsys):
    set_due(course, dt.datetime(2099, 3, 2, 22, 59))
    before = tree(course)
    one_line_error(run(capsys, "release", A, "--solutions", "--course", course),
                   f"{A} is due 2099-03-02 22:59 UTC, not yet passed", "add --force to release it now")
    assert tree(course) == before
    r = run(capsys, "release", A, "--solutions", "--force", "--course", course)
    assert r.returncode == 0, r.stderr
    assert (course / "release" / S / f"{S}.ipynb").is_file()


@pytest.mark.parametrize("gradebook", ["without a due date", "missing"])
def test_an_assignment_with_no_due_date_needs_force(course, capsys, gradebook):
    set_due(course, None)
    if gradebook == "missing":
        (course / "gradebook.db").unlink()
    before = tree(course)
    one_line_error(run(capsys, "release", A, "--solutions", "--course", course),
                   f"{A} has no due date in the gradebook", f"snakekit release {A} --due TIME", "--force")
    assert tree(course) == before


def test_an_assignment_never_released_is_refused(course, capsys):
    shutil.rmtree(course / "release" / A)
    before = tree(course)
    one_line_error(run(capsys, "release", A, "--solutions", "--force", "--course", course),
                   f"{A} was never released", f"release it first (snakekit release {A} --due TIME)")
    assert tree(course) == before


BAD = [
    (["06_coded_swep", "--solutions"], ["no assignment '06_coded_swep'", f"the course has: {A}"]),
    ([A, "--solutions", "--due", "2026-03-02 23:59"], ["--solutions releases only the worked solution"]),
    ([A, "--force"], ["--force goes with --solutions"]),
]


@pytest.mark.parametrize("args,says", BAD, ids=[" ".join(a) for a, _ in BAD])
def test_a_bad_request_is_refused_in_one_line_and_nothing_is_written(course, args, says, capsys):
    before = tree(course)
    one_line_error(run(capsys, "release", *args, "--course", course), *says)
    assert tree(course) == before
