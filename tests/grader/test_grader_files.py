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
import subprocess
import zipfile
from pathlib import Path

import pytest

from grader_helpers import ASSIGNMENT, REFERENCES, make_course, snakekit

REPO = Path(__file__).resolve().parents[2]
A = ASSIGNMENT
SOURCE_NB = f"source/{A}/{A}.ipynb"


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
        assert f"nothing is graded yet in {course}'s gradebook: the CSV has the students and no assignment's " \
            "column" in r.stdout, r.stdout
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
    # the notebooks, the manifest, and the roster's names into nbgrader's student table
    assert all(p.startswith(("course/submitted/ann/", "course/collected/")) or p == "course/gradebook.db"
               for p in changed), sorted(changed)
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


# --- rosters and times files as spreadsheets save them ------------------------------------------------

ROSTER = "student,name,canvas_id\njose,José Müller,101\nann,Ann Lee,102\n"
#: How Excel (and LibreOffice) save a table: the bytes of ROSTER in each.
SAVED_AS = {
    "UTF-8": lambda t: t.encode("utf-8"),
    "CSV UTF-8 (with BOM)": lambda t: codecs.BOM_UTF8 + t.encode("utf-8"),
    "UTF-16 LE with BOM": lambda t: codecs.BOM_UTF16_LE + t.encode("utf-16-le"),
    "UTF-16 BE with BOM": lambda t: codecs.BOM_UTF16_BE + t.encode("utf-16-be"),
    "Unicode Text (UTF-16, tabs)": lambda t: codecs.BOM_UTF16_LE + t.replace(",", "\t").encode("utf-16-le"),
    "Windows-1252": lambda t: t.replace("Müller", "Müller’s").encode("cp1252"),
    "Latin-1": lambda t: t.encode("latin-1"),
    "semicolons, CRLF": lambda t: t.replace(",", ";").replace("\n", "\r\n").encode("cp1252"),
}


@pytest.mark.parametrize("saved_as", sorted(SAVED_AS))
def test_a_roster_is_read_in_every_encoding_a_spreadsheet_saves(saved_as, tmp_path):
    from grader.lms.roster import Roster

    path = tmp_path / "roster.csv"
    path.write_bytes(SAVED_AS[saved_as](ROSTER))
    rows = Roster.load(path).rows
    name = "José Müller’s" if saved_as == "Windows-1252" else "José Müller"
    assert rows == [{"student": "jose", "name": name, "canvas_id": "101"},
                    {"student": "ann", "name": "Ann Lee", "canvas_id": "102"}]


@pytest.mark.parametrize("saved_as", sorted(SAVED_AS))
def test_a_times_file_is_read_in_every_encoding_a_spreadsheet_saves(saved_as, tmp_path):
    import datetime as dt

    from grader.lms.collect import read_times

    path = tmp_path / "times.csv"
    path.write_bytes(SAVED_AS[saved_as]("Full name,Last modified (submission)\nJosé Müller,2026-03-02 10:30\n"))
    name = "José Müller’s" if saved_as == "Windows-1252" else "José Müller"
    assert read_times(path, dt.timezone.utc) == [
        ("Full name", name, dt.datetime(2026, 3, 2, 10, 30, tzinfo=dt.timezone.utc))]


def test_utf16_without_a_byte_order_mark_says_how_to_save_it(course, tmp_path, capsys):
    path = tmp_path / "roster.csv"
    path.write_bytes(ROSTER.encode("utf-16-le"))
    r = run(capsys, "collect", A, "--course", course, "--from", tmp_path, "--roster", path)
    one_line_error(r, f"roster {path} is not text", "save it from the spreadsheet as 'CSV UTF-8 (comma delimited)'")


# --- files too large, or not what they should be: one line each -----------------------------------------


def test_a_100_mb_roster_is_refused_before_it_is_read(course, tmp_path):
    path = tmp_path / "roster.csv"
    with open(path, "wb") as f:  # 100 MB without a newline (sparse: the size is what counts)
        f.write(b"student,")
        f.truncate(100 << 20)
    r = snakekit("collect", A, "--course", course, "--from", tmp_path, "--roster", path)
    one_line_error(r, f"roster {path} is 100 MB, more than the 32 MB a roster may be; is it the right file?")


