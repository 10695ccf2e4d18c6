"""``stationd teach``: teach a vehicle model's bolt positions on a real vehicle, through the
running daemon.

    stationd teach --model SIM-1 --user ed [--from bolts.cad.yaml] --out bolts.taught.yaml

Why through the daemon: teach mode is a command like any other (the ``teach`` right, the
normal cycle off meanwhile, every step recorded with its user).  The engineer holds the tool
on each bolt in turn and presses Enter; the station averages several steady localizations
and answers with the bolt end and its dispersion.  Against a CAD table (``--from``) each
taught bolt is compared (flagged beyond the matching tolerance), the taught table is checked
against the spacing rule, and a new file is written with the CAD table's parameters and the
taught positions: ``stationd db import`` then makes a new parameter version of each bolt
that moved, never an overwrite.  Answers: Enter (measure), ``s`` (skip this bolt), ``q``
(stop and write what was taught).
"""

from __future__ import annotations

import argparse
import math
import sys
import urllib.error
from pathlib import Path
from typing import Any

from drivers.counting import counted
from stationd.command_cli import (
    EXIT_REFUSED,
    EXIT_UNREACHABLE,
    ApiClient,
    client_args,
    find_station,
    identify,
    network_words,
    read_password,
    say_refused,
    session_command,
    unreachable_words,
)
from stationd.errors import ConfigError, InputError
from stationd.filekind import expect
from stationd.outfile import write_atomic
from stationd.station.matching import MatchParams, check_spacing
from stationd.stopping import held
from stationd.taught import table_text
from stationd.yamlio import YamlNode


