"""The hub test's checks that the class's identities are each person's own (loop.py runs them):
the log-ins the hub must refuse."""

from __future__ import annotations

import requests

def say(msg: str) -> None:
    print(f"hub-test: {msg}", flush=True)


def fail(msg: str) -> None:
    raise SystemExit(f"hub-test: FAILED: {msg}")


def log_in(hub: str, name: str, password: str) -> tuple[requests.Session, requests.Response]:
    """The hub's log-in form, as a browser posts it: the session and the form's answer."""
    s = requests.Session()
    s.get(f"{hub}/hub/login", timeout=30)  # the form's page sets its _xsrf cookie
    r = s.post(f"{hub}/hub/login", data={"username": name, "password": password, "_xsrf": s.cookies.get("_xsrf")},
               allow_redirects=False, timeout=60)
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
