"""The process-parameter repository: the one object the daemon and the commands use.

Why a repository and not sessions in the callers: every write is one transaction with the
rules in one place (SQLite: ``BEGIN IMMEDIATE``, committed before the method returns), and the
callers see plain values (``BoltInfo``, ``VehicleReport``), never ORM objects tied to a session.
``Repository.open`` migrates the database to the current schema first.  The default URL is
``sqlite:///stationd.db`` (the current directory); the daemon passes one in its StateDirectory.
"""

from __future__ import annotations

import logging
from collections.abc import Collection, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from datetime import datetime, timedelta
from types import TracebackType
from typing import Any, Self

from alembic.util import CommandError
from sqlalchemy import ColumnElement, Engine, func, make_url, null, or_, select
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session

from db import quality
from db.bolts import BoltTable, Parameters, dump_bolts
from db.engine import DEFAULT_URL, make_engine, write_session
from db.errors import DatabaseError, DataError, NotFoundError, VehicleClosedError
from db.holds import ENDS_A_HOLD, open_holds, released_holds
from db.importer import (
    ImportReport,
    current_version,
    import_table,
    parameters_of,
    read_table,
    sent_bolt,
)
from db.kinds import (
    HELD_WITHOUT_RESULT,
    LOOSENING,
    NOT_TAKEN,
    RUNDOWN_KINDS,
    TIGHTENING,
    HeldUnder,
)
from db.ledger import (
    CLOSING,
    CONTROLLER_EVENT,
    GAP,
    LOWERED,
    RUNDOWN,
    UNATTRIBUTED,
    UNREADABLE,
    UNSEEN,
    Ledger,
    add_command,
    append,
    commands_in,
    put_meta,
)
from db.migrate import current_revision, head_revision, upgrade
from db.models import (
    AT_STATION,
    WRITE_PROVED,
    Bolt,
    ControllerEvent,
    Meta,
    ProcessParameters,
    ResultGap,
    TighteningRecord,
    ToolEnable,
    UnattributedResult,
    UnreadableRecord,
    Vehicle,
    VehicleClosing,
    VehicleModel,
    utcnow,
)
from db.report import VehicleInfo, VehicleReport, build_report

EXPORT_HEADER = ("stationd bolt table, exported from the process-parameter database.\n"
                 "Units: positions mm (vehicle frame), torque N m, angle degrees.")
VIN_MAX = 32

#: the controller stamps its results to the second, its clock's offset measured to the
#: second: a result made within this much of an unreadable message's arrival may be its copy
COPY_SLACK = timedelta(seconds=2)

log = logging.getLogger(__name__)


__all__ = ["BoltInfo", "DataError", "DatabaseError", "NotFoundError", "OwedEnable", "Recorded",
           "Repository", "StoredResult", "VehicleClosedError"]


@dataclass(frozen=True)
class BoltInfo:
    """A bolt of a model as the station uses it: where it is and what to send."""

    model: str
    bolt_id: str
    name: str
    position: tuple[float, float, float]
    parameters: Parameters
    parameters_id: int   # pass it back to record_tightening: the version actually sent
    version: int
    order: int | None
    batch: str | None


@dataclass(frozen=True)
class OwedEnable:
    """The last tool enable whose result is not recorded (what a station owes the next)."""

    id: int
    vin: str
    bolt: str
    pset: int | None
    parameters_id: int | None
    selection: dict[str, Any]
    enabled_at: datetime
    off_at: datetime | None


@dataclass(frozen=True)
class Recorded:
    """What :meth:`Repository.record_tightening_once` did: the record's ``id``, and
    ``again``: True when the result was a copy the controller sent again of one stored
    already (that record's id; nothing was written).  For a copy, ``vin`` and ``bolt`` are
    the stored record's: the bolt that tightening was of, which may not be the one the caller
    attributed it to (a new station, after a reload, took B1's copy for B2's owed enable):
    the caller must not take the copy as a result of its own bolt."""

    id: int
    again: bool = False
    vin: str | None = None
    bolt: str | None = None


@dataclass(frozen=True)
class StoredResult:
    """A stored result that a result from the controller is the very copy of
    (:meth:`Repository.stored_result`): its id, and the vehicle and bolt it is of (None: a
    result no bolt owns, stored unattributed, or a controller event of no bolt; ``vin`` None
    where no vehicle was at height)."""

    id: int
    vin: str | None
    bolt: str | None


def _other_schema(have: str | None, want: str | None) -> str:
    """What to do with a database at another schema than this release's: an older one is
    migrated by opening it for writing; a newer one (a later stationd's) only that stationd
    reads (a maintenance trial: told to migrate it, which then failed)."""
    if have is not None and want is not None and have > want:
        return "a newer stationd's database: read it with that stationd"
    return "open it once with write access (the daemon or db import migrates it)"


