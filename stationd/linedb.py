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
  (:func:`bolt_versions` lists them side by side);
- the typed tables, one per kind of record a quality engineer queries (``line_rundowns``,
  ``line_commands``, ``line_gaps``, ``line_calibration_checks``, ``line_unattributed``,
  ``line_controller_events``, ``line_unreadable_results``):
  real columns with their types, units and comments, indexed for the first questions (a VIN
  across stations, a bolt over a shift, the NOK rate per station and hour), what Grafana,
  Power BI or a person's SQL expect instead of ``record->>'torque_nm'``.

Why the typed tables are filled by a trigger on ``line_feed`` and not by the forwarder: the
row and its typed row are committed in the same transaction whoever inserted the row, so a
line whose stations are upgraded one at a time (an older forwarder inserts into ``line_feed``
only) still has every record typed; the trigger is ``SECURITY DEFINER`` so a forwarding role
granted only ``INSERT`` on ``line_feed`` needs no grant on the typed tables (without it, each
of its records would be refused and quarantined); and one SQL mapping per kind (:data:`TYPED`)
fills both the trigger's rows and the backfill of a line database made before a typed table
existed (``line init`` or a forwarder's first connection: what is missing is made and filled
from ``line_feed``).  It is a statement trigger over the inserted rows (a batch of 200 is one
``INSERT ... SELECT`` per kind), and ``ON CONFLICT DO NOTHING`` on ``line_feed`` inserts no
row twice, so a replay types nothing twice either.  Tables, not views over the JSONB: their
columns have real types and planner statistics, and the hourly NOK rate reads narrow rows, not
every record's JSON (curves with their samples share ``line_feed``).

A column a typed table gained in a later version (:attr:`Typed.added`, e.g. an entered
outcome's ``entered_by`` in ``line_rundowns``) is added to a table an earlier version made,
with its comment, and the rows already typed get its value from ``line_feed`` in the same
transaction that brings the trigger up to date (:data:`TYPED_VERSION`).
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    Column,
    Connection,
    DateTime,
    Engine,
    Float,
    Index,
    Integer,
    MetaData,
    String,
    Table,
    Text,
    func,
    inspect,
    select,
    text,
)
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.exc import DBAPIError
from sqlalchemy.schema import SetColumnComment, SetTableComment

from db.kinds import LOOSENING, NOK, OK, TIGHTENING, verdict
from db.ledger import (
    CHECK,
    CLOSING,
    COMMAND,
    CONTROLLER_EVENT,
    GAP,
    RUNDOWN,
    UNATTRIBUTED,
    UNREADABLE,
)

log = logging.getLogger("stationd")
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
#: the columns added to ``line_feed`` after its first version: added where missing (only
#: there: ``ADD COLUMN IF NOT EXISTS`` too wants the table's owner, and a forwarding role is not)
LINE_FEED_ADDED = {"operator": "ALTER TABLE line_feed ADD COLUMN operator VARCHAR(64)"}
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

# -- the typed tables ------------------------------------------------------------------------
# Each column comes with the SQL that computes it from a line_feed row ``f`` (its columns and
# its JSONB ``f.record``).  Every expression yields NULL for a value of another JSON type
# than its column's, never an error: a typed row must never make the line refuse a record
# that line_feed alone would take (it would be quarantined at the station).

TORQUE_UNIT, ANGLE_UNIT = "Nm", "deg"   # the records' torque_nm and angle_deg


def _j(*path: str | int) -> str:
    """The JSONB value at ``path`` in the record (``record->'a'->'b'``, an int an index)."""
    return "f.record" + "".join(f"->{p}" if isinstance(p, int) else f"->'{p}'" for p in path)


def _text(j: str) -> str:
    return f"CASE WHEN jsonb_typeof({j}) = 'string' THEN {j} #>> '{{}}' END"


def _float(j: str) -> str:
    return f"CASE WHEN jsonb_typeof({j}) = 'number' THEN ({j})::double precision END"


def _bool(j: str) -> str:
    return f"CASE WHEN jsonb_typeof({j}) = 'boolean' THEN ({j})::boolean END"


def _int(j: str, bits: int = 32) -> str:
    bound = 2 ** (bits - 1)
    sql_type = "integer" if bits == 32 else "bigint"
    return (f"CASE WHEN jsonb_typeof({j}) = 'number' AND abs(({j})::numeric) < {bound} "
            f"THEN round(({j})::numeric)::{sql_type} END")


def _time(j: str) -> str:
    """An ISO time of the record as a timestamptz: with its offset where it has one, else
    UTC (the station's times are UTC; the session's time zone must not change them)."""
    s = f"({j} #>> '{{}}')"
    return (f"CASE WHEN jsonb_typeof({j}) = 'string' THEN CASE WHEN {s} ~ "
            f"'[T ].*([+-][0-9][0-9](:?[0-9][0-9])?|Z)$' THEN {s}::timestamptz "
            f"ELSE {s}::timestamp AT TIME ZONE 'UTC' END END")


def _literal(value: str) -> str:
    if "'" in value or "\\" in value:
        raise ValueError(f"not a plain SQL literal: {value!r}")
    return f"'{value}'"


def _tz(name: str, comment: str, nullable: bool = True) -> Column[Any]:
    return Column(name, DateTime(timezone=True), nullable=nullable, comment=comment)


