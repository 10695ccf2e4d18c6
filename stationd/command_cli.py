"""People's commands from the command line, through the running daemon's API (the screens'
path: log in with a user's password, give the command, read the station's answer), and the
password hashes the station file keeps.

    stationd skip VIN BOLT [--comment TEXT] --user NAME
    stationd reopen VIN [--comment TEXT] --user NAME
    stationd release VIN BOLT [--comment TEXT] --user NAME
    stationd loosen VIN BOLT [--comment TEXT] --user NAME
    stationd operator sign-in USER [--comment TEXT]   # USER signs in at the station
    stationd operator sign-out --user NAME [--comment TEXT]
    stationd operator status
    stationd feed [--since N] [--limit M]
    stationd user hash

The password comes from ``STATIOND_PASSWORD``, else a prompt (a terminal), else the first
line of standard input; it never goes on the command line (``ps`` would show it); the http
token from ``--token`` or ``STATIOND_TOKEN``.  Exit 0:
accepted; 1: refused by the station (the reason is printed); 2: bad input; 3: no answer, or
the login was refused.
"""

from __future__ import annotations

import argparse
import getpass
import http.cookiejar
import json
import os
import sys
import urllib.error
import urllib.request
from typing import Any

from stationd.access import hash_password
from stationd.errors import InputError
from stationd.web.status_cli import DEFAULT_URL, EXIT_UNREACHABLE, status_url

EXIT_REFUSED = 1


class ApiClient:
    """One session with the daemon's API (a cookie jar; the station token when given)."""

    def __init__(self, url: str, token: str | None, timeout: float) -> None:
        status_url(url)   # checks the form: bad input is exit 2
        if not 0 < timeout <= 3600:    # NaN too
            raise InputError(f"--timeout {timeout:g}: expected seconds in (0, 3600]")
        self.base = url.rstrip("/")
        self.token = token or os.environ.get("STATIOND_TOKEN") or None
        self.timeout = timeout
        self._open = urllib.request.build_opener(
            urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))

    def call(self, path: str, body: dict[str, Any] | None = None) -> tuple[int, Any]:
        """(HTTP status, the JSON or text answer)."""
        data = None if body is None else json.dumps(body).encode()
        req = urllib.request.Request(self.base + path, data=data)  # noqa: S310 - http(s)
        if data is not None:
            req.add_header("Content-Type", "application/json")
        if self.token:
            req.add_header("Authorization", f"Bearer {self.token}")
        try:
            with self._open.open(req, timeout=self.timeout) as r:
                status, raw = r.status, r.read()
        except urllib.error.HTTPError as exc:
            status, raw = exc.code, exc.read()
        text = raw.decode("utf-8", "replace")
        try:
            return status, json.loads(text)
        except ValueError:
            return status, text.strip()


#: the longest password line read from standard input: an endless one (``< /dev/zero``) is
#: refused, never read for ever
MAX_PASSWORD = 1024


def read_password() -> str:
    if "STATIOND_PASSWORD" in os.environ:
        return os.environ["STATIOND_PASSWORD"]
    if sys.stdin.isatty():
        return getpass.getpass("password: ")
    line = sys.stdin.readline(MAX_PASSWORD + 1)
    if len(line) > MAX_PASSWORD:
        raise InputError(f"the password on standard input: no end of line within "
                         f"{MAX_PASSWORD} characters (one line, the password)")
    return line.rstrip("\n")


def say_refused(what: str, status: int, answer: Any) -> int:
    """A refusal before the station saw the command (the token, the login, the API)."""
    if status == 401 and str(answer).startswith("token required"):
        answer = "the daemon refused the http token (--token or STATIOND_TOKEN)"
    elif status in (404, 405) or not str(answer).strip():
        # another server on that port (it said nothing a person could use, or has no such
        # page): said so, never "login refused: " with nothing after it
        answer = (f"not a stationd daemon's screens at this URL (HTTP {status}; --url "
                  "http://HOST:PORT/)")
    sys.stderr.write(f"stationd: {what}: {answer}\n")
    return EXIT_UNREACHABLE


#: the commands that name a bolt of the vehicle at the station
BOLT_COMMANDS = ("skip", "release", "loosen")


def _check_command(args: argparse.Namespace) -> None:
    """The command's words, checked before any login (bad input: exit 2)."""
    if not args.user or not args.user.strip():
        raise InputError("--user: the name of a user of the station's access section")
    if not 1 <= len(args.vin.strip()) <= 32 or any(c.isspace() for c in args.vin.strip()):
        raise InputError(f"VIN {args.vin!r}: 1-32 characters without spaces")
    if args.command in BOLT_COMMANDS and not 1 <= len(args.bolt.strip()) <= 32:
        raise InputError(f"bolt {args.bolt!r}: 1-32 characters")
    check_comment(args.comment)


