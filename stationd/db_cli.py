"""``stationd db`` (import, export, report) and ``stationd config check`` (station files and
bolt tables).

Exit codes follow the CLI contract: 0 success, 1 for a report whose vehicle is incomplete (bolts
missing or NOK), 2 for bad input (an invalid file, an unknown VIN, a database that cannot be
opened) with one readable line per error on stderr.  A file with errors lists *all* of them
(one line each, ``file:line: key: message``) before the final line.

The database is given as a SQLAlchemy URL; the default ``sqlite:///stationd.db`` is a file in
the current directory (the daemon passes its own, under its StateDirectory).  ``import`` is
all-or-nothing: a file with any error changes nothing.
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from collections.abc import Sequence
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import TYPE_CHECKING, Any

from db.holds import RELEASE
from db.kinds import (
    CUT_UNKNOWN,
    ENTER_OUTCOME,
    LOOSENED,
    LOOSENING,
    LOST_UNKNOWN,
    MISSING,
    PENDING,
    SKIPPED,
    TIGHTENING,
    message_words,
    unreadable_note,
)
from drivers.counting import counted
from stationd.errors import ConfigError, InputError
from stationd.jsonout import strict_json
from stationd.outfile import write_atomic
from stationd.words import entered_as_words, nok_why, result_type_words, unrecorded_words

if TYPE_CHECKING:
    from db.report import VehicleReport
    from db.repository import Repository

EXIT_OK, EXIT_INCOMPLETE, EXIT_BAD_INPUT = 0, 1, 2
DB_HELP = "database URL (SQLAlchemy; default sqlite:///stationd.db in the current directory)"
DEFAULT_DB = "sqlite:///stationd.db"


def _add_db_args(parser: argparse.ArgumentParser) -> None:
    """``--db URL`` or ``--config STATION.yaml`` (the database the daemon of that station
    writes, wherever it lives): one or the other."""
    g = parser.add_mutually_exclusive_group()
    g.add_argument("--db", help=DB_HELP)
    g.add_argument("--config", metavar="STATION.yaml",
                   help="use the database of this station file (its database.url)")


def _db_url(args: argparse.Namespace) -> str:
    if getattr(args, "config", None):
        from stationd.config import load_station_config

        return load_station_config(args.config).database_url
    return args.db or DEFAULT_DB


def _station_id(args: argparse.Namespace, url: str) -> str | None:
    """The station's id by its station file (``--config``; None without one, or without an
    id), where ``url`` is that file's own database (not a running demo's): what its exported
    rows name as their station."""
    if not getattr(args, "config", None):
        return None
    from stationd.config import load_station_config, station_identity

    cfg = load_station_config(args.config)
    return station_identity(cfg)["id"] if url == cfg.database_url else None


def _missing(args: argparse.Namespace) -> str:
    """What to do when the database a read command names does not exist, without
    suggesting the option already given."""
    config = getattr(args, "config", None)
    if config:
        return (f"the database of {config} (database.url): the station's daemon or db import "
                f"--config {config} makes it; a demo's results are in its own temporary "
                "database, while it runs")
    if getattr(args, "db", None):
        return "import a bolt table first, or give another --db or --config STATION.yaml"
    return "import a bolt table first, or give --db or --config STATION.yaml"


def _tolerance(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number (mm)") from None
    if not 0 < v < 1000:
        raise argparse.ArgumentTypeError(f"{text} mm: expected 0 < tolerance < 1000")
    return v


def _print_errors(errors: Sequence[ConfigError]) -> None:
    for e in errors:
        sys.stderr.write(f"{e}\n")


def absent_sqlite_file(url: str) -> str | None:
    """The path of the SQLite file ``url`` names where there is none (None: it is there, or
    the URL names no file: another database, one in memory, a ``file:`` URI).  OSError
    where a folder on the way cannot be entered."""
    from sqlalchemy import make_url

    u = make_url(url)
    path = u.database
    if u.get_backend_name() == "sqlite" and path and path != ":memory:" \
            and not path.startswith("file:") and not Path(path).exists():
        return path
    return None


def open_repository(url: str, *, must_exist: bool, read_only: bool | None = None,
                    missing: str = "import a bolt table first, or give --db or --config "
                                   "STATION.yaml") -> Repository:
    """The repository of every ``--db`` (and ``--config``'s database); a read command
    (``must_exist``) does not create a missing SQLite file and opens it read-only (no
    migration, no write access needed: the service user's database can be read by the
    line's engineers); ``read_only=False``: an existing one that the command writes;
    ``missing``: what to do when it does not exist (the command's own options).

    A URL that is no URL or names no installed driver, and an SQLite
    database that cannot keep what is written (in memory, a folder, a missing folder, another
    kind of file) are refused before anything is opened, as ``config check`` refuses them
    (``db.location``)."""
    from sqlalchemy import make_url

    from db.engine import make_engine
    from db.location import sqlite_problem
    from db.reach import unreachable
    from db.repository import Repository

    make_engine(url).dispose()   # the URL's form and driver (DataError: what to write)
    if must_exist:
        try:
            absent = absent_sqlite_file(url)
        except OSError as exc:   # a folder on the way this user may not enter
            path = str(make_url(url).database)
            raise InputError(f"database {path}: {unreachable(Path(path), exc)}") from None
        if absent is not None:
            raise InputError(f"no database at {absent} ({missing})")
    reads_only = must_exist if read_only is None else read_only
    problem = sqlite_problem(url, loses="it starts empty and is gone when the command ends",
                             as_writer=not reads_only)   # a reader need not write its folder
    if problem is not None:
        raise InputError(problem)
    return Repository.open(url, read_only=reads_only)


# -- db import / export / report -------------------------------------------------------------
def cmd_db_import(args: argparse.Namespace) -> int:
    from stationd.boltfile import check_bolts

    tolerance = args.tolerance
    own: Path | None = None     # the bolt table the station file names (its daemon imports it)
    if args.config:
        from stationd.config import load_station_config

        cfg = load_station_config(args.config)
        own = cfg.bolts_path
        if tolerance is None:   # the station's own matching tolerance, else the default
            tolerance = cfg.matching.tolerance_mm
    if tolerance is None:
        tolerance = 8.0
    result = check_bolts(args.file, tolerance_mm=tolerance)
    if result.errors:
        _print_errors(result.errors)
        sys.stderr.write(f"stationd: error: {args.file}: {counted(len(result.errors), 'error')}, "
                         "nothing imported\n")
        return EXIT_BAD_INPUT
    assert result.table is not None  # noqa: S101 - a check without errors holds the table
    if not result.table.models:   # importing it would retire every model of the station
        raise InputError(f"{args.file}: no vehicle model: importing it would retire every "
                         "model of the station; nothing imported")
    for w in result.warnings:
        sys.stderr.write(f"warning: {w}\n")
    if own is not None and Path(args.file).resolve() != own.resolve():
        # imported, but the daemon imports its own table at each start and reload: this one
        # is replaced then (a line engineer's trial: the change silently did not last)
        sys.stderr.write(f"warning: {args.config} names its bolt table ({own}): its daemon "
                         f"imports that file at each start and reload, replacing this import; "
                         f"to keep {args.file}'s tables, copy it there or name it in bolts:\n")
    url = _db_url(args)
    default = not args.db and not args.config
    new = default and absent_sqlite_file(url) is not None
    with open_repository(url, must_exist=False) as repo:
        report = repo.import_bolts(result.table, where=str(args.file))
    if default:
        # without either option the table went into the current folder's stationd.db (a
        # day-one trial: a new file in root's home, said only as what it added, as if the
        # station had the table): said which, and how to name the station's
        sys.stderr.write(f"note: imported into {Path(DEFAULT_DB.split(':///', 1)[1]).resolve()}"
                         f"{', a new database' if new else ''} (the default without --config "
                         "or --db: the current folder's stationd.db); a station's is --config "
                         "STATION.yaml\n")
    if args.json:
        sys.stdout.write(strict_json({"changes": report.has_changes, **report.to_json()}) + "\n")
    else:
        print("\n".join(report.lines()))
    return EXIT_OK


def cmd_db_export(args: argparse.Namespace) -> int:
    from stationd.outfile import need_folder, refuse_to_replace

    if args.out is not None:   # before the database is read: a typo costs nothing
        need_folder(Path(args.out))
        if args.results:       # an earlier export (CSV or JSON) may be replaced, nothing else
            refuse_to_replace(Path(args.out), "results", ("results",))
        else:   # a bolt table may replace a bolt table (export, edit, import)
            refuse_to_replace(Path(args.out), "a bolt table", ("bolts",))
    if args.results:
        return _export_results(args)
    if args.vin is not None or args.since is not None or args.format not in (None, "yaml"):
        raise InputError("--vin, --since and --format csv|json go with --results (the bolt "
                         "table is YAML)")
    with open_repository(_db_url(args), must_exist=True, missing=_missing(args)) as repo:
        text = repo.export_bolts()
        summary = repo.table().summary()
    if args.out is None:
        sys.stdout.write(text)
        return EXIT_OK
    out = Path(args.out)
    write_atomic(out, text)
    print(f"wrote {out}: {summary}")
    return EXIT_OK


def _since(text: str) -> datetime:
    """``--since``: an ISO date or date-time (UTC when no zone is given)."""
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an ISO date or date-time "
                                         "(e.g. 2026-11-23 or 2026-11-23T06:00)") from None
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


def _export_results(args: argparse.Namespace) -> int:
    """Every rundown (OK, NOK, rework) of the chosen vehicles as CSV or JSON, oldest first:
    what quality takes out of the station (the results screen's export, for all vehicles)."""
    from stationd.web.results import (
        CONTROLLER_EVENT_STATUS,
        LOCKED_STATUS,
        LOOSEN_ORDERED_STATUS,
        NOT_RUNDOWNS,
        RELEASED_STATUS,
        UNATTRIBUTED_STATUS,
        UNREADABLE_STATUS,
        Results,
        rundowns_csv,
    )

    if args.format == "yaml":
        raise InputError("--results are exported as csv (the default) or json, not yaml")
    fmt = args.format or "csv"
    # one vehicle: found where ``db report`` finds it (a running demo's database too)
    url = _report_url(args) if args.vin is not None else _read_url(args)
    station = _station_id(args, url)
    with open_repository(url, must_exist=True, missing=_missing(args)) as repo:
        results = Results(repo)
        # (an unknown --vin: the report raises NotFoundError, one line, exit 2)
        listed = [repo.vehicle_report(args.vin).to_json()] if args.vin is not None else \
            list(reversed(results.vehicles(limit=1_000_000)))
        runs = [r for v in listed for r in results.export(v["vin"], station)]
    if args.since is not None:   # a bolt not run down has no time: kept with its vehicle's
        kept = [r for r in runs if r["recorded_at"] is not None
                and _aware(datetime.fromisoformat(r["recorded_at"])) >= args.since]
        # and with a vehicle at the station since (started, reopened or left since then):
        # one that left with no rundown at all was not in a shift's export
        vins_kept = {r["vin"] for r in kept} | {
            v["vin"] for v in listed if any(
                v[key] is not None and _aware(datetime.fromisoformat(v[key])) >= args.since
                for key in ("started_at", "reopened_at", "ended_at"))}
        # by identity: ``r in kept`` compared rows by value, each against all (quadratic:
        # hours for a year's export)
        kept_ids = {id(r) for r in kept}
        runs = [r for r in runs if id(r) in kept_ids or (
            r["status"] in (MISSING, PENDING, SKIPPED) and r["vin"] in vins_kept)]
    text = rundowns_csv(runs) if fmt == "csv" else strict_json(runs) + "\n"
    if args.out is None:
        sys.stdout.write(text)
    else:
        write_atomic(Path(args.out), text)
        rows = Counter(r["status"] for r in runs)
        missing = rows[MISSING]
        # a bolt of a vehicle still open (at the station, or reopened) is not run down yet,
        # not missing (its row says pending): quality read the vehicle on the lift as 45
        # bolts forgotten
        to_do = [r for r in runs if r["status"] == PENDING]
        also = [counted(rows[status], what) for status, what in (
            (SKIPPED, "skipped bolt"), (LOCKED_STATUS, "lock"), (RELEASED_STATUS, "release"),
            (LOOSEN_ORDERED_STATUS, "loosen command"),
            (UNREADABLE_STATUS, "unreadable result"),
            (UNATTRIBUTED_STATUS, "unattributed result"),
            (CONTROLLER_EVENT_STATUS, "controller event")) if rows[status]]
        if to_do:
            on = len({r["vin"] for r in to_do})
            also.append(f"{len(to_do)} not run down yet on {counted(on, 'open vehicle')}")
        rundowns = len(runs) - missing - len(to_do) - rows[SKIPPED] - sum(
            rows[status] for status in NOT_RUNDOWNS)
        print(f"wrote {args.out}: {counted(rundowns, 'rundown')} and "
              f"{counted(missing, 'missing bolt')}"
              + (f" (and {', '.join(also)})" if also else "")
              + f" of {counted(len({r['vin'] for r in runs}), 'vehicle')}")
    return EXIT_OK


def _made_on(u: dict[str, Any], vin: str) -> str:
    """Where a result stored with this vehicle was made when the controller says another
    vehicle (its VIN, MID 0061's), and when: results fetched after a restore or an outage are
    stored with the vehicle at height then, and read as its own without this (a technician's
    trial: a hundred of other vehicles' rundowns under the one on the lift)."""
    made = u.get("controller_vin")
    if not made or made == vin:
        return ""
    at = u.get("result_at")
    return f", made on {made}" + (f" at {at:%Y-%m-%d %H:%M:%S} UTC" if at is not None else "")


def _when(run: dict[str, Any]) -> str:
    """When a rundown was made, as the station took its result (``result_at``), and when it
    was stored where that was later (a result kept while the database was down: dated by its
    storing, it read as tightened after its vehicle had left)."""
    def text(iso: str) -> str:
        return iso[:19].replace("T", " ")
    made: str | None = run.get("result_at")
    stored: str | None = run.get("recorded_at")
    if made is None:
        return f"{text(stored)} UTC" if stored is not None else "- UTC"
    if stored is None or (datetime.fromisoformat(stored)
                          - datetime.fromisoformat(made)).total_seconds() <= 2.0:
        return f"{text(made)} UTC"
    # the day too where it differs (a result kept overnight while the database was down)
    late = text(stored)[11:] if stored[:10] == made[:10] else text(stored)
    return f"{text(made)} UTC (stored {late})"


def _aware(t: datetime) -> datetime:
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


#: what ``db report --json`` gives of each rundown (the export has every field)
RUNDOWN_KEYS = ("bolt", "attempt", "rundown", "status", "pset", "torque_nm", "angle_deg",
                "tightening_id", "result_at", "controller_at", "recorded_at", "operator")


def _report_url(args: argparse.Namespace) -> str:
    """The database ``db report VIN`` reads: ``--db``'s, else ``--config``'s station file's;
    with ``--config``, when that database does not exist or has no such vehicle, a running
    demo's of that station file that has it (said on stderr).  Why: a demo keeps its records
    in a temporary database of its own, and during a demo ``db report VIN --config
    STATION.yaml`` said "no database at .../stationd-sim.db (... or give --db or --config
    STATION.yaml)", suggesting the option already given."""
    url = _db_url(args)
    config = getattr(args, "config", None)
    if not config:
        return url
    from db.errors import DbError, NotFoundError
    from stationd.demo.leftovers import demo_databases

    hint = (f"the database of {config} (database.url), which the station's daemon makes; a "
            "demo keeps its results in a temporary database of its own, found by --config "
            "while the demo runs or holds (--hold), and shown on its screens (/vehicles, "
            "with their CSV and JSON export)")
    try:
        with open_repository(url, must_exist=True, missing=hint) as repo:
            repo.vehicle_report(args.vin)
        return url
    except (InputError, NotFoundError) as exc:
        demos = demo_databases(Path(config))
        for sid, path in demos:
            demo = f"sqlite:///{path}"
            try:
                with open_repository(demo, must_exist=True) as repo:
                    repo.vehicle_report(args.vin)
            except (InputError, DbError):
                continue
            sys.stderr.write(f"stationd: {args.vin} is a running demo's vehicle: reading "
                             f"that demo's database ({sid}, {path}), not {config}'s\n")
            return demo
        nor = "" if not demos else (
            f"; nor is {args.vin} in the database of the running demo of {config} ("
            + ", ".join(f"{sid} {path}" for sid, path in demos) + ")")
        if isinstance(exc, NotFoundError):   # "... not in the database of FILE (did you
            head, sep, tail = str(exc).partition(" (did you mean")   # mean ...?)"
            raise InputError(f"{head} of {config}{sep}{tail}{nor}") from None
        if nor:     # in short: the long hint on where a demo keeps its records is moot here
            absent = _not_there(url)
            if absent is not None:
                raise InputError(f"vehicle {args.vin!r} is in no database of {config}: none "
                                 f"at {absent} yet{nor}") from None
            raise InputError(f"{exc}{nor}") from None
        raise


def _not_there(url: str) -> str | None:
    """:func:`absent_sqlite_file`, where a folder that cannot be entered counts as there
    (opening the database then says why it cannot be reached)."""
    try:
        return absent_sqlite_file(url)
    except OSError:
        return None


def _read_url(args: argparse.Namespace) -> str:
    """The database a read of every vehicle (``db export --results``, ``db spc``) reads:
    ``--db``'s, else ``--config``'s; where that station file's database does not exist and
    one demo of it runs, that demo's (said on stderr); several: which they are, and --db to
    choose.  Why: during a demo, ``db report --config`` found the demo's records while the
    export and the figures said only "no database at .../stationd-sim.db"."""
    url = _db_url(args)
    config: str | None = getattr(args, "config", None)
    absent = _not_there(url) if config else None
    if absent is None or config is None:
        return url
    from stationd.demo.leftovers import demo_databases

    demos = demo_databases(Path(config))
    if len(demos) == 1:
        sid, path = demos[0]
        sys.stderr.write(f"stationd: {config}'s database {absent} is not there yet: reading "
                         f"the running demo's ({sid}, {path})\n")
        return f"sqlite:///{path}"
    if demos:
        raise InputError(f"no database at {absent} ({config}'s); the running demos of it keep "
                         "theirs: " + ", ".join(f"{sid} --db sqlite:///{path}"
                                                for sid, path in demos))
    return url


def cmd_db_report(args: argparse.Namespace) -> int:
    with open_repository(_report_url(args), must_exist=True) as repo:
        report = repo.vehicle_report(args.vin, held=True)
        loose = repo.others.unattributed(args.vin)   # results made at height that no bolt owns
        events = repo.others.controller_events(args.vin)   # batch steps, bypasses, ...: no rundown
        unread = repo.others.unreadable(args.vin)          # results that could not be read
        commands = repo.ledger.commands(args.vin)   # the audit trail: skips, reopens
        from stationd.web.results import Results

        runs = Results(repo).rundowns(args.vin)   # every rundown: its kind, result, time
    if args.json:
        out = report.to_json()
        out["unattributed"] = [{**u, "result_at": _iso(u["result_at"]),
                                "recorded_at": _iso(u["recorded_at"])} for u in loose]
        out["controller_events"] = [{**e, "result_at": _iso(e["result_at"]),
                                     "recorded_at": _iso(e["recorded_at"])} for e in events]
        out["unreadable_results"] = [{**x, "result_at": _iso(x["result_at"]),
                                      "recorded_at": _iso(x["recorded_at"])} for x in unread]
        out["commands"] = [{"at": _iso(c.at), "user": c.user, "source": c.source,
                            "kind": c.kind, "bolt": c.bolt, "comment": c.comment}
                           for c in commands]
        # a NOK's value out of its limits, as the text says it (None: an OK, no window)
        out["rundowns"] = [{**{k: r[k] for k in RUNDOWN_KEYS}, "nok_why": nok_why(r) or None}
                           for r in runs]
        run_down = {r["bolt"] for r in runs}
        for b in out["bolts"]:   # as the vehicle's page: "not tightened", or why held
            if b["bolt"] not in run_down:
                b["unrecorded"] = unrecorded_words(out["held"].get(b["bolt"]), loose)
        sys.stdout.write(strict_json(out) + "\n")
    else:
        print(report.summary())
        for b in report.bolts:
            mine = [r for r in runs if r["bolt"] == b.bolt_id]
            last = mine[-1:]
            skipped = f"by {b.skipped_by}" + (f": {b.comment}" if b.comment else "")
            hold = dict(report.held).get(b.bolt_id)
            # a held bolt never run down: why held, as the vehicle's page says it
            result = ("-" if hold is None else unrecorded_words(hold, loose)) \
                if b.status == MISSING else skipped if b.status == SKIPPED else \
                f"{_num(b.torque_nm)} Nm, {_num(b.angle_deg)} deg, v{b.version}" \
                + _why_nok(last[0] if last else None) + f", {_attempts(b.attempts, mine)}" \
                + (_last_run(last[0]) if last else "") \
                + (f"; then skipped {skipped}" if b.skipped_by else "")
            retired = " (retired)" if b.retired else ""
            held = "" if hold is None else f"; HELD: {hold} (its outcome to be entered)"
            if b.bolt_id in report.locked:   # waits for a supervisor (a supervisor's trial)
                held += "; LOCKED after its NOKs: a supervisor checks it and releases it"
            print(f"  {b.bolt_id:<12} {b.status.upper():<8} {result}  {b.name}{retired}{held}")
            if b.attempts > 1:   # reworked: each rundown, so the loosenings show
                for r in (r for r in runs if r["bolt"] == b.bolt_id):
                    # the controller's id of each attempt, not the last's alone (a quality
                    # trial: a complaint's attempts needed the export for their ids)
                    tid = r.get("tightening_id")
                    print(f"    {r['attempt']}. {r['rundown']} {r['status'].upper()} pset "
                          f"{r['pset'] if r['pset'] is not None else '-'}, "
                          f"{_num(r['torque_nm'])} Nm, {_num(r['angle_deg'])} deg"
                          f"{_why_nok(r)}" + (f", {r['rundown']} {tid}" if tid is not None
                                              else "")
                          + f", at {_when(r)}, by {r['operator'] or '-'}" + _entered(r))
        for c in commands:
            on = f" {c.bolt}" if c.bolt else ""
            why = f": {c.comment}" if c.comment else ""
            print(f"  {c.kind}{on} by {c.user} ({c.source}) at {c.at:%Y-%m-%d %H:%M:%S} "
                  f"UTC{why}")
        for u in loose:
            print(f"  unattributed: {result_type_words(u['result_type'])} "
                  f"{u['tightening_id']} pset {u['pset']} "
                  f"{u['status'].upper()} {_num(u['torque_nm'])} Nm, "
                  f"{_num(u['angle_deg'])} deg{_made_on(u, args.vin)} ({u['reason']})"
                  + entered_as_words(u["entered_as"]))
        holds = dict(report.held)
        for e in events:
            if e["what"] in HOLD_WORDS:    # no result: what the station knows of it
                now = _held_now(e["bolt"], holds, e["note"] or "", "; ", e["recorded_at"],
                                commands)
                print(f"  {HOLD_WORDS[e['what']]} while the tool was on {e['bolt']}: "
                      f"{e['note']}{now}")
                continue
            on = f" while the tool was on {e['bolt']}" if e["bolt"] else ""
            # (its type's code unless its words say it: an auditor's trial found the 9 of a
            # result of an unknown type said nowhere, its words "unknown result type")
            code = "" if f"type {e['result_type']}" in e["what"] \
                else f" (type {e['result_type']})"
            print(f"  controller event: {e['what']}{code}, tightening "
                  f"{e['tightening_id']} pset {e['pset']}{on}: not a rundown")
        for x in unread:
            said = message_words(x["mid"], x["revision"])
            note = unreadable_note(x["tightening_id"], x["mid"], x["revision"])
            print(f"  unreadable result: tightening {x['tightening_id'] or '?'} ({said}"
                  f"{_held_now(x['bolt'], holds, note)}): "
                  f"{x['error'].removeprefix(said + ': ')}")
    return EXIT_OK if report.complete else EXIT_INCOMPLETE


#: the station's own controller events that hold a bolt without a result, as db report
#: names them
HOLD_WORDS = {CUT_UNKNOWN: "link cut", LOST_UNKNOWN: "a result's push lost"}


def _held_now(bolt: str | None, holds: dict[str, str], note: str, sep: str = ", ",
              since: datetime | None = None, commands: Sequence[Any] = ()) -> str:
    """Of a record that held ``bolt`` with ``note`` (stored at ``since``): whether that hold
    is on still (``holds``: the bolts held now, each with its note: a later hold of the same
    bolt is another record's), or ended, and how: the first release, skip or entered
    outcome of that bolt since, by whom and when (``commands``, the vehicle's; a
    supervisor's trial: "held then, no longer", who ended it only in the list above)."""
    if not bolt:
        return ""
    now = holds.get(bolt)       # (a loosening's hold adds ", a loosening ..." to its note)
    if now is not None and (now == note or now.startswith(note + ",")):
        return f"{sep}{bolt} held"
    ended = next((c for c in commands if c.bolt == bolt and c.kind in ENDING_WORDS
                  and (since is None or c.at >= since)), None)
    if ended is None:
        return f"{sep}{bolt} held then, no longer"
    return (f"{sep}{bolt} held then: {ENDING_WORDS[ended.kind]} by {ended.user} at "
            f"{ended.at:%Y-%m-%d %H:%M:%S} UTC")


#: the commands that end a hold, as db report says how one ended
ENDING_WORDS = {RELEASE: "released", "skip": "skipped", ENTER_OUTCOME: "its outcome entered"}


def _why_nok(run: dict[str, Any] | None) -> str:
    """" (torque 56.1 Nm > 55.0 max)" after a NOK rundown's values (:func:`nok_why`)."""
    why = nok_why(run) if run is not None else ""
    return f" ({why})" if why else ""


def _last_run(run: dict[str, Any]) -> str:
    """A bolt's last rundown as its line ends: by whom, the controller's tightening id and
    when (a quality trial: the id and the time were only in --json and the exports).  The
    id is the controller's, said as the rundown's kind: "loosening 12" for a loosening (a
    supervisor's trial: "tightening 12" read as the bolt tightened)."""
    tid = run.get("tightening_id")
    kind = LOOSENING if run.get("rundown") == LOOSENING else TIGHTENING
    return f", by {run['operator'] or '-'}" + _entered(run) + (
        f", {kind} {tid}" if tid is not None else "") + f", at {_when(run)}"


def _entered(run: dict[str, Any]) -> str:
    """A rundown a person entered from the controller's screen, said so (a measured one:
    nothing)."""
    if not run.get("entered_by"):
        return ""
    return f", entered by {run['entered_by']} from the controller's screen, not measured" + (
        f" ({run['entered_comment']})" if run.get("entered_comment") else "")


def _attempts(n: int, runs: list[dict[str, Any]]) -> str:
    """How many rundowns a bolt had: ``3 attempts``, or with loosenings among them ``4
    tightenings, 3 loosenings`` (a loosening is no attempt at the bolt)."""
    loosenings = sum(r["rundown"] == LOOSENING for r in runs)
    if not loosenings:
        return counted(n, "attempt")
    return f"{counted(n - loosenings, 'tightening')}, {counted(loosenings, 'loosening')}"


def cmd_db_spc(args: argparse.Namespace) -> int:
    """Process capability per bolt and pset, and the NOK trend (quality's figures)."""
    with open_repository(_read_url(args), must_exist=True, missing=_missing(args)) as repo:
        if args.model is not None and args.model not in repo.models():
            raise InputError(f"--model {args.model}: no such model (models: "
                             f"{', '.join(repo.models()) or 'none'})")
        doc = repo.spc(args.model, args.since)
    if args.json:
        sys.stdout.write(strict_json(doc) + "\n")
        return EXIT_OK
    if not doc["bolts"]:   # said, not a header alone (a supervisor's trial)
        print("no tightening results" + (f" of model {args.model}" if args.model else "")
              + (f" since {args.since.isoformat()}" if args.since else "")
              + ": nothing to compute")
        return EXIT_OK
    # n: the measured tightenings the figures are computed on (OK and NOK); NOK: of them
    # and entered ones, the NOK rundowns (not bolts); a change of limits starts a new row:
    # its parameter version (v) and limits tell the rows of one bolt and pset apart; s: the
    # sample standard deviation
    print(f"{'model':<10} {'bolt':<8} {'pset':>4} {'n':>4} {'NOK':>4} {'v':>3} "
          f"{'torque Nm':>11}  {'mean':>6} {'s':>5} {'Cp':>5} {'Cpk':>5}  "
          f"{'angle deg':>11}  {'mean':>6} {'s':>5} {'Cp':>5} {'Cpk':>5}")
    rough = False
    for r in doc["bolts"]:
        t, a = r["torque"], r["angle"]
        rough |= any(q["cp"] is not None and q["n"] < ROUGH_N for q in (t, a))
        print(f"{r['model']:<10} {r['bolt']:<8} {r['pset'] or '-':>4} {t['n']:>4} "
              f"{r['nok']:>4} {r['parameter_version'] or '-':>3} {_window(t):>11}  "
              f"{_num(t['mean']):>6} {_num(t['sigma'], 2):>5} {_figs(t)}  "
              f"{_window(a):>11}  {_num(a['mean']):>6} {_num(a['sigma'], 2):>5} {_figs(a)}")
    if rough:
        print(f"* from fewer than {ROUGH_N} results: a rough figure (Cpk of a few results is "
              "off by several tenths either way)")
    for r in doc["bolts"]:   # typed in from the controller's screen: counted apart
        # (a supervisor's trial: an entered NOK was in the NOK column, not in n, unsaid)
        entered = [f"{r[k]} {w}" for k, w in (("entered_ok", "OK"), ("entered_nok", "NOK"))
                   if r.get(k)]
        if entered:
            print(f"{r['model']} {r['bolt']} pset {r['pset'] or '-'}: {' and '.join(entered)} "
                  "entered by a person (not measured: not in n and the figures"
                  + ("; the NOK column counts them" if r.get("entered_nok") else "") + ")")
    for d in doc["trend"]:
        print(f"{d['day']} (UTC): {d['results']} results, {d['nok']} NOK "
              f"({100 * (d['nok_rate'] or 0):.1f} %)")
    return EXIT_OK


#: fewer measured results than this make a capability figure rough (marked ``*``)
ROUGH_N = 25


def _window(q: dict[str, Any]) -> str:
    """A capability's limits, ``45.0-55.0`` (``-`` for a limit not set)."""
    return f"{_num(q['lsl'])}-{_num(q['usl'])}"


def _figs(q: dict[str, Any]) -> str:
    """Cp and Cpk, each marked ``*`` when from fewer than :data:`ROUGH_N` results."""
    mark = "*" if q["cp"] is not None and q["n"] < ROUGH_N else ""
    return f"{_fig(q['cp']) + mark:>5} {_fig(q['cpk']) + mark:>5}"


def _fig(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def _iso(t: datetime | None) -> str | None:
    return None if t is None else _aware(t).isoformat()


def cmd_db_shift(args: argparse.Namespace) -> int:
    """A shift's hand-over: every vehicle at the station in the window with its status and
    its bolts not OK, then the commands people gave (who released which lock and why).
    Exit 0 when every vehicle of the window left complete, 1 when one is open or left with
    bolts not OK, a bolt held among them (something to hand over)."""
    from db.shift import list_status, shift

    # in UTC, as it is said (a zone given is the same instant: "06:00+02:00" read "06:00 UTC")
    until = (args.until or datetime.now(UTC)).astimezone(UTC)
    since = (args.since or until - timedelta(hours=8)).astimezone(UTC)
    if since >= until:
        raise InputError(f"--since {since.isoformat()} is not before --until "
                         f"{until.isoformat()}")
    with open_repository(_read_url(args), must_exist=True, missing=_missing(args)) as repo:
        done = shift(repo, since, until)
    rows = [(r, list_status(r)) for r in done.vehicles]
    if args.json:
        sys.stdout.write(strict_json({
            "since": since.isoformat(), "until": until.isoformat(),
            "vehicles": [{**{k: v for k, v in r.to_json().items() if k != "bolts"},
                          "status": status} for r, status in rows],
            "commands": [{"at": _iso(c.at), "user": c.user, "source": c.source,
                          "kind": c.kind, "vin": c.vin, "bolt": c.bolt,
                          "comment": c.comment, "entered": done.entered.get(c.id)}
                         for c in done.commands]}) + "\n")
    else:
        by = Counter(status for _, status in rows)
        counts = ", ".join(f"{by[w]} {w}" for w in ("complete", "NOK", "incomplete", "open",
                                                     "reopened") if by[w])
        print(f"from {since:%Y-%m-%d %H:%M} to {until:%Y-%m-%d %H:%M} UTC: "
              f"{counted(len(rows), 'vehicle')} at the station" + (f": {counts}" if counts
                                                                    else ""))
        for r, status in rows:
            v = r.vehicle
            # a vehicle reopened for rework, not back yet, did leave: when it last left (a
            # supervisor's trial: "left -" read as still on the lift)
            gone = v.ended_at or (v.last_closed_at if v.waiting else None)
            left = "-" if gone is None else f"{gone:%m-%d %H:%M:%S}"
            print(f"  {v.vin:<18} {v.model:<10} in {v.started_at:%m-%d %H:%M:%S}  left "
                  f"{left:<14} {status:<10} {_undone(r)}".rstrip())
        if done.commands:
            print("commands:")
        for c in done.commands:
            on = " ".join(x for x in (c.bolt, f"of {c.vin}" if c.vin else None) if x)
            what = done.entered.get(c.id)
            print(f"  {c.kind} {on} by {c.user} ({c.source}) at {c.at:%Y-%m-%d %H:%M:%S} UTC"
                  + (f": {what}" if what else "") + (f": {c.comment}" if c.comment else ""))
    # a bolt held for a person is not OK whatever its status says (its last result not
    # known; its vehicle's close names it not OK): something to hand over
    return EXIT_OK if all(status == "complete" and not r.held for r, status in rows) \
        else EXIT_INCOMPLETE


def _undone(r: VehicleReport) -> str:
    """A vehicle's bolts not OK in a hand-over's row: what waits for a person first (locked,
    held, NOK, loosened or to loosen), then the skipped, then the missing, these counted and
    the first named (a supervisor's trial: 47 missing bolts on one 700-character line buried
    "B37 NOK").  A held or locked bolt is said once, beside its status."""
    held = {b for b, _ in r.held}
    status = {b.bolt_id: b.status for b in r.bolts}

    def said(b: str, word: str) -> str:
        return f"{b} {word}" + (" and locked" if b in r.locked else "") + \
            (" and held" if b in held else "")

    first = [said(b, "NOK") for b in r.nok] + \
        [said(b, "loosened" if status[b] == LOOSENED else "to loosen") for b in r.loosen]
    listed = {*r.nok, *r.loosen, *r.skipped, *r.missing}
    first += [said(b, "locked") for b in r.locked if b not in listed] + \
        [f"{b} held" for b in sorted(held - listed - set(r.locked))]
    first += [said(b, "skipped") for b in r.skipped]
    missing = [b for b in r.missing if b not in held and b not in r.locked]
    first += [said(b, "missing") for b in r.missing if b in held or b in r.locked]
    if missing:
        first.append(f"{len(missing)} missing ({', '.join(missing[:SHIFT_NAMED])}"
                     + (f" and {len(missing) - SHIFT_NAMED} more" if len(missing) > SHIFT_NAMED
                        else "") + ")")
    return ", ".join(first)


#: the missing bolts a hand-over's row names (the rest counted)
SHIFT_NAMED = 5


def _num(v: float | None, digits: int = 1) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


# -- config check ----------------------------------------------------------------------------
def cmd_config_check(args: argparse.Namespace) -> int:
    """Check station files and bolt tables, told apart by their top-level keys; every error of
    every file, then one summary line.  Warnings (a pair not registered yet) do not fail."""
    # each with whether it was given as the station file (--config): a bolt table is refused
    # there, not where the same path is also given as a FILE
    files = [*((f, False) for f in args.files), *((f, True) for f in args.config_files)]
    if not files:
        raise InputError("config check: no file to check: stationd config check FILE ... "
                         "(station files, bolt tables) or --config STATION.yaml")
    failed, errors = 0, 0
    named: list[str] = []    # files with errors that were not given: a station file's
    for name, station_file in files:
        summary, found, warnings = _check_file(name, args.tolerance, station_file)
        for w in warnings:
            sys.stderr.write(f"warning: {w}\n")
        if not found:
            print(f"{name}: ok, {summary}")
            continue
        failed += 1
        errors += len(found)
        named += [e.path for e in found if e.path and e.path != name and e.path not in named]
        _print_errors(found)
    if failed:
        # (a technician's trial: "1 error in 1 of 1 file" of an error in the bolt table the
        # station file names)
        where = f" (those of {', '.join(named)} counted with the station file naming it)" \
            if named else ""
        sys.stderr.write(f"stationd: error: {counted(errors, 'error')} in {failed} of "
                         f"{counted(len(files), 'file')}{where}\n")
        return EXIT_BAD_INPUT
    return EXIT_OK


def _check_file(name: str, tolerance_mm: float, station_file: bool = False,
                ) -> tuple[str, list[ConfigError], list[ConfigError]]:
    """(summary when valid, errors, warnings) of one file, a station file or a bolt table
    (``station_file``: given as a station file, ``--config``: a bolt table is an error, as
    ``stationd run --config`` says it)."""
    from stationd.boltfile import check_bolts
    from stationd.stationcheck import check_station

    try:
        kind = file_kind(name)
    except ConfigError as exc:
        return "", [exc], []
    if kind == "bolts" and station_file:
        return "", [ConfigError("this is a bolt table, not a station file: check it without "
                                "--config (stationd config check FILE), or give the station "
                                "file that names it", path=name)], []
    if kind == "bolts":
        bolts = check_bolts(name, tolerance_mm=tolerance_mm)
        return (bolts.table.summary() if bolts.table else ""), bolts.errors, bolts.warnings
    station = check_station(name)
    summary = ""
    if station.config is not None:
        cfg = station.config
        summary = (f"station: {counted(len(cfg.pairs), 'pair')}, "
                   f"{counted(len(cfg.cameras), 'camera')}")
        if station.bolts is not None and station.bolts.table is not None:
            summary += f"; bolts {cfg.bolts_path}: {station.bolts.table.summary()}"
    bolt_warnings = station.bolts.warnings if station.bolts is not None else []
    return summary, station.errors, [*station.warnings, *bolt_warnings]


def file_kind(path: str | Path) -> str:
    """"station" or "bolts": what a file is, by its top-level keys.

    Why by keys: both are YAML mappings and neither has a header; the key sets do not overlap
    (a station file's ``bolts`` names a bolt table, whose keys are ``psets`` and ``models``).
    A file with keys of both, of neither, or that is not a mapping is a ConfigError, as is an
    unreadable, malformed or empty one.
    """
    import yaml

    from stationd.boltfile import TOP_KEYS
    from stationd.config import STATION_KEYS
    from stationd.yamlio import YamlNode

    root = YamlNode.load(path)
    try:
        value = root.value()
    except yaml.YAMLError:  # e.g. a list as a key: not a file of either kind
        value = None
    if not isinstance(value, dict):
        raise root.error("expected a mapping (key: value): a station file or a bolt table")
    keys = [k for k in value if isinstance(k, str)]
    station = [k for k in keys if k in STATION_KEYS]
    bolts = [k for k in keys if k in TOP_KEYS]
    if station and bolts:
        raise root.error(f"cannot tell a station file (it has {', '.join(station)}) from a bolt "
                         f"table (it has {', '.join(bolts)}): a file is one or the other")
    if not station and not bolts:
        from stationd.filekind import described, kind_of_keys

        other = kind_of_keys(set(keys))
        if other is not None:
            raise root.error(f"this is {described(other)}, not a station file or a bolt "
                             "table (config check reads those; the station file names its "
                             "calibrations)")
        found = f"its keys are {', '.join(keys)}" if keys else "it has no keys"
        raise root.error(f"neither a station file nor a bolt table ({found}; a station file "
                         f"has {', '.join(STATION_KEYS)}; a bolt table has "
                         f"{', '.join(TOP_KEYS)})")
    return "station" if station else "bolts"


# -- parsers -----------------------------------------------------------------------------------
def add_db_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``db`` (import, export, report) to the ``stationd`` sub-parsers."""
    d: argparse.ArgumentParser = subparsers.add_parser(
        "db", help="the process-parameter database: bolt tables and vehicle reports")
    dsub = d.add_subparsers(dest="db_command", required=True, parser_class=type(d))
    im = dsub.add_parser(
        "import", help="import a bolt table (validated, all or nothing, idempotent)",
        description="Validates the file (all errors are listed) and brings the database to it "
                    "in one transaction; prints what changed, or 'no changes'.  The file is the "
                    "whole table: models and bolts it no longer lists are removed (kept, "
                    "retired, while records or vehicles refer to them).  Changed parameters of a "
                    "bolt with records, or of a model a vehicle was started under, become a "
                    "new version.")
    im.add_argument("file", help="bolts YAML (see config/bolts.example.yaml)")
    _add_db_args(im)
    im.add_argument("--tolerance", type=_tolerance, default=None, metavar="MM",
                    help="matching tolerance: bolts must be twice as far apart (default: the "
                    "station's with --config, else 8)")
    im.add_argument("--json", action="store_true", help="print the changes as one JSON object")
    im.set_defaults(func=cmd_db_import)
    ex = dsub.add_parser("export", help="write the bolt table back as YAML",
                         description="Writes the table held by the database; importing it "
                                     "again reports no changes.")
    _add_db_args(ex)
    ex.add_argument("--out", help="file to write (default: standard output)")
    ex.add_argument("--results", action="store_true",
                    help="the tightening results (every rundown) instead of the bolt table")
    ex.add_argument("--vin", help="with --results: this vehicle only")
    ex.add_argument("--since", type=_since, metavar="DATE",
                    help="with --results: rundowns recorded since (ISO date or date-time, UTC)")
    ex.add_argument("--format", choices=("yaml", "csv", "json"), default=None,
                    help="yaml for the bolt table; csv (default) or json for --results")
    ex.set_defaults(func=cmd_db_export)
    rp = dsub.add_parser("report", help="a vehicle's bolts: results and missing ones",
                         description="Exit 0 when every bolt is tightened and OK, 1 when bolts "
                                     "are missing or NOK, 2 for an unknown VIN.")
    rp.add_argument("vin", help="VIN or sequence id")
    _add_db_args(rp)
    rp.add_argument("--json", action="store_true", help="print one JSON object")
    rp.set_defaults(func=cmd_db_report)
    sp = dsub.add_parser("spc", help="Cp/Cpk of torque and angle per bolt and pset, and the "
                         "NOK trend per day",
                         description="On every measured tightening (OK and NOK; an outcome "
                                     "a person entered is counted apart): Cp = (USL-LSL)/6s, "
                                     "Cpk = min(USL-mean, mean-LSL)/3s against the limits "
                                     "sent; '-' with fewer than 5 results, '*' on a figure "
                                     f"from fewer than {ROUGH_N} (rough).  Days are UTC "
                                     "days.")
    _add_db_args(sp)
    sp.add_argument("--model", help="this vehicle model only")
    sp.add_argument("--since", type=_since, metavar="DATE",
                    help="results from this date on (UTC unless an offset is given)")
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    sp.set_defaults(func=cmd_db_spc)
    sh = dsub.add_parser("shift", help="a shift's hand-over: its vehicles, those not OK, who "
                         "released or skipped what",
                         description="Every vehicle at the station between --since and "
                                     "--until (default: the last 8 hours), with its status "
                                     "and bolts not OK, then the commands given (releases, "
                                     "skips, reopens, loosenings, entered outcomes).  Exit 0 "
                                     "when every one left complete, 1 when one is open or "
                                     "left with bolts not OK.")
    _add_db_args(sh)
    sh.add_argument("--since", type=_since, metavar="DATE",
                    help="the shift's start (ISO date or date-time, UTC; default: 8 hours "
                         "before --until)")
    sh.add_argument("--until", type=_since, metavar="DATE",
                    help="the shift's end (default: now)")
    sh.add_argument("--json", action="store_true", help="print one JSON object")
    sh.set_defaults(func=cmd_db_shift)
    return d


def add_config_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``config`` (with ``check``) to the ``stationd`` sub-parsers."""
    c: argparse.ArgumentParser = subparsers.add_parser("config", help="check configuration files")
    csub = c.add_subparsers(dest="config_command", required=True, parser_class=type(c))
    ck = csub.add_parser(
        "check", help="validate station files and bolt tables: every error of each file, all "
        "at once",
        description="Checks station files (station.yaml) and bolt tables (bolts.yaml), told "
                    "apart by their top-level keys.  A station file is checked with the files "
                    "it names (calibrations, to_vehicle transforms, the bolt table) and its "
                    "device URLs (form and scheme; no device is opened).  Every error is "
                    "printed as file:line: key: message; warnings (a pair not registered into "
                    "the vehicle frame yet) do not fail the check.  Exit 0 when all files are "
                    "valid, 2 otherwise.")
    ck.add_argument("files", nargs="*", metavar="FILE")
    # the other commands name the station file with --config: a user types it here too
    ck.add_argument("--config", dest="config_files", action="append", default=[],
                    metavar="STATION.yaml", help="a station file, as the other commands take "
                    "it (the same as giving it as a FILE)")
    ck.add_argument("--tolerance", type=_tolerance, default=8.0, metavar="MM",
                    help="matching tolerance for bolt tables given here: bolts must be twice "
                         "as far apart (default 8); a station file's bolt table is checked "
                         "with the station's own matching.tolerance_mm")
    ck.set_defaults(func=cmd_config_check)
    return c