def _key() -> list[tuple[Column[Any], str]]:
    """The columns every typed table starts with: line_feed's key, the station's time and
    the record's id in the station's own database."""
    return [
        (Column("station_id", String(64), primary_key=True,
                comment="the station (its line.station_id)"), "f.station_id"),
        (Column("db_id", String(36), primary_key=True,
                comment="the station's local database (a new one restarts seq and ids)"),
         "f.db_id"),
        (Column("seq", BigInteger, primary_key=True,
                comment="the record's number in the station's results feed (line_feed.seq)"),
         "f.seq"),
        (_tz("at", "when the station stored it (its feed entry's time: the record's "
             "recorded_at where it has one)", False), "f.at"),
        (Column("record_id", BigInteger,
                comment="the record's id in the station's own database"), _int(_j("id"), 64)),
    ]


def _received() -> tuple[Column[Any], str]:
    return (_tz("received_at", "when the line database took it", False), "f.received_at")


@dataclass(frozen=True)
class Typed:
    """The typed table of one kind of record: its table and the SQL of each column."""

    kind: str                        # the feed's record kind (db.ledger's constant)
    table: Table
    exprs: tuple[str, ...]           # one per column of ``table``, in order
    #: the columns added after the table's first version (last in ``table``): a table made
    #: by an earlier version gets them added and filled from ``line_feed``
    added: tuple[str, ...] = ()

    def fill_sql(self, source: str) -> str:
        """``INSERT`` into the table the rows of ``source`` (``line_feed`` or the trigger's
        transition table) of this kind; a row already there is left as it is."""
        cols = ", ".join(c.name for c in self.table.columns)
        # the SQL is this module's own (names and constants, _literal-checked), never input
        select = f"SELECT {', '.join(self.exprs)}\n    FROM {source} f"  # noqa: S608
        return (f"INSERT INTO {self.table.name} ({cols})\n    {select}"
                f" WHERE f.kind = {_literal(self.kind)}\n    ON CONFLICT DO NOTHING")


def _typed(kind: str, name: str, comment: str, columns: list[tuple[Column[Any], str]],
           *indexes: Index, added: list[tuple[Column[Any], str]] | None = None) -> Typed:
    """A typed table; ``added``: its columns of later versions, after ``received_at`` as
    ``ALTER TABLE ... ADD COLUMN`` puts them in a table made before them (one column order
    whichever version made the table)."""
    cols = [*_key(), *columns, _received(), *(added or [])]
    table = Table(name, LINE, *(c for c, _ in cols), *indexes, comment=comment)
    return Typed(kind, table, tuple(e for _, e in cols),
                 tuple(c.name for c, _ in added or []))


def _window(what: str, suffix: str, unit: str, key: str) -> list[tuple[Column[Any], str]]:
    """The target, min and max columns of a window: ``suffix`` ends their names (``nm``,
    lower case as SQL names are), ``unit`` is said in their comments (``Nm``: "nm" reads as
    nanometres)."""
    return [(Column(f"{what}_{label}_{suffix}", Float,
                    comment=f"the {what} window's {label} in force ({unit}; NULL: none)"),
             _float(_j("parameters", what, key)))
            for label, key in (("target", "target"), ("min", "min"), ("max", "max"))]


