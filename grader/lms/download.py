"""An LMS's download as ``snakekit collect`` reads it: which notebook is whose, and what its name says.

* Canvas ("Download Submissions"): ``<sortablename>[_LATE]_<userid>_<fileid>_<filename>``.
* Moodle ("Download all submissions"): ``<Full Name>_<participantid>_assignsubmission_file[_]/<filename>``
  (or the same prefix on each file).
* a plain folder (or zip) of ``<student>.ipynb`` or ``<student>/<anything>.ipynb``.

Sizes are checked before anything is unpacked (:data:`grader.files.MAX_FILE` a notebook,
:data:`grader.files.MAX_DOWNLOAD` the download).
"""

from __future__ import annotations

import re
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

from grader.errors import CourseError
from grader.files import MAX_DOWNLOAD, MAX_FILE, excerpt, size_text

CANVAS = re.compile(r"^(?:(?P<name>.*?)_)??(?:(?P<late>late)_)?(?P<uid>\d+|anon_[A-Za-z0-9]+)_(?P<fid>\d+)_(?P<file>.+)$",
                    re.I | re.S)
MOODLE_DIR = re.compile(r"^(?P<name>.+?)_(?P<pid>\d+)_assignsubmission_[a-z]+_?$")
MOODLE_FLAT = re.compile(r"^(?P<name>.+?)_(?P<pid>\d+)_assignsubmission_file_(?P<file>.+)$", re.S)
RESUBMISSION = re.compile(r"^(?P<stem>.*?)-(?P<n>\d+)$")


@dataclass(frozen=True)
class Upload:
    """One notebook file of the download, and what its name says."""

    lms: str                 # canvas, moodle, folder
    lms_id: str              # Canvas user id, Moodle participant id, or the file's student name
    lms_name: str            # the name the LMS wrote (Canvas: doejane; Moodle: Jane Doe)
    file: str                # the student's own file name
    entry: str               # where it is in the download
    data: bytes
    late: bool = False
    order: tuple = ()        # larger is newer: (Canvas file id, resubmission number)


def _name_order(filename: str) -> int:
    m = RESUBMISSION.match(Path(filename).stem)
    return int(m.group("n")) if m else 0


def classify(entry: str, data: bytes) -> Upload | None:
    """What a file of the download is (None: not a notebook)."""
    parts = [p for p in entry.replace("\\", "/").split("/") if p]
    if not parts or not parts[-1].lower().endswith(".ipynb") or any(p.startswith((".", "__MACOSX")) for p in parts):
        return None
    base = parts[-1]
    for folder in parts[:-1]:
        m = MOODLE_DIR.match(folder)
        if m:
            return Upload("moodle", m["pid"], m["name"], base, entry, data, order=(0, _name_order(base)))
    m = MOODLE_FLAT.match(base)
    if m:
        return Upload("moodle", m["pid"], m["name"], m["file"], entry, data, order=(0, _name_order(m["file"])))
    m = CANVAS.match(base)
    if m:
        return Upload("canvas", m["uid"], m["name"] or "", m["file"], entry, data, late=bool(m["late"]),
                      order=(int(m["fid"]), _name_order(m["file"])))
    who = parts[-2] if len(parts) >= 2 else Path(base).stem
    return Upload("folder", who, who, base, entry, data, order=(0, _name_order(base)))


def read_download(source: Path) -> tuple[list[Upload], list[str]]:
    """Every notebook in a zip or a folder, classified; and the problems of those not read.

    Sizes are checked before anything is read: a notebook over :data:`MAX_FILE` bytes (as the
    zip declares it, and as it really unpacks) is not read, nor a download whose notebooks
    declare more than :data:`MAX_DOWNLOAD` bytes together; an entry that does not unpack (a
    damaged or encrypted one) is a problem of its own and the others are read.
    """
    out, problems = [], []

    def too_big(entry: str, size: int) -> bool:
        if size > MAX_FILE:
            problems.append(f"{excerpt(entry, quote=False)}: {size_text(size)} uncompressed, more than the "
                            f"{size_text(MAX_FILE)} a notebook may have; not read (ask the student for the notebook "
                            "without its outputs)")
        return size > MAX_FILE

    def climbs(entry: str) -> bool:
        parts = entry.replace("\\", "/").split("/")
        if ".." in parts and parts[-1].lower().endswith(".ipynb"):
            problems.append(f"{excerpt(entry, quote=False)}: a name that climbs out of the download (..); not read")
        return ".." in parts

    def at_most(total: int) -> None:
        if total > MAX_DOWNLOAD:
            raise CourseError(f"{source}: its notebooks hold {size_text(total)}, more than the "
                              f"{size_text(MAX_DOWNLOAD)} a download may hold; nothing was read (download the "
                              "submissions in parts, or check the download)")

    if source.is_dir():
        found = [(p, u) for p in sorted(source.rglob("*")) if p.is_file() and not p.is_symlink()
                 for u in [classify(str(p.relative_to(source)), b"")] if u is not None]
        at_most(sum(p.stat().st_size for p, _ in found))
        for p, u in found:
            if not too_big(u.entry, p.stat().st_size):
                out.append(replace(u, data=p.read_bytes()))
        return out, problems
    try:
        with zipfile.ZipFile(source) as z:
            found = [(info, u) for info in z.infolist() if not info.is_dir() and not climbs(info.filename)
                     for u in [classify(info.filename, b"")] if u is not None]
            at_most(sum(info.file_size for info, _ in found))
            for info, u in found:
                if too_big(u.entry, info.file_size):
                    continue
                try:
                    with z.open(info) as f:
                        data = f.read(MAX_FILE + 1)
                except Exception as e:  # noqa: BLE001 - BadZipFile, zlib.error, EOFError, an encrypted entry...
                    problems.append(f"{excerpt(u.entry, quote=False)}: cannot be unpacked ({type(e).__name__}: "
                                    f"{excerpt(e, 100)}); not read (download it again, or ask the student to upload "
                                    "it again)")
                    continue
                if not too_big(u.entry, len(data)):
                    out.append(replace(u, data=data))
    except zipfile.BadZipFile as e:
        raise CourseError(f"{source} is not a zip file ({excerpt(e, 100)}); give the LMS's download or the folder it "
                          "unpacked into") from None
    return out, problems
