"""``snakekit release ASSIGNMENT``: an assignment out to the students in one command.

    snakekit release 06_coded_sweep [--due "2026-03-02 23:59"] [--timezone Europe/Zurich]
                                    [--late-penalty per-hour:1] [--exchange [DIR]] [--course course/]
    snakekit release 06_coded_sweep --solutions [--force] [--exchange [DIR]]   (after the due date)

nbgrader's ``generate_assignment`` (``release/<a>/``, the gradebook's cells), the due date into
the gradebook (what nbgrader's late penalty counts from), the late-penalty rule into the
course's ``nbgrader_config.py`` with the plug-in that applies it (:mod:`grader.late`), and, with
``--exchange``, nbgrader's ``release_assignment`` to the hub's exchange. With ``--solutions``,
after the due date, the worked solution instead (:mod:`grader.course.solutions`), released as
the assignment ``06_coded_sweep-solutions``. Every argument is checked before anything is
written: a bad one exits 2 with one line saying what to give.
"""

from __future__ import annotations

import datetime as dt
import os
import re
import sys
from pathlib import Path

from snakekit.errors import SnakekitError

from grader.commands.late import EXAMPLES, LatePenalty, LateRule, parse
from grader.course import solutions
from grader.course.folder import backup_gradebook, config, default_course, gradebook, regenerate
from grader.errors import CourseError
from grader.files import CommandParser, excerpt, one_line

PLUGIN = f"{LatePenalty.__module__}.{LatePenalty.__name__}"
BEGIN = "# --- late penalties: written by `snakekit release` (change them with it) ---"
END = "# --- end of the late penalties ---"


def parse_due(text: str, zone_name: str) -> dt.datetime:
    """``text`` as an aware time: ``2026-03-02 23:59`` in ``zone_name``, or with its own zone
    (``2026-03-02 23:59 Europe/Zurich``, ``2026-03-02T23:59+01:00``); a :class:`CourseError` if it is none."""
    import dateutil.parser
    import dateutil.tz

    said = f"--due {excerpt(text)}"
    zone = dateutil.tz.gettz(zone_name) if zone_name else None
    if zone is None:
        raise CourseError(f"--timezone {excerpt(zone_name)} is not a time zone; give e.g. UTC or Europe/Zurich")
    words = str(text).split()
    if len(words) == 3 and re.search(r"[A-Za-z]", words[2]):  # a zone name after the time, as nbgrader writes it
        zone = dateutil.tz.gettz(words[2])
        if zone is None:
            raise CourseError(f"{said}: '{excerpt(words[2], quote=False)}' is not a time zone; give e.g. "
                              "'2026-03-02 23:59 Europe/Zurich' or --timezone")
        text = " ".join(words[:2])
    try:
        t = dateutil.parser.isoparse(str(text).replace(" ", "T", 1))
    except (ValueError, OverflowError):
        raise CourseError(f"{said} is not a time; give it as YYYY-MM-DD HH:MM (e.g. --due '2026-03-02 23:59'), "
                          "in --timezone (default UTC) or with its own zone") from None
    return t if t.tzinfo is not None else t.replace(tzinfo=zone)


def late_block(rules: dict[str, str]) -> str:
    """The config lines that make ``rules`` the course's late penalties."""
    lines = [BEGIN, f'c.AssignLatePenalties.plugin_class = "{PLUGIN}"', "c.LatePenalty.rules = {"]
    lines += [f"    {a!r}: {r!r},  # {parse(r).describe()}" for a, r in sorted(rules.items())]
    return "\n".join(lines + ["}", END, ""])


def with_rules(text: str, rules: dict[str, str]) -> str:
    """The config ``text`` with its late-penalty block (added at the end, or replaced) holding ``rules``."""
    start, stop = text.find(BEGIN), text.find(END)
    if start >= 0 and stop > start:
        return text[:start] + late_block(rules) + text[stop + len(END):].lstrip("\n")
    return text.rstrip("\n") + "\n\n" + late_block(rules)


def _rules_now(course: Path) -> dict[str, str]:
    """The late-penalty rules the course's config has; a :class:`CourseError` when it sets another
    plug-in (a penalty of its own, which this command would silently replace)."""
    cfg = config(course)
    plugin = cfg.AssignLatePenalties.get("plugin_class") if "AssignLatePenalties" in cfg else None
    if plugin is not None and str(getattr(plugin, "__module__", "") + "." + getattr(plugin, "__name__", "")
                                  if not isinstance(plugin, str) else plugin) != PLUGIN:
        raise CourseError(f"{course}/nbgrader_config.py sets its own late-penalty plug-in "
                          f"(c.AssignLatePenalties.plugin_class = {excerpt(str(plugin))}); remove that line to let "
                          "--late-penalty set the penalty, or leave --late-penalty out")
    rules = dict(cfg.LatePenalty.get("rules", {})) if "LatePenalty" in cfg else {}
    return {str(a): str(r) for a, r in rules.items()}