class Repository:
    """Open with :meth:`open`; use as a context manager or call :meth:`close`."""

    def __init__(self, engine: Engine) -> None:
        self._engine = engine
        #: the feed, the commands, the database's id (the same transactions)
        self.ledger = Ledger(lambda write: self._session(write))

    @classmethod
    def open(cls, url: str = DEFAULT_URL, *, read_only: bool = False) -> Repository:
        """Connect to ``url`` (any SQLAlchemy URL) and migrate it to the current schema.

        ``read_only`` (reports, exports): no migration and, for an SQLite file, no write
        access needed; a database not at this release's schema is refused with the reason."""
        engine = make_engine(url, read_only=read_only)
        where = make_url(url).render_as_string()  # the password, if any, is masked
        try:
            if read_only:
                with engine.connect() as conn:
                    have, want = current_revision(conn), head_revision()
                if have != want:
                    engine.dispose()
                    raise DatabaseError(f"{where}: schema {have or 'none'}, this stationd "
                                        f"reads {want}: " + _other_schema(have, want))
                return cls(engine)
            before, after = upgrade(engine)
            if before is not None and before != after:
                # an upgrade of stationd moved an existing database on: said once (a
                # maintenance trial found it silent), with the way back
                log.warning("%s: schema %s migrated to %s (this stationd's); a stationd of "
                            "schema %s no longer opens it: keep a backup made before",
                            where, before, after, before)
        except SQLAlchemyError as exc:
            engine.dispose()
            raise DatabaseError(f"{where}: cannot open: {_reason(exc)}") from None
        except CommandError as exc:  # e.g. a schema revision this release does not know
            engine.dispose()
            raise DatabaseError(f"{where}: cannot migrate: {exc} (a database of a newer "
                                "stationd?)") from None
        return cls(engine)

    @property
    def engine(self) -> Engine:
        return self._engine

    def close(self) -> None:
        self._engine.dispose()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    # -- transactions ---------------------------------------------------------------------
    @contextmanager
    def _session(self, write: bool) -> Iterator[Session]:
        """One transaction: committed when the block ends, rolled back if it raises."""
        try:
            if write:   # the write lock taken as it begins (db.engine.write_session)
                with write_session(self._engine) as s:
                    yield s
            else:
                with Session(self._engine, expire_on_commit=False) as s, s.begin():
                    yield s
        except SQLAlchemyError as exc:
            raise DatabaseError(f"database {'write' if write else 'read'} failed: "
                                f"{_reason(exc)}") from None

    def prove_writable(self) -> None:
        """One committed write (the meta table's ``write_proved``, the time): a database that
        opened may still take no writes (an SQLite file its user may not write opens
        read-only, every read answering), and only a write that commits proves it does.
        Raises :class:`DatabaseError` as any write."""
        with self._session(write=True) as s:
            put_meta(s, WRITE_PROVED, utcnow().isoformat())

    # -- bolt table -----------------------------------------------------------------------
    def import_bolts(self, table: BoltTable, *, where: str | None = None) -> ImportReport:
        """Import a checked bolt table (``stationd.boltfile`` reads and checks the file; ``where``
        names it in the parameter versions), all or nothing.

        The table is the whole table: models and bolts it no longer lists are removed (kept as
        retired while records refer to them).  Importing the same table again changes nothing.
        """
        with self._session(write=True) as s:
            return import_table(s, table, where)

    def table(self) -> BoltTable:
        with self._session(write=False) as s:
            return read_table(s)

    def export_bolts(self) -> str:
        """The bolt table as YAML text that imports back with no changes."""
        return dump_bolts(self.table(), EXPORT_HEADER)

    def models(self) -> list[str]:
        with self._session(write=False) as s:
            return list(s.scalars(select(VehicleModel.name).where(
                VehicleModel.removed_at.is_(None)).order_by(VehicleModel.seq)))

    def model_for_code(self, code: int) -> str | None:
        """The model whose lift code is ``code`` (what the lift PLC reports), if any."""
        with self._session(write=False) as s:
            return s.scalar(select(VehicleModel.name).where(
                VehicleModel.code == code, VehicleModel.removed_at.is_(None)))

    def model_codes(self) -> dict[str, int | None]:
        """Each model and its lift code (what a lift PLC reports for it), in table order."""
        with self._session(write=False) as s:
            return {name: code for name, code in s.execute(
                select(VehicleModel.name, VehicleModel.code).where(
                    VehicleModel.removed_at.is_(None)).order_by(VehicleModel.seq))}

    def bolts_for_model(self, model: str) -> list[BoltInfo]:
        """The model's bolts in file order, each with its current parameter version."""
        with self._session(write=False) as s:
            row = _model(s, model)
            return [_info(model, b) for b in row.bolts if b.removed_at is None]

    # -- vehicles -------------------------------------------------------------------------
    def start_vehicle(self, vin: str, model: str, *, reopen: bool = False) -> VehicleInfo:
        """Start (or, after a daemon restart, resume) a vehicle; ``reopen`` a closed one.  It
        is the vehicle at the station from now on (:meth:`left_unseen`)."""
        _check_vin(vin)
        with self._session(write=True) as s:
            put_meta(s, AT_STATION, vin)
            m = _model(s, model)
            v = s.scalar(select(Vehicle).where(Vehicle.vin == vin))
            if v is None:
                v = Vehicle(vin=vin, model_id=m.id, started_at=utcnow())
                s.add(v)
                s.flush()
            elif v.model_id != m.id:
                raise DataError(f"vehicle {vin} is already known as model {v.model.name}, "
                                 f"not {model}")
            elif v.ended_at is not None:
                if not reopen:
                    raise VehicleClosedError(
                        f"vehicle {vin} was closed at {v.ended_at:%Y-%m-%d %H:%M:%S} UTC; "
                        "reopen it to tighten again", vin=vin)
                v.ended_at = None
                v.reopened_at = utcnow()
            return VehicleInfo(v.vin, model, v.started_at, v.ended_at, v.reopened_at)

    def at_station(self) -> str | None:
        """The vehicle the station loaded last and did not close (the lift still up when the
        station stopped: a real PLC keeps it there through the restart), else None."""
        with self._session(write=False) as s:
            here = s.get(Meta, AT_STATION)
            if here is None or not here.value:
                return None
            v = s.scalar(select(Vehicle).where(Vehicle.vin == here.value))
            return None if v is None or v.ended_at is not None else v.vin

    def reopen_vehicle(self, vin: str, *, at: datetime, user: str, source: str,
                       comment: str) -> None:
        """Reopen the closed vehicle ``vin`` for rework, recorded as a command of ``user``, in
        one transaction.  ``NotFoundError`` for an unknown VIN, ``DataError`` for one that is
        not closed."""
        with self._session(write=True) as s:
            v = _vehicle(s, vin)
            if v.ended_at is None:
                here = s.get(Meta, AT_STATION)
                waits = v.reopened_at is not None and (here is None or here.value != vin)
                raise DataError(f"vehicle {vin} is not closed" + (
                    f": reopened for rework at {v.reopened_at:%Y-%m-%d %H:%M:%S} UTC, not "
                    "back at the station yet" if waits else ""))
            v.ended_at, v.reopened_at = None, at
            add_command(s, at=at, user=user, source=source, kind="reopen", vin=vin, bolt=None,
                        comment=comment)

    def record_tightening(self, vin: str, bolt: str, **kw: Any) -> int:
        """Record one tightening; return its id (the stored one for a resent copy).  As
        :meth:`record_tightening_once` (its keywords), for callers that need not know whether
        it was a copy."""
        return self.record_tightening_once(vin, bolt, **kw).id

    def record_tightening_once(
        self, vin: str, bolt: str, *, ok: bool, position_mm: Sequence[float],
        match_distance_mm: float, tilt_deg: float, torque_nm: float | None,
        angle_deg: float | None, parameters_id: int | None = None,
        params_sent: Mapping[str, Any] | None = None, acknowledged: bool = True,
        tightening_id: int | None = None, sent_at: datetime | None = None,
        result_at: datetime | None = None, images: Sequence[str] = (),
        enable_id: int | None = None, kind: str = TIGHTENING, operator: str | None = None,
        controller_at: datetime | None = None, offline: bool = False,
    ) -> Recorded:
        """Record one tightening of ``bolt`` on the open vehicle ``vin``: its id, and whether
        it was a copy the controller sent again (then nothing is written).

        Committed (and on disk) before it returns.  A resent copy is only the very same
        tightening: a record with the same ``tightening_id``, torque and angle, and the same
        controller timestamp (``controller_at``, the controller's own time of the
        tightening, MID 0061): of any vehicle where both have that timestamp, of this
        vehicle where one lacks it (:func:`_stored_copy`).  The returned :class:`Recorded`
        names the stored record's vehicle and bolt, and ``enable_id`` is settled only when
        it is that bolt's own enable (a copy is no result of another bolt).  Why the
        timestamp: a controller replaced or reset numbers its tightenings from 1 again,
        and its torque (to 0.01 N m) and angle (to whole degrees, near the target) can
        coincide with an earlier result's; taken for a copy, such a result was lost
        silently.  Where a timestamp is not known (a controller
        without a clock, a record from before it was kept) the values decide, as before.
        ``result_at`` is the station's time of taking the result (its clock).
        ``parameters_id`` is the version that was sent (``BoltInfo.parameters_id``); without
        it, the bolt's current version.  ``params_sent`` defaults to that version's pset and
        targets.  ``enable_id`` (:meth:`note_enable`) is settled in the same transaction: the
        station owes that enable nothing more.  ``kind``: ``tightening`` or ``loosening``
        (a loosening never makes the bolt done).  ``operator``: the user signed in at the
        station when the tool was enabled (None: nobody).  ``offline``: fetched after a link
        cut, made while the link was down.
        """
        if len(position_mm) != 3:
            raise DataError("position_mm: expected x, y, z")
        if kind not in RUNDOWN_KINDS:
            raise DataError(f"kind {kind!r}: one of {', '.join(RUNDOWN_KINDS)}")
        for name, t in (("sent_at", sent_at), ("result_at", result_at),
                        ("controller_at", controller_at)):
            if t is not None and t.tzinfo is None:
                raise DataError(f"{name}: a timestamp with a timezone (UTC) is needed")
        with self._session(write=True) as s:
            v = _vehicle(s, vin)
            if tightening_id is not None:  # a result the controller sent again: stored once
                known = _stored_copy(s, tightening_id, torque_nm, angle_deg, controller_at,
                                     (vin,), others=False)
                if known is not None:
                    # only the stored record's own bolt's enable: another bolt's enable is
                    # still owed its tool's own result (the copy answers nothing of it)
                    _settle(s, enable_id, of=(known.vin, known.bolt))
                    return Recorded(known.id, again=True, vin=known.vin, bolt=known.bolt)
            # a result of a tool enabled (or a result taken) while the vehicle was open is its
            # result, also stored after the close (the database away meanwhile, the lift went
            # down with the result kept in memory; or a result owed across a restart, fetched
            # after the next vehicle closed this one): refused, it held the station in fault
            # until someone reopened the vehicle
            times = [t for t in (sent_at, result_at) if t is not None]
            if v.ended_at is not None and (not times or min(times) > v.ended_at):
                raise DataError(f"vehicle {vin} is closed: a tightening cannot be recorded")
            b = s.scalar(select(Bolt).where(Bolt.model_id == v.model_id, Bolt.code == bolt,
                                            Bolt.removed_at.is_(None)))
            if b is None:   # the bolt the parameters were sent for, retired since
                b = sent_bolt(s, parameters_id, v.model_id, bolt)
            if b is None:
                raise NotFoundError(f"bolt {bolt!r} is not a bolt of model {v.model.name}")
            version = current_version(b) if parameters_id is None \
                else s.get(ProcessParameters, parameters_id)
            if version is None or version.bolt_id != b.id:
                raise DataError(f"parameter version {parameters_id} is not one of bolt {bolt}")
            sent = dict(params_sent) if params_sent is not None \
                else _params_json(parameters_of(version))
            x, y, z = (float(c) for c in position_mm)  # plain floats: NumPy scalars welcome
            rec = TighteningRecord(
                vehicle_id=v.id, bolt_id=b.id, parameters_id=version.id, x_mm=x, y_mm=y,
                z_mm=z, match_distance_mm=float(match_distance_mm), tilt_deg=float(tilt_deg),
                params_sent=sent, acknowledged=bool(acknowledged),
                status="ok" if ok else "nok", torque_nm=_opt_float(torque_nm),
                angle_deg=_opt_float(angle_deg),
                tightening_id=None if tightening_id is None else int(tightening_id),
                sent_at=sent_at, result_at=result_at, recorded_at=utcnow(),
                controller_at=controller_at, offline=bool(offline),
                images=[str(i) for i in images], kind=kind,
                operator=None if operator is None else str(operator)[:64])
            s.add(rec)
            _settle(s, enable_id)
            s.flush()
            append(s, RUNDOWN, rec.id, rec.recorded_at)
            return Recorded(rec.id)

    def nok_streaks(self, vin: str, since: datetime | None = None) -> dict[str, int]:
        """Per bolt of ``vin``: its NOKs in a row at the end of its records (since its last OK
        tightening and its last release or skip command; only records since ``since``, the
        vehicle's last opening).  What the NOK policy counts, also after a reload or a
        restart: a NOK loosening counts, an OK loosening neither counts nor ends the row."""
        with self._session(write=False) as s:
            v = _vehicle(s, vin)
            q = (select(Bolt.code, TighteningRecord.status, TighteningRecord.recorded_at,
                        TighteningRecord.kind)
                 .join(Bolt, TighteningRecord.bolt_id == Bolt.id)
                 .where(TighteningRecord.vehicle_id == v.id)
                 .order_by(TighteningRecord.recorded_at, TighteningRecord.id))
            if since is not None:
                q = q.where(TighteningRecord.recorded_at >= since)
            releases: dict[str, datetime] = {}
            for c in commands_in(s, vin):
                if c.kind in ENDS_A_HOLD and c.bolt is not None:
                    releases[c.bolt] = c.at
            streak: dict[str, int] = {}
            for code, status, at, kind in s.execute(q):
                if (code in releases and at <= releases[code]) or \
                        (status == "ok" and kind != LOOSENING):
                    streak[code] = 0
                elif status == "ok":
                    streak.setdefault(code, 0)
                else:
                    streak[code] = streak.get(code, 0) + 1
            return {k: n for k, n in streak.items() if n}

    def stored_result(self, *, tightening_id: int, torque_nm: float | None,
                      angle_deg: float | None, controller_at: datetime | None,
                      vins: Collection[str]) -> StoredResult | None:
        """The tightening record the given result from the controller is a copy of, if one
        is stored (the rule of :meth:`record_tightening_once`: the same id, torque and angle;
        any vehicle's record with the same ``controller_at``, or one of ``vins``, the
        station's open vehicles, where a timestamp is missing on either side).

        Why a read apart: the station asks it before its core attributes the result, so a
        copy (a result stored, its acknowledgement lost, sent again after a reload) is never
        taken for the result of the bolt the tool is enabled for now: it would close, count
        or settle a bolt that was never tightened."""
        with self._session(write=False) as s:
            return _stored_copy(s, tightening_id, torque_nm, angle_deg, controller_at, vins)

    # -- what the station owes, results no bolt owns ----------------------------------------
    def note_enable(self, vin: str, bolt: str, pset: int | None, parameters_id: int | None,
                    selection: Mapping[str, Any], at: datetime) -> int:
        """The tool is about to be enabled for ``bolt`` of ``vin``: noted (committed) first, so
        that the next station (a reload, a restart) records a late result to that bolt."""
        with self._session(write=True) as s:
            row = ToolEnable(vin=vin, bolt=bolt, pset=pset, parameters_id=parameters_id,
                             selection=dict(selection), enabled_at=at)
            s.add(row)
            s.flush()
            return row.id

    def settle_enable(self, enable_id: int) -> None:
        """The station owes tool enable ``enable_id`` nothing more without a record of it:
        every result the controller made since was fetched, and none was its."""
        with self._session(write=True) as s:
            _settle(s, enable_id)

    def note_tool_off(self, enable_id: int, at: datetime) -> None:
        """The tool went off (the first time counts: the late-result window starts there)."""
        with self._session(write=True) as s:
            row = s.get(ToolEnable, enable_id)
            if row is not None and row.off_at is None:
                row.off_at = at

    def owed_enable(self) -> OwedEnable | None:
        """The latest tool enable, if its result is not recorded (an older one was superseded
        by it: the tool can only have been enabled for the latest)."""
        with self._session(write=False) as s:
            row = s.scalar(select(ToolEnable).order_by(ToolEnable.id.desc()).limit(1))
            if row is None or row.settled_at is not None:
                return None
            return OwedEnable(row.id, row.vin, row.bolt, row.pset, row.parameters_id,
                              dict(row.selection), row.enabled_at, row.off_at)

    def record_unattributed(self, *, vin: str | None, controller_vin: str | None,
                            tightening_id: int | None, pset: int | None, ok: bool,
                            torque_nm: float | None, angle_deg: float | None,
                            result_at: datetime | None, reason: str,
                            result_type: int | None = None) -> int | None:
        """Store a result no bolt owns (``result_type``: the code as the controller sent it,
        None: none); return its id, or None when this very result is
        already stored, attributed or not (a resent copy: the same tightening id, torque and
        angle, and the same controller timestamp ``result_at`` where both have
        one, :func:`_same_result`)."""
        torque, angle = _opt_float(torque_nm), _opt_float(angle_deg)
        with self._session(write=True) as s:
            if tightening_id is not None:
                for model, at in ((TighteningRecord, TighteningRecord.controller_at),
                                  (UnattributedResult, UnattributedResult.result_at)):
                    same = s.scalar(select(model.id).where(*_same_result(
                        model, at, tightening_id, torque, angle, result_at)).limit(1))
                    if same is not None:
                        return None
            row = UnattributedResult(
                vin=vin, controller_vin=controller_vin, tightening_id=tightening_id, pset=pset,
                status="ok" if ok else "nok", torque_nm=torque, angle_deg=angle,
                result_at=result_at, recorded_at=utcnow(), reason=reason[:200],
                result_type=result_type)
            s.add(row)
            s.flush()
            append(s, UNATTRIBUTED, row.id, row.recorded_at)
            return row.id

    def record_controller_event(self, *, result_type: int, what: str, vin: str | None,
                                bolt: str | None, controller_vin: str | None,
                                tightening_id: int | None, pset: int | None,
                                ok: bool | None, torque_nm: float | None,
                                angle_deg: float | None, result_at: datetime | None,
                                enable_id: int | None = None,
                                note: str | None = None) -> int | None:
        """Store a controller result that is not a rundown (a batch step, a bypass, an OK
        without a type outside its bolt's torque window, ...); return its id, or None when
        this very result is stored already (a resent copy: the same type, and the same
        tightening id, torque and angle, and controller timestamp ``result_at`` where both
        have one, :func:`_same_result`).
        ``enable_id``: the tool enable it answers, settled in the same transaction (its bolt
        is held for a person instead, :data:`db.kinds.NOT_TAKEN`).  ``note``: why a bolt is
        held where there is no result (:data:`db.kinds.CUT_UNKNOWN`), whose ``ok`` is None
        (no verdict: status NULL)."""
        with self._session(write=True) as s:
            # (a hold names the result it may be, which holds each bolt it may be: not copies)
            if tightening_id is not None and what not in HELD_WITHOUT_RESULT:
                same = s.execute(select(ControllerEvent.vin, ControllerEvent.bolt).where(
                    ControllerEvent.result_type == int(result_type),
                    *_same_result(ControllerEvent, ControllerEvent.result_at, tightening_id,
                                  torque_nm, angle_deg, result_at)).limit(1)).first()
                if same is not None:
                    # only its own bolt's enable: another bolt's is still owed (as a rundown)
                    _settle(s, enable_id, of=(same[0], same[1]))
                    return None
            row = ControllerEvent(
                result_type=int(result_type), what=what[:32], vin=vin, bolt=bolt,
                controller_vin=controller_vin, tightening_id=tightening_id, pset=pset,
                status=None if ok is None else "ok" if ok else "nok",
                torque_nm=_opt_float(torque_nm), angle_deg=_opt_float(angle_deg),
                result_at=result_at, recorded_at=utcnow(),
                note=None if note is None else note[:500])
            s.add(row)
            _settle(s, enable_id)
            s.flush()
            append(s, CONTROLLER_EVENT, row.id, row.recorded_at)
            return row.id

    def record_unreadable(self, *, mid: int, revision: int, raw: str, error: str,
                          vin: str | None, bolt: str | None, controller_vin: str | None,
                          tightening_id: int | None, pset: int | None,
                          result_at: datetime | None, enable_id: int | None = None,
                          header_len: int = 0) -> int | None:
        """Store a result message that could not be read, whole; return its id, or None when
        the same message is stored already (:meth:`stored_unreadable`: a resent copy; no
        enable is settled by it: it answers none).  ``enable_id``: the tool enable it
        answers, settled in the same transaction (the station owes it nothing more: the
        bolt is held for a person instead)."""
        with self._session(write=True) as s:
            if _unreadable_copy(s, mid, raw, header_len) is not None:
                return None
            row = UnreadableRecord(
                mid=int(mid), revision=int(revision), raw=raw, error=error[:500], vin=vin,
                bolt=bolt, controller_vin=controller_vin, tightening_id=tightening_id,
                pset=pset, result_at=result_at, recorded_at=utcnow())
            s.add(row)
            _settle(s, enable_id)
            s.flush()
            append(s, UNREADABLE, row.id, row.recorded_at)
            return row.id

    def stored_unreadable(self, *, mid: int, raw: str, header_len: int = 0
                          ) -> tuple[str | None, str | None] | None:
        """The vehicle and bolt a stored unreadable message was stored for, where the same
        message is stored already (a copy the controller sent again: the same text after
        its first ``header_len`` characters, its header, whose sequence number a resend
        changes; the text carries the tightening id, the values and the controller's
        timestamp as far as they were written), else None.  Asked before the station's
        core sees the message, so a copy is never held against the bolt enabled now."""
        with self._session(write=False) as s:
            row = _unreadable_copy(s, mid, raw, header_len)
            return None if row is None else (row.vin, row.bolt)

    def unreadable_of(self, *, tightening_id: int, pset: int | None, at: datetime | None,
                      made: datetime | None = None) -> tuple[str | None, str | None] | None:
        """The vehicle and bolt of a stored unreadable message a readable result is the
        copy of: its tightening id, and its pset and controller time where they could be
        picked out of it (and the result has one); else None.  Where a controller time is
        missing on either side, a result ``made`` (on the station's clock, where the
        controller's is known) after the message was stored is not its copy: another
        result under the same id, from a controller whose ids started again."""
        with self._session(write=False) as s:
            for row in s.scalars(select(UnreadableRecord).where(
                    UnreadableRecord.tightening_id == tightening_id)
                    .order_by(UnreadableRecord.id)):
                if row.pset is not None and pset is not None and row.pset != pset:
                    continue
                if row.result_at is not None and at is not None:
                    if row.result_at == at:
                        return row.vin, row.bolt
                    continue
                if made is None or made <= row.recorded_at + COPY_SLACK:
                    return row.vin, row.bolt
            return None

    def controller_events(self, vin: str | None = None) -> list[dict[str, Any]]:
        """The controller results that were not rundowns (of ``vin``, or all), oldest first."""
        with self._session(write=False) as s:
            q = select(ControllerEvent).order_by(ControllerEvent.id)
            if vin is not None:
                q = q.where(ControllerEvent.vin == vin)
            return [{"id": e.id, "result_type": e.result_type, "what": e.what, "vin": e.vin,
                     "bolt": e.bolt, "controller_vin": e.controller_vin,
                     "tightening_id": e.tightening_id, "pset": e.pset, "status": e.status,
                     "torque_nm": e.torque_nm, "angle_deg": e.angle_deg, "note": e.note,
                     "result_at": e.result_at, "recorded_at": e.recorded_at}
                    for e in s.scalars(q)]

    def unreadable(self, vin: str | None = None) -> list[dict[str, Any]]:
        """The result messages that could not be read (of ``vin``, or all), oldest first,
        each whole."""
        with self._session(write=False) as s:
            q = select(UnreadableRecord).order_by(UnreadableRecord.id)
            if vin is not None:
                q = q.where(UnreadableRecord.vin == vin)
            return [{"id": x.id, "mid": x.mid, "revision": x.revision, "raw": x.raw,
                     "error": x.error,
                     "vin": x.vin, "bolt": x.bolt, "controller_vin": x.controller_vin,
                     "tightening_id": x.tightening_id, "pset": x.pset,
                     "result_at": x.result_at, "recorded_at": x.recorded_at}
                    for x in s.scalars(q)]

    def held_bolts(self, vin: str, since: datetime | None = None) -> dict[str, str]:
        """Bolts of ``vin`` held by an unreadable result (bolt -> which result: its tightening
        id, else its MID and revision), or by an OK result without a type outside the bolt's
        torque window (:data:`db.kinds.NOT_TAKEN`: bolt -> its note), or by a link cut during
        its enable that left its result unknown (:data:`db.kinds.CUT_UNKNOWN`, its note): one
        stored for the bolt
        after its last rundown and its last release command (only those since ``since``, the
        vehicle's last opening).  A hold outlives a restart."""
        return {b: note for b, (note, _) in self.holds(vin, since).items()}

    def may_hold(self, vins: Collection[str]) -> set[str]:
        """Of ``vins``, those with a record that may hold one of their bolts (an unreadable
        result, an untyped OK outside its window, a hold without a result), whatever
        ended it since: a list of vehicles asks :meth:`held_bolts` only for these (two
        reads for the whole list, not two for each of its rows)."""
        if not vins:
            return set()
        with self._session(write=False) as s:
            found = set(s.scalars(select(UnreadableRecord.vin).distinct().where(
                UnreadableRecord.vin.in_(vins), UnreadableRecord.bolt.is_not(None))))
            found |= set(s.scalars(select(ControllerEvent.vin).distinct().where(
                ControllerEvent.vin.in_(vins), ControllerEvent.bolt.is_not(None),
                ControllerEvent.what.in_((NOT_TAKEN, *HELD_WITHOUT_RESULT)))))
        return {str(v) for v in found if v is not None}

    def holds(self, vin: str, since: datetime | None = None
              ) -> dict[str, tuple[str, HeldUnder]]:
        """:meth:`held_bolts`, each with what its result came under (:class:`HeldUnder`): for
        an unreadable result, the tool enable it answered, the latest of its bolt noted
        before the result was stored (a held bolt gets no enable until its hold ends; the
        selection stored with every enable says whether it was the loosen pset); no enable
        found: the result's own pset as far as read, ``loosen`` None (not known here: the
        station decides).  An OK result without a type outside the window came under the
        tightening pset (never taken so under a loosen pset)."""
        with self._session(write=False) as s:
            return open_holds(s, vin, commands_in(s, vin), since)

    def released_holds(self, vin: str, since: datetime | None = None) -> frozenset[str]:
        """The bolts of ``vin`` whose last hold a person released, not run down since: open
        again, but they may be tightened already (a restart keeps the operator's warning)."""
        with self._session(write=False) as s:
            return released_holds(s, vin, commands_in(s, vin), since)

    def spc(self, model: str | None = None, since: datetime | None = None,
            last: int = quality.LAST_N) -> dict[str, Any]:
        """Cp/Cpk of torque and angle per bolt and pset (OK results) with each group's last
        ``last`` results and limits, NOK rate per day."""
        with self._session(write=False) as s:
            return quality.spc(s, model, since, last)

    def last_tightening_id(self) -> int | None:
        """The newest controller tightening id the station accounted for (recorded to a
        bolt, unattributed, a controller event, unreadable, or a gap); None before the
        first."""
        with self._session(write=False) as s:
            ids = [s.scalar(select(func.max(TighteningRecord.tightening_id))),
                   s.scalar(select(func.max(UnattributedResult.tightening_id))),
                   s.scalar(select(func.max(ControllerEvent.tightening_id))),
                   s.scalar(select(func.max(UnreadableRecord.tightening_id))),
                   s.scalar(select(func.max(ResultGap.last_id)))]
            known = [int(i) for i in ids if i is not None]
            return max(known) if known else None

    def read_result_stored(self, tightening_id: int) -> bool:
        """Whether a result read from the controller is stored under ``tightening_id`` (a
        rundown it measured, not one a person entered; one unattributed; a controller
        event): one the controller gives under that id now can be compared with it.  Not
        an unreadable message or a gap: the id is accounted for, but nothing read is
        there to compare."""
        with self._session(write=False) as s:
            return any(s.scalar(q.limit(1)) is not None for q in (
                select(TighteningRecord.id).where(TighteningRecord.tightening_id == tightening_id,
                                                  TighteningRecord.entered_by.is_(None)),
                select(UnattributedResult.id).where(
                    UnattributedResult.tightening_id == tightening_id),
                select(ControllerEvent.id).where(ControllerEvent.tightening_id == tightening_id)))

    def record_gap(self, first_id: int, last_id: int, vin: str | None, reason: str) -> int:
        """Tightening ids the station could not get (the controller no longer has them)."""
        with self._session(write=True) as s:
            row = ResultGap(first_id=first_id, last_id=last_id, vin=vin, reason=reason[:200])
            s.add(row)
            s.flush()
            append(s, GAP, row.id, row.found_at)
            return row.id

    def gaps(self) -> list[dict[str, Any]]:
        with self._session(write=False) as s:
            return [{"first_id": g.first_id, "last_id": g.last_id, "vin": g.vin,
                     "reason": g.reason, "found_at": g.found_at}
                    for g in s.scalars(select(ResultGap).order_by(ResultGap.id))]

    def unattributed(self, vin: str | None = None) -> list[dict[str, Any]]:
        """The stored results no bolt owns (of ``vin``, or all), oldest first.  Each with
        ``entered_as``: the bolt and the person (``{"bolt", "by"}``) whose entered outcome is
        that result (the outcome of a bolt held because it may be its own, entered from the
        controller's screen; a quality trial: the one tightening read as two), else None."""
        with self._session(write=False) as s:
            q = select(UnattributedResult).order_by(UnattributedResult.id)
            if vin is not None:
                q = q.where(UnattributedResult.vin == vin)
            rows = list(s.scalars(q))
            ids = {r.tightening_id for r in rows if r.tightening_id is not None}
            entered: dict[tuple[str | None, int | None], dict[str, str]] = {}
            for v, tid, bolt, who in (s.execute(
                    select(Vehicle.vin, TighteningRecord.tightening_id, Bolt.code,
                           TighteningRecord.entered_by)
                    .join(Vehicle, Vehicle.id == TighteningRecord.vehicle_id)
                    .join(Bolt, Bolt.id == TighteningRecord.bolt_id)
                    .where(TighteningRecord.entered_by.is_not(None),
                           TighteningRecord.tightening_id.in_(ids))
                    .order_by(TighteningRecord.id)) if ids else ()):
                entered.setdefault((v, tid), {"bolt": bolt, "by": str(who)})   # the first
            return [{"id": r.id, "vin": r.vin, "controller_vin": r.controller_vin,
                     "tightening_id": r.tightening_id, "pset": r.pset, "status": r.status,
                     "torque_nm": r.torque_nm, "angle_deg": r.angle_deg,
                     "result_at": r.result_at, "recorded_at": r.recorded_at,
                     "reason": r.reason, "result_type": r.result_type,
                     "entered_as": entered.get((r.vin, r.tightening_id))} for r in rows]

    def close_vehicle(self, vin: str) -> VehicleReport:
        """End the vehicle (once; closing again keeps the first end) and return its summary:
        the bolts still missing and those whose last result is NOK.  No vehicle is at the
        station any more."""
        with self._session(write=True) as s:
            v = _vehicle(s, vin)
            closing = v.ended_at is None
            if closing:
                v.ended_at = utcnow()
            here = s.get(Meta, AT_STATION)
            if here is not None and here.value == vin:
                here.value = ""
            s.flush()
            report = _held_in(s, build_report(s, v))   # the journal's close line counts them
            if closing:
                _closed(s, v, report, LOWERED)
        return report

    def left_unseen(self, vin: str) -> VehicleReport | None:
        """Close the vehicle the station loaded last, if it is not ``vin`` and still open, and
        return its summary (None: nothing to close).  Why: the lift going down closes a
        vehicle; a station down then (killed, restarted, its PLC unreachable) never saw it
        go, and the vehicle stayed open for good beside the next one.  A vehicle reopened
        for rework and not back yet was not loaded since: it stays open."""
        with self._session(write=True) as s:
            row = s.get(Meta, AT_STATION)
            if row is None or not row.value or row.value == vin:
                return None
            v = s.scalar(select(Vehicle).where(Vehicle.vin == row.value))
            row.value = ""
            if v is None or v.ended_at is not None:
                return None
            v.ended_at = utcnow()
            s.flush()
            report = _held_in(s, build_report(s, v))
            _closed(s, v, report, UNSEEN)
        return report

    def vehicle_report(self, vin: str, *, held: bool = False) -> VehicleReport:
        """The vehicle's summary; with ``held``, the bolts held for a person too (a read of
        the ledger and the holds: asked where they are shown, a report or a vehicle's page,
        not for each row of a list or an export)."""
        with self._session(write=False) as s:
            v = _vehicle(s, vin)
            report = build_report(s, v)
        return self._with_held(report) if held else report

    def vin_in_other_case(self, vin: str) -> str | None:
        """The VIN the database has that is ``vin`` typed in another case, else None (what a
        refusal suggests: "did you mean ...?")."""
        with self._session(write=False) as s:
            return _vin_in_other_case(s, vin)

    def _with_held(self, report: VehicleReport) -> VehicleReport:
        """``report`` with its held bolts, in the table's order: of every pass of the vehicle
        (a hold outlives a rework: its result is still not known; a supervisor's trial found
        the hold of a car that left, its last push lost, gone at its reopening)."""
        with self._session(write=False) as s:
            return _held_in(s, report)