LINE_RUNDOWNS = _typed(
    RUNDOWN, "line_rundowns",
    "Every rundown of every station (a tightening or a loosening), one row per record of "
    "line_feed of kind rundown, with the limits it was tightened to",
    [(Column("vin", Text, comment="the vehicle"), _text(_j("vin"))),
     (Column("model", Text, comment="the vehicle model of the bolt table"),
      _text(_j("model"))),
     (Column("bolt", Text, comment="the bolt's id in the model's bolt table"),
      _text(_j("bolt"))),
     (Column("kind", Text, comment=f"{TIGHTENING} or {LOOSENING} (a loosening never "
             "closes a bolt)"),
      f"COALESCE({_text(_j('rundown'))}, {_literal(TIGHTENING)})"),
     (Column("status", Text, comment=f"the controller's verdict: {OK} or {NOK}"),
      _text(_j("status"))),
     (Column("pset", Integer, comment="the controller's parameter set run: the bolt "
             "table's (a loosening: its loosen pset)"),
      _int(_j("parameters", "pset"))),
     (Column("parameters_version", Integer,
             comment="the station's version of the bolt's parameters (see line_parameters)"),
      _int(_j("parameters", "version"))),
     (Column("torque_nm", Float, comment="the final torque (Nm)"), _float(_j("torque_nm"))),
     *_window("torque", "nm", TORQUE_UNIT, "torque"),
     (Column("torque_unit", Text, comment="the unit of the torque columns"),
      _literal(TORQUE_UNIT)),
     (Column("angle_deg", Float, comment="the final angle (degrees)"),
      _float(_j("angle_deg"))),
     *_window("angle", "deg", "degrees", "angle"),
     (Column("angle_unit", Text, comment="the unit of the angle columns"),
      _literal(ANGLE_UNIT)),
     (Column("operator", Text, comment="the user signed in at the station (NULL: nobody)"),
      _text(_j("operator"))),
     (Column("tightening_id", BigInteger, comment="the controller's id of the tightening"),
      _int(_j("tightening_id"), 64)),
     (Column("x_mm", Float, comment="the localized bolt end, vehicle frame (mm)"),
      _float(_j("position_mm", 0))),
     (Column("y_mm", Float, comment="the localized bolt end, vehicle frame (mm)"),
      _float(_j("position_mm", 1))),
     (Column("z_mm", Float, comment="the localized bolt end, vehicle frame (mm)"),
      _float(_j("position_mm", 2))),
     (Column("match_distance_mm", Float,
             comment="the tool's distance to the bolt it was matched to (mm)"),
      _float(_j("match_distance_mm"))),
     (Column("tilt_deg", Float, comment="the tool's tilt from the bolt's axis (degrees)"),
      _float(_j("tilt_deg"))),
     (_tz("sent_at", "when the parameters were sent to the controller"),
      _time(_j("sent_at"))),
     # the station's clock, not the controller's: the controller's own time of the
     # tightening is kept at the station (tightening_records.controller_at) and not forwarded
     (_tz("result_at", "when the station took the result, on its clock (an outcome entered "
          "from the controller's screen: when it was entered); not the controller's time, "
          "which the line database does not have; a lock it caused is at this time or later"),
      _time(_j("result_at"))),
     (_tz("recorded_at", "when the station stored it"), _time(_j("recorded_at")))],
    # one VIN across stations; one bolt over a shift; one station's rundowns in time; the
    # NOK rate per station and hour over a period (read from the index alone)
    Index("ix_line_rundowns_vin", "vin", "at"),
    Index("ix_line_rundowns_bolt", "bolt", "at"),
    Index("ix_line_rundowns_station", "station_id", "at"),
    Index("ix_line_rundowns_at", "at", postgresql_include=["station_id", "kind", "status"]),
    # an outcome a supervisor entered from the controller's screen (its result could not be
    # read): a rundown all the same, but not measured; who, why, and the result it resolves
    added=[(Column("entered_by", Text, comment="who entered this outcome from the "
                   "controller's screen, not measured by the station (NULL: measured)"),
            _text(_j("entered_by"))),
           (Column("entered_comment", Text, comment="what the person who entered it said "
                   "they checked (NULL: measured)"), _text(_j("entered_comment"))),
           (Column("unreadable_record_id", BigInteger, comment="the unreadable result it "
                   "resolves: line_unreadable_results.record_id of the same station and "
                   "db_id (NULL: none)"), _int(_j("unreadable_id"), 64)),
           # made while the link to the controller was down (an MES integrator's trial: a
           # result fetched late could not be told apart; OPC UA's IsGeneratedOffline)
           (Column("offline", Boolean, comment="made while the link to the controller was "
                   "down: taken by the station after the reconnect, at result_at (NULL: "
                   "stored before the station kept it)"), _bool(_j("offline")))],
)

LINE_COMMANDS = _typed(
    COMMAND, "line_commands",
    "Every command a person gave a station (skip, reopen, release, loosen, sign-in ...), "
    "with who, from where and why",
    [(_tz("command_at", "when it was given (a NOK policy's lock: when the station decided it, "
          "the result_at of the NOK that caused it)"), _time(_j("at"))),
     (Column("user_name", Text, comment="who gave it"), _text(_j("user"))),
     (Column("source", Text, comment="from where (a screen's address, cli, ...)"),
      _text(_j("source"))),
     (Column("kind", Text, comment="the command (skip, reopen, ...)"), _text(_j("kind"))),
     (Column("vin", Text, comment="the vehicle it was given on (NULL: none)"),
      _text(_j("vin"))),
     (Column("bolt", Text, comment="the bolt it was given on (NULL: none)"),
      _text(_j("bolt"))),
     (Column("comment", Text, comment="the person's reason"), _text(_j("comment")))],
    Index("ix_line_commands_vin", "vin", "at"),
    Index("ix_line_commands_at", "at"),
)

LINE_GAPS = _typed(
    GAP, "line_gaps",
    "Results the controller numbered but the station never received (a gap in the "
    "controller's tightening ids)",
    [(Column("first_id", BigInteger, comment="the first tightening id missing"),
      _int(_j("first_id"), 64)),
     (Column("last_id", BigInteger, comment="the last tightening id missing"),
      _int(_j("last_id"), 64)),
     (Column("vin", Text, comment="the vehicle at height when it was found (NULL: none)"),
      _text(_j("vin"))),
     (Column("reason", Text, comment="why it is a gap"), _text(_j("reason"))),
     (_tz("found_at", "when the station found it"), _time(_j("found_at")))],
    Index("ix_line_gaps_at", "at"),
)

LINE_CHECKS = _typed(
    CHECK, "line_calibration_checks",
    "Every calibration check of a camera pair against the reference markers",
    [(_tz("check_at", "when the pair was checked"), _time(_j("at"))),
     (Column("pair", Text, comment="the camera pair"), _text(_j("pair"))),
     (Column("verdict", Text, comment="ok, moved or not checked"), _text(_j("verdict"))),
     (Column("reference", Text, comment="the worst reference marker"),
      _text(_j("reference"))),
     (Column("offset_mm", Float, comment="the worst reference's offset (mm)"),
      _float(_j("offset_mm"))),
     (Column("tolerance_mm", Float, comment="the tolerance it was held to (mm)"),
      _float(_j("tolerance_mm"))),
     (Column("reason", Text, comment="why it was not checked (NULL: it was)"),
      _text(_j("reason"))),
     (Column("measurements", JSONB, comment="each reference's measurement (offset_mm, measured_mm, "
             "why, note)"), _j("references")),
     (_tz("recorded_at", "when the station stored it"), _time(_j("recorded_at")))],
    Index("ix_line_calibration_checks_pair", "pair", "at"),
)

