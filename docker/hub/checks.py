"""The hub test's checks that the class's identities and views are each person's own (loop.py
runs them): the log-ins the hub must refuse, and a student's 3D view refused to another."""

from __future__ import annotations

import shlex
from typing import TYPE_CHECKING

import requests

if TYPE_CHECKING:
    from loop import User


def say(msg: str) -> None:
    print(f"hub-test: {msg}", flush=True)


def fail(msg: str) -> None:
    raise SystemExit(f"hub-test: FAILED: {msg}")


def log_in(hub: str, name: str, password: str) -> tuple[requests.Session, requests.Response]:
    """The hub's log-in form, as a browser posts it: the session and the form's answer."""
    s = requests.Session()
    # (bounds for a hang: a class arriving at once on a busy machine keeps the hub busy for minutes)
    s.get(f"{hub}/hub/login", timeout=300)  # the form's page sets its _xsrf cookie
    r = s.post(f"{hub}/hub/login", data={"username": name, "password": password, "_xsrf": s.cookies.get("_xsrf")},
               allow_redirects=False, timeout=300)
    return s, r


def refused_log_ins(hub: str, passwords: dict[str, str], old_shared: str) -> None:
    """Names and passwords a student could try: each gets the form again, and no session."""
    other = next(n for n in passwords if n.startswith("s") and n != "s01")
    tries = [(other, passwords["s01"], f"{other} with s01's password"),
             ("teacher", passwords["s01"], "teacher with a student's password"),
             ("teacher", passwords["ta"], "teacher with the TA's password"),
             ("teacher", "", "teacher with no password"), ("s01", "", "s01 with no password"),
             ("mallory", passwords["s01"], "a name without an account")]
    if old_shared:
        tries += [(n, old_shared, f"{n} with the old shared password") for n in ("teacher", "s01", "mallory")]
    for name, password, what in tries:
        s, r = log_in(hub, name, password)
        who = s.get(f"{hub}/hub/api/user", timeout=30).status_code
        if r.status_code != 200 or "Invalid username or password" not in r.text or who != 403:
            fail(f"the log-in of {what} was not refused: the form answered {r.status_code} "
                 f"({r.headers.get('Location', '')}), then /hub/api/user {who}")
    r = requests.get(f"{hub}/hub/signup", timeout=30, allow_redirects=False)
    if r.status_code != 404:
        fail(f"the hub's sign-up page answered {r.status_code}: anyone could make an account")
    say(f"refused log-ins ({len(tries)}): {'; '.join(w for _, _, w in tries)}: each the form again with "
        f"'Invalid username or password.' and no session (/hub/api/user 403); no sign-up page (404)")


PAGE = "viewer.connect(new URL"  # the kit's 3D view page (snakekit.viewer.server.CONNECT)


def is_loopback(addr: str) -> bool:
    """An address as /proc/net/tcp{,6} writes it (hex, little-endian words) is 127.0.0.0/8 (Docker's
    DNS resolver listens on 127.0.0.11), ::1, or 127.x mapped into IPv6."""
    if len(addr) == 8:
        return addr[6:] == "7F"
    return addr == "00000000000000000000000001000000" or (addr[:24] == "0000000000000000FFFF0000" and addr[30:] == "7F")


PROBE = """import socket, sys
for port in sys.argv[2:]:
    try:
        socket.create_connection((sys.argv[1], int(port)), timeout=5).close()
        print(port, "open")
    except OSError as e:
        print(port, type(e).__name__)
"""