# -- helpers ------------------------------------------------------------------------------
def _held_in(s: Session, report: VehicleReport) -> VehicleReport:
    """``report`` with its held bolts (:meth:`Repository._with_held`), read in the caller's
    transaction, in the table's order."""
    vin = report.vehicle.vin
    holds = open_holds(s, vin, commands_in(s, vin), None)
    order = {b.bolt_id: i for i, b in enumerate(report.bolts)}
    return replace(report, held=tuple(sorted(
        ((bolt, note) for bolt, (note, _) in holds.items()),
        key=lambda h: order.get(h[0], len(order)))))


def _closed(s: Session, v: Vehicle, report: VehicleReport, how: str) -> None:
    """The close of ``v`` kept (:class:`db.models.VehicleClosing`) with what its report
    (with its holds: :func:`_held_in`) says it left, and its feed entry, in the caller's
    transaction.  Its bolts held for a person are not OK whatever their status says (their
    last result not known): named in ``not_ok`` too."""
    not_ok = {"nok": report.nok, "missing": report.missing, "skipped": report.skipped,
              "loosen": report.loosen, "held": [bolt for bolt, _ in report.held]}
    assert v.ended_at is not None  # noqa: S101 - closed by the caller
    row = VehicleClosing(vehicle_id=v.id, closed_at=v.ended_at, how=how,
                         bolts=len(report.bolts), ok=len(report.ok), nok=len(report.nok),
                         missing=len(report.missing), skipped=len(report.skipped),
                         loosen=len(report.loosen),
                         not_ok={k: bolts for k, bolts in not_ok.items() if bolts})
    s.add(row)
    s.flush()
    append(s, CLOSING, row.id, row.closed_at)


