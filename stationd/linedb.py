"""The line database's tables, and the line's results read back from them.

Why one module for both: the forwarder (:mod:`stationd.forward`) writes these tables and the
line's views (``stationd line results``, a line page) read them; the shape is declared once.

Tables (PostgreSQL, made if missing):

- ``line_feed``: every record of every station, keyed by (station id, the local database's
  id, sequence number), the record as JSONB; a rundown's ``operator`` (the user signed in at
  the station, NULL: nobody, or a record from before) also as a column, for the line's
  queries per operator (added to a line database made before it);
- ``line_parameters``: the bolt tables each station tightened with, one row per parameter
  version a forwarded rundown carried, keyed by (station id, local database id, model, bolt,
  version).  Why keyed by station: each station imports its own bolt file (a model's table
  may be shared by several stations, or each has its own), and B07 at ST-03 is not B07 at
  ST-11 unless their values say so; the version restarts with a new local database, hence
  its id in the key.  A table shared per model shows as the same values under each station
  (:func:`bolt_versions` lists them side by side).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Column,
    DateTime,
    Engine,
    Float,
    Index,
    Integer,
    MetaData,
    String,
    Table,
    func,
    select,
    text,
)
from sqlalchemy.dialects.postgresql import JSONB

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
    Column("operator", String(64)),      # a rundown's operator (NULL: nobody, or older)
)
#: the columns added to ``line_feed`` after its first version: added where missing
LINE_FEED_ADDED = ("ALTER TABLE line_feed ADD COLUMN IF NOT EXISTS operator VARCHAR(64)",)
#: a vehicle's rundowns at every station: quality's first question
LINE_FEED_VIN = Index("ix_line_feed_vin", LINE_FEED.c.record["vin"].as_string())

LINE_PARAMETERS = Table(
    "line_parameters", LINE,
    Column("station_id", String(64), primary_key=True),
    Column("db_id", String(36), primary_key=True),
    Column("model", String(32), primary_key=True),
    Column("bolt", String(32), primary_key=True),
    Column("version", Integer, primary_key=True),
    Column("pset", Integer),
    Column("torque_target", Float), Column("torque_min", Float), Column("torque_max", Float),
    Column("angle_target", Float), Column("angle_min", Float), Column("angle_max", Float),
    Column("first_seq", BigInteger, nullable=False),   # the first rundown that carried it
    Column("received_at", DateTime(timezone=True), nullable=False, server_default=func.now()),
)


#: the advisory lock that serialises the making of the line's tables (any fixed 64-bit number)
SCHEMA_LOCK_KEY = 0x5354_4C49_4E45


def create_line_schema(engine: Engine) -> None:
    """The line's tables and index, made where missing (a line database made by an earlier
    version gets the new ones too)."""
    with engine.begin() as conn:   # one creator at a time: two first starts (or a reader)
        # racing on "create if missing" made one fail with "relation already exists"
        conn.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": SCHEMA_LOCK_KEY})
        LINE.create_all(conn, checkfirst=True)
        for added in LINE_FEED_ADDED:   # a table made by an earlier version: its new columns
            conn.execute(text(added))
        LINE_FEED_VIN.create(conn, checkfirst=True)


def operator_of(entry: dict[str, Any]) -> str | None:
    """The ``operator`` column of a feed entry: a rundown's operator, else None."""
    if entry["kind"] != "rundown":
        return None
    op = entry["record"].get("operator")
    return None if op is None else str(op)[:64]


