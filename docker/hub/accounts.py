#!/usr/bin/env python3
"""Make the hub's accounts, each with a first password of its own (run in the hub's container:
docker/hub/accounts for the students, docker/hub/up for the instructors and TAs).

    accounts.py NAME...              one account per name
    accounts.py --roster - < roster.csv   one per row of a roster (its column ``student``, as
                                     course/roster.csv)

Prints ``username,password`` (CSV, a header first) for each account made: the only place a
first password is shown, so the teacher keeps the output to hand each student theirs. A name
that already has an account is left alone, its password unchanged (reported on stderr): running
it again with a longer roster makes only the new students'. All names are checked before any
account is made; a bad one (a comma, a space, a slash, or a name JupyterHub refuses) stops it
with exit 2 and nothing made.

Accounts are NativeAuthenticator's (jupyterhub-nativeauthenticator), in the hub's database,
authorized as made: the hub's sign-up page is off, so no one makes an account but the teacher.
"""

from __future__ import annotations

import argparse
import csv
import os
import secrets
import sys

from jupyterhub.orm import new_session_factory
from nativeauthenticator import NativeAuthenticator

DATA = os.environ.get("SNAKEKIT_HUB_DATA", "/srv/data")
# letters and digits a student reads off a slip without confusing them (no 0/o, 1/l/i)
ALPHABET = "abcdefghjkmnpqrstuvwxyz23456789"


def first_password() -> str:
    """Three groups of four (about 59 bits): ``k3m9-tq2x-8bvn``."""
    return "-".join("".join(secrets.choice(ALPHABET) for _ in range(4)) for _ in range(3))


def roster_names(text: str, source: str) -> list[str] | None:
    """The roster's column ``student``; None (and the message) when it has none."""
    rows = csv.DictReader(text.splitlines())
    if "student" not in (rows.fieldnames or []):
        print(f"accounts: {source} has no 'student' column (its columns: {', '.join(rows.fieldnames or []) or 'none'}); "
              "give a roster with one, as course/roster.csv", file=sys.stderr)
        return None
    return [row["student"].strip() for row in rows if (row["student"] or "").strip()]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("names", nargs="*", help="user names")
    p.add_argument("--roster", metavar="CSV", help="a roster with a column 'student' ('-': standard input)")
    args = p.parse_args(argv)
    names = list(args.names)
    if args.roster:
        text = sys.stdin.read() if args.roster == "-" else open(args.roster, encoding="utf-8").read()
        listed = roster_names(text, "the roster" if args.roster == "-" else args.roster)
        if listed is None:
            return 2
        names += listed
    if not names:
        print("accounts: no names given: give user names, or --roster with a roster's CSV", file=sys.stderr)
        return 2
    db = new_session_factory(f"sqlite:///{DATA}/jupyterhub.sqlite")()
    # sign-up on for this instance only (create_user's condition); the hub's own has it off
    auth = NativeAuthenticator(db=db, enable_signup=True)
    wanted = {}
    bad = []
    for raw in names:
        name = auth.normalize_username(raw)
        if not raw or not auth.validate_username(name):
            bad.append(raw)
        wanted.setdefault(name, raw)
    if bad:
        print(f"accounts: not a user name the hub takes: {', '.join(repr(b) for b in bad)} (not empty; no comma, "
              "space or slash); no account was made", file=sys.stderr)
        return 2
    out = csv.writer(sys.stdout, lineterminator="\n")
    out.writerow(["username", "password"])
    kept, made = [], 0
    for name in wanted:
        if auth.user_exists(name):
            kept.append(name)
            continue
        password = first_password()
        info = auth.create_user(name, password)
        if info is None:
            print(f"accounts: {name}: the authenticator made no account; none after it was made", file=sys.stderr)
            return 1
        info.is_authorized = True
        db.commit()
        out.writerow([name, password])
        made += 1
    sys.stdout.flush()
    print(f"accounts: {made} made" + (f"; {len(kept)} had one already, left as they were: {', '.join(kept)}" if kept else ""),
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