def _same_result(model: Any, at: Any, tightening_id: int, torque_nm: float | None,
                 angle_deg: float | None,
                 controller_at: datetime | None) -> list[ColumnElement[bool]]:
    """The conditions under which a stored row of ``model`` (``at``: its column of the
    controller's timestamp) is the very result given, sent again by the controller: the same
    tightening id, torque and angle, and the same controller timestamp where both have one.

    Why all of them: a copy the controller resends (unacknowledged before a reload, a link
    cut) is the same message, every value equal; a controller replaced or reset numbers its
    tightenings from 1 again, and its values can coincide (torque to 0.01 N m, angle to
    whole degrees near the target), so the id and values alone took another tightening for
    a copy and it was lost without a word.  The controller stamps each tightening (MID
    0061), so a different time is another tightening.  A missing time (a controller without
    a clock, a row stored before it was kept) agrees with any: there the values decide, as
    before, rather than storing a true copy twice."""
    same = _same_values(model, tightening_id, torque_nm, angle_deg)
    if controller_at is not None:
        same.append(or_(at.is_(None), at == controller_at))
    return same


def _same_values(model: Any, tightening_id: int, torque_nm: float | None,
                 angle_deg: float | None) -> list[ColumnElement[bool]]:
    """A stored row of ``model`` with the given tightening id, torque and angle (what every
    copy rule starts from)."""
    return [model.tightening_id == int(tightening_id), model.torque_nm == _opt_float(torque_nm),
            model.angle_deg == _opt_float(angle_deg)]


