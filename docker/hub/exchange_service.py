"""The class's nbgrader exchange as a JupyterHub service: who you are is your hub token.

nbgrader's own exchange is a shared folder that trusts ``$JUPYTERHUB_USER``, which a student
sets, and on a hub of containers every server runs as the same uid, so one student could
submit as another or read others' submissions (nbgrader issues #978, #1225). Here the
exchange's files live in a folder only this service (in the hub's container) reaches, and
every request carries the caller's hub token; the hub says whose it is and which groups they
are in. Students' servers speak to it through ``grader.lms.hub_exchange`` (nbgrader's exchange
classes, configured in the image), so ``nbgrader fetch_assignment`` / ``submit`` /
``collect`` / ``release_feedback`` / ``fetch_feedback`` and the Assignments tab work as usual.

The folder keeps nbgrader's layout, per course::

    <course>/outbound/<assignment>/...                          released (instructors write)
    <course>/inbound/<student>+<assignment>+<time>+<random>/...   submitted (its student writes, once)
    <course>/feedback/<student>/<hash>.html                      returned (instructors write)

Who may do what (``GET`` a tar of an area, ``PUT`` a tar into one entry):

============  =============================  ===========================================
area          read                           write
============  =============================  ===========================================
outbound      every hub user                 instructors (the hub groups of SNAKEKIT_INSTRUCTOR_GROUPS)
inbound       instructors (collect)          the student named first in the entry, a new
                                             entry only, at most SNAKEKIT_SUBMIT_LIMIT_MB
feedback      instructors: all; a student:   instructors
              their own folder
============  =============================  ===========================================

A write that would take the exchange over SNAKEKIT_EXCHANGE_QUOTA_MB is refused with a message
saying so. Run by the hub (``jupyterhub_config.py``'s services); settings in the environment:
SNAKEKIT_EXCHANGE_DIR, SNAKEKIT_EXCHANGE_PORT (10102).
"""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import tarfile
from pathlib import Path

from jupyterhub.services.auth import HubAuthenticated
from tornado import ioloop, web
from tornado.log import app_log

ROOT = Path(os.environ.get("SNAKEKIT_EXCHANGE_DIR", "/srv/exchange"))
PREFIX = os.environ.get("JUPYTERHUB_SERVICE_PREFIX", "/services/exchange/")
INSTRUCTORS = set(filter(None, os.environ.get("SNAKEKIT_INSTRUCTOR_GROUPS", "instructors").split(",")))
SUBMIT_LIMIT = int(float(os.environ.get("SNAKEKIT_SUBMIT_LIMIT_MB", "20")) * 1e6)
QUOTA = int(float(os.environ.get("SNAKEKIT_EXCHANGE_QUOTA_MB", "2000")) * 1e6)
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._@+ :-]{0,200}$")  # one path part: no '/', no '..'
AREAS = ("outbound", "inbound", "feedback")


def used_bytes() -> int:
    return sum(f.stat().st_size for f in ROOT.rglob("*") if f.is_file() and not f.is_symlink())


def unpack(data: bytes, dest: Path, *, merge: bool = False) -> None:
    """Extract a tar of regular files and folders into dest (nothing outside it, no links).

    The entry is replaced as a whole, or with ``merge`` its files are added to what it holds.
    """
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:*") as tar:
        members = tar.getmembers()
        for m in members:
            parts = Path(m.name).parts
            if m.name.startswith("/") or ".." in parts or not (m.isfile() or m.isdir()):
                raise web.HTTPError(400, f"the upload holds {m.name!r}: only files and folders inside it are taken")
        tmp = dest.with_name(dest.name + ".part")
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        for m in members:
            target = tmp / m.name
            if m.isdir():
                target.mkdir(parents=True, exist_ok=True)
            else:
                target.parent.mkdir(parents=True, exist_ok=True)
                with tar.extractfile(m) as src, open(target, "wb") as out:
                    shutil.copyfileobj(src, out)
        if merge and dest.is_dir():
            for f in sorted(tmp.rglob("*")):
                if f.is_file():
                    (dest / f.relative_to(tmp)).parent.mkdir(parents=True, exist_ok=True)
                    f.replace(dest / f.relative_to(tmp))
            shutil.rmtree(tmp)
            return
        shutil.rmtree(dest, ignore_errors=True)
        tmp.rename(dest)


