"""People's commands from the command line, through the running daemon's API (the screens'
path: log in with a user's password, give the command, read the station's answer), and the
password hashes the station file keeps.

    stationd skip VIN BOLT --comment TEXT --user NAME
    stationd reopen VIN [--comment TEXT] --user NAME
    stationd release VIN BOLT --comment TEXT --user NAME
    stationd loosen VIN BOLT --comment TEXT --user NAME
    stationd enter-outcome VIN BOLT --ok|--nok --torque NM --angle DEG --comment TEXT --user NAME
    stationd operator sign-in USER [--comment TEXT]   # USER signs in at the station
    stationd operator sign-out --user NAME [--comment TEXT]
    stationd operator status
    stationd feed [--since N] [--limit M]
    stationd status [--json]
    stationd user hash

Which daemon: the one of the station file (``--config STATION.yaml``, by default
:data:`DEFAULT_CONFIG`, the file the systemd unit runs), at its screens' address
(``http.listen``, 127.0.0.1:8080 without one) with its ``http.token``; ``--url`` (and
``--token``) to say another.  Each command first asks the daemon which station it is
(``/api/status``), names it in its first line, and with a station file refuses to act when
another station answers (exit 3): a daemon that could not take its port, with another
station's daemon on it, must not have that station's bolts skipped in its name.

The password comes from ``STATIOND_PASSWORD``, else a prompt (a terminal), else the first
line of standard input; it never goes on the command line (``ps`` would show it); the http
token from ``--token`` or ``STATIOND_TOKEN``.  Exit 0:
accepted; 1: refused by the station (the reason is printed); 2: bad input; 3: no answer, or
the login was refused.
"""

from __future__ import annotations

import argparse
import contextlib
import getpass
import http.cookiejar
import io
import json
import math
import os
import re
import socket
import sys
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from drivers.counting import counted
from stationd.access import hash_password
from stationd.errors import InputError
from stationd.station.commands import WITH_REASON
from stationd.station.events import State
from stationd.web.status_cli import (
    DEFAULT_URL,
    EXIT_FAULT,
    EXIT_RELOAD_REFUSED,
    EXIT_UNREACHABLE,
    format_status,
    status_url,
)

EXIT_REFUSED = 1
#: the station file a command reads when given none: the one ``stationd run`` is given by
#: the systemd unit (systemd/stationd.service), so that on a station PC ``stationd status``
#: asks that station's daemon
DEFAULT_CONFIG = Path("/etc/stationd/station.yaml")


@dataclass(frozen=True)
class Target:
    """The daemon a command talks to: its URL and token, and the station it must be
    (``expected``: ``stationd.config.station_identity`` of the station file; None with
    ``--url`` alone: whichever answers there, named)."""

    url: str
    token: str | None
    expected: dict[str, str | None] | None
    config: str | None
    #: the station file has no ``http:`` section: its daemon serves no API (a command that
    #: finds nothing says so, not "is stationd running?" of a daemon that runs)
    no_api: bool = False
    #: the address is the station file's ``http.listen`` (no ``--url``)
    from_file: bool = False

    def via(self) -> str:
        """How the command reached the station, for a command line it says to give again
        (``stationd teach --stop --user NAME --url ...``): nothing for the default station
        file, else its ``--config`` or ``--url``."""
        return "" if self.config == str(DEFAULT_CONFIG) else \
            f" --config {self.config}" if self.config is not None else f" --url {self.url}"


def daemon_url(cfg: Any) -> str:
    """Where a station's daemon serves its API: its ``http.listen`` (127.0.0.1:8080 without
    an ``http:`` section, where the demo serves its screens; the daemon serves none there,
    and a command then says it found no daemon, or another station).  A daemon bound to
    every address is asked on loopback (a bind is not a client's target)."""
    from stationd.web.config import DEFAULT_LISTEN, split_listen

    host, port = split_listen(cfg.http.listen if cfg.http is not None else DEFAULT_LISTEN)
    host = {"0.0.0.0": "127.0.0.1", "::": "::1"}.get(host, host)  # noqa: S104
    return f"http://{f'[{host}]' if ':' in host else host}:{port}/"


