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
bounds it is an alarm, never a fault.  An entry the line database refuses for good (a value it
will never take) is quarantined locally with its reason, so it never blocks the rest.

The ``line:`` section of the station file (optional: without it nothing is forwarded)::

    line:
      url: postgresql+psycopg://stationd@line-db.plant/line   # a password: PGPASSFILE
      station_id: ST-07
      backlog: {records: 100000, age_h: 72}                   # an alarm past either
"""

from __future__ import annotations

import asyncio
import logging
import random
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Column,
    DateTime,
    Engine,
    MetaData,
    String,
    Table,
    func,
    make_url,
)
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.dialects.postgresql import insert as pg_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.exc import DBAPIError, SQLAlchemyError

from db.engine import make_engine
from db.errors import DbError
from db.repository import Repository
from stationd.yamlio import YamlNode

log = logging.getLogger("stationd")
BATCH = 200                  # entries per transaction
POLL_S = 1.0                 # how often the feed is read when nothing is behind
BACKOFF_S = (1.0, 60.0)      # a line database that is down: first and longest wait
STATUS_S = 5.0               # the status is refreshed at least this often meanwhile
CURSOR_KEY = "forwarded_seq"

LINE = MetaData()
LINE_FEED = Table(
    "line_feed", LINE,
    Column("station_id", String(64), primary_key=True),
    Column("db_id", String(36), primary_key=True),
    Column("seq", BigInteger, primary_key=True),
    Column("kind", String(16), nullable=False),
    Column("at", DateTime(timezone=True), nullable=False),
    Column("record", JSON().with_variant(JSONB(), "postgresql"), nullable=False),
    Column("received_at", DateTime(timezone=True), nullable=False, server_default=func.now()),
)


@dataclass(frozen=True)
class LineConfig:
    url: str
    station_id: str
    max_records: int = 100_000
    max_age_h: float = 72.0

    @classmethod
    def from_node(cls, node: YamlNode) -> LineConfig:
        m = node.mapping(("url", "station_id", "backlog"), required=("url", "station_id"))
        url = m["url"].text()
        try:
            parsed = make_url(url)
            backend, port = parsed.get_backend_name(), parsed.port
        except Exception:
            raise m["url"].error(f"not a database URL: {url!r} (e.g. "
                                 "postgresql+psycopg://stationd@line-db/line)") from None
        if port is not None and not 1 <= port <= 65535:
            raise m["url"].error(f"port {port} is not 1-65535")
        if backend not in ("postgresql", "sqlite"):
            raise m["url"].error(f"a PostgreSQL URL (postgresql+psycopg://...), not {backend}")
        sid = m["station_id"].text()
        if not 1 <= len(sid) <= 64 or not sid.isprintable():
            raise m["station_id"].error("1-64 printable characters")
        records, age = cls.max_records, cls.max_age_h
        if "backlog" in m:
            b = m["backlog"].mapping(("records", "age_h"))
            records = b["records"].integer(lo=1, hi=10**9) if "records" in b else records
            age = b["age_h"].number(lo=0.01, hi=24 * 365) if "age_h" in b else age
        return cls(url, sid, records, age)


class LineDown(Exception):  # noqa: N818 - a state, not a programming error
    """The line database cannot be reached or refuses writes for now: try again later."""


class LineDb:
    """The line database: its table made if missing, entries inserted idempotently."""

    def __init__(self, url: str) -> None:
        self.url = url
        self._engine: Engine | None = None

    def _connect(self) -> Engine:
        if self._engine is None:
            engine = make_engine(self.url)
            LINE.create_all(engine, checkfirst=True)
            self._engine = engine
        return self._engine

    def push(self, station_id: str, db_id: str, entries: list[dict[str, Any]]) -> int:
        """Insert ``entries`` in one transaction (those already there are left alone);
        how many were new.  ``DBAPIError`` for a refused row, ``LineDown`` for the rest."""
        try:
            engine = self._connect()
            insert = pg_insert if engine.dialect.name == "postgresql" else sqlite_insert
            rows = [{"station_id": station_id, "db_id": db_id, "seq": e["seq"],
                     "kind": e["kind"], "at": datetime.fromisoformat(e["at"]).replace(
                         tzinfo=UTC), "record": e["record"]} for e in entries]
            stmt = insert(LINE_FEED).on_conflict_do_nothing().returning(LINE_FEED.c.seq)
            with engine.begin() as conn:
                return len(conn.execute(stmt, rows).all())   # the rows that were new
        except DBAPIError as exc:
            if exc.connection_invalidated or _transient(exc):
                self.dispose()
                raise LineDown(_reason(exc)) from None
            raise
        except (SQLAlchemyError, DbError, OSError) as exc:
            self.dispose()
            raise LineDown(_reason(exc)) from None

    def dispose(self) -> None:
        if self._engine is not None:
            self._engine.dispose()
            self._engine = None


def _transient(exc: DBAPIError) -> bool:
    """A connection or server problem (try again), not a row the database refuses."""
    code = getattr(getattr(exc, "orig", None), "sqlstate", None) or ""
    # classes 08 (connection), 53 (resources), 57 (operator intervention), 58 (system)
    return code[:2] in ("08", "53", "57", "58") or code == ""


def _reason(exc: BaseException) -> str:
    orig = getattr(exc, "orig", None)
    text = str(orig if orig is not None else exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


class Forwarder:
    """Forwards the local feed to the line database, in order, from where it stopped."""

    def __init__(self, repo: Repository, cfg: LineConfig, line: LineDb | None = None,
                 clock: Callable[[], float] = time.time) -> None:
        self.repo, self.cfg = repo, cfg
        self.line = line or LineDb(cfg.url)
        self._clock = clock
        self.cursor = int(repo.ledger.get_meta(CURSOR_KEY) or 0)
        self.db_id = repo.ledger.db_id()
        self.up: bool | None = None        # None: not tried yet
        self.last_error: str | None = None
        self.forwarded = 0                 # entries the line database took (this process)
        self.last_status: dict[str, Any] | None = None   # the latest, for the status API

    def step(self) -> int:
        """Forward up to one batch; how many entries were handled.  ``LineDown`` when the
        line database is away (nothing is lost: the cursor did not move)."""
        entries = self.repo.ledger.since(self.cursor, BATCH)
        if not entries:
            return 0
        try:
            self.forwarded += self.line.push(self.cfg.station_id, self.db_id, entries)
        except LineDown as exc:
            self.up, self.last_error = False, str(exc)
            raise
        except DBAPIError:   # one of them is refused for good: find it, keep the rest moving
            for e in entries:
                try:
                    self.forwarded += self.line.push(self.cfg.station_id, self.db_id, [e])
                except DBAPIError as exc:
                    self.repo.ledger.quarantine(e["seq"], _reason(exc))
                    log.error("line database refused record %d (%s) for good: %s; kept "
                              "in quarantine", e["seq"], e["kind"], _reason(exc))
        self.cursor = int(entries[-1]["seq"])
        self.repo.ledger.set_meta(CURSOR_KEY, str(self.cursor))
        self.up, self.last_error = True, None
        return len(entries)

    def retry_quarantined(self) -> tuple[int, int]:
        """Push the quarantined entries again: (taken, still refused)."""
        taken = refused = 0
        for e in self.repo.ledger.quarantined():
            try:
                self.forwarded += self.line.push(self.cfg.station_id, self.db_id, [e])
            except DBAPIError as exc:
                refused += 1
                self.repo.ledger.quarantine(e["seq"], _reason(exc))
                continue
            self.repo.ledger.release(e["seq"])
            taken += 1
        return taken, refused

    def status(self) -> dict[str, Any]:
        """Backlog, lag and the last error (``/api/status``, systemd's STATUS=, screens)."""
        last = self.repo.ledger.last_seq()
        oldest = self.repo.ledger.since(self.cursor, 1)
        lag = self._clock() - datetime.fromisoformat(oldest[0]["at"]).replace(
            tzinfo=UTC).timestamp() if oldest else 0.0
        backlog = max(0, last - self.cursor)
        alarm = None
        if backlog > self.cfg.max_records:
            alarm = f"{backlog} records not forwarded (bound {self.cfg.max_records})"
        elif lag > self.cfg.max_age_h * 3600:
            alarm = f"records not forwarded for {lag / 3600:.1f} h (bound " \
                    f"{self.cfg.max_age_h:g} h)"
        return {"url": make_url(self.cfg.url).render_as_string(), "station_id":
                self.cfg.station_id, "db_id": self.db_id, "up": self.up, "cursor": self.cursor,
                "last_seq": last, "backlog": backlog, "lag_s": round(lag, 1),
                "last_error": self.last_error, "alarm": alarm,
                "quarantined": len(self.repo.ledger.quarantined())}

    async def run(self, stop: asyncio.Event, on_change: Callable[[dict[str, Any]], None]
                  ) -> None:
        """Forward until ``stop``: at once while behind, every ``POLL_S`` when caught up,
        with backoff while the line database is down; ``on_change`` hears each change of
        up/down or alarm (the journal, STATUS=)."""
        loop = asyncio.get_running_loop()
        rng = random.Random(self.cfg.station_id)  # noqa: S311 - jitter
        wait, told = BACKOFF_S[0], (None, None)
        while not stop.is_set():
            try:
                n = await loop.run_in_executor(None, self.step)
                wait, pause = BACKOFF_S[0], (0.0 if n >= BATCH else POLL_S)
            except LineDown:
                pause = wait * (0.8 + 0.4 * rng.random())
                wait = min(wait * 2, BACKOFF_S[1])
            except (SQLAlchemyError, DbError) as exc:   # the local database: its keeper's
                self.last_error = f"local database: {_reason(exc)}"
                pause = POLL_S
            # the status (backlog, lag, alarm) stays fresh while a long backoff waits
            end = loop.time() + pause
            while True:
                st = await loop.run_in_executor(None, self.status)
                self.last_status = st
                if (st["up"], st["alarm"]) != told:
                    told = (st["up"], st["alarm"])
                    on_change(st)
                left = end - loop.time()
                if left <= 0 or stop.is_set():
                    break
                try:
                    await asyncio.wait_for(stop.wait(), min(left, STATUS_S))
                except TimeoutError:
                    pass


__all__ = ["LINE_FEED", "Forwarder", "LineConfig", "LineDb", "LineDown"]
