"""Store and forward: every record of the station's own database, in order, to the line's
PostgreSQL.

Why this shape: the station's SQLite file is the truth (a result is stored there, then
acknowledged to the controller); the line database is a copy for the plant (quality, the
MES, years of history).  The forwarder reads the results feed (:mod:`db.ledger`, one sequence
for every record) after the last number the line database took, and inserts each entry keyed
by (station id, the local database's id, sequence number): a replay after a crash or a retry
inserts nothing twice, and a station whose local database was replaced (re-commissioned, the
demo's fresh database) keeps its records apart by the new database's id.  While the line
database is down the station goes on tightening and the backlog grows; past the configured
bounds (records, megabytes, hours) it is an alarm, never a fault.  An entry the line database
refuses for good (a value it will never take) is quarantined locally with its reason, so it
never blocks the rest; a refusal of the line database's state (no connection, a role without
the privilege to write, a server that takes no writes) is the line database down, never a
record's fault (:func:`refused_for_good`).

The line database is PostgreSQL and nothing else: the same URL that works on a developer's
SQLite file would take the plant's records into a file nobody queries, so another dialect is a
configuration error (with its file and line), not a line database that seems to work.

The ``line:`` section of the station file (optional: without it nothing is forwarded)::

    line:
      url: postgresql+psycopg://stationd@line-db.plant/line   # a password: PGPASSFILE
      station_id: ST-07
      backlog: {records: 100000, size_mb: 256, age_h: 72}     # an alarm past any
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import random
import time
from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import Connection, Engine, make_url, select
from sqlalchemy.dialects.postgresql import insert as pg_insert
from sqlalchemy.exc import DBAPIError, SQLAlchemyError

from db.engine import make_engine
from db.errors import DbError
from db.repository import Repository
from stationd.lineconfig import LineConfig, line_url_problem, not_postgresql
from stationd.linedb import (
    LINE_FEED,
    LINE_PARAMETERS,
    create_line_schema,
    operator_of,
    parameter_rows,
    write_problem,
)

log = logging.getLogger("stationd")
BATCH = 200                  # entries per transaction
POLL_S = 1.0                 # how often the feed is read when nothing is behind
BACKOFF_S = (1.0, 60.0)      # a line database that is down: first and longest wait
STATUS_S = 5.0               # the status is refreshed at least this often meanwhile
#: while the line database is down, its state (the backlog grown) is said again this often:
#: a quality trial saw one line as the outage began, then nothing while 52 records waited
DOWN_SAID_S = 60.0
HEARTBEAT_S = 10.0           # with nothing to send, the line database is asked this often
MEASURE_S = 0.25             # the most time one status spends measuring new backlog entries
MEASURE_BATCH = 500          # entries read at once to measure them
CURSOR_KEY = "forwarded_seq"


class LineDown(Exception):  # noqa: N818 - a state, not a programming error
    """The line database cannot be reached or refuses writes for now: try again later."""


class SeriesDiverged(Exception):  # noqa: N818 - a finding, not a programming error
    """The line holds, under this database's id, another record at ``seq`` (another kind
    or time) than this database's: the database was put back from a copy (a backup) and
    numbered its new records again from where the copy ended.  Nothing of the batch was
    written (its transaction rolled back)."""

    def __init__(self, seq: int) -> None:
        super().__init__(f"record {seq} is another record on the line")
        self.seq = seq


class LineRefuses(LineDown):
    """The line database answers but will not take this role's records now (a privilege it
    lacks, a server that takes no writes): down for the forwarder all the same (the records
    wait), said apart from "does not answer" by the commands (a grant fixes it, not the
    network)."""


def payload_bytes(entry: dict[str, Any]) -> int:
    """The size of a feed entry's record as the line database takes it: its JSON."""
    return len(json.dumps(entry["record"], separators=(",", ":"), ensure_ascii=False,
                          default=str).encode("utf-8"))