def view_is_the_owners(hub: str, owner: User, other: User) -> None:
    """The owner's 3D view (its server started by lesson 00's kernel, still running) reaches no one
    else: every socket listening in the owner's container but Jupyter's (8888) is on its loopback;
    another student's container on the hub's network is refused at the view's port (and reaches
    Jupyter's, so the network is there); through the hub, another student's token and log-in get
    no page where the owner's gets the view's."""
    listening = []
    for line in owner.sh("cat /proc/net/tcp /proc/net/tcp6").stdout.splitlines():
        f = line.split()
        if len(f) > 3 and f[3] == "0A":  # LISTEN
            addr, port = f[1].rsplit(":", 1)
            listening.append((addr, int(port, 16)))
    views = sorted({port for addr, port in listening if 7000 <= port <= 7009})
    if not views:
        fail(f"no 3D view listens in {owner.name}'s server after lesson 00: {listening}")
    exposed = sorted({port for addr, port in listening if not is_loopback(addr) and port != 8888})
    if exposed:
        fail(f"{owner.name}'s server listens beyond its loopback on {exposed} (all: {listening})")
    host = f"snakekit-lab-{owner.name}"
    out = other.sh(f"python3 -c {shlex.quote(PROBE)} {host} 8888 {' '.join(map(str, views))}").stdout.split()
    got = dict(zip(out[::2], out[1::2]))
    if got.get("8888") != "open" or any(got.get(str(p)) in (None, "open") for p in views):
        fail(f"from {other.name}'s container to {host}: {got} (Jupyter's port open, the view's refused wanted)")
    path = f"{hub}/user/{owner.name}/proxy/{views[0]}/static/"
    mine = owner.http.get(path, timeout=60)
    if mine.status_code != 200 or PAGE not in mine.text:
        fail(f"{owner.name}'s own 3D view through the hub: {mine.status_code} {mine.text[:200]}")
    token = other.http.get(path, timeout=60, allow_redirects=False)
    browser = other.web.get(path, timeout=60)  # the hub's log-in cookie, redirects followed as a browser does
    if token.status_code not in (403, 404) or browser.status_code != 403 or PAGE in token.text + browser.text:
        fail(f"{other.name} at {path}: token {token.status_code}, log-in {browser.status_code} {browser.text[:200]}")
    say(f"refused: {owner.name}'s 3D view to {other.name}: on the hub's network {host}:{views[0]} "
        f"{got[str(views[0])]} (its server listens on 127.0.0.1 only; {host}:8888 open), through the hub "
        f"{path.removeprefix(hub)} {token.status_code} with {other.name}'s token and {browser.status_code} with "
        f"{other.name}'s log-in; {owner.name}'s own: {mine.status_code}, the view's page")


# --- what each role types, as docker/hub/README.md gives it -------------------------------------
ROLES = {"the teacher": "teacher", "a TA": "ta", "a student": "student"}


def role_commands(readme: str) -> dict[str, tuple[str, list[str]]]:
    """{role: (folder, commands)} from the README's ```sh blocks headed ``# <role>'s terminal, in <folder>``.

    Also checks the README's table "| <role> | <n> commands |" against the blocks: a count that
    is not the number of commands the test runs stops the test.
    """
    import re

    blocks = {}
    for block in re.findall(r"^ *```sh\n(.*?)^ *```", readme, re.M | re.S):
        lines = [ln.strip() for ln in block.splitlines()]
        m = re.match(r"# (the teacher|a TA|a student)'s terminal, in (\S+)$", lines[0])
        if m:
            blocks[ROLES[m.group(1)]] = (m.group(2), [ln for ln in lines[1:] if ln.strip() and not ln.startswith("#")])
    table = {ROLES[r]: int(n) for r, n in re.findall(r"^ *\| (the teacher|a TA|a student) \| (\d+) commands? \|", readme, re.M)}
    counted = {role: len(cmds) for role, (_, cmds) in blocks.items()}
    if set(table) != set(ROLES.values()) or any(table[r] != counted.get(r, 0) for r in table):
        fail(f"docker/hub/README.md's commands per role {table} are not its blocks' {counted}")
    return blocks


def memory_of(container: str, docker: str = "docker") -> dict[str, float]:
    """A server's container's memory cgroup, read on the host (v2 or v1): usage and peak [MiB]."""
    import subprocess
    from pathlib import Path

    full = subprocess.run([docker, "inspect", "-f", "{{.Id}}", container], capture_output=True, text=True,
                          check=True).stdout.strip()
    for d in (Path(f"/sys/fs/cgroup/system.slice/docker-{full}.scope"), Path(f"/sys/fs/cgroup/docker/{full}")):
        if (d / "memory.peak").exists():
            return {"usage": int((d / "memory.current").read_text()) / 2**20,
                    "peak": int((d / "memory.peak").read_text()) / 2**20}
    d = Path(f"/sys/fs/cgroup/memory/docker/{full}")
    if not (d / "memory.max_usage_in_bytes").exists():
        fail(f"{container}'s memory cgroup is not under /sys/fs/cgroup (v2 or v1)")
    return {"usage": int((d / "memory.usage_in_bytes").read_text()) / 2**20,
            "peak": int((d / "memory.max_usage_in_bytes").read_text()) / 2**20}