def release(course: Path, assignment: str, *, due: dt.datetime | None = None, rule: str | None = None,
            exchange=None, out=None) -> None:
    """Generate the release, set the due date and the late-penalty rule, release to the exchange."""
    out = out or sys.stdout
    rules = _rules_now(course) if rule is not None else {}
    if rule is not None and due is None:
        with gradebook(course) as gb:
            known = [a for a in gb.assignments if a.name == assignment and a.duedate is not None]
        if not known:
            raise CourseError(f"{assignment} has no due date for --late-penalty to count from; give --due TIME too")
    backup_gradebook(course)
    regenerate(course, assignment)  # a failure leaves the release and the gradebook as they were
    released = sorted(p.name for p in (course / "release" / assignment).glob("*.ipynb"))
    print(f"{assignment}: released {', '.join(released) or 'no notebook'} into {course}/release/{assignment}/ "
          "(nbgrader generate_assignment)", file=out)
    if due is not None:
        utc = due.astimezone(dt.timezone.utc)
        with gradebook(course) as gb:
            gb.update_or_create_assignment(assignment, duedate=utc.replace(tzinfo=None))
        print(f"{assignment}: due {due:%Y-%m-%d %H:%M %Z} ({utc:%Y-%m-%d %H:%M} UTC), in the gradebook", file=out)
    if rule is not None:
        rules[assignment] = rule
        path = course / "nbgrader_config.py"
        text = path.read_text() if path.exists() else ""
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_text(with_rules(text, rules))
        os.replace(tmp, path)
        print(f"{assignment}: late penalty {rule}: {parse(rule).describe()} ({path})", file=out)
    if exchange is not None:
        to_exchange(course, assignment, exchange, out)


def to_exchange(course: Path, name: str, exchange, out, *, again: bool = False) -> None:
    """nbgrader's ``release_assignment`` of ``release/<name>/`` to the exchange (the hub's if
    ``exchange`` is True, else that folder); ``again`` replaces a release already there."""
    from grader.lms.export import nbgrader_api

    api = nbgrader_api(course, None if exchange is True else exchange)
    api.config.ExchangeReleaseAssignment.force = again
    result = api.release_assignment(name)
    if not result.get("success"):
        raise CourseError(f"nbgrader release_assignment {name} failed: "
                          f"{(result.get('error') or result.get('log') or '').strip()[-500:]}")
    print(f"{name}: released to the exchange (students fetch it with the Assignments tab or "
          f"`nbgrader fetch_assignment {name}`)", file=out)


def release_solutions(course: Path, assignment: str, *, force: bool = False, exchange=None, out=None) -> None:
    """The worked solution as the assignment ``<assignment>-solutions`` (:mod:`grader.course.solutions`),
    once the due date has passed (or with ``force``); with ``exchange``, into the exchange."""
    out = out or sys.stdout
    due = solutions.check(course, assignment, force=force)
    folder = solutions.write(course, assignment, due)
    names = ", ".join(sorted(p.name for p in folder.glob("*.ipynb")))
    print(f"{assignment}: its worked solution {names} is in {folder}/ (no hidden test, outputs cleared)", file=out)
    if exchange is not None:
        to_exchange(course, solutions.name(assignment), exchange, out, again=True)
    else:
        print(f"{assignment}: upload it to the LMS, or add --exchange to release it to the hub's exchange", file=out)


def main(argv: list[str] | None = None, out=None) -> int:
    p = CommandParser(prog="snakekit release", description="Release an assignment: nbgrader generate_assignment, the due "
                "date into the gradebook, the late-penalty rule into the course's config, and with --exchange "
                "nbgrader release_assignment.")
    p.add_argument("assignment", help="assignment name, e.g. 06_coded_sweep (a folder of <course>/source/)")
    p.add_argument("--course", type=Path, default=default_course(),
                   help="the nbgrader course folder (default: this folder when it is one, else course/)")
    p.add_argument("--due", default=None, help="the due date, e.g. '2026-03-02 23:59' (in --timezone) or "
                   "'2026-03-02 23:59 Europe/Zurich'")
    p.add_argument("--timezone", default="UTC", help="zone of a --due without one (default: UTC)")
    p.add_argument("--late-penalty", default=None, metavar="RULE", help=f"what a late notebook loses: {EXAMPLES.replace('%', '%%')} "
                   "(per-UNIT:N is N points per started minute/hour/day/week late, per-UNIT:N%% N %% of its score)")
    p.add_argument("--exchange", nargs="?", const=True, default=None, type=Path, metavar="DIR",
                   help="also release to nbgrader's exchange (the hub's, or DIR): nbgrader release_assignment")
    p.add_argument("--solutions", action="store_true", help="after the due date: the worked solution (no hidden "
                   "test) as the assignment ASSIGNMENT-solutions, for students to fetch (with --exchange)")
    p.add_argument("--force", action="store_true", help="with --solutions: release it before the due date")
    args = p.parse_args(argv)
    course = args.course
    try:
        if not course.is_dir():
            raise CourseError(f"no course folder {course} (give --course DIR, the folder with nbgrader_config.py)")
        if not (course / "source" / args.assignment).is_dir():
            have = sorted(d.name for d in (course / "source").iterdir() if d.is_dir()) \
                if (course / "source").is_dir() else []
            raise CourseError(f"no assignment '{args.assignment}' in {course}/source/"
                              + (f"; the course has: {', '.join(have)}" if have else ""))
        due = parse_due(args.due, args.timezone) if args.due is not None else None
        if args.late_penalty is not None:
            parse(args.late_penalty)
        if isinstance(args.exchange, Path) and not args.exchange.is_dir():
            raise CourseError(f"--exchange {args.exchange} is not a folder")
        if args.solutions:
            if args.due is not None or args.late_penalty is not None:
                raise CourseError("--solutions releases only the worked solution: give --due and --late-penalty "
                                  "in a release without it")
            release_solutions(course.resolve(), args.assignment, force=args.force, exchange=args.exchange, out=out)
            return 0
        if args.force:
            raise CourseError("--force goes with --solutions (the worked solution before the due date)")
        release(course.resolve(), args.assignment, due=due, rule=args.late_penalty, exchange=args.exchange, out=out)
    except (SnakekitError, OSError) as e:
        print(f"snakekit release: {one_line(e)}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())


__all__ = ["LateRule", "main", "parse_due", "release", "release_solutions", "to_exchange"]
