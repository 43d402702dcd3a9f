#!/usr/bin/env python3
"""A week of the class on the hub, as its users do it (docker/hub/test.sh runs this).

    loop.py HUB_URL --passwords CSV --students 20 [--submitting K] [--old-shared-password PW] [--browser DIR]

First the log-ins the hub refuses: a student's name with another's password, the teacher's name
with a student's password or none, the old shared password, a name without an account, and
the sign-up page. Then everyone logs in through the hub (its log-in form, with their own
password from CSV, ``username,password`` as docker/hub/accounts prints it, then a token from
the hub's REST API) and
works through their own server behind the hub's proxy: the instructor releases lesson 06;
the students (or the first K of them: --submitting) fetch it (the Assignments tab's API), fill the exercises (the instructor's
answers, or for every third student a slip in one of them), save (the contents API) and
submit; the TA collects, grades (`snakekit grade`, which the hub's grading service runs in the
grader's container on the course volume) and returns the feedback; every student fetches it.
The instructor's and TA's commands are docker/hub/README.md's, run as typed in a terminal of
their server (a login shell in ~/course). The class logs in at once: each student's log-in,
token and server start together, timed to a ready server. Then the
refusals: a student submitting as another, reading another's submission or feedback,
collecting, reaching another's server or the hub's secrets; a submission over the size limit
and a full exchange get their messages; a stopped (culled) server loses nothing saved. After
lesson 00 in Chromium: that student's 3D view is refused to another student, on the hub's
network (its server listens on the container's loopback) and through the hub's proxy.
Instructor and TA commands run in their own servers' containers (`docker exec`, as at their
terminal). Prints lines "figure: ..." and exits non-zero at the first wrong result.
"""

from __future__ import annotations

import argparse
import csv
import io
import os
import shlex
import statistics
import subprocess
import sys
import tarfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import nbformat
import requests
from checks import fail, log_in, memory_of, refused_log_ins, role_commands, say, view_is_the_owners

REPO = Path(__file__).resolve().parents[2]
LESSON = "06_coded_sweep"
COURSE = "snakekit"
DOCKER = os.environ.get("DOCKER", "docker")


def read_passwords(path: str) -> dict[str, str]:
    with open(path, encoding="utf-8") as f:
        return {row["username"]: row["password"] for row in csv.DictReader(f)}


