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
from datetime import datetime
from types import TracebackType
from typing import Any, Self

from alembic.util import CommandError
from sqlalchemy import Connection, Engine, func, inspect, make_url, select
from sqlalchemy.exc import SQLAlchemyError
from sqlalchemy.orm import Session

from db import quality
from db.bolts import BoltTable, Parameters, dump_bolts
from db.copies import StoredResult, opt_float, stored_copy
from db.enables import OwedEnable, ToolEnables, settle
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
    HELD_WITH_RESULT,
    HELD_WITHOUT_RESULT,
    LOCK,
    LOOSENING,
    OK,
    RUNDOWN_KINDS,
    TIGHTENING,
    HeldUnder,
    verdict,
)
from db.ledger import (
    CLOSING,
    LOWERED,
    RUNDOWN,
    UNSEEN,
    Ledger,
    add_command,
    append,
    commands_in,
    open_locks,
    put_meta,
)
from db.migrate import current_revision, head_revision, upgrade
from db.models import (
    AT_STATION,
    WRITE_PROVED,
    Bolt,
    CommandRecord,
    ControllerEvent,
    Meta,
    ProcessParameters,
    ResultGap,
    TighteningRecord,
    UnattributedResult,
    UnreadableRecord,
    Vehicle,
    VehicleClosing,
    VehicleModel,
    utcnow,
)
from db.others import OtherResults
from db.report import VehicleInfo, VehicleReport, build_report

EXPORT_HEADER = ("stationd bolt table, exported from the process-parameter database.\n"
                 "Units: positions mm (vehicle frame), torque N m, angle degrees.")
VIN_MAX = 32


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


def _line_tables(conn: Connection) -> str:
    """The line database's own tables in ``conn``'s database (``line_*``, as
    ``stationd line init`` makes them), named for the words; "" where there are none."""
    names = sorted(n for n in inspect(conn).get_table_names() if n.startswith("line_"))
    return ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")


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
        self.ledger = Ledger(self._session)
        #: the tool enables the station owes a result (noted before the tool goes on)
        self.enables = ToolEnables(self._session)
        #: the results no bolt's rundown owns: unattributed, controller events, unreadable
        #: messages, gaps
        self.others = OtherResults(self._session)

    @classmethod
    def open(cls, url: str = DEFAULT_URL, *, read_only: bool = False) -> Repository:
        """Connect to ``url`` (any SQLAlchemy URL) and migrate it to the current schema.

        ``read_only`` (reports, exports): no migration and, for an SQLite file, no write
        access needed; a database not at this release's schema is refused with the reason."""
        engine = make_engine(url, read_only=read_only)
        where = make_url(url).render_as_string()  # the password, if any, is masked
        try:
            with engine.connect() as conn:
                have, want = current_revision(conn), head_revision()
                line = have is None and _line_tables(conn)
            if line:
                # a quality trial: told to open the line's database with write access, which
                # would have put a station's schema into it
                engine.dispose()
                raise DatabaseError(f"{where}: a line database (its tables {line}), not a "
                                    "station's: read it with `stationd line results "
                                    "--config STATION.yaml` (or `line status`)")
            if read_only:
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
        vehicle where one lacks it (:func:`stored_copy`).  The returned :class:`Recorded`
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
        targets.  ``enable_id`` (:meth:`db.enables.ToolEnables.note`) is settled in the same
        transaction: the station owes that enable nothing more.  ``kind``: ``tightening`` or
        ``loosening`` (a loosening never makes the bolt done).  ``operator``: the user signed
        in at the station when the tool was enabled (None: nobody).  ``offline``: fetched
        after a link cut, made while the link was down.
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
                known = stored_copy(s, tightening_id, torque_nm, angle_deg, controller_at,
                                    (vin,), others=False)
                if known is not None:
                    # only the stored record's own bolt's enable: another bolt's enable is
                    # still owed its tool's own result (the copy answers nothing of it)
                    settle(s, enable_id, of=(known.vin, known.bolt))
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
                status=verdict(ok), torque_nm=opt_float(torque_nm),
                angle_deg=opt_float(angle_deg),
                tightening_id=None if tightening_id is None else int(tightening_id),
                sent_at=sent_at, result_at=result_at, recorded_at=utcnow(),
                controller_at=controller_at, offline=bool(offline),
                images=[str(i) for i in images], kind=kind,
                operator=None if operator is None else str(operator)[:64])
            s.add(rec)
            settle(s, enable_id)
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
                        (status == OK and kind != LOOSENING):
                    streak[code] = 0
                elif status == OK:
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
            return stored_copy(s, tightening_id, torque_nm, angle_deg, controller_at, vins)

    # -- bolts held for a person ---------------------------------------------------------
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
        result, an untyped OK outside its window, a hold without a result) or lock one (the
        NOK policy's lock), whatever ended it since: a list of vehicles asks for its holds
        and locks (``vehicle_report(held=True)``) only for these (three reads for the whole
        list, not three for each of its rows)."""
        if not vins:
            return set()
        with self._session(write=False) as s:
            found = set(s.scalars(select(UnreadableRecord.vin).distinct().where(
                UnreadableRecord.vin.in_(vins), UnreadableRecord.bolt.is_not(None))))
            found |= set(s.scalars(select(ControllerEvent.vin).distinct().where(
                ControllerEvent.vin.in_(vins), ControllerEvent.bolt.is_not(None),
                ControllerEvent.what.in_((*HELD_WITH_RESULT, *HELD_WITHOUT_RESULT)))))
            found |= set(s.scalars(select(CommandRecord.vin).distinct().where(
                CommandRecord.vin.in_(vins), CommandRecord.kind == LOCK)))
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
        """Cp/Cpk of torque and angle per bolt and pset (every measured tightening, OK and
        NOK) with each group's last
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

    def knows_vehicle(self, vin: str) -> bool:
        """Whether the database has the vehicle ``vin`` (exactly so written)."""
        with self._session(write=False) as s:
            return s.scalar(select(Vehicle.id).where(Vehicle.vin == vin).limit(1)) is not None

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
    v = report.vehicle
    commands = commands_in(s, v.vin)
    holds = open_holds(s, v.vin, commands, None)
    order = {b.bolt_id: i for i, b in enumerate(report.bolts)}
    # its locks too (a supervisor's trial: a bolt left locked read "NOK" in the hand-over
    # and the report, as one that simply ended NOK): since its last opening, as the station
    # reads them at its start
    locked = open_locks(commands, v.reopened_at or v.started_at, ENDS_A_HOLD)
    return replace(report, held=tuple(sorted(
        ((bolt, note) for bolt, (note, _) in holds.items()),
        key=lambda h: order.get(h[0], len(order)))),
        locked=tuple(sorted(locked, key=lambda b: (order.get(b, len(order)), b))))


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


def _reason(exc: SQLAlchemyError) -> str:
    orig = getattr(exc, "orig", None)
    return str(orig if orig is not None else exc).splitlines()[0]


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
