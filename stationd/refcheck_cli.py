"""``stationd calibrate check --config STATION.yaml``: check every pair against the station's
reference markers now.

Why two ways: the cameras and the records are the daemon's while it runs (one process per
station, its lock beside the database: :mod:`stationd.lock`); a second process grabbing from
them would steal frames from the vision loop, and a pair it found moved would not stop the
daemon using it.  So while the daemon runs, the command asks *it* for the check, through its
API as every person's command does (``--user`` with the ``calibrate`` right logs in, the
``calibration-check`` command goes to ``POST /api/commands``): the daemon measures, records,
refuses a moved pair's bolts, and answers each pair's verdict, printed here.  When no daemon
runs, the lock is taken for the check, each pair is grabbed once with the cameras opened
here and checked (:func:`stationd.localize.check.check_pair`), and each check is recorded in
the station's database (it joins the results feed).  Either way: one line per pair.

Exit codes: 0 every pair in place, 1 a pair moved or not checked (or the daemon refused the
command: why is printed), 2 bad input (no ``references:`` in the file, a camera that does not
open, the daemon running and no ``--user`` given), 3 the daemon does not answer or refused
the login.
"""

from __future__ import annotations

import argparse
import sys
from datetime import UTC, datetime
from typing import Any

from stationd.errors import InputError
from stationd.jsonout import strict_json

EXIT_OK, EXIT_NOT_OK = 0, 1


def _grab(cfg: Any, name: str) -> tuple[Any, Any] | str:
    """One stereo grab of pair ``name`` (its two cameras opened and closed here), or why not."""
    from drivers.camera.pair import StereoGrabber
    from drivers.devices import Kind, open_device
    from drivers.errors import DriverError

    pc = cfg.pairs[name]
    if pc.left is None or pc.right is None:
        return "the pair names no cameras"
    cams: list[Any] = []
    try:
        for cam in (pc.left, pc.right):
            cams.append(open_device(Kind.CAMERA, cfg.cameras[cam]))
        left, right = StereoGrabber(cams[0], cams[1], pc.max_skew_s, name=name).grab(5.0)
        return left.image, right.image
    except (DriverError, OSError, ValueError) as exc:
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return text
    finally:
        for c in cams:
            try:
                c.close()
            except (DriverError, OSError):
                pass


def cmd_calibrate_check(args: argparse.Namespace) -> int:
    """Check each pair that sees a reference (by the daemon when it runs, else here); print,
    exit 0 only if all are in place."""
    from stationd.config import load_station_config
    from stationd.lock import LockHeldError, StationLock, lock_path

    _check_args(args)
    cfg = load_station_config(args.config, station=True)
    refs = cfg.references
    if refs is None:
        raise InputError(f"{args.config}: no references: section: no calibration check "
                         "configured (every pair is trusted)")
    path = lock_path(cfg.database_url, cfg.records.images_dir)
    lock = StationLock(path) if path is not None else None
    if lock is not None:
        try:
            lock.acquire()
        except LockHeldError as exc:
            return _ask_daemon(args, cfg, exc.pid)
    try:
        results = _check_here(args, cfg)
    finally:
        if lock is not None:
            lock.release()
    from stationd.station.trust import summary
    return _said(args, {c.pair: summary(c) for c in results})


def _check_args(args: argparse.Namespace) -> None:
    """The options, checked before anything is opened (bad input: exit 2)."""
    if args.user is not None and not args.user.strip():
        raise InputError("--user: the name of a user of the station's access section")
    from stationd.command_cli import check_comment

    check_comment(args.comment)
    if not 0 < args.timeout <= 3600:    # NaN too
        raise InputError(f"--timeout {args.timeout:g}: expected seconds in (0, 3600]")


def _ask_daemon(args: argparse.Namespace, cfg: Any, pid: int | None) -> int:
    """The daemon holds the station: the calibration-check command to it through its API, as
    ``--user``; its answer printed as a check done here would be."""
    import urllib.error

    from stationd.command_cli import (
        EXIT_REFUSED,
        ApiClient,
        Target,
        daemon_url,
        identify,
        network_words,
        read_password,
        say_refused,
    )
    from stationd.config import station_identity
    from stationd.web.status_cli import EXIT_UNREACHABLE

    who = f"pid {pid}" if pid is not None else "its pid unknown"
    if args.user is None:
        raise InputError(f"the station's daemon is running ({who}): it owns the cameras; "
                         "give --user NAME (a user with the calibrate right) to ask it for "
                         "the check (the calibration-check command)")
    if args.lift_at_height:
        sys.stderr.write("stationd: calibrate check: --lift-at-height is left to the daemon "
                         "(it reads its lift)\n")
    if args.url is None and cfg.http is None:
        raise InputError(f"{cfg.path}: the daemon serves no API (no http: section): give "
                         "--url, or stop the daemon to check with the cameras opened here")
    url = args.url or daemon_url(cfg)
    token = args.token or (cfg.http.token if cfg.http is not None else None)
    client = ApiClient(url, token, args.timeout)
    # the daemon holding this station's lock is this station's; the one answering at the
    # URL must be it too (another station's on that port would check its own pairs)
    known = identify(client, Target(url, token, station_identity(cfg), str(args.config)),
                     "calibrate check", out=sys.stderr if args.json else sys.stdout)
    if isinstance(known, int):
        return known
    try:
        password = read_password(args.user.strip())
        status, me = client.call("/api/login", {"user": args.user.strip(),
                                                "password": password, "client": "cli"})
        if status != 200:
            return say_refused("login refused", status, me)
        status, nonce = client.call("/api/nonce")
        if status != 200 or not isinstance(nonce, dict):
            return say_refused("calibrate check", status, nonce)
        status, answer = client.call("/api/commands", {
            "kind": "calibration-check", "comment": args.comment or "",
            "nonce": nonce["nonce"]})
        client.call("/api/logout", {})
    except (urllib.error.URLError, OSError) as exc:
        sys.stderr.write(f"stationd: the daemon ({who}) does not answer at {url} "
                         f"({network_words(exc)})\n")
        return EXIT_UNREACHABLE
    if status == 409 and isinstance(answer, dict):
        print(answer["words"])
        return EXIT_REFUSED
    if status != 200 or not isinstance(answer, dict) \
            or not isinstance(answer.get("result"), dict):
        sys.stderr.write(f"stationd: calibrate check: HTTP {status}: {answer}\n")
        return EXIT_UNREACHABLE if status >= 500 else EXIT_REFUSED
    return _said(args, answer["result"])


