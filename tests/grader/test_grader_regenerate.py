"""``snakekit grade --regenerate`` and the release check, as a TA meets them (issue 33).

* Run from the folder above the course (the default ``--course course``), a changed test cell is
  released again and graded; the TA is warned first that the submissions collected before were
  made from the old release.
* A regeneration that fails leaves ``release/<a>/`` and the gradebook as they were, and says
  nbgrader's reason in one line.
* A stray copy of the instructor's notebook in ``source/<a>/`` is named, and nothing regenerated.
* A typo in the assignment name gets one line, the assignments the course has.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import nbformat
import pytest

from grader_helpers import ASSIGNMENT, REFERENCES, make_course, snakekit, submit
from test_grader_files import run, tree

A = ASSIGNMENT
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def released(tmp_path_factory):
    """The test course released, its references inside it, one good submission collected."""
    course = make_course(tmp_path_factory.mktemp("released"))
    shutil.copytree(REFERENCES, course / "references")
    submit(course, "ann")
    return course


@pytest.fixture
def course(released, tmp_path):
    shutil.copytree(released, tmp_path / "course")
    return tmp_path / "course"


def source(course: Path) -> Path:
    return course / "source" / A / f"{A}.ipynb"


def edit_test_cell(course: Path, grade_id: str = "ex1_tool_xy_test", *, change) -> None:
    nb = nbformat.read(source(course), as_version=4)
    cell = next(c for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") == grade_id)
    change(cell)
    nbformat.write(nb, source(course))


def untouched(course: Path) -> dict:
    """What a failed or refused command must leave as it was: the release, the gradebook, the submissions."""
    return {"release": tree(course / "release"), "gradebook": (course / "gradebook.db").read_bytes(),
            "submitted": tree(course / "submitted")}


def comment(cell):
    cell.source = "# checked at q = 0 and at one bent pose\n" + cell.source


def test_regenerate_from_the_folder_above_the_course_releases_the_changed_test_cell(course):
    edit_test_cell(course, change=comment)
    r = snakekit("grade", A, "--regenerate", cwd=course.parent)
    assert r.returncode == 0, r.stderr[-3000:]
    assert (f"snakekit grade: the release of {A} is stale (release/{A}/{A}.ipynb differs from what the source "
            f"gives now); running nbgrader generate_assignment {A} --force") in r.stdout
    warning = [x for x in r.stderr.splitlines() if x.startswith("snakekit grade: warning:")]
    assert warning == [
        f"snakekit grade: warning: 1 submission(s) of {A} were collected from the release before this one, whose "
        "test cells differ (ex1_tool_xy_test): grading marks such a cell 'tests tampered'; to grade them as they "
        f"were released, undo the change in course/source/{A} (the gradebook before it: "
        f"course/backups/{sorted((course / 'backups').glob('gradebook-*.db'))[0].name})"]
    released = nbformat.read(course / "release" / A / f"{A}.ipynb", as_version=4)
    test = next(c for c in released.cells if c.metadata.get("nbgrader", {}).get("grade_id") == "ex1_tool_xy_test")
    assert test.source.startswith("# checked at q = 0 and at one bent pose\n")
    assert not list(course.glob(".snakekit-regenerate-*"))


def duplicate_grade_id(cell):
    cell.metadata.nbgrader["grade_id"] = "ex1_tool_xy"  # the answer cell's id: nbgrader refuses the notebook


def test_a_source_nbgrader_refuses_is_named_in_one_line_and_nothing_changes(course):
    edit_test_cell(course, change=duplicate_grade_id)
    before = untouched(course)
    r = snakekit("grade", A, "--course", course, "--regenerate", cwd=REPO)
    assert r.returncode == 1
    assert r.stderr.splitlines() == [
        f"snakekit grade: nbgrader generate_assignment {A} failed: Duplicate grade id: ex1_tool_xy (ValidationError); "
        f"fix source/{A} and run the command again"]
    assert untouched(course) == before


def test_a_regeneration_that_fails_keeps_the_release_and_the_gradebook(course, capsys, monkeypatch):
    """The source is fine when checked, but nbgrader fails on the course's own release (as it did on a
    gradebook with submissions): the release folder and the gradebook stay as they were."""
    import grader.course.folder as folder

    edit_test_cell(course, change=comment)
    before = untouched(course)
    generate = folder.generate

    def fails_on_the_course(config_dir, root, assignment, **kw):
        if not Path(root).name.startswith("snakekit-release-"):  # not the check's own temporary release
            edit_test_cell(Path(root), change=duplicate_grade_id)
        return generate(config_dir, root, assignment, **kw)

    monkeypatch.setattr(folder, "generate", fails_on_the_course)
    r = run(capsys, "grade", A, "--course", course, "--regenerate")
    assert r.returncode == 1
    assert r.stderr.startswith("snakekit grade: warning: 1 submission(s) of")
    assert r.stderr.splitlines()[1:] == [
        f"snakekit grade: nbgrader generate_assignment {A} failed: Duplicate grade id: ex1_tool_xy (ValidationError); "
        f"fix source/{A} and run the command again; {course}/release/{A}/ and the gradebook are as they were"]
    assert untouched(course) == before
    assert not list(course.glob(".snakekit-regenerate-*"))


@pytest.mark.parametrize("regenerate", [[], ["--regenerate"]])
def test_a_stray_copy_in_source_is_named_and_nothing_is_regenerated(course, regenerate):
    edit_test_cell(course, change=comment)
    shutil.copy(source(course), source(course).with_name(f"{A} (copy).ipynb"))
    before = untouched(course)
    r = snakekit("grade", A, "--course", course, *regenerate, cwd=REPO)
    assert r.returncode == 2
    assert r.stderr.splitlines() == [
        f"snakekit grade: an extra notebook is in {course}/source/{A}/: {A} (copy).ipynb; remove it (or move it "
        "out of source/) and run the command again",
        "snakekit grade: nothing was graded"]
    assert untouched(course) == before


@pytest.mark.parametrize("references", ["course has them", "none recorded"])
def test_a_typo_in_the_assignment_name_gets_one_line(course, references):
    if references == "none recorded":
        shutil.rmtree(course / "references")
    before = untouched(course)
    r = snakekit("grade", "t1_swep", "--student", "ann", cwd=course.parent)
    assert (r.returncode, r.stderr) == (2, f"snakekit grade: no assignment 't1_swep' in course; the course has: {A}\n")
    assert untouched(course) == before


def test_a_known_assignment_without_a_reference_is_told_how_to_record_it(course):
    (course / "references" / f"{A}.npz").unlink()
    r = snakekit("grade", A, cwd=course.parent)
    assert (r.returncode, r.stderr) == (2, f"snakekit grade: no reference course/references/{A}.npz: every test "
                                           f"cell would keep the kernel's own verdict. Record it: "
                                           f"`python -m grader.scoring.references {A} --course course`\n")
