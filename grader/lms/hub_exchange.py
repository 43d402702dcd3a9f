"""nbgrader's exchange through the hub's exchange service, where who you are is your hub token.

nbgrader's own exchange classes do the work (what a release, a submission, a list or a
feedback page is, their names, timestamps and checks), on a private scratch folder: before
each command the part of the exchange the caller may see is fetched from the service, and
after it what the command wrote is sent back. The service (``docker/hub/exchange_service.py``)
decides by the caller's hub token what they may read and write: students fetch released
assignments and their own feedback and submit only as themselves; only instructors and TAs
release, collect and return. Configure it in ``nbgrader_config.py`` (the hub's image does)::

    from grader.lms.hub_exchange import use_hub_exchange
    use_hub_exchange(c)

The service's URL is ``SNAKEKIT_EXCHANGE_URL`` (default: the hub's ``/services/exchange/``
on ``JUPYTERHUB_API_URL``'s host), the token ``JUPYTERHUB_API_TOKEN`` (a hub server has both).
"""

from __future__ import annotations

import glob
import io
import json
import os
import shutil
import tarfile
import tempfile
import urllib.error
import urllib.request
from pathlib import Path
from urllib.parse import quote, urlsplit

from nbgrader.exchange import default
from nbgrader.exchange.abc import ExchangeError


def service_url() -> str:
    url = os.environ.get("SNAKEKIT_EXCHANGE_URL")
    if url:
        return url.rstrip("/") + "/"
    api = os.environ.get("JUPYTERHUB_API_URL")
    if not api:
        raise ExchangeError("no exchange service: this server was not started by a hub "
                            "(set SNAKEKIT_EXCHANGE_URL and JUPYTERHUB_API_TOKEN)")
    u = urlsplit(api)
    return f"{u.scheme}://{u.netloc}/services/exchange/"


def request(method: str, course: str, area: str, entry: str | None = None, data: bytes | None = None) -> bytes:
    """One call to the service; its refusal becomes an ExchangeError with the service's message."""
    token = os.environ.get("JUPYTERHUB_API_TOKEN")
    if not token:
        raise ExchangeError("no hub token (JUPYTERHUB_API_TOKEN): the exchange needs a server started by the hub")
    path = "/".join(quote(p, safe="") for p in (course, area, entry) if p is not None)
    req = urllib.request.Request(service_url() + "api/" + path, data=data, method=method,
                                 headers={"Authorization": f"token {token}", "Content-Type": "application/gzip"})
    try:
        with urllib.request.urlopen(req, timeout=120) as r:
            return r.read()
    except urllib.error.HTTPError as e:
        try:
            message = json.loads(e.read()).get("message") or e.reason
        except ValueError:
            message = e.reason
        raise ExchangeError(f"the exchange refused ({e.code}): {message}") from None
    except urllib.error.URLError as e:
        raise ExchangeError(f"the exchange service at {service_url()} cannot be reached: {e.reason}") from None


def pack(folder: Path) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz", compresslevel=1) as tar:
        for p in sorted(folder.rglob("*")):
            if p.is_file() and not p.is_symlink():
                tar.add(p, arcname=str(p.relative_to(folder)), recursive=False)
    return buf.getvalue()


def unpack(data: bytes, dest: Path, *, flatten: bool = False) -> None:
    dest.mkdir(parents=True, exist_ok=True)
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:*") as tar:
        for m in tar.getmembers():
            parts = Path(m.name).parts
            if not m.isfile() or m.name.startswith("/") or ".." in parts:
                continue
            target = dest / (parts[-1] if flatten else m.name)
            target.parent.mkdir(parents=True, exist_ok=True)
            with tar.extractfile(m) as src, open(target, "wb") as out:
                shutil.copyfileobj(src, out)


