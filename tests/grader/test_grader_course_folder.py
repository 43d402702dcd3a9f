"""Every TA command finds the course folder without ``--course`` where a TA stands: in the
course folder itself (where nbgrader's own commands run, and a hub's TA terminal works), or in
the folder above it (``course/``, the repository's root)."""

from __future__ import annotations

import shutil
from importlib.metadata import entry_points
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
#: Each TA command's arguments besides the course (an assignment the course does not have).
ARGS = {
    "grade": ["nosuch"],
    "release": ["nosuch"],
    "collect": ["nosuch", "--from", "download"],
    "return": ["nosuch"],
    "export": [],
    "lab": ["nosuch", "--emulator"],
    "report": ["nosuch"],
}
COMMANDS = {ep.name: ep for ep in entry_points(group="snakekit.commands")}


def test_every_ta_command_is_covered():
    assert set(COMMANDS) == set(ARGS)


def run(name: str, capsys) -> tuple[int, str]:
    try:
        code = COMMANDS[name].load()(ARGS[name])
    except SystemExit as e:
        code = e.code
    return code, " ".join(capsys.readouterr().err.split())


@pytest.fixture
def course(tmp_path) -> Path:
    shutil.copytree(REPO / "tests/grader/grader_course", tmp_path / "course")
    (tmp_path / "download").mkdir()
    return tmp_path / "course"


def says_it_used(err: str, folder: str) -> bool:
    """The command's one line names the course it read: its assignments, or its missing gradebook."""
    return (f"no assignment 'nosuch' in {folder}; the course has: t1_sweep" in err
            or f"no assignment 'nosuch' in {folder}/source/; the course has: t1_sweep" in err
            or f"the course {folder} has t1_sweep" in err or f"no gradebook in {folder} " in err)


@pytest.mark.parametrize("name", sorted(ARGS))
def test_in_the_course_folder_the_command_works_on_it(name, course, monkeypatch, capsys):
    monkeypatch.chdir(course)
    code, err = run(name, capsys)
    assert code == 2 and says_it_used(err, str(course)), err


@pytest.mark.parametrize("name", sorted(ARGS))
def test_above_it_the_command_works_on_course(name, course, monkeypatch, capsys):
    monkeypatch.chdir(course.parent)
    code, err = run(name, capsys)
    assert code == 2 and says_it_used(err, "course"), err
