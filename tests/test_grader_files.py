"""The TA's commands and the course's files: no command writes where it must not, names from a
roster or an LMS download never leave their folder, and every bad file gets one line.

* Every command that writes a path it is given (``grade --csv``, ``export -o``, ``return -o``,
  ``lab --status --csv``) refuses every file of the course it must not replace, however the
  path is spelled (absolute, relative, ``./``, ``..``, a symbolic link), and nothing changes.
* A hostile roster or LMS download through ``snakekit collect`` as the TA runs it.
* Rosters and times files as spreadsheets save them, damaged gradebooks, zips and manifests,
  files too large to read: one line each, saying what is wrong and what to do.
"""

from __future__ import annotations

import codecs
import hashlib
import os
import sqlite3
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from grader_helpers import ASSIGNMENT, REFERENCES, make_course

REPO = Path(__file__).resolve().parent.parent
A = ASSIGNMENT
SOURCE_NB = f"source/{A}/{A}.ipynb"


def snakekit(*args, cwd=REPO):
    """A command as the TA types it (its own process)."""
    return subprocess.run([sys.executable, "-m", "snakekit.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


def run(capsys, *args):
    """The same command in this process (for the checks made before anything runs)."""
    from snakekit.cli import main

    capsys.readouterr()
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return subprocess.CompletedProcess(args, code, out.out, out.err)


def tree(root: Path) -> dict[str, str]:
    """Every file under ``root`` and a hash of its bytes (links not followed)."""
    out = {}
    for p in sorted(Path(root).rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def one_line_error(r, *says):
    """The command failed with exit 2 and one short line on stderr that says each of ``says``."""
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, (r.returncode, r.stdout[-2000:], r.stderr[-2000:])
    assert len(lines) == 1 and len(lines[0]) < 1000, r.stderr[:3000]
    for s in says:
        assert s in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def released(tmp_path_factory):
    return make_course(tmp_path_factory.mktemp("released"))


@pytest.fixture
def course(released, tmp_path):
    """A copy of the released test course with every file a command must not replace."""
    import shutil

    course = tmp_path / "course"
    shutil.copytree(released, course)
    (course / "roster.csv").write_text("student,name,canvas_id\nann,Ann Lee,101\n")
    (course / "collected").mkdir()
    (course / "collected" / f"{A}.csv").write_text(
        "student,lms,lms_id,lms_name,file,notebook,submitted_at,late,attempts,note\n"
        f"ann,canvas,101,leeann,leeann_101_5001_{A}.ipynb,{A}.ipynb,,,0,\n")
    (course / "lab" / A).mkdir(parents=True)
    (course / "lab" / A / "status.csv").write_text("student,state,points,reason,attempts,updated\n")
    (course / f"grades-{A}.csv").write_text("student,assignment,score,max_score,status,raw_score,late_penalty,"
                                            "submitted_at,detail\n")
    (course / "grades-all.csv").write_text("student,t1_sweep,total\nann,3,3\n")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "times.csv").write_text("student,submitted_at\nann,2026-03-01 10:00\n")
    return course


# --- no output path is a course file, however it is spelled ---------------------------------------

#: The commands that write a path the TA gives: (name, arguments before the path, the option).
WRITERS = {
    "grade": (lambda c: ["grade", A, "--course", c, "--references", REFERENCES, "--csv"]),
    "export": (lambda c: ["export", "--course", c, "-o"]),
    "return": (lambda c: ["return", A, "--course", c, "-o"]),
    "lab": (lambda c: ["lab", A, "--course", c, "--status", "--csv"]),
}
#: Files no command may write over; the others' own files too (grade's CSV is not export's).
PROTECTED = {
    "gradebook": "gradebook.db",
    "roster": "roster.csv",
    "manifest": f"collected/{A}.csv",
    "source notebook": SOURCE_NB,
    "lab's list": f"lab/{A}/status.csv",
    "grade's CSV": f"grades-{A}.csv",
    "export's CSV": "grades-all.csv",
}
OWN = {"grade": "grade's CSV", "export": "export's CSV"}  # replaced by its own command: tested below
SPELLINGS = ["absolute", "relative", "dot-slash", "dot-dot", "symlink", "hardlink"]


def spelled(course: Path, rel: str, how: str) -> str:
    """``course/rel`` as the TA might type it, from the course's parent folder."""
    target = course / rel
    if how == "absolute":
        return str(target)
    if how == "relative":
        return os.path.relpath(target, course.parent)
    if how == "dot-slash":
        return "./" + os.path.relpath(target, course.parent)
    if how == "dot-dot":
        return str(course / "source" / ".." / rel)
    link = course.parent / f"link-{target.name}"
    if how == "symlink":
        link.symlink_to(target)
    else:
        link.hardlink_to(target)
    return str(link)


@pytest.mark.parametrize("command, protected, how", [
    (c, p, h) for c in sorted(WRITERS) for p in sorted(PROTECTED) for h in SPELLINGS if OWN.get(c) != p])
def test_no_command_writes_over_a_course_file(course, command, protected, how, capsys, monkeypatch):
    monkeypatch.chdir(course.parent)
    given = spelled(course, PROTECTED[protected], how)
    before = tree(course.parent)
    r = run(capsys, *WRITERS[command](course), given)
    one_line_error(r, str(Path(given)))  # as the TA gave it (pathlib drops a leading ./)
    assert tree(course.parent) == before


@pytest.mark.parametrize("command", sorted(WRITERS))
def test_a_file_the_command_reads_is_never_its_output(course, command, capsys, tmp_path):
    """The roster given with --roster, the --times file: read, never written over."""
    from grader.files import check_output

    roster = tmp_path / "elsewhere" / "roster.csv"
    roster.write_text("student,total\nann,1\n")  # even a roster that looks like export's own CSV
    suffix = ".zip" if command == "return" else ".csv"
    with pytest.raises(Exception, match="is the roster") as e:
        check_output(roster, course, suffix=suffix, what="-o", command=f"snakekit {command}",
                     reads={roster: "the roster"})
    assert type(e.value).__name__ == "CourseError"


@pytest.mark.parametrize("command", ["grade", "export", "lab"])
def test_each_command_replaces_its_own_file_and_writes_a_new_one(course, command, tmp_path):
    from grader.files import check_output

    own = {"grade": f"grades-{A}.csv", "export": "grades-all.csv", "lab": f"lab/{A}/status.csv"}[command]
    copy = tmp_path / "elsewhere" / "mine.csv"
    copy.write_bytes((course / own).read_bytes())
    for path in (copy, tmp_path / "elsewhere" / "new.csv", course / "new.csv"):
        assert check_output(path, course, suffix=".csv", what="-o", command=f"snakekit {command}") == path


def test_export_writes_and_replaces_its_csv_but_no_other(course, capsys, tmp_path):
    out = tmp_path / "elsewhere" / "grades.csv"
    for _ in range(2):
        r = run(capsys, "export", "--course", course, "-o", out)
        assert r.returncode == 0, r.stderr
    assert out.read_text().splitlines()[0] == "student,total"
    r = run(capsys, "export", "--course", course, "-o", tmp_path / "elsewhere" / "times.csv")
    one_line_error(r, "exists and is not one this command wrote")


def test_return_replaces_only_a_feedback_zip(course, capsys, tmp_path):
    from grader.files import check_output

    mine, other = tmp_path / "mine.zip", tmp_path / "download.zip"
    with zipfile.ZipFile(mine, "w") as z:
        z.writestr("leeann_101_5001_t1_sweep-feedback.html", "<html/>")
    with zipfile.ZipFile(other, "w") as z:
        z.writestr("leeann_101_5001_t1_sweep.ipynb", "{}")
    assert check_output(mine, course, suffix=".zip", what="-o", command="snakekit return") == mine
    r = run(capsys, "return", A, "--course", course, "-o", other)
    one_line_error(r, "exists and is not one this command wrote")


@pytest.mark.parametrize("command", sorted(WRITERS))
def test_an_output_in_a_missing_folder_is_one_line(course, command, capsys, tmp_path):
    suffix = ".zip" if command == "return" else ".csv"
    r = run(capsys, *WRITERS[command](course), tmp_path / "no" / f"out{suffix}")
    one_line_error(r, f"the folder {tmp_path / 'no'} does not exist")


# --- a hostile roster or download through snakekit collect ---------------------------------------


def notebook(course: Path, note: str = "") -> bytes:
    """The assignment's released notebook as a student hands it in (``note`` makes it differ)."""
    import nbformat

    from grader_helpers import release_notebook

    nb = release_notebook(course)
    nb.metadata["note"] = note
    return nbformat.writes(nb).encode()


def roster_file(path: Path, rows: list[list[str]]) -> Path:
    import csv

    with open(path, "w", newline="") as f:
        csv.writer(f).writerows([["student", "canvas_id"], *rows])
    return path


#: Student ids that are no folder name: climbing, absolute, a slash, hidden, control characters, too long.
HOSTILE_IDS = ["../source", "../../outside", "/etc/x", "a/b", "a\\b", "..", ".hidden", "a\nb", "a\x00b", "-rf",
               "x" * 101, " "]


def test_a_roster_id_that_climbs_is_refused_as_the_ta_runs_collect(course, tmp_path):
    roster = roster_file(tmp_path / "elsewhere" / "class.csv", [["ann", "101"], ["../source", "102"]])
    dl = tmp_path / "elsewhere" / "dl.zip"
    with zipfile.ZipFile(dl, "w") as z:
        z.writestr(f"leeann_101_5001_{A}.ipynb", notebook(course, "ann"))
        z.writestr(f"evil_102_5002_{A}.ipynb", notebook(course, "evil"))
    before = tree(tmp_path)
    r = snakekit("collect", A, "--course", course, "--from", dl, "--roster", roster)
    one_line_error(r, f"roster {roster}, row 3: the student id '../source' cannot be a folder name",
                   "letters, digits and . _ @ + -")
    assert tree(tmp_path) == before  # the source notebook above all: nothing was written


@pytest.mark.parametrize("bad", HOSTILE_IDS, ids=repr)
def test_every_roster_id_that_is_no_folder_name_is_refused(course, bad, tmp_path, capsys):
    from grader.files import excerpt

    roster = roster_file(tmp_path / "elsewhere" / "class.csv", [["ann", "101"], [bad, "102"]])
    dl = tmp_path / "elsewhere" / "dl.zip"
    with zipfile.ZipFile(dl, "w") as z:
        z.writestr(f"evil_102_5002_{A}.ipynb", notebook(course, "evil"))
    before = tree(tmp_path)
    r = run(capsys, "collect", A, "--course", course, "--from", dl, "--roster", roster)
    if bad.strip() == "":  # a blank id is a row without a student: skipped, and its upload kept aside
        assert r.returncode == 1 and "Canvas user 102 (evil) is not in the roster" in r.stdout
        return
    if "\x00" in bad:  # no spreadsheet writes a NUL: not read as a table at all
        one_line_error(r, f"roster {roster} is not text (it has NUL bytes", "save it from the spreadsheet as")
    else:
        one_line_error(r, f"roster {roster}, row 3: the student id {excerpt(bad)} cannot be a folder name")
    assert tree(tmp_path) == before


def test_a_hostile_download_stays_in_its_folders_and_keeps_every_file(course, tmp_path):
    """Climbing and absolute names, a newline in a name, and two unknown files of one name in two folders."""
    entries = {
        f"leeann_101_5001_{A}.ipynb": notebook(course, "ann 1"),
        f"leeann_101_5003_my\nwork.ipynb": notebook(course, "ann 2"),  # newer, a newline in its name
        f"../../source/{A}/{A}.ipynb": notebook(course, "climbs"),
        f"sub/../../../{A}.ipynb": notebook(course, "climbs too"),
        f"/etc/{A}.ipynb": notebook(course, "absolute"),
        f"bob\nx/{A}.ipynb": notebook(course, "newline folder"),
        f"a/nobody_999_5006_{A}.ipynb": notebook(course, "first nobody"),
        f"b/nobody_999_5006_{A}.ipynb": notebook(course, "second nobody"),
    }
    dl = tmp_path / "elsewhere" / "dl.zip"
    with zipfile.ZipFile(dl, "w") as z:
        for name, data in entries.items():
            z.writestr(name, data)
    before = tree(tmp_path)
    r = snakekit("collect", A, "--course", course, "--from", dl)  # the course's roster: ann only
    assert r.returncode == 1, r.stderr
    after = tree(tmp_path)
    changed = {p for p in set(before) | set(after) if before.get(p) != after.get(p)}
    assert all(p.startswith(("course/submitted/ann/", "course/collected/")) for p in changed), sorted(changed)
    assert not any("\n" in p for p in after)
    ann = course / "submitted" / "ann" / A
    assert (ann / f"{A}.ipynb").read_bytes() == entries[f"leeann_101_5003_my\nwork.ipynb"]
    assert [p.read_bytes() for p in (ann / "attempts").iterdir()] == [entries[f"leeann_101_5001_{A}.ipynb"]]
    # every unmatched file is kept, under a name of its own, and reported with that name
    aside = course / "collected" / f"{A}-unmatched"
    kept = {p.name: p.read_bytes() for p in aside.iterdir()}
    unmatched = [f"/etc/{A}.ipynb", f"bob\nx/{A}.ipynb", f"a/nobody_999_5006_{A}.ipynb", f"b/nobody_999_5006_{A}.ipynb"]
    assert sorted(kept.values()) == sorted(entries[e] for e in unmatched)
    reported = [line for line in r.stdout.splitlines() if line.startswith("not collected:")]
    assert len(reported) == 6, r.stdout  # the four kept aside and the two that climb
    for name in kept:
        assert sum(f"(kept as {name})" in line for line in reported) == 1, (name, reported)
    assert sum("climbs out of the download" in line for line in reported) == 2
    assert "'bob\\nx' is not in the roster" in r.stdout and "'my\\nwork.ipynb' saved as t1_sweep.ipynb" in r.stdout


def test_the_same_download_collected_twice_keeps_no_second_copy(course, tmp_path, capsys):
    dl = tmp_path / "elsewhere" / "dl.zip"
    with zipfile.ZipFile(dl, "w") as z:
        z.writestr(f"a/nobody_999_5006_{A}.ipynb", notebook(course, "1"))
        z.writestr(f"b/nobody_999_5006_{A}.ipynb", notebook(course, "2"))
    for _ in range(2):
        assert run(capsys, "collect", A, "--course", course, "--from", dl).returncode == 1
    assert len(list((course / "collected" / f"{A}-unmatched").iterdir())) == 2


@pytest.mark.parametrize("name, safe", [
    ("../../x.ipynb", "x.ipynb"), ("/etc/passwd", "passwd"), ("a\\..\\b.ipynb", "b.ipynb"), ("..", "file"),
    (".bashrc", "bashrc"), ("a\nb\x00c.ipynb", "a_b_c.ipynb"), ("my work (2).ipynb", "my work (2).ipynb"),
    ("Übung 1.ipynb", "Übung 1.ipynb"), ("x" * 300 + ".ipynb", "x" * 114 + ".ipynb"),
])
def test_file_names_are_made_safe(name, safe):
    from grader.files import file_name

    assert file_name(name) == safe