def find_station(args: argparse.Namespace) -> Target:
    """The daemon of ``--config`` (or :data:`DEFAULT_CONFIG`), or at ``--url``; bad input
    (exit 2) when neither names one."""
    timeout = getattr(args, "timeout", 15.0)
    if not 0 < timeout <= 3600:    # NaN too; before the file is read
        raise InputError(f"--timeout {timeout:g}: expected seconds in (0, 3600]")
    config: str | None = getattr(args, "config", None)
    url: str | None = getattr(args, "url", None)
    token: str | None = getattr(args, "token", None)
    if config is None and url is None:
        if not DEFAULT_CONFIG.exists():
            raise InputError(f"which station: no {DEFAULT_CONFIG} here (the station file the "
                             "daemon runs); give --config STATION.yaml, or --url "
                             "http://HOST:PORT/ of its screens")
        config = str(DEFAULT_CONFIG)
    if config is None:
        assert url is not None  # noqa: S101 - neither given was handled above
        status_url(url)   # checked before anything is read: bad input is exit 2
        return Target(url, token, None, None)
    from stationd.config import load_station_config, station_identity
    from stationd.errors import ConfigError

    try:
        cfg = load_station_config(config)
    except ConfigError as exc:
        # a reload of this file was refused, perhaps: the daemon runs on what it loaded
        # before, and answers at the address the file's http section still says
        if not Path(config).is_file():
            raise                               # a typo in the path, most likely
        http = _http_section(config)
        if http is None and url is not None:
            http = SimpleNamespace(http=None)   # the daemon's address given: asked there
        if http is None:
            raise InputError(f"{exc}; if a daemon runs on this file (a reload of it "
                             "refused, it keeps what it read before), give --url "
                             "http://HOST:PORT/ of its screens to reach it") from None
        where = "at --url" if url is not None else "at its http section's address"
        sys.stderr.write(f"stationd: {config} does not read ({exc}); asking the daemon "
                         f"{where} (a refused reload leaves it running on the file it read "
                         "before)\n")
        return Target(url or daemon_url(http), token or getattr(http.http, "token", None), None,
                      config)
    if token is None and cfg.http is not None:
        token = cfg.http.token
    return Target(url or daemon_url(cfg), token, station_identity(cfg), config,
                  no_api=url is None and cfg.http is None,
                  from_file=url is None and cfg.http is not None)


def _http_section(path: str) -> Any:
    """The ``http:`` section of a station file that does not read as a whole, read alone by
    its own reader (an object with ``http``, as :func:`daemon_url` takes it); None where that
    section does not read either, or the file's sections cannot be read at all."""
    from stationd.config import read_all
    from stationd.errors import ConfigError
    from stationd.web.config import HttpConfig

    top = read_all(path).sections
    node = top.get("http") if top else _http_alone(path)
    if top and node is None:
        return SimpleNamespace(http=None)
    if node is None:
        return None
    try:
        return SimpleNamespace(http=HttpConfig.from_node(node))
    except ConfigError:
        return None


#: the first line of a station file's ``http:`` section (a top-level key)
_HTTP_LINE = re.compile(r"^http\s*:")


def _http_alone(path: str) -> Any:
    """The ``http:`` section of a file that does not parse as YAML at all (a bad indent
    elsewhere, a bracket left open): its lines alone, parsed at their own line numbers;
    None where there is none or it does not parse either.  The most common bad edit must
    not keep a supervisor's release from the daemon still running on the file it read."""
    from stationd.errors import ConfigError
    from stationd.yamlio import MAX_YAML_BYTES, YamlNode, read_text_file

    try:
        lines = read_text_file(Path(path), MAX_YAML_BYTES, "a YAML file").splitlines()
    except ConfigError:
        return None
    start = next((i for i, line in enumerate(lines) if _HTTP_LINE.match(line)), None)
    if start is None:
        return None
    end = next((i for i in range(start + 1, len(lines))
                if lines[i][:1] not in ("", " ", "\t", "#")), len(lines))
    try:
        root = YamlNode.parse("\n" * start + "\n".join(lines[start:end]), path)
        return root.mapping(("http",)).get("http")
    except ConfigError:
        return None


