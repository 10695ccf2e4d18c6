"""The process-parameter database schema (SQLAlchemy 2 declarative models).

Why parameters live in their own versioned table: a tightening record must say exactly which
targets the controller was given.  Once a bolt has records, a change of its parameters adds a
new ``ProcessParameters`` version and the old row stays, still referenced by the old records;
only versions nobody references are updated in place.  The current version of a bolt is its
highest ``version``.

Bolts and models removed from the bolt file are kept (``removed_at`` set) when records or
vehicles refer to them, so history never dangles; otherwise they are deleted.

This module is the schema's description for the code; ``db/migrations`` creates it in a
database, and a test checks that the two agree.  Change both together (new revision).
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    CheckConstraint,
    DateTime,
    Dialect,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    String,
    Text,
    TypeDecorator,
    UniqueConstraint,
    false,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

# named constraints: alembic can then alter them on SQLite (batch mode) and on other databases
NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


def utcnow() -> datetime:
    return datetime.now(UTC)


class UtcDateTime(TypeDecorator[datetime]):
    """Timestamps stored as naive UTC, returned timezone-aware (SQLite keeps no zone)."""

    impl = DateTime
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        if value.tzinfo is None:
            raise ValueError("naive datetime: give timestamps with a timezone (UTC)")
        return value.astimezone(UTC).replace(tzinfo=None)

    def process_result_value(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        return None if value is None else value.replace(tzinfo=UTC)


class Base(DeclarativeBase):
    metadata = MetaData(naming_convention=NAMING)


class VehicleModel(Base):
    """A vehicle model of the bolt table (the YAML key), with the code the lift reports."""

    __tablename__ = "vehicle_models"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(32), unique=True)
    code: Mapped[int | None] = mapped_column(Integer, unique=True)
    description: Mapped[str | None] = mapped_column(String(200))
    seq: Mapped[int] = mapped_column(default=0)  # position in the file, for the export
    removed_at: Mapped[datetime | None] = mapped_column(UtcDateTime)

    bolts: Mapped[list[Bolt]] = relationship(back_populates="model", order_by="Bolt.seq")


class PsetProgram(Base):
    """A controller program (pset) definition: global when ``model_id`` is NULL."""

    __tablename__ = "psets"
    __table_args__ = (UniqueConstraint("model_id", "number"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    model_id: Mapped[int | None] = mapped_column(ForeignKey("vehicle_models.id"))
    number: Mapped[int]
    name: Mapped[str | None] = mapped_column(String(100))
    torque_target: Mapped[float]
    torque_min: Mapped[float]
    torque_max: Mapped[float]
    angle_target: Mapped[float | None]
    angle_min: Mapped[float | None]
    angle_max: Mapped[float | None]
    seq: Mapped[int] = mapped_column(default=0)


class Bolt(Base):
    """A bolt of a model: its identity and geometry; its parameters are versioned apart."""

    __tablename__ = "bolts"
    __table_args__ = (UniqueConstraint("model_id", "code"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    model_id: Mapped[int] = mapped_column(ForeignKey("vehicle_models.id"))
    code: Mapped[str] = mapped_column(String(32))  # the bolt id of the file
    name: Mapped[str] = mapped_column(String(100))
    x_mm: Mapped[float]
    y_mm: Mapped[float]
    z_mm: Mapped[float]
    tighten_order: Mapped[int | None]
    batch: Mapped[str | None] = mapped_column(String(32))
    seq: Mapped[int] = mapped_column(default=0)
    removed_at: Mapped[datetime | None] = mapped_column(UtcDateTime)

    model: Mapped[VehicleModel] = relationship(back_populates="bolts")
    # deleting a bolt deletes its versions; the database refuses it while records refer to them
    versions: Mapped[list[ProcessParameters]] = relationship(
        back_populates="bolt", order_by="ProcessParameters.version",
        cascade="all, delete-orphan")


class ProcessParameters(Base):
    """One version of a bolt's parameters: pset and/or torque and angle windows."""

    __tablename__ = "process_parameters"
    __table_args__ = (UniqueConstraint("bolt_id", "version"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    bolt_id: Mapped[int] = mapped_column(ForeignKey("bolts.id"))
    version: Mapped[int]
    pset: Mapped[int | None]
    torque_target: Mapped[float]
    torque_min: Mapped[float]
    torque_max: Mapped[float]
    angle_target: Mapped[float | None]
    angle_min: Mapped[float | None]
    angle_max: Mapped[float | None]
    created_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
    source: Mapped[str | None] = mapped_column(String(500))  # the file it was imported from

    bolt: Mapped[Bolt] = relationship(back_populates="versions")


class Vehicle(Base):
    """A vehicle at the station: its VIN (or sequence id), model, start and end."""

    __tablename__ = "vehicles"

    id: Mapped[int] = mapped_column(primary_key=True)
    vin: Mapped[str] = mapped_column(String(32), unique=True)
    model_id: Mapped[int] = mapped_column(ForeignKey("vehicle_models.id"))
    started_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
    ended_at: Mapped[datetime | None] = mapped_column(UtcDateTime)
    #: the last time a closed vehicle was reopened for rework (None: never)
    reopened_at: Mapped[datetime | None] = mapped_column(UtcDateTime)

    model: Mapped[VehicleModel] = relationship()


class VehicleClosing(Base):
    """A vehicle leaving the station (``how``: the lift lowered, or found gone at the next
    vehicle's start, the station down as it left) and what it left: its bolts' counts by
    status and the bolts not OK by name (``not_ok``: status -> bolts, in the table's order).
    Every close is kept (a reworked vehicle closes again; its first close stays); it joins
    the results feed, so the line and an MES know a vehicle left with bolts undone."""

    __tablename__ = "vehicle_closings"
    __table_args__ = (Index("ix_vehicle_closings_vehicle", "vehicle_id"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    vehicle_id: Mapped[int] = mapped_column(ForeignKey("vehicles.id"))
    closed_at: Mapped[datetime] = mapped_column(UtcDateTime)
    how: Mapped[str] = mapped_column(String(16))
    bolts: Mapped[int]
    ok: Mapped[int]
    nok: Mapped[int]
    missing: Mapped[int]
    skipped: Mapped[int]
    loosen: Mapped[int]
    not_ok: Mapped[dict[str, list[str]]] = mapped_column(JSON)

    vehicle: Mapped[Vehicle] = relationship()


class TighteningRecord(Base):
    """One rundown (a tightening or a loosening): where the wrench was, what was sent, what
    the controller answered."""

    __tablename__ = "tightening_records"
    __table_args__ = (
        CheckConstraint("status IN ('ok', 'nok')", name="status"),
        CheckConstraint("kind IN ('tightening', 'loosening')", name="kind"),
        Index("ix_tightening_records_vehicle_bolt", "vehicle_id", "bolt_id"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    vehicle_id: Mapped[int] = mapped_column(ForeignKey("vehicles.id"))
    bolt_id: Mapped[int] = mapped_column(ForeignKey("bolts.id"))
    parameters_id: Mapped[int] = mapped_column(ForeignKey("process_parameters.id"))
    x_mm: Mapped[float]              # the localized bolt end, vehicle frame
    y_mm: Mapped[float]
    z_mm: Mapped[float]
    match_distance_mm: Mapped[float]
    tilt_deg: Mapped[float]
    params_sent: Mapped[dict[str, Any]] = mapped_column(JSON)
    acknowledged: Mapped[bool]       # the controller accepted the parameters
    status: Mapped[str] = mapped_column(String(3))
    torque_nm: Mapped[float | None]
    angle_deg: Mapped[float | None]
    tightening_id: Mapped[int | None]  # the controller's own id of the tightening
    sent_at: Mapped[datetime | None] = mapped_column(UtcDateTime)
    #: when the station took the result, on its clock: the time of the input the core decided
    #: on (:attr:`stationd.station.actions.Record.t`), so a lock the result caused
    #: (``commands.at``) is at that time or later; the controller's own is ``controller_at``
    result_at: Mapped[datetime | None] = mapped_column(UtcDateTime)
    #: when the database took it (its feed entry's ``at``, the same instant)
    recorded_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
    images: Mapped[list[str]] = mapped_column(JSON)  # references (paths/URLs) of the frames
    #: the controller's own time of the tightening (its clock, MID 0061's timestamp): what
    #: tells a resent copy from another result under the same id (None: not known, a
    #: controller without a clock, an entered outcome, a record from before revision 0014)
    controller_at: Mapped[datetime | None] = mapped_column(UtcDateTime)
    #: tightening or loosening (``db.kinds``): the result's type, else what was sent; a
    #: loosening is never a bolt done
    kind: Mapped[str] = mapped_column(String(10), default="tightening",
                                      server_default="tightening")
    #: the user signed in at the station when the tool was enabled (None: nobody, or a
    #: record from before operators signed in)
    operator: Mapped[str | None] = mapped_column(String(64))
    #: an outcome a person entered from the controller's own screen, its result message
    #: unreadable (None: measured, as the controller sent it): who, their comment, and the
    #: unreadable result it resolves (``unreadable_results.id``, None if none was stored)
    entered_by: Mapped[str | None] = mapped_column(String(64))
    entered_comment: Mapped[str | None] = mapped_column(String(500))
    unreadable_id: Mapped[int | None]
    #: fetched after a link cut (Open Protocol MID 0064): made while the link was down, taken
    #: by the station at the reconnect (its ``result_at``), not as it was made
    offline: Mapped[bool] = mapped_column(default=False, server_default=false())

    vehicle: Mapped[Vehicle] = relationship()
    bolt: Mapped[Bolt] = relationship()
    parameters: Mapped[ProcessParameters] = relationship()


class ToolEnable(Base):
    """The tool enabled for a bolt: what the station owes until that bolt's result is recorded.

    Written before the tool is enabled, so that a reload or a restart (kill -9 included) knows
    which bolt a late result belongs to; ``off_at`` is when the tool went off (None: the
    station stopped with it on); ``settled_at`` when its result was recorded.  Kept as the trail
    of every enable.
    """

    __tablename__ = "tool_enables"

    id: Mapped[int] = mapped_column(primary_key=True)
    vin: Mapped[str] = mapped_column(String(32))
    bolt: Mapped[str] = mapped_column(String(32))   # the bolt's code
    pset: Mapped[int | None]
    parameters_id: Mapped[int | None] = mapped_column(ForeignKey("process_parameters.id"))
    selection: Mapped[dict[str, Any]] = mapped_column(JSON)  # where the wrench was, when
    enabled_at: Mapped[datetime] = mapped_column(UtcDateTime)
    off_at: Mapped[datetime | None] = mapped_column(UtcDateTime)
    settled_at: Mapped[datetime | None] = mapped_column(UtcDateTime)


class UnattributedResult(Base):
    """A controller result no bolt owns (no tool enable it belongs to): stored before it is
    acknowledged, never only logged, so that quality can see every tightening made."""

    __tablename__ = "unattributed_results"
    __table_args__ = (CheckConstraint("status IN ('ok', 'nok')", name="status"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    vin: Mapped[str | None] = mapped_column(String(32))   # the vehicle at height, if any
    controller_vin: Mapped[str | None] = mapped_column(String(32))  # as the result carries it
    tightening_id: Mapped[int | None]
    pset: Mapped[int | None]
    status: Mapped[str] = mapped_column(String(3))
    torque_nm: Mapped[float | None]
    angle_deg: Mapped[float | None]
    result_at: Mapped[datetime | None] = mapped_column(UtcDateTime)   # controller's clock
    recorded_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
    reason: Mapped[str] = mapped_column(String(200))
    #: the result type as the controller sent it (1 tightening, 2 loosening, ...; NULL: none,
    #: a revision without one): an unattributed loosening read as "tightened OK"
    result_type: Mapped[int | None]


class ControllerEvent(Base):
    """A result from the controller that is not a rundown (Open Protocol MID 0061 revision 3+
    result types 3 batch increment, 4 batch decrement, 5 bypass parameter set, 6 abort job,
    8 reference setup, or a type the specification does not name): it never closes, opens
    or counts a bolt, and is kept so that quality sees what happened on the controller."""

    __tablename__ = "controller_events"
    __table_args__ = (CheckConstraint("status IN ('ok', 'nok')", name="status"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    result_type: Mapped[int]                               # the code as the controller sent it
    what: Mapped[str] = mapped_column(String(32))          # its name ("batch increment")
    vin: Mapped[str | None] = mapped_column(String(32))    # the vehicle at height, if any
    bolt: Mapped[str | None] = mapped_column(String(32))   # the tool was enabled for, if any
    controller_vin: Mapped[str | None] = mapped_column(String(32))
    tightening_id: Mapped[int | None]
    pset: Mapped[int | None]
    # NULL: no verdict, a hold the station stored where no result says it (an MES counting
    # status 'nok' counted those as NOK tightenings: an MES integrator's trial)
    status: Mapped[str | None] = mapped_column(String(3))
    torque_nm: Mapped[float | None]
    angle_deg: Mapped[float | None]
    result_at: Mapped[datetime | None] = mapped_column(UtcDateTime)   # controller's clock
    recorded_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
    # why a bolt is held where no result says it (:data:`db.kinds.CUT_UNKNOWN`)
    note: Mapped[str | None] = mapped_column(String(500))


class UnreadableRecord(Base):
    """A result message the station could not read: kept whole (its text as received, the
    revision it said it was, the parse error) before the controller was told it may forget
    it, with the bolt it may belong to (held until a supervisor checks it on the
    controller and releases it)."""

    __tablename__ = "unreadable_results"

    id: Mapped[int] = mapped_column(primary_key=True)
    mid: Mapped[int]
    revision: Mapped[int]
    raw: Mapped[str] = mapped_column(Text)
    error: Mapped[str] = mapped_column(String(500))
    vin: Mapped[str | None] = mapped_column(String(32))    # the vehicle at height, if any
    bolt: Mapped[str | None] = mapped_column(String(32))   # the bolt it may belong to
    controller_vin: Mapped[str | None] = mapped_column(String(32))
    tightening_id: Mapped[int | None]                      # as far as it could be read
    pset: Mapped[int | None]
    result_at: Mapped[datetime | None] = mapped_column(UtcDateTime)
    recorded_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)


class CommandRecord(Base):
    """A command a person gave the station (skip a bolt, reopen a vehicle, ...), accepted by
    its rules: who, from where, when, on what, and why (their comment).  Never edited."""

    __tablename__ = "commands"
    # a vehicle's commands found by its VIN (each report reads them; a year of them was read
    # whole for every vehicle of an export or a hand-over)
    __table_args__ = (Index("ix_commands_vin", "vin"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    at: Mapped[datetime] = mapped_column(UtcDateTime)
    user: Mapped[str] = mapped_column(String(64))
    source: Mapped[str] = mapped_column(String(100))   # "screen 10.0.0.7", "cli", ...
    kind: Mapped[str] = mapped_column(String(32))      # skip, reopen, ...
    vin: Mapped[str | None] = mapped_column(String(32))
    bolt: Mapped[str | None] = mapped_column(String(32))
    comment: Mapped[str] = mapped_column(String(500), default="")


class FeedEntry(Base):
    """The results feed: every record (a rundown, an unattributed result, a command) gets the
    next sequence number in the transaction that writes it, so a reader that was away
    ("since N") misses nothing and sees each once, in order."""

    __tablename__ = "feed"
    # a number is never used twice; a record's entry found by its kind and id (an export's
    # result_id of each row: without it the whole feed was read for each vehicle)
    __table_args__ = (Index("ix_feed_kind_ref", "kind", "ref"),
                      {"sqlite_autoincrement": True})

    seq: Mapped[int] = mapped_column(primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))     # rundown, unattributed, command
    ref: Mapped[int]                                  # the id in that kind's table
    #: when the station stored the record: its ``recorded_at`` (``found_at``) where it has
    #: one, the same instant (:func:`db.ledger.append`)
    at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)


#: the meta key of the vehicle loaded at the station now ("": none)
AT_STATION = "at_station"
#: the meta key of the last write that proved the database takes writes (its time, ISO):
#: written at the daemon's start and on the database's way back from a fault
WRITE_PROVED = "write_proved"


class Meta(Base):
    """The database's own facts: ``db_id``, a random id made when it was created (a station's
    records stay unique on a line when its local database is replaced)."""

    __tablename__ = "meta"

    key: Mapped[str] = mapped_column(String(32), primary_key=True)
    value: Mapped[str] = mapped_column(String(200))


class ForwardQuarantine(Base):
    """A feed entry the line database refused for good, with its reason: kept here, visible
    and retried on demand, never blocking the entries after it."""

    __tablename__ = "forward_quarantine"

    seq: Mapped[int] = mapped_column(primary_key=True, autoincrement=False)
    reason: Mapped[str] = mapped_column(String(500))
    at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)


class ResultGap(Base):
    """Tightening ids the controller made and the station could not get (the controller no
    longer had them when asked after a reconnect): a gap, recorded so it is seen."""

    __tablename__ = "result_gaps"

    id: Mapped[int] = mapped_column(primary_key=True)
    first_id: Mapped[int]
    last_id: Mapped[int]
    vin: Mapped[str | None] = mapped_column(String(32))   # the vehicle at height, if any
    reason: Mapped[str] = mapped_column(String(200))
    found_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)


class TighteningCurve(Base):
    """One trace of a tightening as the controller sent it (Open Protocol MID 0900): its
    type (1 angle, 2 torque, ...), unit, sample period and values, with the rundown it
    belongs to when the station knew it at storing time (``record_id``), always with the
    controller's tightening id (a curve that came before its result is found by that)."""

    __tablename__ = "curves"
    __table_args__ = (
        Index("ix_curves_tightening_id", "tightening_id"),
        Index("ix_curves_record_id", "record_id"),
    )

    id: Mapped[int] = mapped_column(primary_key=True)
    record_id: Mapped[int | None] = mapped_column(ForeignKey("tightening_records.id"))
    tightening_id: Mapped[int]
    trace_type: Mapped[int]
    unit: Mapped[str] = mapped_column(String(16))
    sample_period_s: Mapped[float | None]          # None: ``times_s`` has each sample's time
    values: Mapped[list[float]] = mapped_column(JSON)
    times_s: Mapped[list[float] | None] = mapped_column(JSON)
    result_at: Mapped[datetime | None] = mapped_column(UtcDateTime)   # controller's clock
    recorded_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)


class OpcUaAcknowledged(Base):
    """A rundown (its feed entry) an MES acknowledged over OPC UA (AcknowledgeResults of
    OPC 40450-1): it is no longer sent by RequestUnacknowledgedResults, also after a
    restart.  Who acknowledged it is kept beside it."""

    __tablename__ = "opcua_acknowledged"

    seq: Mapped[int] = mapped_column(ForeignKey("feed.seq"), primary_key=True,
                                     autoincrement=False)
    acknowledged_by: Mapped[str] = mapped_column(String(64))   # the OPC UA user
    at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)


class CameraPin(Base):
    """The camera (its serial number) a pair's side was first used with under one
    calibration (``calibration``: the digest of the pair's calibration): a camera with
    another serial under the same calibration is a unit replaced without calibrating the
    pair again, refused (``db.cameras``)."""

    __tablename__ = "camera_pins"

    pair: Mapped[str] = mapped_column(String(64), primary_key=True)
    side: Mapped[str] = mapped_column(String(8), primary_key=True)
    calibration: Mapped[str] = mapped_column(String(64), primary_key=True)
    serial: Mapped[str] = mapped_column(String(128))
    pinned_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)


class CalibrationCheck(Base):
    """A camera pair checked against the reference markers: when, its verdict (ok, moved, not
    checked), the worst reference and its offset against the tolerance, why it was not
    checked, and each reference's measurement (``references``: name -> offset_mm,
    measured_mm, why, note).  Never edited; it joins the results feed."""

    __tablename__ = "calibration_checks"
    __table_args__ = (Index("ix_calibration_checks_pair", "pair"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    at: Mapped[datetime] = mapped_column(UtcDateTime)
    pair: Mapped[str] = mapped_column(String(64))
    verdict: Mapped[str] = mapped_column(String(16))
    reference: Mapped[str | None] = mapped_column(String(64))
    offset_mm: Mapped[float | None]
    tolerance_mm: Mapped[float]
    reason: Mapped[str | None] = mapped_column(String(200))
    references: Mapped[dict[str, Any]] = mapped_column(JSON)
    recorded_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