LINE_UNATTRIBUTED = _typed(
    UNATTRIBUTED, "line_unattributed",
    "Results the station could not attribute to a bolt of a vehicle (kept, never a bolt "
    "done)",
    [(Column("vin", Text, comment="the vehicle at height (NULL: none)"), _text(_j("vin"))),
     (Column("controller_vin", Text, comment="the VIN as the result carried it"),
      _text(_j("controller_vin"))),
     (Column("tightening_id", BigInteger, comment="the controller's id of the tightening"),
      _int(_j("tightening_id"), 64)),
     (Column("pset", Integer, comment="the controller's parameter set"), _int(_j("pset"))),
     (Column("status", Text, comment=f"the controller's verdict: {OK} or {NOK}"),
      _text(_j("status"))),
     (Column("torque_nm", Float, comment="the final torque (Nm)"), _float(_j("torque_nm"))),
     (Column("angle_deg", Float, comment="the final angle (degrees)"),
      _float(_j("angle_deg"))),
     (_tz("result_at", "the controller's time of the result, on its clock (NULL: a "
          "controller without a clock, or none given)"), _time(_j("result_at"))),
     (_tz("recorded_at", "when the station stored it"), _time(_j("recorded_at"))),
     (Column("reason", Text, comment="why it was not attributed"), _text(_j("reason")))],
    Index("ix_line_unattributed_vin", "vin", "at"),
    # its type: an unattributed loosening read as a tightening OK (an MES integrator's trial)
    added=[(Column("result_type", Integer, comment="the result type as the controller sent "
                   "it: 1 tightening, 2 loosening, 7 synchronized tightening, ... (NULL: none "
                   "sent, a revision without one, or stored before the type was kept)"),
            _int(_j("result_type")))],
)

LINE_CONTROLLER_EVENTS = _typed(
    CONTROLLER_EVENT, "line_controller_events",
    "Results from the controller that are not rundowns (batch increment or decrement, "
    "bypass of a parameter set, abort job, reference setup, a type not named): never a bolt "
    "done, kept so that quality sees what happened on the controller",
    [(Column("result_type", Integer, comment="the result type code the controller sent "
             "(Open Protocol MID 0061 parameter 49)"), _int(_j("result_type"))),
     (Column("what", Text, comment="its name (batch increment, bypass, ...)"),
      _text(_j("what"))),
     (Column("vin", Text, comment="the vehicle at height (NULL: none)"), _text(_j("vin"))),
     (Column("bolt", Text, comment="the bolt the tool was enabled for (NULL: none)"),
      _text(_j("bolt"))),
     (Column("controller_vin", Text, comment="the VIN as the result carried it"),
      _text(_j("controller_vin"))),
     (Column("tightening_id", BigInteger, comment="the controller's id of the result"),
      _int(_j("tightening_id"), 64)),
     (Column("pset", Integer, comment="the controller's parameter set"), _int(_j("pset"))),
     (Column("status", Text, comment=f"the controller's verdict: {OK} or {NOK}"),
      _text(_j("status"))),
     (Column("torque_nm", Float, comment="the torque it reported (Nm)"),
      _float(_j("torque_nm"))),
     (Column("angle_deg", Float, comment="the angle it reported (degrees)"),
      _float(_j("angle_deg"))),
     (_tz("result_at", "the controller's time of the result, on its clock (NULL: a "
          "controller without a clock, or none given)"), _time(_j("result_at"))),
     (_tz("recorded_at", "when the station stored it"), _time(_j("recorded_at")))],
    Index("ix_line_controller_events_vin", "vin", "at"),
    Index("ix_line_controller_events_at", "at"),
    # a hold's reason: which tightening may be the bolt's own (an MES integrator's trial: the
    # line had "result unknown after a lost push" and no word of which result it was)
    added=[(Column("note", Text, comment="why the bolt is held where no result says it (a "
                   "link cut, a lost push: the tightening that may be its own; NULL: none)"),
            _text(_j("note")))],
)

LINE_UNREADABLE = _typed(
    UNREADABLE, "line_unreadable_results",
    "Result messages the station could not read, kept whole (the text as received, the "
    "revision it said it was, the parse error), with the bolt it may belong to",
    [(Column("mid", Integer, comment="the Open Protocol message id"), _int(_j("mid"))),
     (Column("revision", Integer, comment="the revision the message said it was"),
      _int(_j("revision"))),
     (Column("raw", Text, comment="the message as received"), _text(_j("raw"))),
     (Column("error", Text, comment="why it could not be read"), _text(_j("error"))),
     (Column("vin", Text, comment="the vehicle at height (NULL: none)"), _text(_j("vin"))),
     (Column("bolt", Text, comment="the bolt it may belong to (NULL: none)"),
      _text(_j("bolt"))),
     (Column("controller_vin", Text, comment="the VIN, as far as it could be read"),
      _text(_j("controller_vin"))),
     (Column("tightening_id", BigInteger, comment="the tightening id, as far as it could be "
             "read"), _int(_j("tightening_id"), 64)),
     (Column("pset", Integer, comment="the parameter set, as far as it could be read"),
      _int(_j("pset"))),
     (_tz("result_at", "the controller's time of the result, on its clock, as far as it "
          "could be read (NULL: not read)"),
      _time(_j("result_at"))),
     (_tz("recorded_at", "when the station stored it"), _time(_j("recorded_at")))],
    Index("ix_line_unreadable_results_vin", "vin", "at"),
)