def _copy_of(model: Any, at: Any, vin: Any, tightening_id: int, torque_nm: float | None,
             angle_deg: float | None, controller_at: datetime | None,
             vins: Collection[str]) -> list[ColumnElement[bool]]:
    """:func:`_stored_copy`'s rule on a row of ``model`` (``at``: its column of the
    controller's timestamp, ``vin``: of its vehicle): the same values, and the same
    timestamp on any vehicle, or where either lacks one, a vehicle of ``vins``."""
    within = vin.in_(list(vins))
    return [*_same_values(model, tightening_id, torque_nm, angle_deg),
            or_(at == controller_at, at.is_(None) & within) if controller_at is not None
            else within]


def _unreadable_copy(s: Session, mid: int, raw: str, header_len: int
                     ) -> UnreadableRecord | None:
    """The stored unreadable message ``raw`` is a copy of: the same MID and the same text
    after its header (``header_len`` characters).  Compared here, not in SQL: SQLite's text
    functions stop at a NUL, which a garbled message may hold."""
    body = raw[header_len:]
    for row in s.scalars(select(UnreadableRecord).where(UnreadableRecord.mid == int(mid))
                         .order_by(UnreadableRecord.id)):
        if row.raw[header_len:] == body:
            return row
    return None


def _settle(s: Session, enable_id: int | None,
            of: tuple[str | None, str | None] | None = None) -> None:
    """The tool enable ``enable_id`` answered (the station owes it nothing more); with ``of``
    (vin, bolt), only when it is an enable of that bolt of that vehicle."""
    if enable_id is not None:
        row = s.get(ToolEnable, enable_id)
        if row is not None and row.settled_at is None and (
                of is None or (row.vin, row.bolt) == of):
            row.settled_at = utcnow()


