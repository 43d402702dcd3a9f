"""The course folder as the TA's commands share it: its configuration, its gradebook (backed
up before a batch writes it; a damaged one is a :class:`CourseError` saying how to restore it),
and whether the release and the references still match the source. The paths a command may
write are checked in :mod:`grader.files`.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import os
import shutil
import sqlite3
import sys
import tempfile
import warnings
from pathlib import Path

from snakekit.errors import SnakekitError
from grader.errors import CourseError

#: Backups of the gradebook kept in ``<course>/backups/`` (the oldest are removed).
BACKUPS_KEPT = 20


def default_course() -> Path:
    """The course folder a TA's command works on without ``--course``: the current folder when it
    is one (it holds ``nbgrader_config.py``, as ``course/`` does where nbgrader's own commands
    run), else ``course/`` in it (the repository's root)."""
    return Path.cwd() if Path("nbgrader_config.py").is_file() else Path("course")


def config(course: Path):
    """The course's ``nbgrader_config.py`` as a traitlets Config (empty if there is none)."""
    from traitlets.config import Config
    from traitlets.config.loader import PyFileConfigLoader

    course = Path(course)
    if not (course / "nbgrader_config.py").exists():
        return Config()
    with on_path(course):  # a late-penalty plugin may live beside the config (nbgrader's docs: late.py)
        return PyFileConfigLoader("nbgrader_config.py", path=str(course)).load_config()


@contextlib.contextmanager
def on_path(folder: Path):
    sys.path.insert(0, str(folder))
    try:
        yield
    finally:
        with contextlib.suppress(ValueError):
            sys.path.remove(str(folder))


def course_id(course: Path) -> str:
    try:
        cfg = config(course)
        cid = cfg.CourseDirectory.get("course_id") if "CourseDirectory" in cfg else None
        return cid if isinstance(cid, str) and cid else "default_course"
    except Exception:  # noqa: BLE001 - a config we cannot read: nbgrader's default id
        return "default_course"


def db_url(course: Path) -> str:
    return f"sqlite:///{Path(course) / 'gradebook.db'}"


@contextlib.contextmanager
def gradebook(course: Path):
    """nbgrader's Gradebook of the course (its SQLAlchemy session warnings silenced)."""
    from nbgrader.api import Gradebook
    from sqlalchemy.exc import DatabaseError

    path = Path(course) / "gradebook.db"
    if path.is_file() and path.stat().st_size == 0:  # nbgrader would make an empty gradebook of it: all grades gone
        raise gradebook_error(course, sqlite3.DatabaseError("the file is empty, 0 bytes"))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Gradebook(db_url(course), course_id(course)) as gb:
                yield gb
    except (DatabaseError, sqlite3.DatabaseError) as e:
        raise gradebook_error(course, e) from None


def gradebook_error(course: Path, e: Exception) -> CourseError:
    """What to do about an SQLite error of the course's gradebook."""
    why = str(getattr(e, "orig", None) or e).splitlines()[0][:200]
    path = Path(course) / "gradebook.db"
    if "locked" in why or "busy" in why:
        return CourseError(f"the gradebook {path} is in use ({why}); wait for the other command (or formgrader's "
                           "save) to end and run this again")
    backups = sorted((Path(course) / "backups").glob("gradebook-*.db"))
    restore = (f"restore the newest backup: cp {backups[-1]} {path}" if backups else
               f"restore it from a copy (no backups in {Path(course) / 'backups'})")
    return CourseError(f"the gradebook {path} cannot be read ({why}): it is damaged or not a gradebook; {restore}")


def assignments(course: Path) -> list[str]:
    """Assignments the course has: in ``source/`` or in the gradebook."""
    course = Path(course)
    names = {p.name for p in (course / "source").iterdir() if p.is_dir() and not p.name.startswith(".")} \
        if (course / "source").is_dir() else set()
    if (course / "gradebook.db").exists():
        with gradebook(course) as gb:  # a damaged one: CourseError, saying how to restore it
            names |= {a.name for a in gb.assignments if a.notebooks}
    return sorted(names)


def check_assignment(course: Path, assignment: str) -> None:
    """Raise :class:`CourseError` naming the assignments that exist if ``assignment`` is not one."""
    found = assignments(course)
    if assignment not in found:
        raise CourseError(f"no assignment '{assignment}' in {course}"
                          + (f"; the course has: {', '.join(found)}" if found else " (no source/ folder, no gradebook)"))


def require(course: Path, assignment: str | None = None) -> None:
    """Raise :class:`CourseError` unless ``course`` is a folder (with ``assignment``)."""
    if not Path(course).is_dir():
        raise CourseError(f"no course folder {course} (give --course DIR, the folder with nbgrader_config.py)")
    if assignment is not None:
        check_assignment(course, assignment)


def default_roster(course: Path, given: Path | None) -> Path | None:
    """``--roster`` if given (it must be a file), else ``<course>/roster.csv`` if there is one."""
    if given is not None and not Path(given).is_file():
        raise CourseError(f"--roster {given} is not a file")
    return given or (Path(course) / "roster.csv" if (Path(course) / "roster.csv").is_file() else None)


# --- the gradebook's backups ------------------------------------------------------------------


def backup_gradebook(course: Path, keep: int = BACKUPS_KEPT) -> Path | None:
    """Copy ``gradebook.db`` to ``<course>/backups/gradebook-<UTC time>.db`` (SQLite's online
    backup: a consistent copy even while formgrader has it open); keep the newest ``keep``."""
    src = Path(course) / "gradebook.db"
    if not src.exists():
        return None
    folder = Path(course) / "backups"
    folder.mkdir(exist_ok=True)
    stamp = dt.datetime.now(dt.timezone.utc).strftime("%Y%m%d-%H%M%S-%f")
    dest = folder / f"gradebook-{stamp}.db"
    try:
        _copy_db(src, dest)
    except sqlite3.DatabaseError as e:
        dest.unlink(missing_ok=True)
        raise gradebook_error(course, e) from None
    for old in sorted(folder.glob("gradebook-*.db"))[:-keep]:
        old.unlink()
    return dest


# --- is the release (and the gradebook) what the source gives now? ---------------------------


def generate(config_dir: Path, root: Path, assignment: str, *, db: str | None = None) -> None:
    """``nbgrader generate_assignment`` of ``root/source/<assignment>`` with the course's own
    configuration (read from ``config_dir``), its gradebook ``db`` (default: ``root``'s)."""
    from nbgrader.apps import NbGraderAPI
    from nbgrader.coursedir import CourseDirectory
    from traitlets.config import Config

    config_dir, root = Path(config_dir).resolve(), Path(root).resolve()  # nbgrader works from inside root
    cfg = config(config_dir)
    cfg.merge(Config({"CourseDirectory": {"root": str(root), "course_id": course_id(config_dir),
                                          "db_url": db or db_url(root)}}))
    venv_bin = str(Path(os.path.abspath(sys.executable)).parent)  # nbgrader calls alembic
    if venv_bin not in os.environ.get("PATH", "").split(os.pathsep):
        os.environ["PATH"] = f"{venv_bin}{os.pathsep}{os.environ.get('PATH', '')}"
    cwd = os.getcwd()
    os.chdir(root)  # nbgrader resolves some paths from the working folder
    try:
        with on_path(config_dir):
            api = NbGraderAPI(CourseDirectory(config=cfg), config=cfg)
            out = api.generate_assignment(assignment, force=True, create=True)
    finally:
        os.chdir(cwd)
    if not out.get("success"):
        raise CourseError(f"nbgrader generate_assignment {assignment} failed: {nbgrader_reason(out)}; fix "
                          f"source/{assignment} and run the command again")


def nbgrader_reason(out: dict) -> str:
    """What nbgrader says was wrong, in one line: the first exception its log names (its own last
    words are often only "Please see the above traceback"), else the last line of its traceback."""
    import re

    lines = f"{out.get('log') or ''}\n{out.get('error') or ''}".splitlines()
    said = [m for m in (re.match(r"\s*(?:[\w.]+\.)?(\w+(?:Error|Exception)): (.+)", x) for x in lines) if m]
    said = [m for m in said if "above traceback" not in m[2]]
    if said:
        return f"{said[0][2].strip()} ({said[0][1]})"
    return next((x.strip() for x in reversed(lines) if x.strip()), "no reason given")


def regenerate(course: Path, assignment: str) -> None:
    """``nbgrader generate_assignment --force`` into a temporary copy of the course's release and
    gradebook; ``release/<a>`` and the gradebook are replaced only when it succeeded, so a failure
    (raised as :class:`CourseError`) leaves both as they were."""
    course = Path(course).resolve()
    with tempfile.TemporaryDirectory(prefix=".snakekit-regenerate-", dir=course) as tmp:
        root = Path(tmp)
        shutil.copytree(course / "source" / assignment, root / "source" / assignment,
                        ignore=shutil.ignore_patterns(".ipynb_checkpoints"))
        book = course / "gradebook.db"
        if book.exists():
            _copy_db(book, root / "gradebook.db")
        try:
            generate(course, root, assignment)
        except CourseError as e:
            raise CourseError(f"{e}; {course}/release/{assignment}/ and the gradebook are as they were") from None
        release = course / "release" / assignment
        release.parent.mkdir(exist_ok=True)
        if release.exists():
            release.rename(root / "previous-release")
        (root / "release" / assignment).rename(release)
        _copy_db(root / "gradebook.db", book)


def _copy_db(src: Path, dest: Path) -> None:
    with contextlib.closing(sqlite3.connect(src)) as s, contextlib.closing(sqlite3.connect(dest)) as d:
        s.backup(d)


def _cells(nb_path: Path) -> list:
    import nbformat

    nb = nbformat.read(nb_path, as_version=4)
    return [(c.cell_type, c.source, dict(c.metadata.get("nbgrader", {}))) for c in nb.cells]


def _gradebook_cells(url: str, cid: str, assignment: str) -> dict:
    from nbgrader.api import Gradebook, MissingEntry

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with Gradebook(url, cid) as gb:
            try:
                a = gb.find_assignment(assignment)
            except MissingEntry:
                return {}
            out = {}
            for nb in a.notebooks:
                for c in nb.source_cells:
                    out[(nb.name, c.name)] = (c.cell_type, c.source, bool(c.locked))
                for g in nb.grade_cells:
                    out[(nb.name, g.name, "points")] = float(g.max_score)
            return out


def extra_notebooks(course: Path, assignment: str) -> list[str]:
    """The notebooks of ``source/<a>`` that its release never had (by name; a stray copy such as
    ``06_coded_sweep (copy).ipynb``): from ``release/<a>`` if the course has it, else the gradebook."""
    course = Path(course)
    release = course / "release" / assignment
    if release.is_dir():
        had = {p.name for p in release.glob("*.ipynb")}
    else:
        with gradebook(course) as gb:
            had = {f"{nb.name}.ipynb" for a in gb.assignments if a.name == assignment for nb in a.notebooks}
    return sorted(p.name for p in (course / "source" / assignment).glob("*.ipynb") if p.name not in had) if had \
        else []


def release_differences(course: Path, assignment: str) -> list[str]:
    """How ``release/<a>`` (if the course has it) and the gradebook differ from what ``nbgrader
    generate_assignment`` gives from ``source/<a>`` now (empty: current)."""
    course = Path(course)
    with tempfile.TemporaryDirectory(prefix="snakekit-release-") as tmp:
        root = Path(tmp)
        shutil.copytree(course / "source" / assignment, root / "source" / assignment,
                        ignore=shutil.ignore_patterns(".ipynb_checkpoints"))
        generate(course, root, assignment)
        out = []
        fresh = sorted((root / "release" / assignment).glob("*.ipynb"))
        released = (course / "release" / assignment).is_dir()  # a grading-only copy of the course may have none
        for nb in fresh if released else []:
            have = course / "release" / assignment / nb.name
            if not have.exists():
                out.append(f"release/{assignment}/{nb.name} is missing")
            elif _cells(have) != _cells(nb):
                out.append(f"release/{assignment}/{nb.name} differs from what the source gives now")
        old = _gradebook_cells(db_url(course), course_id(course), assignment)
        new = _gradebook_cells(db_url(root), course_id(course), assignment)
        changed = sorted({k[1] for k in set(old) | set(new) if old.get(k) != new.get(k)})
        if changed:
            out.append(f"the gradebook's cells differ from the source's ({', '.join(changed[:6])}"
                       + (", ..." if len(changed) > 6 else "") + "): grading would run the old tests")
    return out


# --- the source a reference was recorded from -----------------------------------------------


def released_files(course: Path, assignment: str) -> list[Path]:
    """The files of ``source/<a>`` nbgrader's release copies: none whose name (or a folder's on
    its way) matches the course's ``CourseDirectory.ignore``, only those matching its
    ``include`` (what a run of the notebook writes beside it is ignored by the course's config)."""
    import fnmatch

    from nbgrader.coursedir import CourseDirectory

    cd = CourseDirectory(config=config(course))
    folder = Path(course) / "source" / assignment
    return sorted(p for p in folder.rglob("*") if p.is_file()
                  and not any(fnmatch.fnmatch(part, g) for part in p.relative_to(folder).parts for g in cd.ignore)
                  and any(fnmatch.fnmatch(p.name, g) for g in cd.include))


#: A class's files in a course folder: what a copy of the course for grading another class leaves out.
CLASS_FILES = ("release", "submitted", "autograded", "feedback", "gradebook.db", ".nbgrader.log", "backups",
               "collected", "draws", "__pycache__")


def course_copy_ignore(folder: str, names: list[str]) -> list[str]:
    """``shutil.copytree``'s ``ignore`` for a copy of a course as a class would grade it: none of a class's
    files, no run's ``.npz`` beside a notebook; the references in ``references/`` stay (grading reads them)."""
    runs = [n for n in names if n.endswith(".npz")] if Path(folder).name != "references" else []
    return [n for n in names if n in CLASS_FILES] + runs


def source_hash(course: Path, assignment: str) -> str:
    """A hash of what a reference depends on in ``source/<a>``: every code cell of its
    notebooks and every other file the release ships (markdown and outputs do not change a
    hand-in, nor a file a run of the notebook wrote: :func:`released_files`)."""
    import nbformat

    folder = Path(course) / "source" / assignment
    h = hashlib.sha256()
    for path in released_files(course, assignment):
        h.update(str(path.relative_to(folder)).encode() + b"\0")
        if path.suffix == ".ipynb":
            for c in nbformat.read(path, as_version=4).cells:
                if c.cell_type == "code":
                    h.update(c.source.encode() + b"\0")
        else:
            h.update(path.read_bytes())
    return h.hexdigest()[:16]