LINE_CLOSINGS = _typed(
    CLOSING, "line_vehicle_closings",
    "Every vehicle leaving a station, with what it left undone there: incomplete vehicles "
    "are the rows with ok below bolts, or held bolts in not_ok",
    [(Column("vin", Text, comment="the vehicle (its VIN)"), _text(_j("vin"))),
     (Column("model", Text, comment="its model in the station's bolt table"),
      _text(_j("model"))),
     (_tz("closed_at", "when it left the station"), _time(_j("closed_at"))),
     (Column("how", Text, comment="lowered (its lift lowered at the station) or unseen (the "
             "station down as it left: found gone at the next vehicle's start)"),
      _text(_j("how"))),
     (Column("bolts", Integer, comment="its bolts at this station"), _int(_j("bolts"))),
     (Column("ok", Integer, comment="bolts whose last rundown is OK"), _int(_j("ok"))),
     (Column("nok", Integer, comment="bolts whose last rundown is NOK"), _int(_j("nok"))),
     (Column("missing", Integer, comment="bolts never run down"), _int(_j("missing"))),
     (Column("skipped", Integer, comment="bolts a person skipped, never run down"),
      _int(_j("skipped"))),
     (Column("loosen", Integer, comment="bolts loosened last or to be loosened: to be "
             "tightened again"), _int(_j("loosen"))),
     (Column("not_ok", JSONB, comment="the bolts not OK by name: {nok, missing, skipped, "
             "loosen, held: [bolt, ...]}, each list in the bolt table's order; held: held for "
             "a person, their last result not known, whatever the counts say"),
      _j("not_ok"))],
    Index("ix_line_vehicle_closings_vin", "vin"),
)

#: every typed table; a new kind of record is one more ``_typed(...)`` here: the next
#: ``line init`` or forwarder start makes its table, fills it from line_feed and types the
#: new rows from then on
TYPED: tuple[Typed, ...] = (LINE_RUNDOWNS, LINE_COMMANDS, LINE_GAPS, LINE_CHECKS,
                            LINE_UNATTRIBUTED, LINE_CONTROLLER_EVENTS, LINE_UNREADABLE,
                            LINE_CLOSINGS)
TRIGGER = "line_feed_typed"   # the trigger and its function
#: the version of the trigger's SQL, one more with each change of :data:`TYPED` (a test holds
#: the SQL to it).  Why a number and not the SQL compared: on a line whose stations are
#: upgraded one at a time, an older forwarder would put its older SQL back at each start; it
#: replaces only an older version.
TYPED_VERSION = 7   # 2: line_controller_events, line_unreadable_results; 3: line_rundowns'
#                       entered outcomes (entered_by, entered_comment, unreadable_record_id);
#                       4: line_unattributed's result_type; 5: line_rundowns' offline;
#                       6: line_controller_events' note; 7: line_vehicle_closings
_VERSION_LINE = re.compile(r"-- stationd typed tables, version (\d+)\n")


def trigger_body(typed: tuple[Typed, ...] = TYPED, version: int = TYPED_VERSION) -> str:
    """The trigger function's body: each typed table filled from the statement's new rows
    (``typed`` and ``version``: those of this version, other ones to make an earlier
    version's line database in a test)."""
    fills = "".join(f"  {t.fill_sql('new_rows')};\n" for t in typed)
    return (f"\n-- stationd typed tables, version {version}\nBEGIN\n{fills}"
            "  RETURN NULL;\nEND\n")


def installed_version(body: str | None) -> int:
    """The version of a trigger body found in the database (0: none, or not ours)."""
    m = None if body is None else _VERSION_LINE.search(body)
    return 0 if m is None else int(m.group(1))


#: the advisory lock that serialises the making of the line's tables (any fixed 64-bit number)
SCHEMA_LOCK_KEY = 0x5354_4C49_4E45


@dataclass(frozen=True)
class SchemaChange:
    """What :func:`create_line_schema` made: tables, and the rows each new typed table took
    from ``line_feed`` (records forwarded before it existed)."""

    made: tuple[str, ...] = ()
    filled: tuple[tuple[str, int], ...] = ()
    #: columns added to a typed table an earlier version made: (table, its new columns, the
    #: rows of line_feed that gave them values)
    added: tuple[tuple[str, tuple[str, ...], int], ...] = ()
    trigger: bool = False            # the trigger (or its function) made or brought up to date
    #: why the typed tables or their trigger could not be made by this role (None: they are
    #: there); line_feed and line_parameters are, and the records go on being forwarded
    typed_refused: str | None = None
    #: the comments (``table`` or ``table.column``) an earlier version wrote otherwise,
    #: brought up to date
    comments: tuple[str, ...] = ()