class HubExchange:
    """Runs nbgrader's command on a scratch exchange: ``pull`` before it, ``push`` after."""

    pulls: tuple[str, ...] = ()  # areas fetched first ("?area": when the caller may read it)
    makes: tuple[str, ...] = ()

    def course(self) -> str:
        if not self.coursedir.course_id:
            self.fail("No course id specified. Re-run with --course flag.")
        return self.coursedir.course_id

    def pull(self, area: str, *, optional: bool = False) -> None:
        try:
            data = request("GET", self.course(), area)
        except ExchangeError as e:
            if optional:
                return
            self.fail(str(e))
        # feedback comes as <student>/<hash>.html; nbgrader looks for <hash>.html
        unpack(data, Path(self.root) / self.course() / area, flatten=area == "feedback")

    def push(self, area: str, entry: str, folder: Path) -> None:
        try:
            request("PUT", self.course(), area, entry, pack(folder))
        except ExchangeError as e:
            self.fail(str(e))

    def after(self) -> None:
        """Send back what the command wrote."""

    def start(self):
        with tempfile.TemporaryDirectory(prefix="nbgrader-exchange-") as scratch:
            self.root = scratch
            for area in self.pulls:
                self.pull(area.lstrip("?"), optional=area.startswith("?"))
            for area in self.makes:  # folders nbgrader expects to find
                (Path(scratch) / self.course() / area).mkdir(parents=True, exist_ok=True)
            result = super().start()
            self.after()
        return result


class Exchange(HubExchange, default.Exchange):
    pass


class ExchangeReleaseAssignment(HubExchange, default.ExchangeReleaseAssignment):
    def after(self):
        self.push("outbound", self.coursedir.assignment_id, Path(self.dest_path))


class ExchangeFetchAssignment(HubExchange, default.ExchangeFetchAssignment):
    pulls = ("outbound",)


class ExchangeSubmit(HubExchange, default.ExchangeSubmit):
    pulls = ("outbound",)
    makes = ("inbound",)

    def after(self):
        self.push("inbound", self.assignment_filename, Path(self.inbound_path) / self.assignment_filename)


class ExchangeCollect(HubExchange, default.ExchangeCollect):
    pulls = ("inbound",)

    def start(self):
        self.check_owner = False  # the service checked who submitted; the scratch files are all ours
        return super().start()


class ExchangeList(HubExchange, default.ExchangeList):
    pulls = ("outbound", "feedback", "?inbound")

    def remove_files(self):
        self.fail("removing from the hub's exchange is not offered: release the assignment again with --force")


class ExchangeReleaseFeedback(HubExchange, default.ExchangeReleaseFeedback):
    def copy_files(self):
        # one student at a time, so that each page is stored under its student's name
        pattern = self.coursedir.format_path(self.coursedir.feedback_directory, "*", self.coursedir.assignment_id)
        students = sorted({Path(p).parent.parent.name for p in glob.glob(os.path.join(pattern, "*.html"))})
        wanted = self.coursedir.student_id
        for student in students:
            if wanted not in ("", "*") and student != wanted:
                continue
            self.coursedir.student_id = student
            self.init_src()
            shutil.rmtree(self.dest_path, ignore_errors=True)
            Path(self.dest_path).mkdir(parents=True)
            super().copy_files()
            self.push("feedback", student, Path(self.dest_path))
        self.coursedir.student_id = wanted


class ExchangeFetchFeedback(HubExchange, default.ExchangeFetchFeedback):
    pulls = ("feedback",)


def use_hub_exchange(c) -> None:
    """Point nbgrader's ExchangeFactory at these classes (in an nbgrader_config.py)."""
    for name in ("exchange", "fetch_assignment", "fetch_feedback", "release_assignment", "release_feedback",
                 "list", "submit", "collect"):
        cls = {"exchange": Exchange, "fetch_assignment": ExchangeFetchAssignment,
               "fetch_feedback": ExchangeFetchFeedback, "release_assignment": ExchangeReleaseAssignment,
               "release_feedback": ExchangeReleaseFeedback, "list": ExchangeList, "submit": ExchangeSubmit,
               "collect": ExchangeCollect}[name]
        setattr(c.ExchangeFactory, name, f"{__name__}.{cls.__name__}")