class Exchange(HubAuthenticated, web.RequestHandler):
    """``GET api/<course>/<area>`` and ``PUT api/<course>/<area>/<entry>``."""

    def write_error(self, status_code, **kwargs):
        exc = kwargs.get("exc_info", (None, None))[1]
        message = getattr(exc, "log_message", None) or self._reason
        self.set_header("Content-Type", "application/json")
        self.finish(json.dumps({"status": status_code, "message": message}))

    @property
    def who(self) -> tuple[str, bool]:
        user = self.current_user
        return user["name"], bool(INSTRUCTORS & set(user.get("groups") or ()))

    def check(self, course: str, area: str, entry: str | None = None) -> Path:
        if area not in AREAS or not NAME.match(course) or (entry is not None and not NAME.match(entry)):
            raise web.HTTPError(404, f"no such place in the exchange: {course}/{area}/{entry or ''}")
        return ROOT / course / area

    @web.authenticated
    def get(self, course: str, area: str, entry: str | None = None):
        base = self.check(course, area)
        name, instructor = self.who
        entries = sorted(p for p in base.iterdir() if not p.name.endswith(".part")) if base.is_dir() else []
        if not instructor and area == "inbound":
            raise web.HTTPError(403, f"{name} is not an instructor or TA of this hub: only they collect submissions")
        if not instructor and area == "feedback":
            entries = [p for p in entries if p.name == name]
        buf = io.BytesIO()
        with tarfile.open(fileobj=buf, mode="w:gz", compresslevel=1) as tar:
            for p in entries:
                tar.add(p, arcname=p.name)
        self.set_header("Content-Type", "application/gzip")
        self.finish(buf.getvalue())

    @web.authenticated
    def put(self, course: str, area: str, entry: str):
        base = self.check(course, area, entry)
        name, instructor = self.who
        body = self.request.body
        if area == "inbound":
            if entry.split("+", 1)[0] != name:
                raise web.HTTPError(403, f"you are signed in as {name}: you can submit only as {name}, "
                                         f"not as {entry.split('+', 1)[0]}")
            if (base / entry).exists():
                raise web.HTTPError(409, f"{entry} was submitted already; submit again for a new entry")
            if len(body) > SUBMIT_LIMIT:
                raise web.HTTPError(413, f"the submission is {len(body) / 1e6:.1f} MB, over the class's limit of "
                                         f"{SUBMIT_LIMIT / 1e6:.0f} MB: remove large outputs or data files "
                                         f"(Kernel > Restart and Clear Outputs), save, and submit again")
        elif not instructor:
            raise web.HTTPError(403, f"{name} is not an instructor or TA of this hub: only they may write {area}")
        if used_bytes() + len(body) > QUOTA:
            raise web.HTTPError(507, f"the class's exchange is full ({QUOTA / 1e6:.0f} MB): nothing was stored; "
                                     f"tell your instructor, who can free space or raise SNAKEKIT_EXCHANGE_QUOTA_MB")
        base.mkdir(parents=True, exist_ok=True)
        unpack(body, base / entry, merge=area == "feedback")
        app_log.info("%s stored %s/%s/%s (%d bytes)", name, course, area, entry, len(body))
        self.finish({"stored": f"{course}/{area}/{entry}"})


def main() -> None:
    ROOT.mkdir(parents=True, exist_ok=True)
    part = r"([^/]+)"
    app = web.Application([
        (rf"{PREFIX}api/{part}/{part}/?", Exchange),
        (rf"{PREFIX}api/{part}/{part}/{part}/?", Exchange),
    ], cookie_secret=os.urandom(32))
    app.listen(int(os.environ.get("SNAKEKIT_EXCHANGE_PORT", "10102")), max_body_size=max(QUOTA, SUBMIT_LIMIT) + 10**6)
    ioloop.IOLoop.current().start()


if __name__ == "__main__":
    main()