#: PostgreSQL's insufficient_privilege (no right to create, not the owner)
NOT_ALLOWED = "42501"


def create_line_schema(engine: Engine, *, comments: bool = False) -> SchemaChange:
    """The line's tables, indexes and trigger, made where missing (a line database made by an
    earlier version gets the new ones, its typed tables filled from ``line_feed``).  Nothing
    is written where nothing is missing, so a forwarding role without the right to create
    (the owner ran ``line init``) connects through here.

    Why a role that may make ``line_feed``'s part but not the typed tables still gets its
    schema: a station upgraded before its line database must go on forwarding (its records
    are the line's copy); the typed part is then ``typed_refused`` (a warning), and the
    owner's ``line init`` makes it later and types every record ``line_feed`` holds."""
    with engine.begin() as conn:   # one creator at a time: two first starts (or a reader)
        # racing on "create if missing" made one fail with "relation already exists"
        conn.execute(text("SELECT pg_advisory_xact_lock(:key)"), {"key": SCHEMA_LOCK_KEY})
        before = set(inspect(conn).get_table_names())
        LINE.create_all(conn, tables=[LINE_FEED, LINE_PARAMETERS], checkfirst=True)
        has = {c["name"] for c in inspect(conn).get_columns(LINE_FEED.name)}
        for column, added in LINE_FEED_ADDED.items():   # a table an earlier version made
            if column not in has:
                conn.execute(text(added))
        LINE_FEED_VIN.create(conn, checkfirst=True)
        try:
            with conn.begin_nested():
                change = _typed_schema(conn, before)
        except DBAPIError as exc:
            if getattr(exc.orig, "sqlstate", None) != NOT_ALLOWED:
                raise
            reason = str(exc.orig).strip().splitlines()[0]
            log.warning("line database: the typed tables (line_rundowns ...) cannot be made "
                        "by this role (%s); records are forwarded to line_feed, and the "
                        "tables' owner's `stationd line init URL` makes and fills them",
                        reason)
            change = SchemaChange(typed_refused=reason)
        else:
            # ``comments``: brought up to this version's words, by ``line init`` alone (a
            # forwarder at every start wrote back over a DBA's own words, and an older
            # version's station over a newer one's)
            if comments:
                change = replace(change, comments=_comments_updated(conn))
        after = set(inspect(conn).get_table_names())
        return replace(change, made=tuple(t.name for t in LINE.sorted_tables
                                          if t.name in after - before))


def _typed_schema(conn: Connection, before: set[str]) -> SchemaChange:
    """The typed tables and their trigger, made where missing, each new table filled from
    ``line_feed`` (also every table when the trigger was missing: rows came in untyped)."""
    LINE.create_all(conn, tables=[t.table for t in TYPED], checkfirst=True)
    current = installed_version(conn.execute(text(
        "SELECT prosrc FROM pg_proc WHERE proname = :n AND "
        "pronamespace = current_schema()::regnamespace"), {"n": TRIGGER}).scalar())
    has_trigger = conn.execute(text(
        "SELECT 1 FROM pg_trigger WHERE tgname = :n AND tgrelid = 'line_feed'::regclass"),
        {"n": TRIGGER}).first() is not None
    fill = [t for t in TYPED if not has_trigger or t.table.name not in before]
    missing = _missing_columns(conn, before)
    if current >= TYPED_VERSION and has_trigger and not fill and not missing:
        return SchemaChange()
    # inserts wait from here until this commits: a row committed meanwhile is either filled
    # below or typed by the trigger, never neither
    conn.execute(text("LOCK TABLE line_feed IN SHARE ROW EXCLUSIVE MODE"))
    added = tuple((t.table.name, tuple(c.name for c in cols), _add_columns(conn, t, cols))
                  for t, cols in missing)
    if current < TYPED_VERSION:
        # SECURITY DEFINER: a forwarding role granted INSERT on line_feed alone types its
        # rows too; the search path fixed to where the tables are
        conn.execute(text(
            f"CREATE OR REPLACE FUNCTION {TRIGGER}() RETURNS trigger LANGUAGE plpgsql "
            f"SECURITY DEFINER SET search_path FROM CURRENT AS $typed${trigger_body()}$typed$"))
    if not has_trigger:
        conn.execute(text(
            f"CREATE TRIGGER {TRIGGER} AFTER INSERT ON line_feed REFERENCING NEW TABLE "
            f"AS new_rows FOR EACH STATEMENT EXECUTE FUNCTION {TRIGGER}()"))
    filled = tuple((t.table.name, int(conn.execute(text(t.fill_sql("line_feed"))).rowcount))
                   for t in fill)
    return SchemaChange(filled=filled, trigger=True, added=added)