def station_words(url: str, station: Any, hint: bool = True) -> str:
    """The station that answered at ``url``, as a command's first line names it; ``hint``:
    with how to give a station without an id one (said by ``status`` and where the wrong
    station answered; on every command's first line it was noise: two users' trials)."""
    if not isinstance(station, dict) or (not station.get("config") and not station.get("id")):
        return f"station at {url}: it does not say which (not a stationd daemon of this " \
               "version?)"
    if station.get("id"):
        return f"station {station['id']} at {url} ({station.get('config') or 'its file unsaid'})"
    return f"station at {url}: {station.get('config')}" + (
        " (it has no station id: set line.station_id or opcua.station_id in its station file "
        "to name it)" if hint else "")


def same_station(expected: dict[str, str | None], answered: Any) -> bool:
    """Whether the station that answered is the one the station file names: the same file
    (resolved), or the same station id (a copy of its file, on another PC)."""
    if not isinstance(answered, dict):
        return False
    if expected.get("config") and answered.get("config") == expected["config"]:
        return True
    return bool(expected.get("id")) and answered.get("id") == expected["id"]


def identify(client: ApiClient, target: Target, what: str, *, out: Any = None
             ) -> dict[str, Any] | int:
    """Ask the daemon which station it is (its ``/api/status``, which is returned), name it
    on ``out`` (stdout, or stderr for a command whose stdout is JSON); an exit code instead
    when nothing answers, something else answers, or another station does."""
    try:
        status, doc = client.call("/api/status")
    except (urllib.error.URLError, OSError) as exc:
        return _unreachable(target, exc, what)
    if status != 200 or not isinstance(doc, dict):
        return say_refused(what, status, doc)
    answered = doc.get("station")
    if target.expected is not None and not same_station(target.expected, answered):
        want = station_words(target.url, target.expected).split(" at ", 1)[0] \
            if target.expected.get("id") else f"the station of {target.expected['config']}"
        sys.stderr.write(
            f"stationd: {what}: {station_words(target.url, answered)}, not {want} "
            f"(--config {target.config}): nothing done; is that station's daemon running, "
            "and serving its screens at its http.listen? (--url to say where)\n")
        return EXIT_UNREACHABLE
    print(station_words(target.url, answered, hint=what == "status"), file=out or sys.stdout,
          flush=True)
    return doc


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


#: what a command says when it was given no password (bad input, exit 2)
NO_PASSWORD = ("no password given: set STATIOND_PASSWORD, type it at the prompt, or give it "  # noqa: S105
               "as the first line of standard input")


def prompts() -> bool:
    """Whether :func:`read_password` asks at a terminal (else it reads without waiting for a
    person: the environment or standard input)."""
    return "STATIOND_PASSWORD" not in os.environ and sys.stdin.isatty()


def read_password(user: str | None = None) -> str:
    """The password (see the module's words), of ``user`` as a prompt asks it; an empty one
    (standard input empty, ``< /dev/null``) is bad input, said so, never sent as a login a
    daemon refuses."""
    if "STATIOND_PASSWORD" in os.environ:
        password = os.environ["STATIOND_PASSWORD"]
    elif sys.stdin.isatty():
        password = getpass.getpass(f"{user}'s password: " if user else "password: ")
    else:
        line = sys.stdin.readline(MAX_PASSWORD + 1)
        if len(line) > MAX_PASSWORD:
            raise InputError(f"the password on standard input: no end of line within "
                             f"{MAX_PASSWORD} characters (one line, the password)")
        password = line.rstrip("\r\n")
    if not password:
        raise InputError(NO_PASSWORD)
    return password


