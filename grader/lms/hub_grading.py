"""``snakekit grade`` in an instructor's or TA's server on the class's hub: the hub grades.

A hub's servers cannot make the grader's sandboxes (they keep Docker's seccomp profile and
/proc masking), so there the command asks the hub's grading service
(``docker/hub/grading_service.py``) to run the grader's container on the course volume, with
the server's hub token; the service refuses anyone outside the instructors' group (403). The
output is the grader's, as it comes; the exit code is the grader's. The hub sets
``SNAKEKIT_GRADING_URL`` (and ``SNAKEKIT_HUB_COURSE``, the course volume's folder, ``~/course``)
for the instructors' servers only.
"""

from __future__ import annotations

import json
import os
import re
import sys
import urllib.error
import urllib.request
from pathlib import Path
from urllib.parse import quote

#: The service's last line: this and the grader's exit code (grading_service.MARK).
MARK = "grading-service: exit"


#: The course folder as the grading service's container names it (docker/hub/grading_service.py).
SERVICE_COURSE = re.compile(r"(?<![\w.~/-])/course(?=[/\s:;,)'\"`]|$)")


def problems(args) -> list[str]:
    """What `snakekit grade` on the hub cannot do: another course folder, a CSV or references elsewhere."""
    from grader.scoring.references import course_references

    course = Path(os.environ.get("SNAKEKIT_HUB_COURSE", "~/course")).expanduser()
    out = []
    if args.course.resolve() != course.resolve():
        out.append(f"on the hub, grading runs on the class's course folder {course}, not {args.course}: "
                   f"`cd {course}` and run the command again")
    if args.csv is not None:
        out.append(f"on the hub the grades go to {course}/grades-{args.assignment}.csv: leave out --csv")
    if args.references is not None and args.references.resolve() != course_references(course).resolve():
        out.append(f"on the hub grading reads the course's own references ({course_references(course)}): "
                   f"leave out --references")
    return out


def grade_on_hub(args, out=None) -> int:
    """Sends ``args`` (grader.commands.grade's parsed arguments) to the hub's grading service; prints its output."""
    out = out or sys.stdout
    bad = problems(args)
    if bad:
        for p in bad:
            print(f"snakekit grade: {p}", file=sys.stderr)
        return 2
    course = Path(os.environ.get("SNAKEKIT_HUB_COURSE", "~/course")).expanduser()
    token = os.environ.get("JUPYTERHUB_API_TOKEN", "")
    url = os.environ["SNAKEKIT_GRADING_URL"].rstrip("/") + "/api/grade/" + quote(args.assignment, safe="")
    options = {"students": args.student, "regenerate": args.regenerate, "jobs": args.jobs, "timeout": args.timeout,
               "cell_timeout": args.cell_timeout, "memory": args.memory, "seed": args.seed}
    req = urllib.request.Request(url, data=json.dumps({k: v for k, v in options.items() if v}).encode(), method="POST",
                                 headers={"Authorization": f"token {token}", "Content-Type": "application/json"})
    print(f"snakekit grade: {args.assignment} graded by the hub's grading service (the grader's sandboxes, "
          f"on the course folder)", file=out, flush=True)
    code = None
    try:
        with urllib.request.urlopen(req, timeout=3600) as r:
            for raw in r:
                line = raw.decode("utf-8", "replace")
                if line.startswith(MARK):
                    code = int(line.split()[-1])
                else:   # the service's paths are the grader container's (/course): the TA's are their own
                    out.write(SERVICE_COURSE.sub(str(course).replace("\\", "\\\\"), line))
                    out.flush()
    except urllib.error.HTTPError as e:
        try:
            message = json.loads(e.read()).get("message")
        except ValueError:
            message = None
        print(f"snakekit grade: the hub's grading service refused ({e.code}): {message or e.reason}", file=sys.stderr)
        return 2
    except (urllib.error.URLError, OSError) as e:
        print(f"snakekit grade: the hub's grading service at {url} did not answer ({e}): ask the hub's "
              "administrator whether the hub runs", file=sys.stderr)
        return 1
    if code is None:
        print("snakekit grade: the hub's grading service stopped before the grader finished: run the command "
              "again", file=sys.stderr)
        return 1
    return code