def _comments_updated(conn: Connection) -> tuple[str, ...]:
    """The typed tables' comments and their columns' made what this version declares where
    an earlier version wrote them otherwise (none written where they agree); the ones
    changed, ``table`` or ``table.column``.

    Why: a comment is what ``\\d+``, Grafana and Power BI show as the column's meaning, and
    a wrong one outlived the version that wrote it (``create_all`` leaves a table that is
    there as it is): ``line_rundowns.result_at`` said the controller's clock where it holds
    the station's, the torque windows "nm".  Only the tables' owner may comment on them: a
    forwarding role that is not leaves them (said in its log), the owner's ``line init``
    writes them."""
    names = [t.table.name for t in TYPED]
    found: dict[tuple[str, str | None], str | None] = {}
    for table, column, comment in conn.execute(text(
            "SELECT c.relname, a.attname, col_description(c.oid, a.attnum) FROM pg_class c "
            "JOIN pg_attribute a ON a.attrelid = c.oid AND a.attnum > 0 AND NOT "
            "a.attisdropped WHERE c.relname = ANY(:names) AND c.relnamespace = "
            "current_schema()::regnamespace "
            "UNION ALL SELECT c.relname, NULL, obj_description(c.oid, 'pg_class') "
            "FROM pg_class c WHERE c.relname = ANY(:names) AND c.relnamespace = "
            "current_schema()::regnamespace"), {"names": names}):
        found[(table, column)] = comment
    stale: list[tuple[str, Any]] = []
    for t in TYPED:
        if (t.table.name, None) in found and found[(t.table.name, None)] != t.table.comment:
            stale.append((t.table.name, SetTableComment(t.table)))
        stale += [(f"{t.table.name}.{c.name}", SetColumnComment(c)) for c in t.table.columns
                  if (t.table.name, c.name) in found
                  and found[(t.table.name, c.name)] != c.comment]
    if not stale:
        return ()
    try:
        with conn.begin_nested():
            for _, ddl in stale:
                conn.execute(ddl)
    except DBAPIError as exc:
        if getattr(exc.orig, "sqlstate", None) != NOT_ALLOWED:
            raise
        log.info("line database: %d comments of the typed tables are an earlier version's "
                 "(%s ...); this role may not write them, the tables' owner's `stationd line "
                 "init URL` does", len(stale), stale[0][0])
        return ()
    return tuple(name for name, _ in stale)


def _missing_columns(conn: Connection, before: set[str]
                     ) -> list[tuple[Typed, list[Column[Any]]]]:
    """The added columns (:attr:`Typed.added`) a typed table made by an earlier version
    lacks."""
    out = []
    for t in TYPED:
        if not t.added or t.table.name not in before:
            continue
        has = {c["name"] for c in inspect(conn).get_columns(t.table.name)}
        cols = [t.table.c[name] for name in t.added if name not in has]
        if cols:
            out.append((t, cols))
    return out


def _add_columns(conn: Connection, t: Typed, cols: list[Column[Any]]) -> int:
    """``cols`` added to ``t``'s table with their comments, and given their values in the
    rows already typed (from ``line_feed``, as the trigger would have); the number of rows
    that had a value for one of them (the others stay NULL: no row is rewritten for
    nothing, on a line database of years)."""
    name = t.table.name
    for c in cols:
        conn.execute(text(f"ALTER TABLE {name} ADD COLUMN {c.name} "
                          f"{c.type.compile(dialect=conn.dialect)}"))
        conn.execute(SetColumnComment(c))
    exprs = dict(zip((c.name for c in t.table.columns), t.exprs, strict=True))
    values = ", ".join(f"{c.name} = {exprs[c.name]}" for c in cols)
    some = " OR ".join(f"({exprs[c.name]}) IS NOT NULL" for c in cols)
    # the SQL is this module's own (names and constants, _literal-checked), never input
    return int(conn.execute(text(
        f"UPDATE {name} t SET {values} FROM line_feed f WHERE f.station_id = t.station_id "  # noqa: S608
        f"AND f.db_id = t.db_id AND f.seq = t.seq AND f.kind = {_literal(t.kind)} "
        f"AND ({some})")).rowcount)


#: what a forwarder does to the line's tables (:meth:`stationd.forward.LineDb.push`): it
#: inserts into both, and reads back which of its ``line_feed`` rows were new (``RETURNING``)
FORWARD_PRIVILEGES: tuple[tuple[str, tuple[str, ...]], ...] = (
    (LINE_FEED.name, ("INSERT", "SELECT")), (LINE_PARAMETERS.name, ("INSERT",)))
#: the grant that lets a forwarding role write them (README's "Setting up the line database")
FORWARD_GRANT = "GRANT SELECT, INSERT ON line_feed, line_parameters TO {role}"


def write_problem(conn: Connection) -> str | None:
    """Why this connection's role cannot forward to the line's tables, in one line: which
    privilege it lacks on which table, and the grant that fixes it (or a server that takes
    no writes); None when it can, or while the tables are not made yet (the forwarder's
    first connection makes them, or says why it cannot).

    Why asked, not found out by the first insert: a role that connects but may not write
    (the tables made by another role, no grant) answered every query, so ``line init`` said
    "ready for the stations' forwarders" and ``line status`` "answers", while each forwarded
    record was refused; asked here, the commands and the forwarder's link say it at once,
    naming the role and the privilege (the server's "permission denied for table line_feed"
    names neither the role nor the privilege)."""
    role, quoted, read_only = conn.execute(text(
        "SELECT current_user, quote_ident(current_user), "
        "current_setting('transaction_read_only')")).one()
    if read_only == "on":
        return (f"the server takes no writes (read-only: a standby, or "
                f"default_transaction_read_only): role {role} cannot insert into line_feed")
    lacks = []
    for table, privileges in FORWARD_PRIVILEGES:
        if conn.execute(text("SELECT to_regclass(:t)"), {"t": table}).scalar() is None:
            continue
        missing = [p for p in privileges if not conn.execute(
            text("SELECT has_table_privilege(:t, :p)"), {"t": table, "p": p}).scalar()]
        if missing:
            lacks.append(f"{' and '.join(missing)} on {table}")
    if not lacks:
        return None
    return (f"role {role} lacks {', '.join(lacks)}: the forwarders cannot write (as the "
            f"tables' owner: {FORWARD_GRANT.format(role=quoted)})")


