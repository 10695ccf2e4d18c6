"""``stationd line init|status|quarantine|results|bolts``: the line database and the
store-and-forward to it, from the station's own files (the daemon need not run).

    stationd line init postgresql+psycopg://USER:PASSWORD@HOST:PORT/DATABASE   # the tables
    stationd line status --config STATION.yaml            # backlog, lag, quarantine
    stationd line quarantine --config STATION.yaml [--retry] [--export FILE.json]
    stationd line results --config STATION.yaml [--vin V] [--station ST] [--bolt B]
                          [--since T] [--until T]                        # the line's
    stationd line bolts --config STATION.yaml [--model M] [--bolt B]       # tables used

Why on the station's side: the quarantine (records the line database refused for good) lives
in the station's database; a quality engineer retries it after the line database was fixed,
or exports it to hand over.  Exit 0: nothing waits; 1: a backlog or a quarantine remains;
2: bad input; 3: the line database cannot be reached (``--retry``), or (``status``) does not
take the forwarders' writes.

``results`` and ``bolts`` read the line database itself (every station's records, as the
forwarders put them there): a VIN's rundowns at every station (or a bolt's over a shift),
newest first, from the typed ``line_rundowns``, and the bolt tables the stations tightened
with.  Exit 0: found; 1: nothing; 3: the line database cannot
be reached.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from db.kinds import LOOSENING
from drivers.counting import counted
from stationd.errors import InputError

if TYPE_CHECKING:   # each command imports its libraries when run: every command builds this
    # parser, and SQLAlchemy with the configuration here cost each of them a second
    from sqlalchemy import Engine, Table

    from stationd.config import StationConfig
    from stationd.forward import Forwarder, LineDb

EXIT_WAITING, EXIT_UNREACHABLE = 1, 3
#: said when a filter found nothing: "b07" finds no "B07" (a person takes it for "none at all")
EXACT = "(names are matched exactly, case included)"
T = TypeVar("T")
CONNECT_TIMEOUT_S = 10


def _forwarder(args: argparse.Namespace, *, write: bool = False,
               cfg: StationConfig | None = None) -> Forwarder:
    """The station's forwarder on its existing database: a missing one is said, never made
    (a wrong path or station file would read as "everything forwarded").  ``cfg``: the
    station file as read already."""
    from stationd.config import load_station_config
    from stationd.db_cli import open_repository
    from stationd.forward import Forwarder

    cfg = cfg if cfg is not None else load_station_config(args.config)
    if cfg.line is None:
        raise InputError(f"{args.config}: no line section: nothing is forwarded")
    missing = (f"the station has recorded nothing yet, or {args.config}'s database.url "
               "names another file")
    return Forwarder(open_repository(cfg.database_url, must_exist=True, read_only=not write,
                                     missing=missing), cfg.line)


def _asked(line: LineDb) -> dict[str, Any]:
    """Whether the line database answers now (``answers``, else why not: ``unreachable``)
    and takes the forwarders' writes (else why not: ``cannot_write``); asked once, then
    let go."""
    from stationd.forward import LineDown, LineRefuses

    try:
        line.reachable()
        return {"answers": True, "unreachable": None, "cannot_write": None}
    except LineRefuses as exc:   # it answers, but not as a forwarder needs
        return {"answers": True, "unreachable": None, "cannot_write": str(exc)}
    except LineDown as exc:
        return {"answers": False, "unreachable": str(exc), "cannot_write": None}
    finally:
        line.dispose()


def _not_made_yet(args: argparse.Namespace, cfg: StationConfig) -> int | None:
    """A station whose SQLite database is not there yet (nothing recorded): said, and the
    line database asked all the same (it said only "no database at ...", exit 2, nothing of
    whether the line answers: what a person setting the line up wants to know first).  Exit
    3 when the line does not answer or take the forwarders' writes, else 0 (nothing waits);
    None where the database is there (or is not a file, or cannot be looked at: the
    forwarder says why)."""
    from stationd.db_cli import absent_sqlite_file
    from stationd.forward import LineDb

    if cfg.line is None:
        return None                     # said by _forwarder, as before
    try:
        path = absent_sqlite_file(cfg.database_url)
    except OSError:
        return None
    if path is None:
        return None
    st = {"url": _shown(cfg.line.url), "station_id": cfg.line.station_id, "db_id": None,
          **_asked(LineDb(cfg.line.url)), "backlog": 0, "quarantined": 0, "recorded": False}
    if args.json:
        print(json.dumps(st))
    else:
        print(f"no database at {path} yet: the station has recorded nothing, so nothing "
              f"waits (or {args.config}'s database.url names another file)")
        print(f"line database {st['url']}: " + (
            f"the forwarders cannot write ({st['cannot_write']})" if st["cannot_write"] else
            "answers" if st["answers"] else f"does not answer ({st['unreachable']})"))
    return EXIT_UNREACHABLE if not st["answers"] or st["cannot_write"] else 0


def cmd_line_status(args: argparse.Namespace) -> int:
    """The forwarding as the station's database records it, and whether the line database
    answers now (asked once: the backlog alone does not say why records wait).  Exit 3 when
    it does not answer or will not take the forwarders' writes (a role without the privilege:
    the records wait all the same), else 1 while records wait or are quarantined."""
    from stationd.config import load_station_config

    cfg = load_station_config(args.config)
    unmade = _not_made_yet(args, cfg)
    if unmade is not None:
        return unmade
    fwd = _forwarder(args, cfg=cfg)
    try:
        st = {**fwd.status(), **_asked(fwd.line)}
    finally:
        fwd.repo.close()
    if args.json:
        print(json.dumps(st))
    else:
        print(f"line database {st['url']} as station {st['station_id']} "
              f"(local database {st['db_id']})")
        if st["cannot_write"]:
            print(f"line database: the forwarders cannot write ({st['cannot_write']}); the "
                  "records wait in the station's database until they can")
        else:
            print("line database: answers" if st["answers"] else
                  f"line database: does not answer ({st['unreachable']}); the records wait "
                  "in the station's database until it does")
        print(f"forwarded up to record {st['cursor']} of {st['last_seq']}: {st['backlog']} "
              f"waiting ({st['backlog_bytes'] / 1e6:.2f} MB), the oldest for "
              f"{st['lag_s']:.0f} s; {st['quarantined']} quarantined")
        if st["alarm"]:
            print(f"ALARM: {st['alarm']}")
    if not st["answers"] or st["cannot_write"]:
        return EXIT_UNREACHABLE
    return EXIT_WAITING if st["backlog"] or st["quarantined"] else 0


def cmd_line_quarantine(args: argparse.Namespace) -> int:
    from stationd.config import load_station_config
    from stationd.db_cli import absent_sqlite_file
    from stationd.forward import LineDown, LineRefuses
    from stationd.outfile import need_folder, write_atomic

    if args.export:
        out = Path(args.export)
        if out.exists() or out.is_symlink():   # before anything is read
            raise InputError(f"--export {out}: exists; the export is written to a new file "
                             "(choose another name)")
        need_folder(out, "--export")
    cfg = load_station_config(args.config)
    try:
        path = absent_sqlite_file(cfg.database_url) if cfg.line is not None else None
    except OSError:
        path = None                      # the forwarder says why
    if path is not None and not args.export and not args.retry:
        # as line status says it (a newcomer's trial: "no database", exit 2, beside line
        # status's "nothing waits", exit 0, for the same station)
        print(f"no database at {path} yet: the station has recorded nothing, so nothing is "
              f"quarantined (or {args.config}'s database.url names another file)")
        return 0
    fwd = _forwarder(args, write=args.retry, cfg=cfg)
    try:
        if args.export:
            rows: list[dict[str, Any]] = fwd.repo.ledger.quarantined()
            write_atomic(out, json.dumps(rows, indent=1))
            print(f"{counted(len(rows), 'quarantined record')} written to {out}")
        if args.retry:
            try:
                fwd.line.reachable()   # exit 3 also with nothing to retry
                taken, refused = fwd.retry_quarantined()
            except LineRefuses as exc:   # it answers: not "unreachable"
                sys.stderr.write(f"stationd: line database {_shown(fwd.cfg.url)}: {exc}\n")
                return EXIT_UNREACHABLE
            except LineDown as exc:   # in the words of line results' and line init's
                return _unreachable(fwd.cfg.url, exc)
            finally:
                fwd.line.dispose()
            print(f"retried: {taken} taken by the line database, {refused} still refused")
        left = fwd.repo.ledger.quarantined()
    finally:
        fwd.repo.close()
    if not args.export and not args.retry:
        for q in left:
            print(f"record {q['seq']} ({q['kind']}, {q['at']}): {q['reason']}")
        if not left:
            print("nothing quarantined: every record was taken by the line database or waits "
                  "to be forwarded (`stationd line status`)")
    return EXIT_WAITING if left else 0


def _line_url(args: argparse.Namespace) -> str:
    from stationd.config import load_station_config

    cfg = load_station_config(args.config)
    if cfg.line is None:
        raise InputError(f"{args.config}: no line section: no line database to read")
    return cfg.line.url


def _shown(url: str) -> str:
    from sqlalchemy import make_url

    return make_url(url).render_as_string()


def _unreachable(url: str, exc: BaseException) -> int:
    from stationd.forward import error_line

    sys.stderr.write(f"stationd: line database {_shown(url)} unreachable: "
                     f"{error_line(exc)}\n")
    return EXIT_UNREACHABLE


def _has(engine: Engine, table: str) -> bool:
    from sqlalchemy import inspect

    return bool(inspect(engine).has_table(table))


def _read_line(url: str, table: Table, read: Callable[[Engine], list[T]]) -> list[T] | None:
    """What ``read`` finds in the line database at ``url``: nothing while ``table`` was never
    made there (no station forwarded yet); None when the database cannot be reached, said in
    one line on stderr.  A line database with records but without ``table`` was made by an
    earlier stationd and nothing upgraded it yet: said, with the command that does (a reader
    makes nothing)."""
    from sqlalchemy import make_url
    from sqlalchemy.exc import SQLAlchemyError

    from db.engine import make_engine
    from stationd.linedb import LINE_FEED

    engine = make_engine(url)
    try:
        if _has(engine, table.name):
            return read(engine)
        if _has(engine, LINE_FEED.name):
            raise InputError(
                f"line database {make_url(url).render_as_string()}: no {table.name} (made by "
                f"an earlier stationd): `stationd line init URL` adds it, filled from "
                f"{LINE_FEED.name}, as does a forwarder of this version on its next start")
        return []
    except SQLAlchemyError as exc:
        _unreachable(url, exc)
        return None
    finally:
        engine.dispose()


def _n(v: float | None, digits: int = 1) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def cmd_line_results(args: argparse.Namespace) -> int:
    from stationd.jsonout import strict_json
    from stationd.linedb import LINE_RUNDOWNS, results

    url = _line_url(args)
    if args.limit < 1:
        raise InputError(f"--limit {args.limit}: at least 1")
    since, until = _when(args.since, "--since"), _when(args.until, "--until")
    if since is not None and until is not None and since > until:
        raise InputError(f"--since {args.since} is after --until {args.until}: no time lies "
                         "between them (give the earlier one as --since)")
    rows = _read_line(url, LINE_RUNDOWNS.table, lambda engine: results(
        engine, vin=args.vin, station=args.station, bolt=args.bolt, since=since, until=until,
        limit=args.limit))
    if rows is None:
        return EXIT_UNREACHABLE
    if args.json:
        for r in rows:
            print(strict_json(r.to_json()))
        return 0 if rows else EXIT_WAITING
    what = " ".join(x for x in (f"VIN {args.vin}" if args.vin else "",
                                f"station {args.station}" if args.station else "",
                                f"bolt {args.bolt}" if args.bolt else "") if x)
    if not rows:
        print(f"no rundowns{' of ' + what if what else ''} in the line database"
              + (f" {EXACT}" if what else ""))
        return EXIT_WAITING
    stations = sorted({r.station_id for r in rows})
    print(f"{counted(len(rows), 'rundown')}{' of ' + what if what else ''} at "
          f"{counted(len(stations), 'station')}, newest first"
          f"{' (--limit reached)' if len(rows) == args.limit else ''}")
    head = ("time (UTC)", "station", "VIN", "bolt", "result", "torque Nm", "angle deg",
            "version", "operator")
    table = [[r.at.strftime("%Y-%m-%d %H:%M:%S"), r.station_id, r.vin, r.bolt,
              ("OK" if r.ok else "NOK") + (" (loosening)" if r.kind == LOOSENING else "")
              + (f" (entered by {r.entered_by})" if r.entered_by else ""),
              _n(r.torque_nm), _n(r.angle_deg), "-" if r.version is None else str(r.version),
              r.operator or "-"]
             for r in rows]
    widths = [max(len(row[i]) for row in [list(head), *table]) for i in range(len(head))]
    for row in [list(head), *table]:
        print("  ".join(c.ljust(w) if i < 5 or i == 8 else c.rjust(w)
                        for i, (c, w) in enumerate(zip(row, widths, strict=True))).rstrip())
    return 0


def _when(text: str | None, option: str) -> datetime | None:
    """An ISO time of ``--since``/``--until`` (without an offset: UTC, as the line's times)."""
    if text is None:
        return None
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        raise InputError(f"{option} {text!r}: an ISO time, e.g. 2026-11-27T06:00 (UTC) or "
                         "2026-11-27T06:00+01:00") from None
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


def _window(t: tuple[float | None, float | None, float | None]) -> str:
    target, lo, hi = t
    if target is None and lo is None and hi is None:
        return "-"
    return f"{_n(target)} [{_n(lo)}, {_n(hi)}]"


def cmd_line_bolts(args: argparse.Namespace) -> int:
    from stationd.jsonout import strict_json
    from stationd.linedb import LINE_PARAMETERS, bolt_versions

    url = _line_url(args)
    rows = _read_line(url, LINE_PARAMETERS, lambda engine: bolt_versions(
        engine, model=args.model, bolt=args.bolt, station=args.station))
    if rows is None:
        return EXIT_UNREACHABLE
    if args.json:
        for v in rows:
            print(strict_json({"station_id": v.station_id, "db_id": v.db_id,
                               "model": v.model, "bolt": v.bolt, "version": v.version,
                               "pset": v.pset, "torque": list(v.torque),
                               "angle": list(v.angle)}))
        return 0 if rows else EXIT_WAITING
    if not rows:
        asked = " ".join(f"{what} {value}" for what, value in (
            ("model", args.model), ("bolt", args.bolt), ("station", args.station)) if value)
        print(f"no bolt parameters of {asked} in the line database {EXACT}" if asked else
              "no bolt parameters in the line database (none forwarded with a rundown)")
        return EXIT_WAITING
    for v in rows:
        print(f"{v.model} {v.bolt} at {v.station_id} (database {v.db_id[:8]}) version "
              f"{v.version}: pset {'-' if v.pset is None else v.pset}, torque "
              f"{_window(v.torque)} Nm, angle {_window(v.angle)} deg")
    return 0


def cmd_line_init(args: argparse.Namespace) -> int:
    """Make the line database's tables where missing (a line engineer prepares the database
    before any station forwards; a database made by an earlier version gets the new ones):
    what the forwarders make on their first connection anyway, so running it again, or
    after stations forwarded, changes nothing."""
    from sqlalchemy import make_url
    from sqlalchemy.exc import OperationalError, SQLAlchemyError

    from db.engine import make_engine
    from stationd.forward import error_line, line_url_problem
    from stationd.linedb import LINE, create_line_schema, write_problem

    problem = line_url_problem(args.url)   # the station file's line.url check
    if problem is not None:
        raise InputError(f"line init: {problem}")
    parsed, shown = make_url(args.url), _shown(args.url)   # (said as the user gave it)
    if "connect_timeout" not in parsed.query:   # a host that does not answer: not forever
        parsed = parsed.update_query_dict({"connect_timeout": str(CONNECT_TIMEOUT_S)})
    engine = make_engine(parsed.render_as_string(hide_password=False))
    try:
        change = create_line_schema(engine, comments=True)
        # tables another role made, that this one may not write: not ready for a forwarder
        # of this role (each of its records would wait); said with the grant that fixes it
        with engine.connect() as conn:
            cannot = write_problem(conn)
    except OperationalError as exc:   # not reached (or not let in): as line status says it
        return _unreachable(args.url, exc)
    except SQLAlchemyError as exc:
        raise InputError(f"line database {shown}: {error_line(exc)}") from None
    finally:
        engine.dispose()
    if cannot is not None:   # the forwarders could not write: as line status says it
        sys.stderr.write(f"stationd: line database {shown}: {cannot}\n")
        return EXIT_UNREACHABLE
    if change.typed_refused is not None:   # line_feed's part made; the typed part not
        raise InputError(f"line database {shown}: the typed tables: "
                         f"{change.typed_refused} (run line init as the tables' owner)")
    ours = sorted(t.name for t in LINE.sorted_tables)
    made = sorted(change.made)
    print(f"line database {shown}: "
          + (f"made {', '.join(made)}" if change.made else "every table there already")
          # the tables named once: when it made them all, they are the ones ready
          + (": ready for the stations' forwarders" if made == ours else
             f" ({', '.join(ours)}: ready for the stations' forwarders)"))
    if change.trigger and not change.made:   # tables there, the typing of new rows not
        print("the trigger that types line_feed's new rows: made or brought up to date")
    filled = [(name, n) for name, n in change.filled if n]
    for name, cols, n in change.added:   # a typed table an earlier version made
        print(f"added to {name}: {', '.join(cols)} ({counted(n, 'row')} given their values from "
              "line_feed)")
    if filled:   # a line database an earlier version made: its records typed once
        print("filled from line_feed: " + ", ".join(f"{name} {counted(n, 'row')}"
                                                     for name, n in filled))
    if change.comments:   # an earlier version's words for what a column holds
        print("comments brought up to date: " + ", ".join(change.comments))
    return 0


def add_line_parser(sub: Any) -> None:
    ln = sub.add_parser("line", help="the store-and-forward to the line database")
    lsub = ln.add_subparsers(dest="line_command", required=True)
    i = lsub.add_parser("init", help="make (or upgrade) the line database's tables, before "
                        "any station forwards")
    i.add_argument("url", metavar="URL",
                   help="postgresql+psycopg://USER:PASSWORD@HOST:PORT/DATABASE")
    i.set_defaults(func=cmd_line_init)
    st = lsub.add_parser("status", help="backlog, lag and quarantine of the forwarding")
    st.add_argument("--config", required=True, metavar="STATION.yaml")
    st.add_argument("--json", action="store_true", help="print one JSON object")
    st.set_defaults(func=cmd_line_status)
    q = lsub.add_parser("quarantine", help="records the line database refused for good: "
                        "list, --retry, --export")
    q.add_argument("--config", required=True, metavar="STATION.yaml")
    q.add_argument("--retry", action="store_true", help="push them to the line database again")
    q.add_argument("--export", metavar="FILE.json", help="write them to a new JSON file")
    q.set_defaults(func=cmd_line_quarantine)
    r = lsub.add_parser("results", help="the line's rundowns (every station's, from the line "
                        "database), newest first")
    r.add_argument("--config", required=True, metavar="STATION.yaml",
                   help="a station file of the line (its line.url)")
    r.add_argument("--vin", help="only this vehicle's rundowns")
    r.add_argument("--station", metavar="ST", help="only this station's (its station_id)")
    r.add_argument("--bolt", help="only this bolt's (its id in the bolt table)")
    r.add_argument("--since", metavar="TIME", help="recorded at or after this ISO time "
                   "(UTC without an offset), e.g. the start of a shift")
    r.add_argument("--until", metavar="TIME", help="recorded before this ISO time")
    r.add_argument("--limit", type=int, default=1000, help="at most N (default: %(default)s)")
    r.add_argument("--json", action="store_true", help="one JSON object per rundown")
    r.set_defaults(func=cmd_line_results)
    b = lsub.add_parser("bolts", help="the bolt parameters each station tightened with "
                        "(from the line database)")
    b.add_argument("--config", required=True, metavar="STATION.yaml",
                   help="a station file of the line (its line.url)")
    b.add_argument("--model", help="only this model's bolts")
    b.add_argument("--bolt", help="only this bolt (its id in the bolt table)")
    b.add_argument("--station", metavar="ST", help="only this station's")
    b.add_argument("--json", action="store_true", help="one JSON object per version")
    b.set_defaults(func=cmd_line_bolts)


__all__ = ["add_line_parser", "cmd_line_bolts", "cmd_line_init", "cmd_line_quarantine",
           "cmd_line_results", "cmd_line_status"]
