"""``stationd status [--url URL] [--token T] [--json]``: ask a running daemon its state.

Why over HTTP: the daemon already serves ``/api/status`` for its screens; the command is a
client of it (no second channel into the daemon, nothing it can change).
"""

from __future__ import annotations

import argparse
import json
import sys
import urllib.error
import urllib.parse
import urllib.request
from typing import Any

from stationd.errors import InputError

DEFAULT_URL = "http://127.0.0.1:8080/"
EXIT_FAULT = 1          # answered, but the station is in fault: not OK for a monitor
# no status at all (no daemon answers, or it refused: a wrong token): another alarm than a
# station in fault, so a monitoring script can tell them apart
EXIT_UNREACHABLE = 3


def add_status_parser(sub: Any) -> None:
    """Add the ``status`` sub-command to ``build_parser``'s sub-parsers."""
    st = sub.add_parser("status", help="a running daemon's state (from its web server)",
                        description="Exit 0: the daemon answers and its station is not in "
                                    "fault; 1: it is in fault (the reason is printed); 2: bad "
                                    "input; 3: no status (no daemon answers, or it refused the "
                                    "token).  For monitoring scripts.")
    st.add_argument("--url", default=DEFAULT_URL, help=f"the daemon's screens (default "
                    f"{DEFAULT_URL})")
    st.add_argument("--token", help="the http token, when the daemon has one")
    st.add_argument("--json", action="store_true", help="print the status object as it is")
    st.add_argument("--timeout", type=float, default=5.0, help="seconds (default 5)")
    st.set_defaults(func=cmd_status)


def status_url(url: str) -> str:
    """``http://host:port[/]`` -> its ``/api/status``; InputError for anything else."""
    try:
        u = urllib.parse.urlsplit(url)
        port = u.port        # checks the port's range
    except ValueError:
        raise InputError(f"--url {url!r}: expected http://host:port/") from None
    if u.scheme not in ("http", "https") or not u.hostname or port == 0:
        raise InputError(f"--url {url!r}: expected http://host:port/")
    if any(c.isspace() or not c.isprintable() for c in url):
        # http.client refuses them later with InvalidURL, which is no ValueError
        raise InputError(f"--url {url!r}: a URL has no spaces or control characters "
                         "(expected http://host:port/)")
    return urllib.parse.urlunsplit((u.scheme, u.netloc, u.path.rstrip("/") + "/api/status",
                                    "", ""))


def fetch_status(url: str, token: str | None = None, timeout: float = 5.0) -> dict[str, Any]:
    req = urllib.request.Request(status_url(url))  # noqa: S310 - scheme checked: http(s)
    if token:
        req.add_header("Authorization", f"Bearer {token}")
    with urllib.request.urlopen(req, timeout=timeout) as r:  # noqa: S310
        doc: dict[str, Any] = json.loads(r.read().decode())
        return doc


def format_status(st: dict[str, Any]) -> str:
    """The status as a few readable lines."""
    lines = [f"state:    {st['state']}" + (f" ({st['reason']})" if st.get("reason") else "")]
    if st.get("headline") and st["headline"] not in (st["state"], st.get("reason")):
        lines.append(f"now:      {st['headline']}")
    v = st.get("vehicle")
    c = st.get("counters", {})
    lines.append("vehicle:  " + ("none" if not v else
                                 f"{v['vin']} ({v['model']}{', rework' if v.get('rework') else ''})"
                                 f": {c.get('done', 0)}/{c.get('total', 0)} done, "
                                 f"{c.get('nok', 0)} NOK"))
    op = st.get("operator") or {}
    if op.get("user") or op.get("required"):
        lines.append("operator: " + (op.get("user") or "nobody signed in: sign in to tighten"))
    for name, d in sorted(st.get("devices", {}).items()):
        check = d.get("check") or {}   # a pair's calibration check: up is not trusted
        lines.append(f"device:   {name}: " + (
            "ok" if d["ok"] else "not opened yet" if d.get("kind") == "opening"
            else f"{d.get('kind', '')} {d.get('reason', '')}")
            + (f"; {check['words']}" if d["ok"] and check and not check.get("trusted")
               else ""))
    vers = st.get("versions", {})
    lines.append("versions: " + ", ".join(f"{k} {x}" for k, x in sorted(vers.items())))
    return "\n".join(lines)


def cmd_status(args: argparse.Namespace) -> int:
    if not 0 < args.timeout <= 3600:
        raise InputError(f"--timeout {args.timeout:g}: expected seconds in (0, 3600]")
    status_url(args.url)   # bad input is exit 2, not "no daemon"
    try:
        st = fetch_status(args.url, args.token, args.timeout)
    except urllib.error.HTTPError as exc:
        hint = " (the daemon has an http token: --token TOKEN)" if exc.code == 401 else ""
        sys.stderr.write(f"stationd: status: {args.url}: HTTP {exc.code} {exc.reason}"
                         f"{hint}\n")
        return EXIT_UNREACHABLE
    except (urllib.error.URLError, OSError, ValueError) as exc:
        reason = getattr(exc, "reason", exc)
        sys.stderr.write(f"stationd: status: no daemon answers at {args.url}: {reason}\n")
        return EXIT_UNREACHABLE
    print(json.dumps(st, indent=1) if args.json else format_status(st))
    return EXIT_FAULT if st.get("state") == "fault" else 0