def say_refused(what: str, status: int, answer: Any) -> int:
    """A refusal before the station saw the command (the token, the login, the API)."""
    if status == 401 and str(answer).startswith("token required"):
        answer = ("the daemon refused the http token (HTTP 401; --token, the station file's "
                  "http.token, or STATIOND_TOKEN)")
    elif status in (404, 405) or not str(answer).strip():
        # another server on that port (it said nothing a person could use, or has no such
        # page): said so, never "login refused: " with nothing after it
        answer = (f"not a stationd daemon's screens at this URL (HTTP {status}; --url "
                  "http://HOST:PORT/)")
    sys.stderr.write(f"stationd: {what}: {answer}\n")
    return EXIT_UNREACHABLE


#: the commands that name a bolt of the vehicle at the station
BOLT_COMMANDS = ("skip", "release", "loosen", "enter-outcome")


def _check_command(args: argparse.Namespace) -> None:
    """The command's words, checked before any login (bad input: exit 2)."""
    if not args.user or not args.user.strip():
        raise InputError("--user: the name of a user of the station's access section")
    if not 1 <= len(args.vin.strip()) <= 32 or any(c.isspace() for c in args.vin.strip()):
        raise InputError(f"VIN {args.vin!r}: 1-32 characters without spaces")
    if args.command in BOLT_COMMANDS and not 1 <= len(args.bolt.strip()) <= 32:
        raise InputError(f"bolt {args.bolt!r}: 1-32 characters")
    check_comment(args.comment)
    if args.command in WITH_REASON and not (args.comment or "").strip():
        raise InputError(f"--comment: why ({REASON_NOUNS[args.command]} is kept with its "
                         "reason: quality reads it)")
    if args.command == "enter-outcome":
        _check_outcome(args)


def _check_outcome(args: argparse.Namespace) -> None:
    """An entered outcome's values, as the controller's screen shows them (bad input: exit
    2): finite numbers, a torque not below 0, and a comment saying what was checked."""
    for name, v, low in (("--torque", args.torque, 0.0), ("--angle", args.angle, -1e5)):
        if not math.isfinite(v) or not low <= v <= 1e5:
            raise InputError(f"{name} {v:g}: a number from {low:g} to 100000, as the "
                             "controller's screen shows it")
    if not (args.comment or "").strip():
        raise InputError("--comment: what was checked on the controller (required for an "
                         "entered outcome)")


#: the longest comment a command keeps (the screens' limit too)
MAX_COMMENT = 500
#: how a refusal for a missing reason names each command given only with its reason
#: (``station.commands.WITH_REASON``, which decides)
REASON_NOUNS = {"skip": "a skip", "release": "a release", "loosen": "a loosen order"}


def check_comment(comment: str | None) -> None:
    """A command's ``--comment``, checked before any login (bad input: exit 2)."""
    if len(comment or "") > MAX_COMMENT:
        raise InputError(f"--comment: at most {MAX_COMMENT} characters ({len(comment or '')} "
                         "given)")
    if not (comment or "").isprintable():
        raise InputError("--comment: printable characters only (no newline, tab or control "
                         "character)")


def network_words(exc: BaseException) -> str:
    """Why a request got no answer, in words ("connection refused", "timed out", "the host
    name HOST is not known"), not as ``[Errno 111] Connection refused``."""
    reason = getattr(exc, "reason", exc)
    if isinstance(reason, ConnectionRefusedError):
        return "connection refused"
    if isinstance(reason, TimeoutError) or "timed out" in str(reason):
        return "timed out"
    if isinstance(reason, socket.gaierror):
        return "the host name is not known"
    if isinstance(reason, OSError) and reason.strerror:
        return reason.strerror[0].lower() + reason.strerror[1:]
    return str(reason) or type(reason).__name__


def unreachable_words(url: str, exc: BaseException, hint: str | None = None) -> str:
    """"no daemon answers at URL (connection refused): is stationd running?" and the like:
    the URL asked, why in words, and what to look at (``hint``, where the caller knows
    better than the network's why)."""
    why = network_words(exc)
    if hint is None:
        hint = {"connection refused": "is stationd running?",
                "timed out": "is stationd running there, and not stopped? (a larger "
                             "--timeout if it is busy)"}.get(
            why, "is the URL right, and stationd running?")
    return f"no daemon answers at {url} ({why}): {hint}"