@pytest.mark.parametrize("what, content", [
    ("roster", "student," + "x" * 1_000_000),                  # one field of a million characters
    ("roster", ",".join(["name"] * 1_000_000) + "\n"),         # a million columns, none of them student
    ("times file", "student,submitted_at\nann," + "9" * 100_000 + "\n"),  # a time of 100,000 digits
    ("times file", "student\tname\n" + "x" * 1_000_000),       # no time column, a huge row
])
def test_a_message_quotes_only_an_excerpt_of_a_huge_input(course, what, content, tmp_path, capsys):
    path = tmp_path / "input.csv"
    path.write_text(content)
    option = "--roster" if what == "roster" else "--times"
    r = run(capsys, "collect", A, "--course", course, "--from", tmp_path, option, path)
    line = one_line_error(r, f"{what} {path}")
    assert len(line) < 600 and "…" in line, line  # the input is quoted, cut short


def test_excerpt_and_one_line_cap_a_150_million_character_input():
    from grader.files import EXCERPT, MESSAGE, excerpt, one_line

    huge = "ab\n" * 50_000_000
    shown = excerpt(huge)
    assert len(shown) == EXCERPT and shown.startswith("'ab\\nab\\n") and shown.endswith("…")
    line = one_line(f"bad input: {huge}")
    assert len(line) == MESSAGE and "\n" not in line and line.startswith("bad input: ab ab") and line.endswith("…")
    assert excerpt("ann", quote=False) == "ann" and excerpt("a\nb", quote=False) == "'a\\nb'"