#: the longest comment a command keeps (the screens' limit too)
MAX_COMMENT = 500


def check_comment(comment: str | None) -> None:
    """A command's ``--comment``, checked before any login (bad input: exit 2)."""
    if len(comment or "") > MAX_COMMENT:
        raise InputError(f"--comment: at most {MAX_COMMENT} characters ({len(comment or '')} "
                         "given)")


def _unreachable(url: str, exc: BaseException) -> int:
    reason = getattr(exc, "reason", exc)
    sys.stderr.write(f"stationd: no daemon answers at {url}: {reason}\n")
    return EXIT_UNREACHABLE


def cmd_command(args: argparse.Namespace) -> int:
    """``skip``, ``reopen``, ``release`` and ``loosen``: log in, give the command, print the
    station's answer."""
    _check_command(args)
    body: dict[str, Any] = {"kind": args.command, "vin": args.vin.strip(),
                            "comment": args.comment or ""}
    if args.command in BOLT_COMMANDS:
        body["bolt"] = args.bolt.strip()
    return _session_command(args, args.user, body)


def _session_command(args: argparse.Namespace, user: str, body: dict[str, Any]) -> int:
    """Log in as ``user``, give ``body``'s command, print the station's answer."""
    client = ApiClient(args.url, args.token, args.timeout)
    try:
        status, who = client.call("/api/login", {"user": user, "password": read_password(),
                                                 "client": "cli"})
        if status != 200:
            return say_refused("login refused", status, who)
        status, nonce = client.call("/api/nonce")
        if status != 200 or not isinstance(nonce, dict):
            return say_refused(body["kind"], status, nonce)
    except (urllib.error.URLError, OSError) as exc:
        return _unreachable(args.url, exc)
    try:
        status, answer = client.call("/api/commands", {**body, "nonce": nonce["nonce"]})
    except (urllib.error.URLError, OSError) as exc:
        # the daemon answered the login: the command may well have been taken; giving it
        # again blind could skip or loosen twice, so say what is known and where to look
        sys.stderr.write(
            f"stationd: {body['kind']}: sent to {args.url}, but its answer did not arrive "
            f"({getattr(exc, 'reason', exc)}); it may have been accepted: check the "
            "journal or `stationd status` before giving it again\n")
        return EXIT_UNREACHABLE
    try:
        client.call("/api/logout", {})
    except (urllib.error.URLError, OSError):
        pass   # the answer is in hand; the session times out by itself
    if status in (200, 409) and isinstance(answer, dict):
        print(answer["words"])
        return 0 if answer["accepted"] else EXIT_REFUSED
    sys.stderr.write(f"stationd: {body['kind']}: HTTP {status}: {answer}\n")
    return EXIT_UNREACHABLE if status >= 500 else EXIT_REFUSED


def cmd_operator(args: argparse.Namespace) -> int:
    """``operator sign-in USER``: USER signs in at the station (their password); ``sign-out
    --user NAME``: whoever is signed in is signed out (NAME's password); ``status``: who is
    signed in (no login: the screens' status)."""
    if args.operator_command == "status":
        return _operator_status(args)
    user = args.user if args.operator_command == "sign-out" else args.name
    if not user or not user.strip() or len(user) > 64:
        raise InputError(f"user {user!r}: the name of a user of the station's access section")
    check_comment(args.comment)
    return _session_command(args, user.strip(), {"kind": args.operator_command,
                                                 "comment": args.comment or ""})


def _operator_status(args: argparse.Namespace) -> int:
    client = ApiClient(args.url, args.token, args.timeout)
    try:
        status, doc = client.call("/api/status")
    except (urllib.error.URLError, OSError) as exc:
        return _unreachable(args.url, exc)
    if status != 200 or not isinstance(doc, dict):
        return say_refused("operator status", status, doc)
    op = doc.get("operator") or {}
    if op.get("user"):
        print(f"operator: {op['user']} signed in")
    else:
        print("operator: nobody signed in" + (
            " (the station requires one: sign in to tighten)" if op.get("required") else ""))
    return 0


