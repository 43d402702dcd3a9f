"""``snakekit start``: check this system, then open the lessons in a student's JupyterLab.

``make lab`` runs it, on Linux and macOS alike. It first says what the system lacks, with
what to install there (:func:`snakekit.host.missing`); then it starts JupyterLab on the
lessons in ``notebooks/``:

- nbgrader's Validate button on, its teacher tools (formgrader, create assignment, the
  exchange's lists) off: their server extensions by
  ``tools/student-server/jupyter_server_config.json``, their UI by
  ``tools/student-lab/labconfig/page_config.json`` (the container and Binder read both too);
- offline: no update check (and the news feed off, by ``tools/jupyterlab-overrides.json``,
  which tools/setup copies into the venv);
- without rfc3987-syntax: jsonschema loads it, when installed, for an "iri" format check
  Jupyter never makes, and it compiles 25 Earley grammars on import (about 1.9 s of every
  start, more than half of the time to a ready JupyterLab; see bench/RESULTS.md).

    snakekit start [--ip 127.0.0.1] [--port 8888] [--notebooks DIR] [--check]

Exit codes: 0 the checks passed (``--check``) or JupyterLab ended normally, 1 the system
lacks something (printed, with the fix), 2 bad arguments; otherwise JupyterLab's own.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

from . import host

#: the checkout the kit runs from (``make lab``): the lessons and the student lab's settings
KIT = Path(__file__).resolve().parents[1]
STUDENT_LAB_CONFIG = KIT / "tools" / "student-lab"
#: the same lab's server settings (apart, so that a TA's JupyterLab can share the page's)
STUDENT_SERVER_CONFIG = KIT / "tools" / "student-server"

LAB_MAIN = ('import sys; sys.modules["rfc3987_syntax"] = None; '
            'from jupyterlab.labapp import main; sys.exit(main())')


def lab_arguments(notebooks: Path, *, ip: str, port: int) -> list[str]:
    """JupyterLab's command-line options for the student's lab on ``notebooks``."""
    return ["--no-browser", "--allow-root", f"--ip={ip}", f"--port={port}",
            f"--ServerApp.root_dir={notebooks}", "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate"]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="snakekit start", description="Check this system, then open the lessons in "
                                "JupyterLab (what `make lab` runs).")
    p.add_argument("--ip", default="127.0.0.1", help="address JupyterLab listens on (default: 127.0.0.1)")
    p.add_argument("--port", type=int, default=8888, help="its port (default: 8888)")
    p.add_argument("--notebooks", type=Path, default=KIT / "notebooks", metavar="DIR",
                   help="the folder of lessons to open (default: the kit's notebooks/)")
    p.add_argument("--check", action="store_true", help="only check this system: say what it lacks and exit")
    return p


def main(argv: list[str] | None = None, out=None) -> int:
    out = out or sys.stdout
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    if not 0 < args.port < 65536:
        print(f"snakekit start: --port {args.port} is not a TCP port (1-65535)", file=sys.stderr)
        return 2

    gl = host.choose_mujoco_gl()
    needs = host.missing()
    if not args.notebooks.is_dir():
        needs.append(host.Need(f"the lessons' folder {args.notebooks} does not exist",
                               "run from the kit's folder (`make lab`), or give the folder with --notebooks DIR"))
    for settings in (STUDENT_LAB_CONFIG, STUDENT_SERVER_CONFIG):
        if not settings.is_dir():
            needs.append(host.Need(f"the student lab's settings ({settings}) are missing",
                                   "run from a checkout of the kit (`make lab`)"))
    where = f"{host.describe()}, Python {sys.version.split()[0]}, MUJOCO_GL={gl or '(MuJoCo default)'}"
    if needs:
        print(f"snakekit start: this system ({where}) lacks what the lessons need:", file=sys.stderr)
        for need in needs:
            print(f"- {need}", file=sys.stderr)
        return 1
    if args.check:
        print(f"snakekit start: this system ({where}) has what the lessons need", file=out)
        return 0

    print(f"snakekit: JupyterLab on the lessons in {args.notebooks} (the simulator is the default robot)", file=out)
    out.flush()
    os.environ["JUPYTER_CONFIG_PATH"] = os.pathsep.join(map(str, (STUDENT_LAB_CONFIG, STUDENT_SERVER_CONFIG)))
    command = [sys.executable, "-c", LAB_MAIN, *lab_arguments(args.notebooks, ip=args.ip, port=args.port)]
    if os.name == "posix":  # JupyterLab takes this process's place: Ctrl-C and SIGTERM reach it directly
        sys.stderr.flush()
        os.execv(sys.executable, command)
    return subprocess.call(command)