def _damage(course: Path, how: str) -> None:
    db = course / "gradebook.db"
    if how == "not a database":
        db.write_bytes(b"this is not SQLite\n" * 500)
    elif how == "emptied":  # nbgrader would take it for a new gradebook: every grade gone
        db.write_bytes(b"")
    else:  # truncated: the first pages of a real gradebook only
        data = db.read_bytes()
        db.write_bytes(data[: len(data) // 3])


@pytest.mark.parametrize("how", ["not a database", "truncated", "emptied"])
@pytest.mark.parametrize("command", ["grade", "export", "collect", "return"])
def test_a_damaged_gradebook_is_one_line_saying_how_to_restore_it(course, command, how, tmp_path, capsys):
    from grader.course.folder import backup_gradebook

    backup = backup_gradebook(course)
    _damage(course, how)
    args = {"grade": ["grade", A, "--course", course, "--references", REFERENCES],
            "export": ["export", "--course", course, "-o", tmp_path / "g.csv"],
            "collect": ["collect", A, "--course", course, "--from", tmp_path / "elsewhere"],
            "return": ["return", A, "--course", course]}[command]
    before = tree(course)
    r = run(capsys, *args)
    one_line_error(r, f"the gradebook {course / 'gradebook.db'} cannot be read (",
                   f"restore the newest backup: cp {backup} {course / 'gradebook.db'}")
    assert tree(course) == before


def test_a_damaged_gradebook_without_backups_says_so(course, tmp_path, capsys):
    _damage(course, "not a database")
    r = run(capsys, "export", "--course", course, "-o", tmp_path / "g.csv")
    one_line_error(r, "file is not a database", f"restore it from a copy (no backups in {course / 'backups'})")


@pytest.mark.parametrize("damage", [b"\x00\xff" * 400, b"student,lms\n", b"\xff\xfe\x00"])
@pytest.mark.parametrize("command", ["collect", "return"])
def test_a_damaged_manifest_is_one_line(course, command, damage, tmp_path, capsys):
    manifest = course / "collected" / f"{A}.csv"
    manifest.write_bytes(damage)
    (course / "feedback" / "ann" / A).mkdir(parents=True)
    (course / "feedback" / "ann" / A / f"{A}.html").write_text("<html/>")
    dl = tmp_path / "elsewhere" / "dl"
    (dl / "ann").mkdir(parents=True)
    (dl / "ann" / f"{A}.ipynb").write_bytes(notebook(course))
    before = tree(course)
    args = ["collect", A, "--from", dl] if command == "collect" else ["return", A]
    r = run(capsys, *args, "--course", course)
    line = one_line_error(r, f"manifest {manifest}", f"move it away and collect {A} again")
    assert len(line) < 600
    assert tree(course) == before  # collect places nothing before it knows it can write the manifest


def test_a_damaged_zip_entry_is_reported_and_the_others_collected(course, tmp_path):
    dl = tmp_path / "elsewhere" / "dl.zip"
    good, bad = notebook(course, "good"), notebook(course, "bad")
    with zipfile.ZipFile(dl, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(f"leeann_101_5001_{A}.ipynb", good)
        z.writestr(f"leeann_101_5002_{A}-1.ipynb", bad)
    with zipfile.ZipFile(dl) as z:
        info = z.getinfo(f"leeann_101_5002_{A}-1.ipynb")
        start = info.header_offset + 30 + len(info.filename) + len(info.extra)
    data = bytearray(dl.read_bytes())
    data[start + 100: start + 140] = bytes(40)  # the deflated stream of the second entry, damaged
    dl.write_bytes(bytes(data))
    r = snakekit("collect", A, "--course", course, "--from", dl)
    assert r.returncode == 1, r.stderr
    assert f"not collected: leeann_101_5002_{A}-1.ipynb: cannot be unpacked (" in r.stdout
    assert (course / "submitted" / "ann" / A / f"{A}.ipynb").read_bytes() == good


def test_a_zip_bomb_is_not_unpacked(course, tmp_path):
    """Three notebooks of 100 MB of spaces each (300 KB zipped): over the 64 MB a notebook may have."""
    dl = tmp_path / "elsewhere" / "bomb.zip"
    with zipfile.ZipFile(dl, "w", zipfile.ZIP_DEFLATED) as z:
        for k in range(3):
            with z.open(f"student{k}/{A}.ipynb", "w") as f:
                for _ in range(100):
                    f.write(b" " * (1 << 20))
    assert dl.stat().st_size < 1 << 20
    r = snakekit("collect", A, "--course", course, "--from", dl)
    assert r.returncode == 1, r.stderr
    refused = [line for line in r.stdout.splitlines() if "100 MB uncompressed, more than the 64 MB" in line]
    assert len(refused) == 3, r.stdout
    assert not (course / "submitted").exists()


def test_a_download_over_its_bound_is_refused_before_anything_is_read(course, tmp_path, capsys, monkeypatch):
    import grader.lms.download

    monkeypatch.setattr(grader.lms.download, "MAX_DOWNLOAD", 3 << 20)
    dl = tmp_path / "elsewhere" / "big.zip"
    with zipfile.ZipFile(dl, "w", zipfile.ZIP_DEFLATED) as z:
        for k in range(4):
            z.writestr(f"student{k}/{A}.ipynb", b" " * (1 << 20))
    r = run(capsys, "collect", A, "--course", course, "--from", dl)
    one_line_error(r, f"{dl}: its notebooks hold 4.0 MB, more than the 3.0 MB a download may hold; nothing was read")
    assert not (course / "submitted").exists()


@pytest.mark.parametrize("lms_name, entry", [
    ("Jane O'Neil", "Jane O'Neil_9001_assignfeedback_file_/t1_sweep-feedback.html"),
    ("../../etc", None), ("a/b", None), ("a\\b", None), ("a\nb", None), (".hidden", None),
])
def test_a_feedback_zip_entry_never_climbs_out_of_its_folder(lms_name, entry):
    """``return`` names a Moodle page by the manifest's name; a name that is no folder name is refused."""
    from grader.lms.export import lms_name as feedback_entry

    row = {"lms": "moodle", "lms_name": lms_name, "lms_id": "9001"}
    assert feedback_entry(row, Path(f"/feedback/ann/{A}/{A}.html")) == entry


def test_grade_reads_the_course_s_own_references_unless_told_otherwise(course, capsys):
    """Without --references, `grade` judges by <course>/references/, beside the course's cases/."""
    assert not (course / "references").exists()
    one_line_error(run(capsys, "grade", A, "--course", course),
                   f"no references folder {course}/references; give --references DIR, or record them with "
                   f"`python -m grader.scoring.references {A} --course {course}`")
    (course / "references").mkdir()
    one_line_error(run(capsys, "grade", A, "--course", course),
                   f"no reference {course}/references/{A}.npz: every test cell would keep the kernel's own verdict. "
                   f"Record it: `python -m grader.scoring.references {A} --course {course}`")


def test_grade_refuses_a_bad_lab_json_before_it_backs_up_or_grades(course, capsys):
    """A TA's slip in the lab's settings stops `grade` with exit 2 before anything is written,
    not as a failure of the grader after a backup (which would push an older one out)."""
    lab = course / "lab" / A / "lab.json"
    lab.write_text('{"sim_tolerance": NaN, "exercise": "ex2_sweep_test", '
                   '"case": {"points": 30, "rate": 10.0, "sweeps": 2, "amplitude": 0.2}}')
    handed_in = course / "submitted" / "ann" / A / f"{A}.ipynb"
    handed_in.parent.mkdir(parents=True)
    handed_in.write_bytes(notebook(course))
    before = tree(course)
    r = run(capsys, "grade", A, "--course", course, "--references", REFERENCES)
    one_line_error(r, 'lab.json: "sim_tolerance" must be a finite number > 0 and <= 0.5 [rad], got nan',
                   "nothing was graded")
    assert tree(course) == before  # no backup, no grade, no CSV