class BacklogBytes:
    """The bytes of the records not forwarded yet, kept without reading them all again.

    Why this way: the backlog of a line database that was down for days is tens of thousands
    of records, each read with a query; sizing them every few seconds would cost more than
    forwarding them.  Each entry is measured once, when it is read after the last one measured
    (``head``), and taken off when the forwarder moves past it.  ``total`` is the size of
    the entries after the cursor up to ``head``; until ``head`` reaches the last record (a
    large backlog found at start is measured a slice at a time) it is a lower bound, so an
    alarm on it is never false, only possibly late."""

    def __init__(self, cursor: int) -> None:
        self.head, self.total = cursor, 0

    def forwarded(self, entries: list[dict[str, Any]], cursor: int) -> None:
        """The forwarder moved its cursor past ``entries`` (taken or quarantined)."""
        self.total -= sum(payload_bytes(e) for e in entries if e["seq"] <= self.head)
        if cursor >= self.head:    # nothing measured is left: exact again
            self.head, self.total = cursor, 0
        self.total = max(0, self.total)

    def measure(self, since: Callable[[int, int], list[dict[str, Any]]], last: int,
                budget_s: float | None) -> bool:
        """Measure the entries after ``head`` up to ``last``, for at most ``budget_s`` (None:
        all of them, 0: none); whether ``total`` is now the whole backlog's size."""
        deadline = None if budget_s is None else time.monotonic() + budget_s
        while self.head < last and (budget_s is None or budget_s > 0):
            batch = since(self.head, MEASURE_BATCH)
            if not batch:
                break
            self.total += sum(payload_bytes(e) for e in batch)
            self.head = int(batch[-1]["seq"])
            if deadline is not None and time.monotonic() >= deadline:
                break
        return self.head >= last


class LineDb:
    """The line database (PostgreSQL): its table made if missing, entries inserted
    idempotently."""

    def __init__(self, url: str) -> None:
        backend = make_url(url).get_backend_name()
        if backend != "postgresql":   # the config refuses it with its line; this is the code's
            raise ValueError(not_postgresql(url, backend))
        self.url = url
        self._engine: Engine | None = None

    def _connect(self) -> Engine:
        """The engine, the line's tables made where missing.  Why a failure to make them is
        ``LineDown`` and never a refused record: it is the line database's state (a role
        without the right to create them, two stations' first starts racing to make them),
        the same for every record; as a refusal it would quarantine every record in turn."""
        if self._engine is None:
            engine = make_engine(self.url)
            try:
                create_line_schema(engine)
                with engine.connect() as conn:   # the tables there: may this role write them?
                    problem = write_problem(conn)
            except SQLAlchemyError as exc:
                engine.dispose()
                if isinstance(exc, DBAPIError) and _transient(exc):   # no connection at all
                    raise LineDown(error_line(exc)) from None
                raise LineDown(f"the line tables: {error_line(exc)}") from None
            if problem is not None:
                engine.dispose()
                raise LineRefuses(problem)
            self._engine = engine
        return self._engine

    def push(self, station_id: str, db_id: str, entries: list[dict[str, Any]]) -> int:
        """Insert ``entries`` in one transaction (those already there are left alone);
        how many were new.  ``DBAPIError`` for a refused row, ``LineDown`` for the rest."""
        try:
            engine = self._connect()
            rows = [{"station_id": station_id, "db_id": db_id, "seq": e["seq"],
                     "kind": e["kind"], "at": datetime.fromisoformat(e["at"]).replace(
                         tzinfo=UTC), "record": e["record"], "operator": operator_of(e)}
                    for e in entries]
            stmt = pg_insert(LINE_FEED).on_conflict_do_nothing().returning(LINE_FEED.c.seq)
            versions = parameter_rows(station_id, db_id, entries)
            with engine.begin() as conn:
                taken = set(conn.execute(stmt, rows).scalars())   # the rows that were new
                new = len(taken)
                if new < len(rows):   # a replay (the same records), or another series
                    _same_records(conn, station_id, db_id,
                                  [r for r in rows if r["seq"] not in taken])
                if versions:   # the bolt tables the rundowns were tightened with
                    conn.execute(pg_insert(LINE_PARAMETERS).on_conflict_do_nothing(),
                                 versions)
                return new
        except DBAPIError as exc:
            if not refused_for_good(exc):
                raise self._down(exc) from None
            raise
        except (SQLAlchemyError, DbError, OSError) as exc:
            self.dispose()
            raise LineDown(error_line(exc)) from None

    def _down(self, exc: DBAPIError) -> LineDown:
        """The line database's state that refused a push, as the link says it: a refusal of
        this role's writes (a grant revoked since the connection was checked) is asked again
        on a new connection, whose check names the role and the privilege it lacks."""
        self.dispose()
        if not _refuses_role(exc):
            return LineDown(error_line(exc))
        try:
            self._connect()
        except LineDown as down:
            return down
        self.dispose()   # the check found nothing: the server's words, with the role
        return LineRefuses(f"role {make_url(self.url).username}: {error_line(exc)}")

    def reachable(self) -> None:
        """``LineDown`` when the line database does not answer now (a command says so,
        also when it has nothing to send)."""
        try:
            with self._connect().connect() as conn:
                conn.exec_driver_sql("SELECT 1")
        except (SQLAlchemyError, OSError) as exc:
            self.dispose()
            raise LineDown(error_line(exc)) from None

    def dispose(self) -> None:
        if self._engine is not None:
            self._engine.dispose()
            self._engine = None