def _stored_copy(s: Session, tightening_id: int, torque_nm: float | None,
                 angle_deg: float | None, controller_at: datetime | None,
                 vins: Collection[str], *, others: bool = True) -> StoredResult | None:
    """The tightening record a result is the very copy of: :func:`_same_result`'s id and
    values, and either the same controller timestamp (both have one: any vehicle's record,
    the tightening is the controller's, wherever the station put it; a copy resent after
    the vehicle changed was stored again as the next vehicle's bolt's OK) or, where one of
    them lacks it, a record of one of ``vins`` (the values alone decide there, as before,
    and only within the vehicle: a value coincidence across vehicles is not a copy).  Then,
    with ``others``, the same among the results stored unattributed and the controller
    events (the rundowns' own write asks the rundowns only: those are checked as they are
    stored, each in its own table)."""
    rec = TighteningRecord
    row = s.execute(select(rec.id, Vehicle.vin, Bolt.code)
                    .join(Vehicle, rec.vehicle_id == Vehicle.id)
                    .join(Bolt, rec.bolt_id == Bolt.id)
                    .where(*_copy_of(rec, rec.controller_at, Vehicle.vin, tightening_id,
                                     torque_nm, angle_deg, controller_at, vins))
                    .order_by(rec.id).limit(1)).first()
    if row is not None:
        return StoredResult(int(row[0]), str(row[1]), str(row[2]))
    if not others:
        return None
    # stored as a result no bolt owns, or as a controller event: a copy of one, taken for
    # the owed enable's result, would close that bolt as well
    for model, bolt in ((UnattributedResult, null()), (ControllerEvent, ControllerEvent.bolt)):
        found = s.execute(select(model.id, model.vin, bolt).where(*_copy_of(
            model, model.result_at, model.vin, tightening_id, torque_nm, angle_deg,
            controller_at, vins)).order_by(model.id).limit(1)).first()
        if found is not None:
            return StoredResult(int(found[0]), found[1], found[2])
    return None