def _unreachable(target: Target, exc: BaseException, what: str = "") -> int:
    hint = None if not target.no_api else (
        f"{target.config} has no http: section, so its daemon serves no API for stationd "
        "status and the commands: add one (http: {listen: '127.0.0.1:8080'}) and reload, or "
        "give --url")
    if hint is None and target.from_file:
        # the file's address, which a daemon whose reload of it was refused does not serve
        # (a technician's trial: http.listen moved to a port in use, the reload refused, the
        # daemon alive on its old port, and status said only "is stationd running?")
        why = network_words(exc)
        hint = ("is stationd running? " if why == "connection refused" else
                "is stationd running there? ") + \
            "(a daemon whose reload of this file was refused serves the address it read " \
            "before: its journal says which; --url to ask it there)"
    sys.stderr.write(f"stationd: {what + ': ' if what else ''}"
                     f"{unreachable_words(target.url, exc, hint)}\n")
    return EXIT_UNREACHABLE


def cmd_command(args: argparse.Namespace) -> int:
    """``skip``, ``reopen``, ``release`` and ``loosen``: log in, give the command, print the
    station's answer."""
    _check_command(args)
    body: dict[str, Any] = {"kind": args.command, "vin": args.vin.strip(),
                            "comment": args.comment or ""}
    if args.command in BOLT_COMMANDS:
        body["bolt"] = args.bolt.strip()
    if args.command == "enter-outcome":
        body.update(ok=args.ok, torque_nm=args.torque, angle_deg=args.angle)
    return session_command(args, args.user, body)


