"""The adversarial corpus: bad and malicious submissions of the test course, with the verdict due.

Each :class:`Case` makes one student's submission and states what the grader must report:
the CSV status, the score (out of 7: exercise 1 is 2 points, exercise 2 is 4, exercise 3 is 1)
and a phrase of the reason. ``tests/grader/test_grader_adversarial.py`` grades them all in one batch.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Callable

from grader_helpers import GOOD, submit

#: a marker the host-side checks look for (a file that must never appear, a port that must stay silent)
PWNED = "snakekit-grader-pwned"


@dataclass(frozen=True)
class Case:
    kind: str
    student: str
    make: Callable  # (course, student, ctx) -> None
    status: str
    score: float
    reason: str = ""  # a phrase of the CSV detail or of an exercise's message
    at_most: bool = False  # the score is a bound (it depends on the batch's cases), not the exact score


def answers(**cells):
    return lambda course, student, ctx: submit(course, student, {k: v.format(**ctx) for k, v in cells.items()})


def edit(fn):
    return lambda course, student, ctx: submit(course, student, edit=fn)


def _cell(nb, gid):
    return next(c for c in nb.cells if c.get("metadata", {}).get("nbgrader", {}).get("grade_id") == gid)


def _delete(nb):
    nb.cells.remove(_cell(nb, "ex1_tool_xy_test"))


def _edit(nb):
    _cell(nb, "ex2_sweep_test").source = "sweep = my_sweep()  # the check is gone"


def _duplicate(nb):
    c = _cell(nb, "ex1_tool_xy_test")
    twin = copy.deepcopy(c)
    twin["id"] = "twin-of-" + c["id"][:20]  # Jupyter gives a pasted copy an id of its own
    nb.cells.insert(nb.cells.index(c) + 1, twin)


GOOD_XY = GOOD["ex1_tool_xy"]
#: right at q = 0, so the visible check passes and the hidden cases reach the grader
AT_ZERO = "def tool_xy(q):\n    if not np.any(q):\n        return np.array([0.3315, 0.0])\n"

CASES = [
    Case("a good submission", "good", answers(), "graded", 7.0),
    Case("an infinite loop", "loop", answers(ex3_peak_speed="while True:\n    pass"), "timeout", 6.0, "longer than"),
    Case("a sleep that never ends", "sleep", answers(ex1_tool_xy="import time\ntime.sleep(10**6)"), "timeout", 5.0,
         "longer than"),
    Case("an exception at import", "import_error", answers(ex1_tool_xy="import snakekit_solutions_please\n" + GOOD_XY),
         "graded", 5.0, "nothing was handed in"),
    Case("sys.exit", "sys_exit", answers(ex1_tool_xy="import sys\nsys.exit(3)"), "graded", 5.0, "nothing was handed in"),
    Case("os._exit", "os_exit", answers(ex2_sweep="import os\nos._exit(0)"), "kernel died", 2.0, "kernel stopped"),
    Case("a kernel crash (segfault)", "segfault", answers(ex2_sweep="import ctypes\nctypes.string_at(0)"),
         "kernel died", 2.0, "kernel stopped"),
    Case("killing the kernel's parent", "kill_parent",
         answers(ex3_peak_speed="import os, signal\nos.kill(os.getppid(), signal.SIGKILL)\n" + GOOD["ex3_peak_speed"]),
         "graded", 7.0),
    Case("a memory hog", "memory_hog", answers(ex3_peak_speed="hog = np.ones((3 << 30) // 8)"), "memory limit", 6.0,
         "more than"),
    Case("megabytes of output", "big_output",
         answers(ex3_peak_speed="for i in range(20000):\n    print('spam ' * 40)\n" + GOOD["ex3_peak_speed"]),
         "graded", 7.0),
    # a test cell is always run as released: an edit to it costs nothing, and the TA is told
    Case("a deleted test cell", "deleted_test", edit(_delete), "tests restored", 7.0, "deleted: put back as released"),
    Case("an edited test cell", "edited_test", edit(_edit), "tests restored", 7.0, "edited: run as released"),
    Case("a duplicated test cell", "duplicated_test", edit(_duplicate), "tests restored", 7.0,
         "duplicated: run once, as released"),
    Case("a renamed function", "renamed", answers(ex1_tool_xy=GOOD_XY.replace("def tool_xy", "def tool_position")),
         "graded", 5.0, "nothing was handed in"),
    Case("wrong shapes", "wrong_shape", answers(ex1_tool_xy=AT_ZERO + "    return np.zeros(3)"), "graded", 5.0,
         "has shape (3,), expected (2,)"),
    Case("NaN", "nan", answers(ex1_tool_xy=AT_ZERO + "    return np.array([np.nan, 0.0])"), "graded", 5.0,
         "the result[0] is nan: every value must be a finite number"),
    Case("monkeypatching numpy", "patch_numpy",
         answers(ex1_tool_xy="np.allclose = lambda *a, **k: True\ndef tool_xy(q):\n    return np.array([0.3315, 0.0])"),
         "graded", 5.0, "8 of 8 hidden cases wrong"),
    Case("monkeypatching the checks (a forged hand-in)", "patch_checks",
         answers(ex1_tool_xy=GOOD_XY + "\nimport os\nfrom snakekit import handin\n"
                 "def _forged(self, grade_id, fn, **kw):\n"
                 "    folder = os.environ.get('SNAKEKIT_HANDIN_DIR')\n"
                 "    if folder:\n"
                 "        open(os.path.join(folder, grade_id + '.npz'), 'wb').write(handin.encode_results([np.zeros(2)] * 8))\n"
                 "checks.Exercise.hand_in = _forged"),
         "graded", 1.0, "8 of 8 hidden cases wrong"),
    Case("reading the references and the hidden tests", "read_secrets",
         answers(ex1_tool_xy="import glob, os\nfound = []\n"
                 "for pattern in {secrets!r}:\n"
                 "    for p in glob.glob(pattern, recursive=True):\n"
                 "        try:\n            open(p, 'rb').read(1); found.append(p)\n"
                 "        except OSError:\n            pass\n"
                 "print('found', found)\n"
                 "def tool_xy(q):\n    return np.array([0.3315, 0.0]) if not found else np.array([0.0, 0.0])"),
         "graded", 5.0, "8 of 8 hidden cases wrong"),
    Case("writing outside its folder and into the gradebook", "write_outside",
         answers(ex3_peak_speed="import glob, os, sqlite3\nwritten = []\n"
                 "for p in {targets!r}:\n"
                 "    try:\n        open(p, 'a').write('x'); written.append(p)\n    except OSError:\n        pass\n"
                 "for db in glob.glob({gradebook!r}):\n"
                 "    try:\n        sqlite3.connect(db).execute('DROP TABLE grade'); written.append(db)\n"
                 "    except Exception:\n        pass\n"
                 "print('written', written)\n"
                 "import resource\nstatus = open('/proc/self/status').read()\n"
                 "print('who', os.getuid(), os.geteuid(), 'nonewprivs', status.split('NoNewPrivs:')[1].split()[0], "
                 "'memory', resource.getrlimit(resource.RLIMIT_AS)[0] >> 20, "
                 "'cpu', resource.getrlimit(resource.RLIMIT_CPU)[0])\n" + GOOD["ex3_peak_speed"]),
         "graded", 7.0),
    Case("network access", "network",
         answers(ex3_peak_speed="import socket\nreached = []\n"
                 "for host, port in [('127.0.0.1', {port}), ({host_ip!r}, {port}), ('1.1.1.1', 53)]:\n"
                 "    try:\n        socket.create_connection((host, port), timeout=2).sendall(b'{pwned}'); "
                 "reached.append(host)\n"
                 "    except OSError:\n        pass\n"
                 "print('reached', reached)\n" + GOOD["ex3_peak_speed"]),
         "graded", 7.0),
    Case("asking the case socket before the test cell runs", "peek_cases",
         answers(ex1_tool_xy="import os\nfrom snakekit.handin import fetch_cases\n"
                 "early = fetch_cases(os.environ['SNAKEKIT_CASES'], 'ex1_tool_xy_test') "
                 "if os.environ.get('SNAKEKIT_CASES') else []\n"
                 "looked_up = {{np.asarray(a[0], dtype=float).tobytes(): np.asarray(snakekit.tool_pose_2d(a[0])[:2]) "
                 "for a in early}}\n"
                 "print('asked ahead:', len(early), 'cases')\n"
                 "def tool_xy(q):\n    q = np.asarray(q, dtype=float)\n"
                 "    if not np.any(q):\n        return np.array([0.3315, 0.0])\n"
                 "    return looked_up.get(q.tobytes(), np.zeros(2))"),
         "graded", 5.0, "asked ahead: 0 cases"),
    Case("printing whatever it can read, plain and base64", "print_secrets",
         answers(ex1_tool_xy="import base64, os\nfrom pathlib import Path\n"
                 "import snakekit\n"
                 "kit = Path(snakekit.__file__).resolve().parents[1]  # the kit's own public files (a clone under /tmp)\n"
                 "roots = [Path.cwd().parents[3], Path('/tmp'), Path('/dev/shm')]\n"
                 "for root in roots:\n"
                 "    for p in sorted(root.rglob('*')):\n"
                 "        try:\n"
                 "            if not p.is_file() or p.stat().st_size > 2 << 20 or '.mpl' in p.parts or \\\n"
                 "                    p.resolve().is_relative_to(kit) or 'site-packages' in p.parts:\n"
                 "                continue\n"
                 "            data = p.read_bytes()\n"
                 "        except OSError:\n            continue\n"
                 "        print('FILE', p)\n"
                 "        print(data.decode('utf-8', 'replace'))\n"
                 "        print('B64', base64.b64encode(data).decode())\n" + GOOD_XY),
         "graded", 7.0, "FILE"),
    Case("a library result kept from import time", "import_time_result",
         answers(ex2_sweep="_kept = snakekit.side_sweep()  # before the shortcut guard is in place\n"
                 "def my_sweep(points=500, rate=10.0, sweeps=50, amplitude=0.2):\n    return _kept"),
         "graded", 4.5, "points: 500, expected", at_most=True),
    Case("a reference to the library function kept in the notebook", "kept_reference",
         answers(ex1_tool_xy="fk = snakekit.tool_pose_2d  # kept before the shortcut guard patches it\n"
                 "def tool_xy(q):\n    return fk(q)[:2]"),
         "graded", 5.0, "`snakekit.tool_pose_2d` was called"),
    Case("a reference to the library function kept in a default argument", "kept_in_default",
         answers(ex1_tool_xy="def tool_xy(q, _fk=snakekit.tool_pose_2d):  # out of the guard's reach\n"
                 "    return _fk(q)[:2]"),
         "graded", 7.0),
    Case("calling the visible check cell's helper", "check_helper",
         answers(ex1_tool_xy="def tool_xy(q):\n    return at_home()  # the check's own worked number"),
         "graded", 5.0, "8 of 8 hidden cases wrong"),
    Case("a classmate whose notebook holds a marker", "classmate",
         answers(ex3_peak_speed="# classmate-marker-7c1f\n" + GOOD["ex3_peak_speed"]), "graded", 7.0),
    Case("a notebook that is not valid JSON", "not_json",
         lambda course, student, ctx: submit(course, student, raw='{"cells": [ this is not JSON'),
         "invalid notebook", 0.0, "not a valid notebook"),
]