class User:
    """A hub user: logged in through the form, with a token from the REST API."""

    def __init__(self, hub: str, name: str, password: str):
        self.hub, self.name = hub.rstrip("/"), name
        s, r = log_in(self.hub, name, password)
        if r.status_code != 302:
            fail(f"{name} could not log in with their own password: {r.status_code}")
        self.web = s  # the browser's session: the hub's log-in cookie
        r = s.post(f"{self.hub}/hub/api/users/{name}/tokens", json={"note": "class week", "expires_in": 7200},
                   headers={"X-XSRFToken": s.cookies.get("_xsrf")}, timeout=300)
        if r.status_code != 201:
            fail(f"{name}: no token from the REST API: {r.status_code} {r.text[:200]}")
        self.token = r.json()["token"]
        self.http = requests.Session()
        self.http.headers["Authorization"] = f"token {self.token}"
        # a connection kept open while the user waits (grading) is closed by the proxy after its
        # keep-alive time, and a request sent on it as it closes is reset: one connection each
        self.http.headers["Connection"] = "close"

    def api(self, method: str, path: str, **kw) -> requests.Response:
        return self.http.request(method, f"{self.hub}/hub/api{path}", timeout=300, **kw)

    def server(self, method: str, path: str, **kw) -> requests.Response:
        return self.http.request(method, f"{self.hub}/user/{self.name}/{path}", timeout=300, **kw)

    def spawn(self, t: float | None = None) -> float:
        """Starts the server and waits until it answers: seconds from ``t`` (default: now)."""
        t = time.monotonic() if t is None else t
        r = self.api("POST", f"/users/{self.name}/server")
        if r.status_code not in (201, 202, 400):
            fail(f"{self.name}: spawn refused: {r.status_code} {r.text[:200]}")
        return self.wait_ready(t)

    def wait_ready(self, t: float, limit: float = 900) -> float:
        while time.monotonic() - t < limit:
            model = self.api("GET", f"/users/{self.name}").json()
            srv = model.get("servers", {}).get("", {})
            if srv.get("ready"):
                # twice in a row: a swarm service just made again can answer once, then refuse a
                # moment (its address taken over from the removed one) before the new server listens
                if self.server("GET", "api/status").status_code == 200:
                    time.sleep(0.25)
                    if self.server("GET", "api/status").status_code == 200:
                        return time.monotonic() - t
            elif not srv.get("pending") and time.monotonic() - t > 5:
                fail(f"{self.name}: the server did not start: {model}")
            time.sleep(0.25)
        fail(f"{self.name}: the server was not ready within {limit} s")

    def stop(self) -> None:
        self.api("DELETE", f"/users/{self.name}/server")
        t = time.monotonic()
        while self.api("GET", f"/users/{self.name}").json().get("servers") and time.monotonic() - t < 120:
            time.sleep(0.25)

    def action(self, action: str) -> list | dict:
        r = self.server("POST", f"assignments/{action}", data={"course_id": COURSE, "assignment_id": LESSON},
                        headers={"X-XSRFToken": "x"}, cookies={"_xsrf": "x"})
        out = r.json() if r.status_code == 200 else {}
        if not out.get("success"):
            fail(f"{self.name}: {action}: {r.status_code} {str(out.get('value', r.text))[-600:]}")
        return out["value"]  # the assignment list after the action

    def assignments(self) -> list:
        r = self.server("GET", "assignments", params={"course_id": COURSE})
        if r.status_code != 200:
            fail(f"{self.name}: the assignment list: {r.status_code} {r.text[:300]}")
        return r.json()["value"]

    def exchange(self, method: str, area: str, entry: str | None = None, data: bytes | None = None) -> requests.Response:
        path = f"{self.hub}/services/exchange/api/{COURSE}/{area}" + (f"/{entry}" if entry else "")
        return self.http.request(method, path, data=data, timeout=120)

    def container(self) -> str:
        ids = subprocess.run([DOCKER, "ps", "-q", "--filter", f"name=snakekit-lab-{self.name}"], capture_output=True,
                             text=True, check=True).stdout.split()
        if len(ids) != 1:
            fail(f"{self.name}: {len(ids)} containers")
        return ids[0]

    def terminal(self, cmd: str, folder: str = "work", check: bool = True) -> subprocess.CompletedProcess:
        """``cmd`` as typed in a terminal of the user's JupyterLab: a login shell (its /etc/profile
        sets PATH afresh) in ~/folder, with the server's environment."""
        r = subprocess.run([DOCKER, "exec", "-w", f"/home/student/{folder.rstrip('/')}", self.container(), "bash", "-lc",
                            cmd], capture_output=True, text=True)
        if check and r.returncode != 0:
            fail(f"{self.name}'s terminal, in {folder}$ {cmd}: exit {r.returncode}\n{r.stdout[-1500:]}\n{r.stderr[-1500:]}")
        return r

    def sh(self, cmd: str, check: bool = True) -> subprocess.CompletedProcess:
        r = subprocess.run([DOCKER, "exec", "-w", "/home/student/work", self.container(), "bash", "-c", cmd],
                           capture_output=True, text=True)
        if check and r.returncode != 0:
            fail(f"{self.name}$ {cmd}: exit {r.returncode}\n{r.stdout[-1500:]}\n{r.stderr[-1500:]}")
        return r


#: The folder the newest shell the Jupyter server started (a terminal) runs in; run in the container.
TERMINAL_CWD = """
import os
def field(pid, key):
    with open(f"/proc/{pid}/status") as f:
        return next(line.split()[1] for line in f if line.startswith(key + ":"))
shells = []
for pid in filter(str.isdigit, os.listdir("/proc")):
    try:
        parent = field(pid, "PPid")
        if field(pid, "Name") in ("bash", "sh", "dash") and parent != "0" and field(parent, "Name") not in ("bash", "sh", "dash"):
            shells.append(int(pid))
    except (OSError, StopIteration):
        pass
print(os.readlink(f"/proc/{max(shells)}/cwd") if shells else "no terminal")
"""


def solutions() -> dict[str, str]:
    nb = nbformat.read(REPO / "course" / "source" / LESSON / f"{LESSON}.ipynb", as_version=4)
    return {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells if c.metadata.get("nbgrader", {}).get("solution")}