def session_command(args: argparse.Namespace, user: str, body: dict[str, Any]) -> int:
    """Name the station, log in as ``user``, give ``body``'s command, print the station's
    answer."""
    target = find_station(args)
    client = ApiClient(target.url, target.token, args.timeout)
    # a password read without a person (the environment, standard input) is read first:
    # none given is told without asking the daemon; a prompt comes after the station is
    # named, so that the person knows whose password is asked
    password = None if prompts() else read_password(user)
    known = identify(client, target, body["kind"])
    if isinstance(known, int):
        return known
    if password is None:
        password = read_password(user)
    try:
        status, who = client.call("/api/login", {"user": user, "password": password,
                                                 "client": "cli"})
        if status != 200:
            return say_refused("login refused", status, who)
        status, nonce = client.call("/api/nonce")
        if status != 200 or not isinstance(nonce, dict):
            return say_refused(body["kind"], status, nonce)
    except (urllib.error.URLError, OSError) as exc:
        return _unreachable(target, exc)
    try:
        status, answer = client.call("/api/commands", {**body, "nonce": nonce["nonce"]})
    except (urllib.error.URLError, OSError) as exc:
        # the daemon answered the login: the command may well have been taken; giving it
        # again blind could skip or loosen twice, so say what is known and where to look
        sys.stderr.write(
            f"stationd: {body['kind']}: sent to {target.url}, but its answer did not arrive "
            f"({network_words(exc)}); it may have been accepted: check the "
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
    return session_command(args, user.strip(), {"kind": args.operator_command,
                                                 "comment": args.comment or ""})


def _operator_status(args: argparse.Namespace) -> int:
    target = find_station(args)
    doc = identify(ApiClient(target.url, target.token, args.timeout), target,
                   "operator status", out=sys.stderr if args.json else sys.stdout)
    if isinstance(doc, int):
        return doc
    op = doc.get("operator") or {}
    if args.json:   # for a script: as the status's own JSON says it
        print(json.dumps({"user": op.get("user"), "required": bool(op.get("required"))}))
    elif op.get("user"):
        print(f"operator: {op['user']} signed in")
    else:
        print("operator: nobody signed in" + (
            " (the station requires one: sign in to tighten)" if op.get("required") else ""))
    return 0


def cmd_feed(args: argparse.Namespace) -> int:
    """Every record after ``--since``, one JSON object per line (what a forwarder reads)."""
    if args.since < 0 or not 1 <= args.limit <= 1000:
        raise InputError("--since >= 0, --limit 1-1000")
    target = find_station(args)
    client = ApiClient(target.url, target.token, args.timeout)
    known = identify(client, target, "feed", out=sys.stderr)   # stdout: JSON lines only
    if isinstance(known, int):
        return known
    try:
        status, doc = client.call(f"/api/feed?since={args.since}&limit={args.limit}")
    except (urllib.error.URLError, OSError) as exc:
        return _unreachable(target, exc)
    if status != 200 or not isinstance(doc, dict):
        return say_refused("feed", status, doc)
    entries = doc["entries"]
    for e in entries:
        print(json.dumps({"db_id": doc["db_id"], **e}, separators=(",", ":")))
    last = doc.get("last_seq")
    if entries and isinstance(last, int) and last > entries[-1]["seq"]:
        # a reader that stops at --limit without a word takes the page for the whole
        sys.stderr.write(f"stationd: feed: {counted(len(entries), 'record')} up to seq "
                         f"{entries[-1]['seq']}; more up to seq {last}: give --since "
                         f"{entries[-1]['seq']}\n")
    return 0


def cmd_status(args: argparse.Namespace) -> int:
    """``stationd status``: the station that answered, then its state (``--json``: the
    status object, the station's line on stderr).  Exit 0 not in fault, 1 in fault (the
    station, or a device that reports one: a lift PLC's fault bit), 3 no
    status of this station, 4 not in fault but its last reload refused (it runs on what it
    read before)."""
    if not 0 < args.timeout <= 3600:    # NaN too
        raise InputError(f"--timeout {args.timeout:g}: expected seconds in (0, 3600]")
    target = find_station(args)
    client = ApiClient(target.url, target.token, args.timeout)
    if not args.json:
        doc = identify(client, target, "status", out=sys.stdout)
        if isinstance(doc, int):
            return doc
        print(format_status(doc, target.via()))
    else:
        # no status: a JSON object still, saying why (a technician's trial: a monitoring
        # script got nothing on stdout); the words on stderr as ever
        said = io.StringIO()
        try:
            with contextlib.redirect_stderr(said):
                doc = identify(client, target, "status", out=sys.stderr)
        finally:    # said whatever happened (an error raised is told after it)
            sys.stderr.write(said.getvalue())
        if isinstance(doc, int):
            why = said.getvalue().strip().splitlines()
            print(json.dumps({"answered": False, "url": target.url, "exit": doc,
                              "error": why[-1].removeprefix("stationd: ") if why else None},
                             indent=1))
            return doc
        print(json.dumps(doc, indent=1))
    # the daemon's own verdict, as /healthz's 503 (a device reporting its fault too); a
    # daemon of an earlier version gives its state alone
    if doc.get("in_fault", doc.get("state") == State.FAULT):
        return EXIT_FAULT
    return EXIT_RELOAD_REFUSED if doc.get("reload_refused") else 0


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


def client_args(p: argparse.ArgumentParser, timeout: float = 15.0,
                config: bool = True) -> None:
    """``--config``, ``--url``, ``--token``, ``--timeout`` of a command to the daemon
    (``config``: False for a command that has its own ``--config``)."""
    if config:
        p.add_argument("--config", metavar="STATION.yaml",
                       help=f"the station file of the daemon to ask (default {DEFAULT_CONFIG}, "
                       "the file the systemd unit runs): its http.listen and http.token; "
                       "a daemon of another station is refused")
    p.add_argument("--url", help=f"the daemon's screens, http://HOST:PORT/ (default: the "
                   f"station file's http.listen, else {DEFAULT_URL}); with --config, checked "
                   "to be that station's")
    p.add_argument("--token", help="the http token, when the daemon has one (default: the "
                   "station file's http.token, else STATIOND_TOKEN; an argument shows in ps)")
    p.add_argument("--timeout", type=float, default=timeout,
                   help=f"seconds (default {timeout:g})")


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
    rl = sub.add_parser("release", help="release a bolt locked after too many NOKs, or held "
                        "(its result not known: it is tightened again; where the controller "
                        "shows its result, enter-outcome instead) (a command to the running "
                        "daemon; the release right)", epilog=epilog)
    rl.add_argument("vin")
    rl.add_argument("bolt")
    lo = sub.add_parser("loosen", help="loosen a tightened bolt for rework: it gets its loosen "
                        "pset next, then its tightening pset (a command to the running "
                        "daemon; the loosen right)", epilog=epilog)
    lo.add_argument("vin")
    lo.add_argument("bolt")
    eo = sub.add_parser("enter-outcome", help="resolve a held bolt (its result could not be "
                        "read) with the outcome read on the controller's own screen: recorded "
                        "as entered by you, OK closes the bolt, NOK counts as a NOK (a command "
                        "to the running daemon; the release right)", epilog=epilog)
    eo.add_argument("vin")
    eo.add_argument("bolt")
    verdict = eo.add_mutually_exclusive_group(required=True)
    verdict.add_argument("--ok", dest="ok", action="store_true", default=None,
                         help="the controller shows the tightening OK")
    verdict.add_argument("--nok", dest="ok", action="store_false",
                         help="the controller shows it NOK")
    eo.add_argument("--torque", type=float, required=True, metavar="NM",
                    help="the final torque the controller shows, N m")
    eo.add_argument("--angle", type=float, required=True, metavar="DEG",
                    help="the final angle the controller shows, degrees")
    for p, name in ((sk, "skip"), (ro, "reopen"), (rl, "release"), (lo, "loosen"),
                    (eo, "enter-outcome")):
        if p is eo:     # what was read on the controller: the entry's only evidence
            p.add_argument("--comment", required=True,
                           help="what you checked on the controller (kept with the command)")
        elif name in WITH_REASON:
            p.add_argument("--comment", default="", help="why (required: kept with the "
                                                         "command)")
        else:
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
    st.add_argument("--json", action="store_true",
                    help="one JSON object on stdout ({\"user\", \"required\"}), the station's "
                         "line on stderr")
    for p in (si, so):
        p.add_argument("--comment", default="", help="kept with the command")
    for p in (si, so, st):
        client_args(p)
        p.set_defaults(func=cmd_operator)
    fd = sub.add_parser("feed", help="the records after a sequence number, one JSON per line")
    fd.add_argument("--since", type=int, default=0,
                    help="the last sequence number already read (default: 0, from the first)")
    fd.add_argument("--limit", type=int, default=100,
                    help="records at most, 1-1000 (default: 100; more are said on stderr)")
    client_args(fd)
    fd.set_defaults(func=cmd_feed)
    us = sub.add_parser("user", help="users of the station's access section")
    usub = us.add_subparsers(dest="user_command", required=True)
    uh = usub.add_parser("hash", help="print the scrypt hash of a password for "
                         "access.users.NAME.password",
                         description="The password is read from STATIOND_PASSWORD when it "
                         "is set, else asked twice at a terminal, else the first line of "
                         "standard input (never an argument: ps would show it); at least 8 "
                         "characters.  The hash goes to standard output.")
    uh.set_defaults(func=cmd_user_hash)
    st = sub.add_parser("status", help="a running daemon's state (from its web server)",
                        description="The first line names the station that answered (its "
                        "id, station file and URL).  Exit 0: the daemon answers and its "
                        "station is not in fault; 1: it is in fault (the reason is printed); "
                        "2: bad input; 3: no status of this station (no daemon answers, it "
                        "refused the token, or another station's daemon answered); 4: not in "
                        "fault, but its last reload was refused (it runs on what it read "
                        "before; the reason is printed).  For monitoring scripts.")
    st.add_argument("--json", action="store_true", help="print the status object as it is "
                    "(the station's line on stderr)")
    client_args(st, timeout=5.0)
    st.set_defaults(func=cmd_status)


__all__ = ["DEFAULT_CONFIG", "EXIT_REFUSED", "EXIT_UNREACHABLE", "ApiClient", "Target",
           "add_command_parsers", "check_comment", "client_args", "cmd_command", "cmd_feed",
           "cmd_operator", "cmd_status", "cmd_user_hash", "daemon_url", "find_station",
           "identify", "network_words", "read_password", "same_station", "say_refused",
           "station_words", "unreachable_words"]