def _reason(exc: SQLAlchemyError) -> str:
    orig = getattr(exc, "orig", None)
    return str(orig if orig is not None else exc).splitlines()[0]


def _opt_float(v: float | None) -> float | None:
    return None if v is None else float(v)


def _check_vin(vin: str) -> None:
    if not vin or len(vin) > VIN_MAX or not vin.isprintable() or any(c.isspace() for c in vin):
        raise DataError(f"VIN {vin!r}: 1-{VIN_MAX} printable characters without spaces")


def _model(s: Session, name: str) -> VehicleModel:
    row = s.scalar(select(VehicleModel).where(VehicleModel.name == name,
                                              VehicleModel.removed_at.is_(None)))
    if row is None:
        raise NotFoundError(f"vehicle model {name!r} is not in the bolt table")
    return row


def _vehicle(s: Session, vin: str) -> Vehicle:
    v = s.scalar(select(Vehicle).where(Vehicle.vin == vin))
    if v is None:
        raise NotFoundError(f"vehicle {vin!r} is not in the database{_other_case(s, vin)}")
    return v


def _other_case(s: Session, vin: str) -> str:
    """" (did you mean VIN?)" when the database has ``vin`` in another case (a VIN typed in
    lower case is another VIN: it is matched exactly), else ""."""
    other = _vin_in_other_case(s, vin)
    return f" (did you mean {other}?)" if other is not None else ""


def _vin_in_other_case(s: Session, vin: str) -> str | None:
    """The VIN the database has that is ``vin`` in another case, else None."""
    other = s.scalar(select(Vehicle.vin).where(func.upper(Vehicle.vin) == vin.upper()).limit(1))
    return other if other is not None and other != vin else None


def _info(model: str, b: Bolt) -> BoltInfo:
    version = current_version(b)
    return BoltInfo(model, b.code, b.name, (b.x_mm, b.y_mm, b.z_mm), parameters_of(version),
                    version.id, version.version, b.tighten_order, b.batch)


def _params_json(p: Parameters) -> dict[str, Any]:
    def w(x: Any) -> dict[str, float] | None:
        return None if x is None else {"target": x.target, "min": x.min, "max": x.max}
    return {"pset": p.pset, "torque": w(p.torque), "angle": w(p.angle)}