def fill(nb: dict, answers: dict[str, str]) -> dict:
    for c in nb["cells"]:
        gid = c.get("metadata", {}).get("nbgrader", {}).get("grade_id")
        if gid in answers:
            c["source"] = answers[gid]
    return nb


def tar_of(files: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        for name, data in files.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return buf.getvalue()


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("hub")
    p.add_argument("--students", type=int, default=20)
    p.add_argument("--submitting", type=int, default=0, metavar="K",
                   help="how many of them fetch, fill and submit the lesson, the TA grades and returns (default: all); "
                        "every student still logs in at once, and the refusals are tried between two of them")
    p.add_argument("--passwords", required=True, metavar="CSV",
                   help="username,password for everyone (docker/hub/accounts' output, the instructors' from docker/hub/up)")
    p.add_argument("--old-shared-password", default="", help="the old dummy log-in's shared password, to be refused")
    p.add_argument("--submit-limit-mb", type=float, default=float(os.environ.get("SNAKEKIT_SUBMIT_LIMIT_MB", "20")))
    p.add_argument("--browser", metavar="OUT_DIR", help="open lesson 00 in headless Chromium through the hub's "
                   "proxy with docker/browser-check (the 3D view through the Jupyter port), screenshots to OUT_DIR")
    p.add_argument("--bench", action="store_true", help="then the figures of bench/hub.py: warm spawns, "
                   "the hub and proxy under 50 users' requests")
    args = p.parse_args()
    t0 = time.monotonic()
    pw = read_passwords(args.passwords)
    names = [f"s{i:02d}" for i in range(1, args.students + 1)]
    missing = [n for n in ["teacher", "ta", *names] if n not in pw]
    if missing:
        fail(f"no password in {args.passwords} for {', '.join(missing)}")
    refused_log_ins(args.hub, pw, args.old_shared_password)
    teacher, ta = User(args.hub, "teacher", pw["teacher"]), User(args.hub, "ta", pw["ta"])

    # --- the servers: the instructor's and TA's first (they share the course volume) ------------
    spawn_teacher = teacher.spawn()
    print(f"figure: spawn to ready, first server (the engine's image cache warm): {spawn_teacher:.1f} s", flush=True)
    ta.spawn()

    # --- the class logs in at once. With --bench first with no server running: each student's log-in
    # form, token and server start together, until it answers; then (always) to the servers the
    # teacher started before the lesson (Start All), as docker/hub/README.md advises.
    if args.bench:
        def arrive(name: str) -> tuple[User, float]:
            t = time.monotonic()
            u = User(args.hub, name, pw[name])
            return u, u.spawn(t)

        t = time.monotonic()
        with ThreadPoolExecutor(len(names)) as pool:
            arrived = list(pool.map(arrive, names))
        students, ready = [u for u, _ in arrived], [r for _, r in arrived]
        print(f"figure: {len(students)} students logging in at once, no server running, log-in to a ready server: "
              f"median {statistics.median(ready):.1f} s, max {max(ready):.1f} s; each: "
              + ", ".join(f"{u.name} {r:.1f}" for u, r in arrived), flush=True)
        with ThreadPoolExecutor(8) as pool:
            list(pool.map(User.stop, students))
    students = prestarted(args.hub, teacher, names, pw)
    say(f"{len(students)} students logged in at once, each with a ready server")
    peaks = [memory_of(u.container(), DOCKER)["peak"] for u in students]
    print(f"figure: memory: {len(students)} students' servers, started and logged in to, each container's peak: "
          f"median {statistics.median(peaks):.0f} MiB, max {max(peaks):.0f} MiB", flush=True)

    # --- every terminal has the kit's commands, login shells included -----------------------------
    for u in (teacher, ta, students[0]):
        for shell in ("bash -lc", "sh -lc"):
            r = u.sh(f"env -i HOME=/home/student PATH=/usr/bin:/bin {shell} 'command -v snakekit && command -v nbgrader'")
            if r.stdout.split() != ["/opt/venv/bin/snakekit", "/opt/venv/bin/nbgrader"]:
                fail(f"{u.name}: {shell} 'command -v snakekit && command -v nbgrader' gave {r.stdout!r}")
    say("every terminal has snakekit and nbgrader on its PATH: bash -l and sh -l, in the teacher's, "
        "the TA's and a student's server")
    # --- a terminal from JupyterLab's Launcher starts where the README's `cd course` works ----------
    for u, where in ((teacher, "/home/student"), (ta, "/home/student"), (students[0], "/home/student/work")):
        r = u.server("POST", "api/terminals", json={"cwd": ""})   # the Launcher's request, its file browser at /
        if r.status_code != 200:
            fail(f"{u.name}: a terminal from the Launcher: {r.status_code} {r.text[:200]}")
        term = r.json()["name"]
        cwd = u.sh(f"python3 -c {shlex.quote(TERMINAL_CWD)}").stdout.strip()
        u.server("DELETE", f"api/terminals/{term}")
        if cwd != where:
            fail(f"{u.name}: a terminal from the Launcher starts in {cwd!r}, not {where!r}"
                 + (" (the README's `cd course` fails there)" if u is not students[0] else ""))
    say("a terminal from the Launcher starts in ~ for the teacher and the TA (beside course/), in ~/work for a student")

    # --- the instructor releases lesson 06 (their commands as docker/hub/README.md gives them) ------
    roles = role_commands((REPO / "docker/hub/README.md").read_text())
    folder, commands = roles["teacher"]
    for cmd in commands:
        teacher.terminal(cmd, folder)
    say(f"teacher: {LESSON} generated and released to the hub's exchange "
        f"({len(commands)} commands in the teacher's terminal, in {folder})")

    # --- the students: fetch, fill, save, submit ---------------------------------------------------
    class_ = students
    students = class_[:args.submitting or len(class_)]
    sol = solutions()
    slip = {**sol, "ex06_1_sweep_times": "def sweep_times(points, rate):\n    return np.arange(points) / 10.0"}
    plan = {s.name: ("wrong" if i % 3 == 2 else "right") for i, s in enumerate(students)}

    def work(s: User) -> None:
        listed = s.assignments()
        if not any(a["assignment_id"] == LESSON and a["status"] == "released" for a in listed):
            fail(f"{s.name}: {LESSON} is not in the assignment list: {listed}")
        s.action("fetch")
        path = f"api/contents/{LESSON}/{LESSON}.ipynb"
        r = s.server("GET", path)
        if r.status_code != 200:
            fail(f"{s.name}: the fetched notebook: {r.status_code}")
        nb = fill(r.json()["content"], sol if plan[s.name] == "right" else slip)
        r = s.server("PUT", path, json={"type": "notebook", "format": "json", "content": nb})
        if r.status_code not in (200, 201):
            fail(f"{s.name}: saving: {r.status_code} {r.text[:200]}")
        s.action("submit")

    t = time.monotonic()
    with ThreadPoolExecutor(8) as pool:
        list(pool.map(work, students))
    say(f"{len(students)} students fetched, filled and submitted {LESSON} in {time.monotonic() - t:.1f} s")

    # --- the TA: collect, grade, return, in their terminal (docker/hub/README.md's commands) --------
    folder, commands = roles["ta"]
    if [c.split()[:2] for c in commands] != [["nbgrader", "collect"], ["snakekit", "grade"], ["snakekit", "return"]]:
        fail(f"docker/hub/README.md's TA commands are not collect, grade, return: {commands}")
    out = ta.terminal(commands[0] + " 2>&1", folder).stdout
    collected = sorted(d for d in ta.sh("ls ~/course/submitted").stdout.split())
    if collected != sorted(s.name for s in students):
        fail(f"collected {collected}, expected {[s.name for s in students]}\n{out[-800:]}")
    say(f"ta: collected {len(collected)} submissions from the exchange")
    t = time.monotonic()
    r = ta.terminal(commands[1], folder, check=False)
    grade_s = time.monotonic() - t
    if r.returncode != 0 or "graded by the hub's grading service" not in r.stdout:
        fail(f"grading from the TA's terminal: exit {r.returncode}\n{r.stdout[-1500:]}\n{r.stderr[-1500:]}")
    print(f"figure: grading the {len(collected)} collected submissions (snakekit grade in the TA's terminal, the "
          f"hub's grading service): {grade_s:.1f} s", flush=True)
    r = students[0].http.post(f"{args.hub}/services/grading/api/grade/{LESSON}", json={}, timeout=60)
    own = students[0].sh(f"cd ~/course && SNAKEKIT_GRADING_URL=http://hub:10103/services/grading/ "
                         f"snakekit grade {LESSON} --course /home/student/course", check=False)
    if r.status_code != 403 or own.returncode != 2 or "refused (403)" not in own.stderr:
        fail(f"a student grading: the service answered {r.status_code}; snakekit grade in their server: exit "
             f"{own.returncode} {own.stderr[-400:]}")
    say(f"refused: grading for a student (the grading service 403 to {students[0].name}'s token; snakekit grade "
        f"in their server: {own.stderr.strip().splitlines()[-1][:160]})")
    rows = {row["student"]: row for row in csv.DictReader(io.StringIO(ta.sh(f"cat ~/course/grades-{LESSON}.csv").stdout))}
    for s in students:
        row = rows.get(s.name) or fail(f"no grade for {s.name}: {sorted(rows)}")
        full = float(row["score"]) == float(row["max_score"]) > 0
        if row["status"] != "graded" or full != (plan[s.name] == "right"):
            fail(f"{s.name} ({plan[s.name]}): {row}")
    say(f"grades: {sum(v == 'right' for v in plan.values())} right at full marks, "
        f"{sum(v == 'wrong' for v in plan.values())} with a slip below them")
    out = ta.terminal(commands[2] + " 2>&1", folder).stdout
    if f"released {len(students)} student(s)' feedback to the exchange" not in out:
        fail(f"snakekit return: {out[-800:]}")
    say(f"ta: feedback returned ({out.strip().splitlines()[-1][:120]})")

    # --- every student fetches their feedback -------------------------------------------------------
    def feedback(s: User) -> None:
        listed = s.action("fetch_feedback")
        subs = [x for a in listed if a["assignment_id"] == LESSON for x in a.get("submissions") or []]
        if not subs or not subs[-1].get("has_local_feedback"):
            fail(f"{s.name}: no feedback after fetch_feedback: {listed}")
        r = s.server("GET", f"api/contents/{LESSON}/feedback")
        if r.status_code != 200:
            fail(f"{s.name}: the feedback folder: {r.status_code}")

    with ThreadPoolExecutor(8) as pool:
        list(pool.map(feedback, students))
    say(f"every student fetched their feedback page ({time.monotonic() - t0:.0f} s since the log-ins)")

    # --- refusals ----------------------------------------------------------------------------------------
    a, b = students[0], students[1]
    r = a.sh(f"nbgrader submit {LESSON} --course {COURSE} --student {b.name} 2>&1", check=False)
    if r.returncode == 0 or f"you can submit only as {a.name}" not in r.stdout:
        fail(f"{a.name} submitting as {b.name} was not refused: {r.stdout[-600:]}")
    r = a.exchange("PUT", "inbound", f"{b.name}+{LESSON}+2026-01-01 00:00:00.000000 UTC+x",
                   tar_of({f"{LESSON}.ipynb": b"{}"}))
    if r.status_code != 403:
        fail(f"a forged submission as {b.name} with {a.name}'s token: {r.status_code}")
    say(f"refused: {a.name} submitting as {b.name} (nbgrader submit --student, and straight to the exchange: 403)")
    r = a.sh(f"mkdir -p /tmp/c && cd /tmp/c && nbgrader collect {LESSON} --course {COURSE} 2>&1", check=False)
    if r.returncode == 0 or "only they collect" not in r.stdout:
        fail(f"a student's collect was not refused: {r.stdout[-600:]}")
    r = a.exchange("GET", "inbound")
    if r.status_code != 403:
        fail(f"{a.name} read the submissions: {r.status_code}")
    say(f"refused: {a.name} collecting or reading others' submissions (403)")
    r = a.exchange("GET", "feedback")
    with tarfile.open(fileobj=io.BytesIO(r.content)) as tar:
        tops = {Path(m.name).parts[0] for m in tar.getmembers()}
    if tops != {a.name}:
        fail(f"{a.name} got feedback of {tops}")
    say(f"refused: another's feedback (the exchange gives {a.name} only {a.name}'s)")
    r = a.http.get(f"{args.hub}/user/{b.name}/api/contents/{LESSON}", timeout=30, allow_redirects=False)
    if r.status_code not in (403, 404):
        fail(f"{a.name} reached {b.name}'s server: {r.status_code}")
    mounts = a.sh("awk '{print $2}' /proc/mounts").stdout.split()
    listing = a.sh("ls -a /home/student/work").stdout.split()
    if any(b.name in m for m in mounts) or "course" in listing or any(m.endswith("/course") for m in mounts) or "/var/run/docker.sock" in mounts:
        fail(f"{a.name}'s container mounts {mounts}")
    say(f"refused: {b.name}'s files ({a.name}'s token at {b.name}'s server: {r.status_code}; "
        f"{a.name}'s container has only {a.name}'s volume, no course, no engine socket)")
    tools = {path: a.server("GET", path, allow_redirects=False).status_code for path in ("formgrader", "formgraders")}
    if set(tools.values()) != {404}:
        fail(f"{a.name}'s server serves nbgrader's teacher tools: {tools}")
    r = teacher.server("GET", "formgrader")  # its page: manage_assignments
    if r.status_code != 200:
        fail(f"the teacher's formgrader answered {r.status_code}")
    say(f"refused: nbgrader's teacher tools on a student's server (formgrader, course list: "
        f"{'/'.join(map(str, tools.values()))}); the teacher's formgrader answers {r.status_code}")
    env = a.sh("env").stdout
    if any(k in env for k in ("CONFIGPROXY_AUTH_TOKEN", "JPY_COOKIE_SECRET", "JUPYTERHUB_CRYPT_KEY")):
        fail("a hub secret is in a student's environment")
    r = a.api("GET", "/users")
    if r.status_code != 403:
        fail(f"a student listed the hub's users: {r.status_code}")
    r = a.api("GET", f"/users/{b.name}/tokens")
    if r.status_code not in (403, 404):
        fail(f"a student read another's tokens: {r.status_code}")
    r = a.sh("python3 -c \"import urllib.request as u, urllib.error as e\ntry: u.urlopen('http://hub:8001/api/routes', timeout=5); print('open')\n"
             "except e.HTTPError as x: print(x.code)\nexcept Exception as x: print('unreachable', x)\"").stdout.strip()
    if r == "open":
        fail("the proxy's API answered a student without its token")
    r2 = a.sh("ls /srv/data 2>&1; true").stdout
    say(f"the hub's tokens: not in a student's environment or files ({r2.strip()[:60]}); the users list 403, "
        f"another's tokens refused, the proxy's API: {r}")

    # --- limits: a submission over the size limit, a full exchange ---------------------------------
    big = int(args.submit_limit_mb * 1e6) + 500_000
    a.sh(f"head -c {big} /dev/urandom > {LESSON}/data.bin")
    r = a.sh(f"nbgrader submit {LESSON} --course {COURSE} 2>&1", check=False)
    if r.returncode == 0 or "over the class's limit" not in r.stdout:
        fail(f"an oversized submission: {r.stdout[-600:]}")
    say(f"over the size limit: nbgrader submit says: {next(l for l in r.stdout.splitlines() if 'limit' in l).strip()[:160]}")
    part = int(args.submit_limit_mb * 1e6) - 500_000
    a.sh(f"head -c {part} /dev/urandom > {LESSON}/data.bin")
    for i in range(200):
        r = a.sh(f"nbgrader submit {LESSON} --course {COURSE} 2>&1", check=False)
        if r.returncode != 0:
            break
    if "exchange is full" not in r.stdout:
        fail(f"a full exchange: {r.stdout[-600:]}")
    a.sh(f"rm {LESSON}/data.bin")
    say(f"a full exchange (after {i} more submissions): {next(l for l in r.stdout.splitlines() if 'full' in l).strip()[:160]}")

    # --- a culled server loses nothing saved ------------------------------------------------------------
    r = a.server("PUT", "api/contents/saved-before-cull.txt", json={"type": "file", "format": "text", "content": "kept"})
    if r.status_code not in (200, 201):
        fail(f"saving a file: {r.status_code}")
    a.stop()  # what jupyterhub-idle-culler does to an idle server: DELETE .../server
    warm = a.spawn()
    print(f"figure: spawn to ready, warm (the student's volume exists): {warm:.1f} s", flush=True)
    r = a.server("GET", "api/contents/saved-before-cull.txt")
    for _ in range(60):  # the proxy says 503 while the new server is not listening yet; a browser retries
        if r.status_code not in (502, 503):
            break
        time.sleep(0.5)
        r = a.server("GET", "api/contents/saved-before-cull.txt")
    if r.status_code != 200 or r.json()["content"] != "kept":
        fail(f"after the restart: {r.status_code}")
    r = a.server("GET", f"api/contents/{LESSON}/{LESSON}.ipynb")
    cells = {c["metadata"].get("nbgrader", {}).get("grade_id"): c["source"] for c in r.json()["content"]["cells"]} \
        if r.status_code == 200 else {}
    if cells.get("ex06_1_sweep_times") != sol["ex06_1_sweep_times"]:
        fail("the filled lesson is not there after the restart")
    say(f"{a.name}'s server stopped as the idle culler does and started again: the saved file and the filled lesson are there")
    r = teacher.api("GET", "/services")
    if r.status_code != 200 or not {"exchange", "idle-culler"} <= set(r.json()):
        fail(f"the hub's services (the exchange and the idle culler): {r.status_code} {r.text[:200]}")

    # --- lesson 00 through the hub's proxy --------------------------------------------------------------
    r = a.server("GET", "lab")
    if r.status_code != 200 or "JupyterLab" not in r.text:
        fail(f"{a.name}'s JupyterLab through the proxy: {r.status_code}")
    r = a.server("GET", "api/contents/00_meet_the_arm.ipynb")
    if r.status_code != 200:
        fail(f"lesson 00: {r.status_code}")
    say(f"lesson 00 and JupyterLab reached through the hub's proxy at {args.hub}/user/{a.name}/lab")
    if args.browser:
        # the student's JupyterLab in Chromium through the hub, logged in on the hub's page: lessons
        # listed, lesson 00 run, the arm drawn in the 3D view and moved (pixels compared), every
        # request to the hub's port
        t = time.monotonic()
        r = subprocess.run([sys.executable, str(REPO / "docker/browser-check"), f"{args.hub}/user/{a.name}", args.browser,
                            "--hub-user", a.name], capture_output=True, text=True,
                           env=dict(os.environ, SNAKEKIT_HUB_PASSWORD=pw[a.name]))
        for line in r.stdout.splitlines():
            if line.startswith("browser:"):
                say(line)
        if r.returncode != 0:
            fail(f"lesson 00 in Chromium through the hub: exit {r.returncode}: {r.stdout[-1500:]}\n{r.stderr[-1500:]}")
        print(f"figure: lesson 00 in headless Chromium through the hub's proxy, the arm drawn and moved: "
              f"{time.monotonic() - t:.0f} s", flush=True)
        mem = memory_of(a.container(), DOCKER)
        print(f"figure: memory: {a.name}'s server with lesson 00 run and its 3D view open in Chromium: usage "
              f"{mem['usage']:.0f} MiB, peak {mem['peak']:.0f} MiB (its container's cgroup)", flush=True)
        view_is_the_owners(args.hub, a, b)
    print(f"figure: the whole loop on the hub ({len(class_)} students, {len(students)} submitting): "
          f"{time.monotonic() - t0:.0f} s", flush=True)
    if args.bench:
        bench(args.hub, class_)
    return 0


def prestarted(hub: str, teacher: User, names: list[str], pw: dict[str, str]) -> list[User]:
    """The class logging in at once to servers the teacher started before the lesson (the admin
    page's Start All: the hub's API with the teacher's token): each student's log-in to a ready server."""
    def start_for(name: str) -> None:
        r = teacher.api("POST", f"/users/{name}/server")
        if r.status_code not in (201, 202, 400):  # 400: running already
            fail(f"the teacher starting {name}'s server: {r.status_code} {r.text[:200]}")
        t = time.monotonic()
        while not teacher.api("GET", f"/users/{name}").json().get("servers", {}).get("", {}).get("ready"):
            if time.monotonic() - t > 900:
                fail(f"{name}'s server, started by the teacher, was not ready within 900 s")
            time.sleep(0.5)

    # the class on the hub's user list (Admin > Add Users, once: an account alone is not a hub user
    # until its first log-in); 409 when every name is there already
    r = teacher.api("POST", "/users", json={"usernames": names})
    if r.status_code not in (201, 409):
        fail(f"the teacher adding the class to the hub's users: {r.status_code} {r.text[:200]}")
    # five at a time: 25 servers started together on a busy 2-core machine starve the proxy, whose
    # API then times out on the hub (it stops those servers: bench/hub.py's run at load 35)
    t = time.monotonic()
    with ThreadPoolExecutor(5) as pool:
        list(pool.map(start_for, names))
    print(f"figure: teacher: every student's server started before the lesson (five at a time) in "
          f"{time.monotonic() - t:.1f} s", flush=True)

    def arrive(name: str) -> tuple[User, float]:
        t = time.monotonic()
        u = User(hub, name, pw[name])
        return u, u.spawn(t)  # running already: the hub says so (400), and it answers

    with ThreadPoolExecutor(len(names)) as pool:
        arrived = list(pool.map(arrive, names))
    print(f"figure: {len(names)} students logging in at once to servers started before the lesson, log-in to "
          f"a ready server: median {statistics.median([r for _, r in arrived]):.1f} s, max "
          f"{max(r for _, r in arrived):.1f} s (target <= 30 s); each: "
          + ", ".join(f"{u.name} {r:.1f}" for u, r in arrived), flush=True)
    return [u for u, _ in arrived]


def hub_memory() -> float:
    """The hub's container (hub, proxy, exchange, culler) memory in MiB, from docker stats."""
    out = subprocess.run([DOCKER, "stats", "--no-stream", "--format", "{{.MemUsage}}", "snakekit-hub"],
                         capture_output=True, text=True, check=True).stdout.split("/")[0].strip()
    value, unit = float(out.rstrip("KMGiB")), out.lstrip("0123456789.")
    return value * {"KiB": 1 / 1024, "MiB": 1, "GiB": 1024}[unit]


def bench(hub: str, students: list[User], clients: int = 50, per_client: int = 40) -> None:
    """Five warm spawns, then 50 users' worth of requests through the hub and its proxy."""
    s = students[1]
    warm = []
    for _ in range(5):
        s.stop()
        warm.append(s.spawn())
    print(f"figure: spawn to ready, warm: median {statistics.median(warm):.1f} s of {', '.join(f'{w:.1f}' for w in warm)} "
          f"(target <= 5 s; {len(students) + 2} servers running)", flush=True)
    # a bounded load: 50 clients on loopback, each with its own connection, one request at a time,
    # alternating the hub's API (GET /hub/api/user) and a server through the proxy (GET .../api/status)
    idle_mem = hub_memory()
    lat: dict[str, list[float]] = {"hub": [], "proxy": []}

    def client(i: int) -> None:
        u = students[i % len(students)]
        http = requests.Session()
        http.headers["Authorization"] = f"token {u.token}"
        for k in range(per_client):
            kind, url = (("hub", f"{hub}/hub/api/user") if k % 2 == 0 else
                         ("proxy", f"{hub}/user/{u.name}/api/status"))
            t = time.monotonic()
            r = http.get(url, timeout=60)
            lat[kind].append(time.monotonic() - t)
            if r.status_code != 200:
                fail(f"under load: {url}: {r.status_code}")

    peak = [idle_mem]
    done = False

    def sample() -> None:
        while not done:
            peak.append(hub_memory())
            time.sleep(1)

    sampler = ThreadPoolExecutor(1)
    sampler.submit(sample)
    t = time.monotonic()
    with ThreadPoolExecutor(clients) as pool:
        list(pool.map(client, range(clients)))
    wall = time.monotonic() - t
    done = True
    sampler.shutdown()
    n = clients * per_client

    def pct(xs: list[float], q: float) -> float:
        return sorted(xs)[min(len(xs) - 1, int(q * len(xs)))] * 1000

    for kind, label in (("hub", "the hub's API (GET /hub/api/user)"), ("proxy", "a server through the proxy (GET /user/<name>/api/status)")):
        print(f"figure: under load, {label}: p50 {pct(lat[kind], 0.5):.0f} ms, p95 {pct(lat[kind], 0.95):.0f} ms "
              f"({len(lat[kind])} requests)", flush=True)
    print(f"figure: under load: {n} requests from {clients} clients in {wall:.1f} s ({n / wall:.0f}/s); the hub's "
          f"container (hub, proxy, exchange, culler) {idle_mem:.0f} MiB before, peak {max(peak):.0f} MiB", flush=True)


if __name__ == "__main__":
    sys.exit(main())
