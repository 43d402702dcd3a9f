"""The class's report (``snakekit report``) in formgrader, for the instructor: a "Class reports" link in
formgrader's menu, a page listing each assignment's report, and the report itself.

Installed by the course's config (:func:`grader.commands.nbgrader_plugins.use_safe_grading`), which
formgrader reads before it registers its pages: the two pages join formgrader's own (before its
catch-all "not found"), behind formgrader's own login and XSRF checks, as its handlers are
(``@web.authenticated``, nbgrader's ``check_xsrf`` and ``check_notebook_dir``). A page serves the report
``snakekit report`` wrote in the course (``<course>/report-<assignment>/report.html``); it never
builds one (for 500 submissions that takes a minute): without one it says the command that writes it.
"""

from __future__ import annotations

import functools
import html
import re
import sys
from pathlib import Path

#: formgrader's pages of the reports, below its base URL.
ROUTES = (r"/formgrader/reports/?", r"/formgrader/reports/([^/]+)/?")
#: the menu entry, after formgrader's own three
NAV = '<li role="presentation"><a href="{base_url}/formgrader/reports">Class reports</a></li>'
_LAST_NAV = re.compile(r'(<a href="[^"]*/formgrader/manage_students">Manage Students</a></li>)')
#: the list of reports, as formgrader's other pages (its base template: menu, style, scripts)
LIST = """{%- extends 'base.tpl' -%}
{%- block breadcrumbs -%}<ol class="breadcrumb"><li class="active">Class reports</li></ol>{%- endblock -%}
{%- block table_header -%}<tr><th>Assignment</th><th>Report</th></tr>{%- endblock -%}
{%- block table_body -%}{{ rows }}{%- endblock -%}
{%- block table_footer -%}<tr><td colspan="2">A report is written by <code>snakekit report ASSIGNMENT</code>
after <code>snakekit grade</code>, in the course folder.</td></tr>{%- endblock -%}
"""


def report_file(course: Path, assignment: str) -> Path:
    from grader.commands.report import default_out
    from grader.report.page import PAGE

    return default_out(course, assignment) / PAGE


def _with_nav(render):
    """formgrader's page rendering, every page's menu with "Class reports" after its own entries."""

    @functools.wraps(render)   # keeps the marks of the wrappers inside it: each wraps formgrader once
    def rendered(self, name, **ns):
        page = render(self, name, **ns)
        link = NAV.format(base_url=html.escape(ns.get("base_url", self.base_url)))
        return page if link in page else _LAST_NAV.sub(lambda m: m.group(1) + link, page, count=1)

    rendered._snakekit_reports = True
    return rendered


def handlers_for(base, nbgrader_handlers):
    """formgrader's two report pages (``base``: its ``base`` module, for ``BaseHandler`` and its checks)."""
    from tornado import web

    class ReportsHandler(base.BaseHandler):
        """The course's assignments, each with its report or the command that writes it."""

        def _course(self) -> Path:
            return Path(self.coursedir.root)

        def _assignments(self) -> list[str]:
            with self.gradebook as gb:
                return sorted(a.name for a in gb.assignments)

        @web.authenticated
        @base.check_xsrf
        @base.check_notebook_dir
        def get(self, assignment: str | None = None):
            course = self._course()
            names = self._assignments()
            if assignment is None:
                rows = "".join(
                    f"<tr><td>{html.escape(a)}</td><td>"
                    + (f'<a href="{html.escape(self.base_url)}/formgrader/reports/{html.escape(a)}">the report</a>'
                       if report_file(course, a).is_file() else f"none yet: <code>snakekit report {html.escape(a)}</code>")
                    + "</td></tr>" for a in names)
                page = self.settings["nbgrader_jinja2_env"].from_string(LIST).render(
                    base_url=self.base_url, rows=rows or '<tr><td colspan="2">No assignment yet.</td></tr>')
                self.write(_with_nav(lambda _s, _n, **_ns: page)(self, "", base_url=self.base_url))
                return
            if assignment not in names:   # a name of the gradebook's, never a path
                raise web.HTTPError(404)
            path = report_file(course, assignment)
            if not path.is_file():
                self.set_status(404)
                self.write(f"<p>No report of {html.escape(assignment)} yet: run <code>snakekit report "
                           f"{html.escape(assignment)}</code> in the course folder after <code>snakekit grade</code>.</p>")
                return
            self.set_header("Content-Type", "text/html; charset=utf-8")
            self.write(path.read_bytes())

    return [(ROUTES[0], ReportsHandler), (ROUTES[1], ReportsHandler)]


def install(handlers) -> None:
    """formgrader (``handlers``: its API handlers' module) with the report pages and the menu entry. Installing
    twice changes nothing; after formgrader registered its pages, the routes wait for the next server."""
    package = handlers.__name__.rsplit(".", 1)[0]
    base = sys.modules[package + ".base"]
    pages = sys.modules.get(package + ".handlers")
    if pages is not None and not any(route[0] == ROUTES[0] for route in pages.default_handlers):
        pages.default_handlers[:0] = handlers_for(base, pages)
    if not getattr(base.BaseHandler.render, "_snakekit_reports", False):
        base.BaseHandler.render = _with_nav(base.BaseHandler.render)