def _sqlstate(exc: DBAPIError) -> str:
    return str(getattr(getattr(exc, "orig", None), "sqlstate", None) or "")


def _transient(exc: DBAPIError) -> bool:
    """A connection or server problem (try again), not a row the database refuses."""
    code = _sqlstate(exc)
    # classes 08 (connection), 40 (transaction rollback: a deadlock, a serialization
    # failure, which a retry resolves), 53 (resources), 57 (operator intervention), 58
    # (system); and the line's own schema not (yet) there or older than this forwarder:
    # 42P01 undefined table, 42703 undefined column, 42883 undefined function (a trigger's),
    # the same for every record until ``stationd line init`` has run
    return code[:2] in ("08", "40", "53", "57", "58") or code == "" \
        or code in ("42P01", "42703", "42883")


#: refusals of the role, not of a record: class 28 (invalid authorization), 42501
#: (insufficient_privilege), 25006 (read_only_sql_transaction: a standby, a read-only default)
ROLE_REFUSED = ("28", "42501", "25006")


def _refuses_role(exc: DBAPIError) -> bool:
    """The server refuses this role's writes (its privileges, or no writes at all)."""
    code = _sqlstate(exc)
    return code[:2] == ROLE_REFUSED[0] or code in ROLE_REFUSED[1:]


def refused_for_good(exc: DBAPIError) -> bool:
    """Whether the line database refused a push for the records' own content (quarantine
    them), not for its own state (keep them in the backlog and try again: the line database
    down).  The one place the forwarder decides "for good".

    Why a refusal of the role is the state: it is the same for every record, so as "for
    good" it quarantined each in turn (a role without INSERT on line_feed emptied the
    backlog into the quarantine, and the demo then removed its station database with them);
    a grant, or the server taking writes again, lets every waiting record through."""
    return not (exc.connection_invalidated or _transient(exc) or _refuses_role(exc))


