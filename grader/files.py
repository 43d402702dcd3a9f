"""The course's files as every TA command reads and writes them.

* Names from outside (student ids, LMS names, the students' file names) stay in their folder:
  :func:`student_id` refuses an id that is not a plain folder name, :func:`file_name` makes a
  file name safe and :func:`unique_in` never writes over another file kept beside it.
* :func:`check_output` is the one check of every path a command is told to write: never the
  gradebook, a roster, a manifest, a notebook, a file the command reads, a file inside a folder
  another command keeps, nor an existing file the command did not write itself.
* :func:`read_table` reads a CSV as spreadsheets save it (UTF-8 with or without a byte order
  mark, UTF-16 with one, Windows-1252 / Latin-1; commas, tabs or semicolons), its size checked
  before it is read.
* :func:`excerpt` is how a message quotes what it was given: one line, at most
  :data:`EXCERPT` characters.
* :func:`uninterrupted` holds Ctrl-C back until one student's files are written whole.
"""

from __future__ import annotations

import argparse
import codecs
import contextlib
import csv
import io
import os
import re
import signal
import sys
import threading
import zipfile
from pathlib import Path

from grader.errors import CourseError


class CommandParser(argparse.ArgumentParser):
    """The grader's commands' argument parser: a bad argument prints the usage and one line, exit 2."""

    def error(self, message):
        self.print_usage(sys.stderr)
        print(f"{self.prog}: {message}", file=sys.stderr)
        raise SystemExit(2)

#: The longest quote of an input in a message [characters].
EXCERPT = 200
#: The longest message a command prints [characters].
MESSAGE = 2000
#: The largest notebook (or hand-in) the grader reads [bytes]; a larger one is not read at all.
MAX_FILE = 64 << 20
#: The largest roster, times file or manifest read [bytes] (a class of 10,000 is under 2 MB).
MAX_TABLE = 32 << 20
#: The most a download's notebooks may hold together, uncompressed [bytes].
MAX_DOWNLOAD = 2 << 30

#: What a student id may be: a folder name of letters, digits and ``. _ @ + -``.
STUDENT_ID = re.compile(r"[^\W_][\w.@+-]{0,99}")
ALLOWED_ID = "letters, digits and . _ @ + - (starting with a letter or digit, at most 100 characters)"


def excerpt(value, limit: int = EXCERPT, *, quote: bool = True) -> str:
    """``value`` quoted for a message: one line (newlines and control characters escaped), at
    most ``limit`` characters, ``…`` where it was cut; only the start of a long value is read.
    With ``quote=False`` a short printable value is shown as it is (a file name in a list)."""
    text = str(value)
    if not quote and len(text) <= limit and text.isprintable():
        return text
    shown = repr(text[:limit])
    return shown if len(text) <= limit and len(shown) <= limit else shown[: limit - 1] + "…"


def one_line(message, limit: int = MESSAGE) -> str:
    """A message as a command prints it: one line of at most ``limit`` characters."""
    text = " ".join(str(message)[: limit + 1].split())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def fitted(message, limit: int = 200) -> str:
    """A message for a line that quotes it: whole, or the sentences of it that fit in ``limit`` characters, or cut at
    a word; " …" where it was cut, never mid-word.

    >>> fitted("BusWatchdogError: they stopped. Call robot.torque_on() to clear it.", 40)
    'BusWatchdogError: they stopped. …'
    >>> fitted("CommunicationError: servo 1 did not answer the SyncRead", 40)
    'CommunicationError: servo 1 did not …'
    """
    text = " ".join(str(message).split())
    if len(text) <= limit:
        return text
    cut = text[:limit - 2]
    end = cut.rfind(". ")
    if end > len(text.split(":", 1)[0]) + 2:  # a sentence of the message, not its error type alone
        return cut[:end + 1] + " …"
    return cut.rsplit(" ", 1)[0] + " …"


def size_text(n: int) -> str:
    """``n`` bytes as a message says it (MB or GB)."""
    if n >= 1 << 30:
        return f"{n / 2**30:.1f} GB"
    return f"{n / 2**20:.1f} MB" if n < 10 << 20 else f"{n / 2**20:.0f} MB"