def cmd_feed(args: argparse.Namespace) -> int:
    """Every record after ``--since``, one JSON object per line (what a forwarder reads)."""
    if args.since < 0 or not 1 <= args.limit <= 1000:
        raise InputError("--since >= 0, --limit 1-1000")
    client = ApiClient(args.url, args.token, args.timeout)
    try:
        status, doc = client.call(f"/api/feed?since={args.since}&limit={args.limit}")
    except (urllib.error.URLError, OSError) as exc:
        return _unreachable(args.url, exc)
    if status != 200 or not isinstance(doc, dict):
        return say_refused("feed", status, doc)
    for e in doc["entries"]:
        print(json.dumps({"db_id": doc["db_id"], **e}, separators=(",", ":")))
    return 0


def cmd_user_hash(args: argparse.Namespace) -> int:
    """The scrypt hash of a password (asked twice at a terminal) for ``access.users``."""
    password = read_password()
    if sys.stdin.isatty() and "STATIOND_PASSWORD" not in os.environ \
            and getpass.getpass("again: ") != password:
        raise InputError("the two passwords differ")
    if len(password) < 8:
        raise InputError("a password of at least 8 characters")
    print(hash_password(password))
    return 0


def client_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--url", default=DEFAULT_URL, help=f"the daemon's screens (default "
                   f"{DEFAULT_URL})")
    p.add_argument("--token", help="the http token, when the daemon has one (or "
                   "STATIOND_TOKEN: an argument shows in ps)")
    p.add_argument("--timeout", type=float, default=15.0, help="seconds (default 15)")


def add_command_parsers(sub: Any) -> None:
    """``skip``, ``reopen``, ``release``, ``feed`` and ``user hash`` on ``build_parser``'s
    sub-parsers."""
    epilog = ("The password: STATIOND_PASSWORD, else a prompt, else the first line of "
              "standard input.  Exit 0 accepted, 1 refused (why is printed), 2 bad input, "
              "3 no answer or login refused.")
    sk = sub.add_parser("skip", help="skip a bolt of the vehicle at the station (a command "
                        "to the running daemon)", epilog=epilog)
    sk.add_argument("vin")
    sk.add_argument("bolt")
    ro = sub.add_parser("reopen", help="reopen a closed vehicle for rework (a command to the "
                        "running daemon)", epilog=epilog)
    ro.add_argument("vin")
    rl = sub.add_parser("release", help="release a bolt locked after too many NOKs (a "
                        "command to the running daemon)", epilog=epilog)
    rl.add_argument("vin")
    rl.add_argument("bolt")
    lo = sub.add_parser("loosen", help="loosen a tightened bolt for rework: it gets its loosen "
                        "pset next, then its tightening pset (a command to the running "
                        "daemon; the loosen right)", epilog=epilog)
    lo.add_argument("vin")
    lo.add_argument("bolt")
    for p, name in ((sk, "skip"), (ro, "reopen"), (rl, "release"), (lo, "loosen")):
        p.add_argument("--comment", default="", help="why (kept with the command)")
        p.add_argument("--user", required=True, help="who gives the command")
        client_args(p)
        p.set_defaults(func=cmd_command, command=name)
    op = sub.add_parser("operator", help="the operator signed in at the station: every "
                        "rundown is recorded with them (commands to the running daemon)",
                        epilog=epilog)
    osub = op.add_subparsers(dest="operator_command", required=True)
    si = osub.add_parser("sign-in", help="USER signs in at the station as its operator (any "
                         "user of the access section, with their password)", epilog=epilog)
    si.add_argument("name", metavar="USER")
    so = osub.add_parser("sign-out", help="whoever is signed in at the station is signed out",
                         epilog=epilog)
    so.add_argument("--user", required=True, help="who gives the command")
    st = osub.add_parser("status", help="who is signed in at the station")
    for p in (si, so):
        p.add_argument("--comment", default="", help="kept with the command")
    for p in (si, so, st):
        client_args(p)
        p.set_defaults(func=cmd_operator)
    fd = sub.add_parser("feed", help="the records after a sequence number, one JSON per line")
    fd.add_argument("--since", type=int, default=0)
    fd.add_argument("--limit", type=int, default=100)
    client_args(fd)
    fd.set_defaults(func=cmd_feed)
    us = sub.add_parser("user", help="users of the station's access section")
    usub = us.add_subparsers(dest="user_command", required=True)
    uh = usub.add_parser("hash", help="print the scrypt hash of a password for "
                         "access.users.NAME.password")
    uh.set_defaults(func=cmd_user_hash)


__all__ = ["EXIT_REFUSED", "EXIT_UNREACHABLE", "ApiClient", "add_command_parsers",
           "check_comment", "client_args", "cmd_command", "cmd_feed", "cmd_operator",
           "cmd_user_hash", "read_password", "say_refused"]