def error_line(exc: BaseException) -> str:
    """The first line of a database error in the server's or driver's words (the error
    SQLAlchemy wraps), or the error's type."""
    orig = getattr(exc, "orig", None)
    text = str(orig if orig is not None else exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _same_records(conn: Connection, station_id: str, db_id: str,
                  rows: list[dict[str, Any]]) -> None:
    """The rows the line had already are the same records (a replay after a crash between
    the push and the cursor saved: same kind, same time), else :class:`SeriesDiverged` at
    the first that is not (the transaction then rolls back)."""
    f = LINE_FEED.c
    there = {seq: (kind, at) for seq, kind, at in conn.execute(
        select(f.seq, f.kind, f.at).where(f.station_id == station_id, f.db_id == db_id,
                                           f.seq.in_([r["seq"] for r in rows])))}
    for r in sorted(rows, key=lambda r: r["seq"]):
        seen = there.get(r["seq"])
        if seen is not None and seen != (r["kind"], r["at"]):
            raise SeriesDiverged(r["seq"])


class Forwarder:
    """Forwards the local feed to the line database, in order, from where it stopped."""

    def __init__(self, repo: Repository, cfg: LineConfig, line: LineDb | None = None,
                 clock: Callable[[], float] = time.time,
                 ticks: Callable[[], float] = time.monotonic) -> None:
        self.repo, self.cfg = repo, cfg
        self.line = line or LineDb(cfg.url)
        self._clock = clock      # the records' time (their lag)
        self._ticks = ticks      # intervals (a clock stepped back stops no heartbeat)
        self.cursor = int(repo.ledger.get_meta(CURSOR_KEY) or 0)
        self.series = repo.ledger.series()
        self.up: bool | None = None        # None: not tried yet
        self.last_error: str | None = None
        self.forwarded = 0                 # entries the line database took (this process)
        self.tries = 0                     # pushes to the line database finished, taken or not
        self.last_status: dict[str, Any] | None = None   # the latest, for the status API
        self.size = BacklogBytes(self.cursor)
        self._heard = -math.inf            # when the line database last answered (ticks)

    def step(self) -> int:
        """Forward up to one batch; how many entries were handled.  ``LineDown`` when the
        line database is away (nothing is lost: the cursor did not move)."""
        entries = self.repo.ledger.since(self.cursor, BATCH)
        if not entries:
            # not known to answer, or not heard from for HEARTBEAT_S: asked (a station
            # with nothing to send said the line database "up" for as long as it was
            # stopped, until its next record)
            if self.up is not True or self._ticks() - self._heard >= HEARTBEAT_S:
                self._probe()
            return 0
        try:
            try:
                self._push_each(entries)
            except SeriesDiverged as diverged:
                # the ones before it are this series' (the same records, or new): theirs;
                # from it on, a new series the line has nothing of
                self._push_each([e for e in entries if e["seq"] < diverged.seq])
                self._renew(diverged.seq)
                self._push_each([e for e in entries if e["seq"] >= diverged.seq])
        except LineDown as exc:   # also midway through the batch: the cursor did not move
            self.up, self.last_error = False, str(exc)
            self.tries += 1
            raise
        self.cursor = int(entries[-1]["seq"])
        self.repo.ledger.set_meta(CURSOR_KEY, str(self.cursor))
        self.size.forwarded(entries, self.cursor)
        self.up, self.last_error, self._heard = True, None, self._ticks()
        self.tries += 1
        return len(entries)

    def _push(self, entries: list[dict[str, Any]]) -> int:
        """``entries`` to the line, each under its series' id (:class:`db.ledger.Series`);
        how many were new."""
        by_id: dict[str, list[dict[str, Any]]] = {}
        for e in entries:
            by_id.setdefault(self.series.id_of(e["seq"]), []).append(e)
        return sum(self.line.push(self.cfg.station_id, db_id, group)
                   for db_id, group in by_id.items())

    def _push_each(self, entries: list[dict[str, Any]]) -> None:
        """``entries`` pushed in one transaction; one refused for good: each alone, the
        refused kept in quarantine, the rest moving."""
        try:
            self.forwarded += self._push(entries)
        except DBAPIError:   # one is refused for good: find it, keep the rest moving
            for e in entries:
                try:
                    self.forwarded += self._push([e])
                except DBAPIError as exc:
                    self.repo.ledger.quarantine(e["seq"], error_line(exc))
                    log.error("line database refused record %d (%s) for good: %s; kept "
                              "in quarantine", e["seq"], e["kind"], error_line(exc))

    def _renew(self, seq: int) -> None:
        """The line has other records under this database's id from ``seq`` on: the
        database was put back from a copy (a backup), which numbered its new records again.
        Its records from ``seq`` go as a new series (a new id): the line keeps the ones
        it has (the records the copy lacked), and takes these beside them, none lost."""
        old = self.series.db_id
        self.series = self.repo.ledger.renew_db_id(seq)
        log.warning("line database: record %d of this station's database is another record "
                    "there (database %s): the database was put back from a copy (a backup) "
                    "and numbered its records again; from record %d on they go as a new "
                    "series (database %s), beside the ones the line keeps", seq, old, seq,
                    self.series.db_id)

    def _probe(self) -> None:
        """Nothing to send, and the line database not known to answer: whether it does
        (``LineDown`` when not).  Why: a station with nothing in its backlog (a fresh
        database, the demo's) tried the line database only with its first record, so an
        unreachable one was said minutes in, or, in the demo, only at its end; now its state
        is known (the journal, STATUS=, ``/api/status``) from the start, and its return while
        nothing waits, under the same backoff."""
        try:
            self.line.reachable()
        except LineDown as exc:
            self.up, self.last_error = False, str(exc)
            raise
        self.up, self.last_error, self._heard = True, None, self._ticks()

    def retry_quarantined(self) -> tuple[int, int]:
        """Push the quarantined entries again: (taken, still refused)."""
        taken = refused = 0
        for e in self.repo.ledger.quarantined():
            try:
                self.forwarded += self._push([e])
            except (DBAPIError, SeriesDiverged) as exc:
                # (diverged: the line has another record at its number under its id, which
                # a renewal from there would take from the records forwarded since)
                refused += 1
                self.repo.ledger.quarantine(e["seq"], error_line(exc))
                continue
            self.repo.ledger.release(e["seq"])
            taken += 1
        return taken, refused

    def status(self, measure_s: float | None = None) -> dict[str, Any]:
        """Backlog (records and bytes), lag and the last error (``/api/status``, systemd's
        STATUS=, screens).  ``measure_s``: the most time spent sizing backlog entries not
        measured yet (None: all of them; ``backlog_bytes_partial`` says when it stopped
        short, the bytes then a lower bound)."""
        last = self.repo.ledger.last_seq()
        oldest = self.repo.ledger.since(self.cursor, 1)
        lag = self._clock() - datetime.fromisoformat(oldest[0]["at"]).replace(
            tzinfo=UTC).timestamp() if oldest else 0.0
        backlog = max(0, last - self.cursor)
        whole = self.size.measure(self.repo.ledger.since, last, measure_s)
        size = self.size.total if backlog else 0
        alarm = None
        if backlog > self.cfg.max_records:
            alarm = f"{backlog} records not forwarded (bound {self.cfg.max_records})"
        elif size > self.cfg.max_mb * 1e6:
            alarm = f"{size / 1e6:.1f} MB of records not forwarded (bound " \
                    f"{self.cfg.max_mb:g} MB)"
        elif lag > self.cfg.max_age_h * 3600:
            alarm = f"records not forwarded for {lag / 3600:.1f} h (bound " \
                    f"{self.cfg.max_age_h:g} h)"
        return {"url": make_url(self.cfg.url).render_as_string(), "station_id":
                self.cfg.station_id, "db_id": self.series.db_id, "up": self.up,
                "cursor": self.cursor,
                "last_seq": last, "backlog": backlog, "backlog_bytes": size,
                "backlog_bytes_partial": not whole, "lag_s": round(lag, 1),
                "last_error": self.last_error, "alarm": alarm,
                "quarantined": len(self.repo.ledger.quarantined())}

    async def run(self, stop: asyncio.Event, on_change: Callable[[dict[str, Any]], None],
                  wake: asyncio.Event | None = None) -> None:
        """Forward until ``stop``: at once while behind, every ``POLL_S`` when caught up (at
        once when ``wake`` is set: the station recorded something; a poll alone would leave
        a record up to ``POLL_S`` behind), with backoff while the line database is down (a
        record does not cut a backoff short); ``on_change`` hears each change of up/down,
        alarm or, while down, of why (the journal, STATUS=, the line asset's ErrorMessage in
        OPC UA: a line database that answers again but refuses this role must not keep
        saying "connection refused")."""
        loop = asyncio.get_running_loop()
        rng = random.Random(self.cfg.station_id)  # noqa: S311 - jitter
        wait = BACKOFF_S[0]
        told: tuple[Any, ...] = (None, None, None)
        told_at = loop.time()
        waited = None    # since the line database was last down: the most records waiting
        while not stop.is_set():
            if wake is not None:
                wake.clear()     # what is recorded from here on is read by this step or wakes
            try:
                n = await loop.run_in_executor(None, self.step)
                wait, pause = BACKOFF_S[0], (0.0 if n >= BATCH else POLL_S)
            except LineDown:
                pause = wait * (0.8 + 0.4 * rng.random())
                wait = min(wait * 2, BACKOFF_S[1])
            except (SQLAlchemyError, DbError) as exc:   # the local database: its keeper's
                self.last_error = f"local database: {error_line(exc)}"
                pause = POLL_S
            # while draining, entries are forwarded, not sized ahead of the forwarding
            measure = 0.0 if pause == 0.0 else MEASURE_S
            woken = wake if self.up and pause == POLL_S else None
            # the status (backlog, lag, alarm) stays fresh while a long backoff waits
            end = loop.time() + pause
            while True:
                st = await loop.run_in_executor(None, self.status, measure)
                self.last_status = st
                now = (st["up"], st["alarm"], st["last_error"] if st["up"] is False else None)
                if st["up"] is False:
                    waited = max(waited or 0, int(st["backlog"] or 0))
                caught_up = waited is not None and st["up"] is True and not st["backlog"]
                if caught_up:   # after an outage, every record through: said, with how many
                    st = {**st, "caught_up": waited}
                    waited = None
                if now != told or caught_up or (st["up"] is False
                                                and loop.time() - told_at >= DOWN_SAID_S):
                    told, told_at = now, loop.time()
                    on_change(st)
                left = end - loop.time()
                if left <= 0 or stop.is_set() or (woken is not None and woken.is_set()):
                    break
                await _first(stop, woken, min(left, STATUS_S))


async def _first(stop: asyncio.Event, wake: asyncio.Event | None, timeout: float) -> None:
    """Until ``stop`` or ``wake`` (when given) is set, or ``timeout`` s."""
    waits = [asyncio.ensure_future(stop.wait())]
    if wake is not None:
        waits.append(asyncio.ensure_future(wake.wait()))
    try:
        await asyncio.wait(waits, timeout=timeout, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for w in waits:
            w.cancel()


__all__ = ["CURSOR_KEY", "LINE_FEED", "BacklogBytes", "Forwarder", "LineConfig", "LineDb",
           "LineDown", "LineRefuses", "error_line", "line_url_problem", "not_postgresql",
           "payload_bytes", "refused_for_good"]