@contextlib.contextmanager
def uninterrupted():
    """Run the block whole: a Ctrl-C (SIGINT) during it is held back and raised as
    :class:`KeyboardInterrupt` when it ends, so a command stops between two students, never
    in the middle of one student's files or gradebook rows. Outside the main thread, or when
    SIGINT is not Python's own handler, the block runs as it is."""
    if threading.current_thread() is not threading.main_thread() or \
            signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    held = []
    signal.signal(signal.SIGINT, lambda signum, frame: held.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if held:
        raise KeyboardInterrupt


# --- names that stay in their folder ---------------------------------------------------------


def student_id(value: str, where: str) -> str:
    """``value`` if it can be a student's folder name; else :class:`CourseError` saying ``where``."""
    if not STUDENT_ID.fullmatch(value):
        raise CourseError(f"{where}: the student id {excerpt(value)} cannot be a folder name; a student id is "
                          f"{ALLOWED_ID}")
    return value


def file_name(name: str, *, limit: int = 120) -> str:
    """A name to save a student's file under: the last part of ``name``, every character other
    than letters, digits, space and ``. , _ - + ( ) @ # & '`` made ``_``, no leading dot, at most
    ``limit`` characters (the suffix kept)."""
    base = re.split(r"[/\\]", str(name))[-1]
    safe = re.sub(r"[^\w .,+()@#&'-]", "_", base).strip().lstrip(".") or "file"
    if len(safe) > limit:
        stem, dot, suffix = safe.rpartition(".")
        suffix = f".{suffix}" if dot and len(suffix) < 10 else ""
        safe = safe[: limit - len(suffix)] + suffix
    return safe


def unique_in(folder: Path, name: str, data: bytes) -> Path:
    """Where to keep ``data`` as ``name`` in ``folder`` (a safe name): the name itself, or with
    ``-2``, ``-3``, ... when another file has it; the same file again goes to the same place."""
    name = file_name(name)
    stem, suffix = (name.rsplit(".", 1)[0], "." + name.rsplit(".", 1)[1]) if "." in name else (name, "")
    n = 1
    while True:
        path = Path(folder) / (name if n == 1 else f"{stem}-{n}{suffix}")
        if not path.exists() or (path.is_file() and not path.is_symlink() and path.stat().st_size == len(data)
                                 and path.read_bytes() == data):
            return path
        n += 1


# --- paths a command may write ------------------------------------------------------------------

#: The first line of each table a command writes: a file that exists is replaced only if it is one.
OWNED = {
    "snakekit grade": re.compile(r"student,assignment,score,max_score,status(,.*)?"),
    "snakekit export": re.compile(r"student(,.*)?,total|Student,ID,SIS User ID,SIS Login ID,Section\b.*"
                                  r"|Full name,Email address,ID number,Username\b.*"),
    "snakekit lab": re.compile(r"student,state,points,reason,attempts,updated"),
}
#: Folders of a course that only their own command writes (the output of another never goes there).
KEPT = {"source": "the instructor's sources", "release": "nbgrader's release", "submitted": "the submissions",
        "autograded": "the graded copies", "feedback": "the feedback pages", "exchange": "nbgrader's exchange",
        "backups": "the gradebook's backups", "collected": "snakekit collect's manifests",
        "lab": "snakekit lab's queues and results", "cases": "the hidden test cases",
        "draws": "the hidden cases each attempt met"}
#: Files of a course no command's output may be.
COURSE_FILES = {"gradebook.db": "the gradebook", "roster.csv": "the roster", "nbgrader_config.py": "the configuration"}


def _owned_by(path: Path, command: str) -> bool:
    if command == "snakekit return":  # its zips hold feedback pages only
        try:
            with zipfile.ZipFile(path) as z:
                return all(n.endswith(("-feedback.html", "/")) for n in z.namelist())
        except (zipfile.BadZipFile, OSError, ValueError):
            return False
    with open(path, "rb") as f:
        first = f.readline(4096).decode("utf-8", "replace").lstrip("\ufeff").rstrip("\r\n")
    return bool(OWNED[command].fullmatch(first))


def check_output(path: Path, course: Path, *, suffix: str, what: str, command: str, reads: dict | None = None) -> Path:
    """Refuse an output path that would write over something of the course's (a
    :class:`CourseError` naming what it is and what to do); return ``path``.

    Every spelling of a path is the same path here (relative, ``./``, ``..``, a symbolic link,
    a hard link). ``path`` must end in ``suffix`` and lie in an existing folder; it must not be
    the gradebook or any database, a notebook, a file of :data:`COURSE_FILES`, a file inside a
    folder of :data:`KEPT`, a file of ``reads`` (``{path: what it is}``: the files this command
    reads), a file with other names (hard links), nor an existing file ``command`` did not
    write (see :data:`OWNED`).
    """
    path = Path(path)
    resolved = path.resolve()
    root = Path(course).resolve()
    said = f"{what} {path}"
    if resolved.is_dir():
        raise CourseError(f"{said} is a folder; give a file name ending in {suffix}")
    if resolved.name.lower().endswith((".db", ".sqlite", ".sqlite3")):
        raise CourseError(f"{said} would write over a gradebook; give a file name ending in {suffix}")
    if resolved.name.lower().endswith(".ipynb"):
        raise CourseError(f"{said} would write over a notebook; give a file name ending in {suffix}")
    named = {root / name: role for name, role in COURSE_FILES.items()}
    named.update({Path(p).resolve(): role for p, role in (reads or {}).items() if p is not None})
    for other, role in named.items():
        if resolved == other or (resolved.exists() and other.exists() and os.path.samefile(resolved, other)):
            raise CourseError(f"{said} is {role}; write it elsewhere")
    if resolved.suffix.lower() != suffix:
        raise CourseError(f"{said} must end in {suffix}")
    for name, role in KEPT.items():
        if resolved.is_relative_to(root / name):
            raise CourseError(f"{said} is inside {course}/{name}/ ({role}), which no other command writes; "
                              "write it elsewhere (the course folder itself is fine)")
    if not resolved.parent.is_dir():
        raise CourseError(f"cannot write {said}: the folder {path.parent} does not exist; create it first or "
                          "give a file in an existing folder")
    if resolved.exists():
        if not resolved.is_file():
            raise CourseError(f"{said} is not a regular file (a pipe, socket or device); give a file name")
        if resolved.stat().st_nlink > 1:
            raise CourseError(f"{said} has other names (hard links) that writing it would change too; give "
                              "another file name")
        if not _owned_by(resolved, command):
            raise CourseError(f"{said} exists and is not one this command wrote ({command} replaces only its own "
                              "files); give another file name")
    return path


# --- tables as spreadsheets save them ----------------------------------------------------------------


SAVE_AS = "save it from the spreadsheet as 'CSV UTF-8 (comma delimited)'"


def _text(raw: bytes, said: str, fix: str = SAVE_AS) -> str:
    if raw.startswith(codecs.BOM_UTF8):
        encoding = "utf-8-sig"
    elif raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        encoding = "utf-16"
    elif b"\0" in raw[:4096]:
        raise CourseError(f"{said} is not text (it has NUL bytes: UTF-16 without a byte order mark, or not a "
                          f"table at all); {fix}")
    else:
        encoding = "utf-8"
    try:
        return raw.decode(encoding)
    except UnicodeDecodeError:
        if encoding != "utf-8":
            raise CourseError(f"{said} is not valid {encoding.upper()} text; {fix}") from None
    try:  # Excel's plain "CSV" on Windows; Latin-1 where a byte is not Windows-1252
        return raw.decode("cp1252")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def read_table(path: Path, what: str, *, need: tuple[str, ...] = (), fix: str = "", unreadable: str = SAVE_AS,
               limit: int = MAX_TABLE) -> tuple[list[str], list[dict]]:
    """``(columns, rows)`` of a CSV table (each row a dict of stripped strings).

    Raises :class:`CourseError` (one line: which file, what is wrong, what to do) for a file
    over ``limit`` bytes (not read), text that is no table, or a column of ``need`` missing;
    ``fix`` is added to the message, ``unreadable`` replaces its advice for text in no encoding
    a spreadsheet writes.
    """
    path = Path(path)
    said = f"{what} {path}"
    try:
        size = path.stat().st_size
        if not path.is_file():
            raise CourseError(f"{said} is not a file")
        if size > limit:
            raise CourseError(f"{said} is {size_text(size)}, more than the {size_text(limit)} a {what} may be; is it the "
                              f"right file?{'; ' + fix if fix else ''}")
        text = _text(path.read_bytes(), said, unreadable)
    except OSError as e:
        raise CourseError(f"cannot read {said}: {e.strerror or e}") from None
    first = text.split("\n", 1)[0]
    delimiter = next((d for d in ",\t;" if d in first), ",")
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    try:
        header = [c.strip() for c in next(reader, [])]
        rows = [dict(zip(header, (v.strip() for v in r))) for r in reader if any(v.strip() for v in r)]
    except csv.Error as e:
        raise CourseError(f"{said}, line {reader.line_num}: not a CSV table ({excerpt(e, 80)}; it starts "
                          f"{excerpt(text, 60)}){'; ' + fix if fix else ''}") from None
    missing = [c for c in need if c not in header]
    if missing:
        raise CourseError(f"{said} has no column {', '.join(missing)} (its columns: "
                          f"{excerpt(', '.join(header) or 'none')}){'; ' + fix if fix else ''}")
    for r in rows:
        r.pop("", None)
    return header, rows