def _said(args: argparse.Namespace, checks: dict[str, Any]) -> int:
    """Each pair's check (:func:`stationd.station.trust.summary` values) printed: a line per
    pair, or one JSON object; exit 0 only if every pair is in place."""
    from stationd.localize.check import Verdict
    from stationd.station.trust import from_summary, reason_of
    from stationd.words import reason_words

    results = [from_summary(pair, s) for pair, s in checks.items()]
    if args.json:
        print(strict_json(checks))
    else:
        for c in results:
            said = reason_of(c)
            print(reason_words(said) if said is not None else
                  f"{c.pair} in place: reference {c.reference} off by {c.offset_mm or 0:.2f} "
                  f"mm (<= {c.tolerance_mm:g} mm)")
    ok = bool(results) and all(c.verdict is Verdict.OK for c in results)
    if not ok:
        sys.stderr.write("stationd: calibrate check: a pair is moved or not checked\n")
    return EXIT_OK if ok else EXIT_NOT_OK


def _check_here(args: argparse.Namespace, cfg: Any) -> list[Any]:
    """No daemon runs (the lock is ours): each pair grabbed with its cameras opened here,
    checked, and each check recorded."""
    from db.checks import record_check
    from db.repository import Repository
    from stationd.localize.check import check_pair, not_checked
    from stationd.station.trust import summary

    refs = cfg.references
    results = []
    for name in refs.pairs:
        pc = cfg.pairs[name]
        got = _grab(cfg, name)
        if isinstance(got, str):
            results.append(not_checked(name, refs.tolerance_mm, got))
            continue
        results.append(check_pair(name, pc.calibration, pc.to_vehicle, got[0], got[1],
                                  refs.of(name), tolerance_mm=refs.tolerance_mm,
                                  search_mm=refs.exclusion_mm, vision=cfg.vision,
                                  marker=cfg.marker, lift_at_height=args.lift_at_height))
    at = datetime.now(UTC)
    repo = Repository.open(cfg.database_url)
    try:
        for c in results:
            why = None if c.why is None else c.why.value + (f": {c.note}" if c.note else "")
            record_check(repo, at=at, pair=c.pair, verdict=c.verdict.value,
                         reference=c.reference, offset_mm=c.offset_mm,
                         tolerance_mm=c.tolerance_mm, reason=why,
                         references=summary(c)["references"])
    finally:
        repo.close()
    return results


def add_check_parser(csub: Any) -> None:
    """Add ``check`` to the ``calibrate`` sub-parsers."""
    k = csub.add_parser(
        "check", help="check every pair against the reference markers (by the running "
                      "daemon, else with the cameras opened here)",
        description="Prints per pair: in place, moved (the worst reference and its offset), "
                    "or not checked (why); each check is recorded in the station's database. "
                    "While the station's daemon runs, it is asked for the check through its "
                    "API (the calibration-check command, as --user with the calibrate "
                    "right; the password from STATIOND_PASSWORD, else a prompt, else the "
                    "first line of standard input): it measures, records and refuses a "
                    "moved pair's bolts. Otherwise each pair that sees a reference marker is "
                    "grabbed once here. Exit 0 all in place, 1 a pair moved or not checked "
                    "(or the command refused), 2 bad input, 3 the daemon does not answer.")
    k.add_argument("--config", required=True, metavar="STATION.yaml",
                   help="the station file (its references: section)")
    k.add_argument("--lift-at-height", action="store_true",
                   help="the lift is at working height: measure the references on it too "
                        "(without a daemon; the daemon reads its lift)")
    k.add_argument("--json", action="store_true", help="print the checks as one JSON object")
    k.add_argument("--user", help="who asks the running daemon (a user of its access "
                   "section with the calibrate right)")
    k.add_argument("--comment", default="", help="why (kept with the daemon's command)")
    k.add_argument("--url", help="the daemon's API (default: from the station file's http: "
                   "section)")
    k.add_argument("--token", help="the http token (default: the station file's http.token, "
                   "or STATIOND_TOKEN)")
    k.add_argument("--timeout", type=float, default=60.0,
                   help="seconds to wait for the daemon's answer (default 60)")
    k.set_defaults(func=cmd_calibrate_check)


__all__ = ["add_check_parser", "cmd_calibrate_check"]