def _cad(path: str, model: str) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The CAD table's YAML tree and the model's bolt entries (ids, positions, parameters)."""
    try:
        # the station's reader: a PNG, a station file, a FIFO are each named as such
        root = YamlNode.load(path)
        expect(root, "bolts", ("psets", "models"))
        doc = root.value()
    except ConfigError as exc:
        raise InputError(f"--from {exc}") from None
    models = doc.get("models") if isinstance(doc, dict) else None
    if not isinstance(models, dict) or model not in models:
        have = ", ".join(models) if isinstance(models, dict) else "none"
        raise InputError(f"--from {path}: no model {model!r} (models: {have})")
    bolts = models[model].get("bolts") or []
    return doc, [b for b in bolts if isinstance(b, dict) and "id" in b]


def _ask(bolt: str) -> str:
    print(f"hold the tool on {bolt}, then press Enter (s: skip, q: stop)", flush=True)
    line = sys.stdin.readline()
    return "q" if line == "" else line.strip().lower()


def cmd_teach(args: argparse.Namespace) -> int:
    if args.stop:
        return _cmd_stop(args)
    if args.model is None or args.out is None:
        raise InputError("teach needs --model M and --out TAUGHT.yaml (or --stop: end teach "
                         "mode left on at the station)")
    out = Path(args.out)
    if out.exists() or out.is_symlink():   # a link too, dangling or not (outfile's rule)
        raise InputError(f"--out {out}: exists; a taught table is a new file, never an "
                         "overwrite (choose another name)")
    if not out.parent.is_dir():            # before any teaching: the work would be lost
        raise InputError(f"--out {out}: the folder {out.parent} does not exist")
    if args.tolerance is not None and not args.tolerance > 0:
        raise InputError(f"--tolerance {args.tolerance:g}: millimetres, > 0")
    doc, cad = _cad(args.from_, args.model) if args.from_ else ({}, [])
    ids = [str(b["id"]) for b in cad] if cad else []
    if args.bolts:
        wanted = [b.strip() for b in args.bolts.split(",")]
        if not all(wanted):
            raise InputError(f"--bolts {args.bolts!r}: bolt ids separated by commas")
        unknown = [b for b in wanted if cad and b not in ids]
        if unknown:
            raise InputError(f"--bolts: not in {args.from_}: {', '.join(unknown)}")
        ids = wanted
    if not ids:
        raise InputError("which bolts: --from a CAD table, or --bolts B01,B02,...")
    target = find_station(args)
    args.url = target.url     # the daemon's, said in the messages below
    args.via = target.via()
    client = ApiClient(target.url, target.token, args.timeout)
    known = identify(client, target, "teach")   # named before anything is asked of it
    if isinstance(known, int):
        return known
    try:
        return _teach(args, client, out, doc, ids, cad)
    except (urllib.error.URLError, OSError) as exc:
        sys.stderr.write(f"stationd: teach: {unreachable_words(args.url, exc)}\n")
        return EXIT_UNREACHABLE


#: how teach mode left on by a session that was cut off is ended (a new session is refused)
LEFT_ON = ("teach mode left on by a session that was cut off (its terminal gone, the "
           "command killed) is ended with stationd teach --stop --user NAME{via}, or the "
           "commissioning screen's Stop teach mode")


def _cmd_stop(args: argparse.Namespace) -> int:
    """``stationd teach --stop``: teach mode ended at the station, whoever's session left it
    on (a kill -9, a laptop gone: a new session was refused, "teach mode is on", and only
    the commissioning screen could end it), given as every command by a person is."""
    return session_command(args, args.user, {"kind": "teach-stop"})


def _teach(args: argparse.Namespace, client: ApiClient, out: Path, doc: dict[str, Any],
           ids: list[str], cad: list[dict[str, Any]]) -> int:
    password = read_password(args.user)
    status, who = client.call("/api/login", {"user": args.user, "password": password,
                                             "client": "cli"})
    if status != 200:
        return say_refused("login refused", status, who)

    def command(body: dict[str, Any]) -> tuple[int, Any]:
        st, nonce = client.call("/api/nonce")
        if st != 200 or not isinstance(nonce, dict):
            return st, nonce
        return client.call("/api/commands", {**body, "nonce": nonce["nonce"]})

    status, answer = command({"kind": "teach-start", "model": args.model})
    if status != 200:
        print(answer["words"] if isinstance(answer, dict) else answer, file=sys.stderr)
        reason = answer.get("reason") if isinstance(answer, dict) else None
        if isinstance(reason, dict) and reason.get("kind") == "teaching":
            print(LEFT_ON.format(via=args.via), file=sys.stderr)
        return EXIT_REFUSED
    taught: dict[str, dict[str, Any]] = {}
    cad_at = {str(b["id"]): b.get("position") for b in cad}
    lost = False
    try:
        for bolt in ids:
            reply = _ask(bolt)
            if reply == "q":
                break
            if reply == "s":
                continue
            try:
                status, answer = command({"kind": "teach-point", "bolt": bolt})
            except (urllib.error.URLError, OSError) as exc:
                # it answered the login and teach start: not "no daemon answers"
                sys.stderr.write(f"stationd: teach: the daemon at {args.url} did not answer "
                                 f"the teach point of {bolt} within {args.timeout:g} s "
                                 f"({network_words(exc)}); a larger --timeout, or "
                                 "see its journal\n")
                lost = True
                break
            if status != 200 or not isinstance(answer, dict) or "result" not in answer:
                why = answer.get("reason", {}).get("words") if isinstance(answer, dict) \
                    else answer
                print(f"{bolt}: not taught: {why}", flush=True)
                continue
            r = answer["result"]
            taught[bolt] = r
            if args.tolerance is None:      # the station's own matching tolerance
                args.tolerance = float(r.get("tolerance_mm", MatchParams().tolerance_mm))
            x, y, z = r["position_mm"]
            line = f"{bolt}: {x:.1f} {y:.1f} {z:.1f} mm, dispersion {r['dispersion_mm']:.2f} mm"
            ref = cad_at.get(bolt)
            if ref is not None:
                d = math.dist((x, y), (float(ref[0]), float(ref[1])))
                flag = "  BEYOND THE TOLERANCE" if d > args.tolerance else ""
                line += f"; CAD {d:.1f} mm away in X-Y{flag}"
            print(line, flush=True)
    finally:
        _stop(args, command, client)
    if not taught:
        print("nothing taught: no file written", file=sys.stderr)
        return EXIT_UNREACHABLE if lost else EXIT_REFUSED
    return finish(out, doc, args.model, taught, cad_at, args.tolerance)


def finish(out: Path, doc: dict[str, Any], model: str, taught: dict[str, dict[str, Any]],
           cad_at: dict[str, Any], tolerance: float | None) -> int:
    """Write what was taught and say how it goes into use.  A table that breaks the spacing
    rule is still written (the measurements are the engineer's work, not to be lost) but the
    command exits 1: ``config check`` and the daemon's reload would refuse it, so it must
    not read as ready."""
    positions = {b: r["position_mm"] for b, r in taught.items()}
    everywhere = {**{k: v for k, v in cad_at.items() if v is not None}, **positions}
    problems = check_spacing(everywhere, MatchParams().tolerance_mm if tolerance is None
                             else tolerance)
    for problem in problems:
        print(f"spacing: {problem}", flush=True)
    _write(out, doc, model, taught)
    if problems:
        print(f"{counted(len(taught), 'bolt')} taught: {out}, NOT READY: it breaks the "
              f"spacing rule ({counted(len(problems), 'pair')} above), which the daemon's "
              "reload and config check refuse; teach those bolts again", file=sys.stderr)
        return EXIT_REFUSED
    use = ("review it, put it in place as the station file's bolts: file and reload the "
           "daemon") if doc else "positions only: merge them into the bolt table by hand"
    print(f"{counted(len(taught), 'bolt')} taught: {out} ({use})")
    return 0


def _stop(args: argparse.Namespace, command: Any, client: ApiClient) -> None:
    """Teach mode off and the session closed; a daemon that no longer answers is said (teach
    mode then stays on there until stopped), never a traceback.  Held against the signals
    (one that comes meanwhile stops the command once it is sent): a terminal's hang-up
    reaches the command twice (the shell resends it to its jobs, the kernel sends it as the
    shell exits), and the second cut the stop the first one sent: teach mode left on.  A
    daemon that does not answer holds a Ctrl-C for at most two requests' --timeout."""
    try:
        with held():    # (the stop alone: a signal then cuts only the logout)
            command({"kind": "teach-stop"})
        client.call("/api/logout", {})
    except (urllib.error.URLError, OSError) as exc:
        sys.stderr.write(f"stationd: teach: the daemon at {args.url} did not answer teach "
                         f"stop ({network_words(exc)}): teach mode may still be on "
                         "there\n")


def _write(out: Path, doc: dict[str, Any], model: str, taught: dict[str, dict[str, Any]]
           ) -> None:
    """The CAD table with the taught positions (or, without one, the positions alone): the
    same text the commissioning screen downloads (:mod:`stationd.taught`)."""
    write_atomic(out, table_text(doc, model, taught))


def add_teach_parser(sub: Any) -> None:
    t = sub.add_parser("teach", help="teach a model's bolt positions on a vehicle (through "
                       "the running daemon, the teach right)")
    t.add_argument("--model", help="the vehicle model (its bolt table name)")
    t.add_argument("--user", required=True, help="who teaches (a user with the teach right)")
    t.add_argument("--from", dest="from_", metavar="CAD.yaml",
                   help="the bolt table to teach (ids, parameters, CAD positions)")
    t.add_argument("--bolts", help="only these bolts, in this order (comma-separated)")
    t.add_argument("--out", help="the taught table to write (a new file)")
    t.add_argument("--stop", action="store_true",
                   help="end teach mode at the station, left on by a session that was cut "
                        "off (a new session is refused while it is on)")
    t.add_argument("--tolerance", type=float, default=None,
                   help="flag a bolt farther than this from CAD, mm (default: the station's "
                        "matching tolerance)")
    client_args(t)
    t.set_defaults(func=cmd_teach)


__all__ = ["add_teach_parser", "cmd_teach"]