def parameter_rows(station_id: str, db_id: str, entries: list[dict[str, Any]]
                   ) -> list[dict[str, Any]]:
    """The ``line_parameters`` rows the rundowns among ``entries`` carry (one per version;
    records written before rundowns carried their version have none)."""
    rows: dict[tuple[str, str, int], dict[str, Any]] = {}
    for e in entries:
        rec = e["record"]
        p = rec.get("parameters") if e["kind"] == "rundown" else None
        if not p or rec.get("model") is None:
            continue
        key = (str(rec["model"]), str(rec["bolt"]), int(p["version"]))
        if key in rows:
            continue
        torque, angle = p.get("torque") or {}, p.get("angle") or {}
        rows[key] = {"station_id": station_id, "db_id": db_id, "model": key[0],
                     "bolt": key[1], "version": key[2], "pset": p.get("pset"),
                     "torque_target": torque.get("target"), "torque_min": torque.get("min"),
                     "torque_max": torque.get("max"), "angle_target": angle.get("target"),
                     "angle_min": angle.get("min"), "angle_max": angle.get("max"),
                     "first_seq": int(e["seq"])}
    return list(rows.values())


@dataclass(frozen=True)
class LineResult:
    """One rundown as the line database holds it."""

    station_id: str
    db_id: str
    seq: int
    at: datetime             # recorded at the station (the feed entry's time)
    vin: str
    model: str | None
    bolt: str
    ok: bool
    kind: str                # tightening or loosening
    torque_nm: float | None
    angle_deg: float | None
    version: int | None      # the parameter version it was tightened with (None: older)
    received_at: datetime    # when the line database took it
    operator: str | None = None   # the user signed in at the station (None: nobody, older)


def _opt(v: Any) -> float | None:
    return None if v is None else float(v)


def results(engine: Engine, *, vin: str | None = None, station: str | None = None,
            limit: int = 1000) -> list[LineResult]:
    """The line's rundowns, newest first (of ``vin`` / of ``station``; at most ``limit``)."""
    f = LINE_FEED.c
    q = select(f.station_id, f.db_id, f.seq, f.at, f.record, f.received_at,
               f.operator).where(
        f.kind == "rundown")
    if vin is not None:
        q = q.where(f.record["vin"].as_string() == vin)
    if station is not None:
        q = q.where(f.station_id == station)
    q = q.order_by(f.at.desc(), f.station_id, f.seq.desc()).limit(max(1, int(limit)))
    out = []
    with engine.connect() as c:
        for r in c.execute(q):
            rec = r.record
            version = (rec.get("parameters") or {}).get("version")
            out.append(LineResult(
                r.station_id, r.db_id, int(r.seq), r.at.astimezone(UTC), str(rec.get("vin")),
                rec.get("model"), str(rec.get("bolt")), rec.get("status") == "ok",
                str(rec.get("rundown") or "tightening"), _opt(rec.get("torque_nm")),
                _opt(rec.get("angle_deg")), None if version is None else int(version),
                r.received_at.astimezone(UTC), r.operator))
    return out


@dataclass(frozen=True)
class BoltVersion:
    """A parameter version a station tightened a bolt with."""

    station_id: str
    db_id: str
    model: str
    bolt: str
    version: int
    pset: int | None
    torque: tuple[float | None, float | None, float | None]   # target, min, max
    angle: tuple[float | None, float | None, float | None]


def bolt_versions(engine: Engine, *, model: str | None = None, bolt: str | None = None,
                  station: str | None = None) -> list[BoltVersion]:
    """The bolt tables the stations used, by model, bolt, station and version."""
    p = LINE_PARAMETERS.c
    q = select(LINE_PARAMETERS)
    for col, want in ((p.model, model), (p.bolt, bolt), (p.station_id, station)):
        if want is not None:
            q = q.where(col == want)
    q = q.order_by(p.model, p.bolt, p.station_id, p.db_id, p.version)
    with engine.connect() as c:
        return [BoltVersion(r.station_id, r.db_id, r.model, r.bolt, int(r.version), r.pset,
                            (r.torque_target, r.torque_min, r.torque_max),
                            (r.angle_target, r.angle_min, r.angle_max))
                for r in c.execute(q)]


__all__ = ["LINE", "LINE_FEED", "LINE_PARAMETERS", "BoltVersion", "LineResult",
           "bolt_versions", "create_line_schema", "operator_of", "parameter_rows", "results"]