def operator_of(entry: dict[str, Any]) -> str | None:
    """The ``operator`` column of a feed entry: a rundown's operator, else None."""
    if entry["kind"] != RUNDOWN:
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
        p = rec.get("parameters") if e["kind"] == RUNDOWN else None
        # a loosening carries its loosen pset, not its version's parameters
        if not p or rec.get("model") is None or rec.get("rundown") == LOOSENING:
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


Window = tuple[float | None, float | None, float | None]   # target, min, max


@dataclass(frozen=True)
class LineResult:
    """One rundown as the line database holds it (a row of ``line_rundowns``)."""

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
    pset: int | None = None
    tightening_id: int | None = None
    torque: Window = (None, None, None)   # the window in force (Nm)
    angle: Window = (None, None, None)    # (deg)
    #: an outcome a person entered from the controller's screen (None: measured): who,
    #: their comment, and the unreadable result it resolves (its record id at the station)
    entered_by: str | None = None
    entered_comment: str | None = None
    unreadable_record_id: int | None = None

    def to_json(self) -> dict[str, Any]:
        """The rundown as ``line results --json`` and ``/api/line/results`` give it: the
        windows as arrays (target, min, max) and, named as the station's exports name them,
        each limit and ``parameter_version`` and ``status`` beside (a quality trial: the
        arrays were not self-describing, and ``ok``/``parameters_version`` spelled
        otherwise than the exports)."""
        (tt, tmin, tmax), (at, amin, amax) = self.torque, self.angle
        return {"station_id": self.station_id, "db_id": self.db_id, "seq": self.seq,
                "at": self.at.isoformat(), "vin": self.vin, "model": self.model,
                "bolt": self.bolt, "ok": self.ok, "status": verdict(self.ok),
                "kind": self.kind, "torque_nm": self.torque_nm, "angle_deg": self.angle_deg,
                "parameters_version": self.version, "parameter_version": self.version,
                "received_at": self.received_at.isoformat(), "operator": self.operator,
                "pset": self.pset, "tightening_id": self.tightening_id,
                "torque_window_nm": list(self.torque), "angle_window_deg": list(self.angle),
                "torque_target_nm": tt, "torque_min_nm": tmin, "torque_max_nm": tmax,
                "angle_target_deg": at, "angle_min_deg": amin, "angle_max_deg": amax,
                # an outcome a person entered from the controller's screen (None: measured)
                "entered_by": self.entered_by, "entered_comment": self.entered_comment,
                "unreadable_record_id": self.unreadable_record_id}


def results(engine: Engine, *, vin: str | None = None, station: str | None = None,
            bolt: str | None = None, since: datetime | None = None,
            until: datetime | None = None, limit: int = 1000) -> list[LineResult]:
    """The line's rundowns, newest first (of ``vin`` / ``station`` / ``bolt``, recorded at
    or after ``since`` and before ``until``; at most ``limit``), from ``line_rundowns``:
    each filter is the leading column of one of its indexes."""
    r = LINE_RUNDOWNS.table.c
    q = select(LINE_RUNDOWNS.table)
    for col, want in ((r.vin, vin), (r.station_id, station), (r.bolt, bolt)):
        if want is not None:
            q = q.where(col == want)
    if since is not None:
        q = q.where(r.at >= since)
    if until is not None:
        q = q.where(r.at < until)
    q = q.order_by(r.at.desc(), r.station_id, r.seq.desc()).limit(max(1, int(limit)))
    with engine.connect() as c:
        return [LineResult(
            row.station_id, row.db_id, int(row.seq), row.at.astimezone(UTC), str(row.vin),
            row.model, str(row.bolt), row.status == OK, row.kind, row.torque_nm,
            row.angle_deg, row.parameters_version, row.received_at.astimezone(UTC),
            row.operator, row.pset, row.tightening_id,
            (row.torque_target_nm, row.torque_min_nm, row.torque_max_nm),
            (row.angle_target_deg, row.angle_min_deg, row.angle_max_deg),
            row.entered_by, row.entered_comment, row.unreadable_record_id)
            for row in c.execute(q)]


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


__all__ = ["FORWARD_GRANT", "FORWARD_PRIVILEGES", "LINE", "LINE_CHECKS", "LINE_COMMANDS",
           "LINE_CONTROLLER_EVENTS", "LINE_FEED", "LINE_GAPS", "LINE_PARAMETERS",
           "LINE_RUNDOWNS", "LINE_UNATTRIBUTED", "LINE_UNREADABLE", "TYPED", "TYPED_VERSION",
           "BoltVersion", "LineResult", "SchemaChange", "Typed", "bolt_versions",
           "create_line_schema", "installed_version", "operator_of", "parameter_rows",
           "results", "trigger_body", "write_problem"]
