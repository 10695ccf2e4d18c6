"""The append-only side of the database: the results feed, the commands people gave, and the
database's own id.

Why apart from the repository: the repository keeps the bolt tables and the vehicles' state;
this keeps what only grows and is read in order by others (a forwarder to a line database, an
MES, the audit trail).  :func:`append` is called by every writer of a record inside its own
transaction, so a record and its feed entry are committed together or not at all.
"""

from __future__ import annotations

import json
import uuid
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import and_, func, or_, select
from sqlalchemy.orm import Session

from db.engine import Transactions
from db.kinds import HELD_WITH_RESULT, LOCK, LOOSENING
from db.models import (
    Bolt,
    CalibrationCheck,
    CommandRecord,
    ControllerEvent,
    FeedEntry,
    ForwardQuarantine,
    Meta,
    OpcUaAcknowledged,
    ProcessParameters,
    ResultGap,
    TighteningCurve,
    TighteningRecord,
    UnattributedResult,
    UnreadableRecord,
    Vehicle,
    VehicleClosing,
    VehicleModel,
    utcnow,
)

#: the kinds of records the feed carries, each in its own table
RUNDOWN, UNATTRIBUTED, COMMAND, GAP = "rundown", "unattributed", "command", "gap"
CHECK = "check"   # a camera pair's calibration check (db.checks)
CLOSING = "closing"   # a vehicle leaving the station, what it left undone (VehicleClosing)
#: how a vehicle closed: its lift lowered at the station, or found gone (the station down as
#: it left) when the next one started
LOWERED, UNSEEN = "lowered", "unseen"
CURVE = "curve"   # one trace of a tightening (db.curves), its samples in the record
#: a controller result that is not a rundown (batch step, bypass, abort, reference setup), and
#: a result message the station could not read (kept whole)
CONTROLLER_EVENT, UNREADABLE = "controller_event", "unreadable"
#: the kinds that are a controller's result an MES is sent (OPC UA): the rundowns, those no
#: bolt owns, those the station could not read (and, of the controller events, the OK results
#: not taken for a tightening: :func:`is_result`)
RESULT_KINDS = (RUNDOWN, UNATTRIBUTED, UNREADABLE)
#: the meta keys of a renewed id (:meth:`Ledger.renew_db_id`): from which sequence number it
#: holds, and the id the records before it keep
DB_ID_FROM, DB_ID_BEFORE = "db_id_from", "db_id_before"
#: the renewals before the last one (a second backup put back): JSON [[from_seq, id before
#: it], ...], oldest first
DB_ID_EARLIER = "db_id_earlier"


def result_id(db_id: str, seq: int) -> str:
    """``db_id:seq``: a record's key outside the station, unique across a replaced or
    restored station database (OPC UA's ResultId; the line's rows are keyed by the two)."""
    return f"{db_id}:{seq}"


@dataclass(frozen=True)
class Series:
    """The ids a database's records go to the line under: ``db_id`` from ``from_seq`` on,
    ``before`` (None: the database never renewed its id) for the records below it."""

    db_id: str
    from_seq: int = 1
    before: str | None = None
    #: the renewals before the last one, oldest first: (from_seq, the id below it); a record
    #: below one of them keeps the id it had then, not ``before``
    earlier: tuple[tuple[int, str], ...] = ()

    def result_id(self, seq: int) -> str:
        """The key of record ``seq`` outside the station: OPC UA's ResultId, the line's
        (db_id, seq) in one text (:func:`result_id`)."""
        return result_id(self.id_of(seq), seq)

    def id_of(self, seq: int) -> str:
        """The id record ``seq`` goes under."""
        if seq >= self.from_seq or self.before is None:
            return self.db_id
        for start, below in self.earlier:   # oldest (lowest) first: the first it is below
            if seq < start:
                return below
        return self.before


def is_result(entry: Mapping[str, Any]) -> bool:
    """Whether the feed ``entry`` is a controller's result an MES is sent: of
    :data:`RESULT_KINDS`, or a controller event that is an OK result without a type outside
    its bolt's torque window, or a result of a type the station does not know, under a bolt's
    enable (:data:`db.kinds.HELD_WITH_RESULT`: perhaps a real tightening, its
    bolt held; an MES counting the controller's rundowns missed it)."""
    return entry["kind"] in RESULT_KINDS or (
        entry["kind"] == CONTROLLER_EVENT and entry["record"].get("what") in HELD_WITH_RESULT)


def _results() -> Any:
    """:func:`is_result` as a condition on the feed's rows."""
    return or_(FeedEntry.kind.in_(RESULT_KINDS), and_(
        FeedEntry.kind == CONTROLLER_EVENT,
        FeedEntry.ref.in_(select(ControllerEvent.id).where(
            ControllerEvent.what.in_(HELD_WITH_RESULT)))))
FEED_LIMIT = 1000


def append(s: Session, kind: str, ref: int, at: datetime | None = None) -> None:
    """The next sequence number for the record ``ref`` of ``kind`` (in the caller's
    transaction).  ``at``: when the station stored it, the record's own ``recorded_at``
    where it has one (one instant, not two clocks read a few milliseconds apart: the feed's
    ``at`` read later than the ``recorded_at`` of its record); None: now."""
    s.add(FeedEntry(kind=kind, ref=ref, at=utcnow() if at is None else at))


def add_command(s: Session, *, at: datetime, user: str, source: str, kind: str,
                vin: str | None, bolt: str | None, comment: str) -> int:
    """An accepted command and its feed entry, in the caller's transaction."""
    row = CommandRecord(at=at, user=user[:64], source=source[:100], kind=kind, vin=vin,
                        bolt=bolt, comment=comment[:500])
    s.add(row)
    s.flush()
    append(s, COMMAND, row.id)
    return row.id


def put_meta(s: Session, key: str, value: str) -> None:
    """The database's fact ``key`` set to ``value``, in the caller's transaction."""
    row = s.get(Meta, key)
    if row is None:
        s.add(Meta(key=key, value=value))
    else:
        row.value = value


@dataclass(frozen=True)
class CommandEntry:
    """An accepted command as recorded."""

    id: int
    at: datetime
    user: str
    source: str
    kind: str
    vin: str | None
    bolt: str | None
    comment: str


class Ledger:
    """Reads and writes of the append-only records, through the repository's transactions."""

    def __init__(self, session: Transactions) -> None:
        self._session = session

    def db_id(self) -> str:
        """The id this database got when it was created (or renewed: :meth:`renew_db_id`)."""
        with self._session(False) as s:
            return str(s.scalar(select(Meta.value).where(Meta.key == "db_id")))

    def series(self) -> Series:
        """Under which id each record goes to the line: the database's id from
        ``from_seq`` on, the id before it below (None: never renewed)."""
        with self._session(False) as s:
            return _series_in(s)

    def result_ids(self, refs: Iterable[tuple[str, int]]) -> dict[tuple[str, int], str]:
        """The key outside the station (:meth:`Series.result_id`) of each record ``(kind,
        id)`` that has a feed entry: an export's rows joined to OPC UA's results and the
        line's rows."""
        wanted: dict[str, set[int]] = {}
        for kind, ref in refs:
            wanted.setdefault(kind, set()).add(ref)
        if not wanted:
            return {}
        with self._session(False) as s:
            series = _series_in(s)
            rows = s.execute(select(FeedEntry.kind, FeedEntry.ref, FeedEntry.seq).where(
                or_(*(and_(FeedEntry.kind == kind, FeedEntry.ref.in_(ids))
                      for kind, ids in wanted.items()))))
            return {(kind, ref): series.result_id(seq) for kind, ref, seq in rows}

    def renew_db_id(self, from_seq: int) -> Series:
        """The records from ``from_seq`` on are a new series (a new random id): the line
        has other records under this database's id at those sequence numbers, which a copy
        put back (a backup) numbered again.  The records before keep the id they had."""
        with self._session(True) as s:
            old = _series_in(s)
            if old.before is not None:   # renewed before: the records below that keep theirs
                put_meta(s, DB_ID_EARLIER, json.dumps(
                    [*old.earlier, (old.from_seq, old.before)]))
            put_meta(s, "db_id", str(uuid.uuid4()))
            put_meta(s, DB_ID_FROM, str(from_seq))
            put_meta(s, DB_ID_BEFORE, old.db_id)
            return _series_in(s)

    def record_command(self, *, at: datetime, user: str, source: str, kind: str,
                       vin: str | None, bolt: str | None, comment: str) -> int:
        """An accepted command, committed (with its feed entry) before it returns."""
        with self._session(True) as s:
            return add_command(s, at=at, user=user, source=source, kind=kind, vin=vin,
                               bolt=bolt, comment=comment)

    def commands(self, vin: str | None = None, *, since: datetime | None = None,
                 until: datetime | None = None) -> list[CommandEntry]:
        """The accepted commands (on ``vin``, or all; given from ``since`` and before
        ``until``), oldest first: the audit trail."""
        with self._session(False) as s:
            return commands_in(s, vin, since=since, until=until)

    def last_of(self, kinds: tuple[str, ...]) -> CommandEntry | None:
        """The last command of one of ``kinds`` (None: none ever)."""
        with self._session(False) as s:
            r = s.scalar(select(CommandRecord).where(CommandRecord.kind.in_(kinds))
                         .order_by(CommandRecord.id.desc()).limit(1))
            return None if r is None else _command(r)

    def skipped(self, vin: str, since: datetime | None) -> dict[str, tuple[str, str]]:
        """The bolts of ``vin`` skipped by a command since ``since`` (the vehicle's last
        opening: a rework starts afresh), with who skipped it and their comment."""
        with self._session(False) as s:
            q = select(CommandRecord).where(CommandRecord.vin == vin,
                                            CommandRecord.kind == "skip")
            if since is not None:
                q = q.where(CommandRecord.at >= since)
            return {str(r.bolt): (r.user, r.comment)
                    for r in s.scalars(q.order_by(CommandRecord.id))}

    def locked(self, vin: str, since: datetime | None,
               ends: frozenset[str]) -> frozenset[str]:
        """The bolts of ``vin`` the NOK policy locked since ``since`` (the vehicle's last
        opening) and no command of ``ends`` (a release, a skip) ended since."""
        with self._session(False) as s:
            q = select(CommandRecord).where(CommandRecord.vin == vin,
                                            CommandRecord.kind.in_((LOCK, *ends)))
            if since is not None:
                q = q.where(CommandRecord.at >= since)
            return open_locks([_command(r) for r in s.scalars(q.order_by(CommandRecord.id))],
                              None, ends)    # (``since`` asked of the database)

    def get_meta(self, key: str) -> str | None:
        with self._session(False) as s:
            return s.scalar(select(Meta.value).where(Meta.key == key))

    def set_meta(self, key: str, value: str) -> None:
        with self._session(True) as s:
            put_meta(s, key, value)

    def quarantine(self, seq: int, reason: str) -> None:
        """Keep feed entry ``seq`` aside: the line database refused it for good."""
        with self._session(True) as s:
            if s.get(ForwardQuarantine, seq) is None:
                s.add(ForwardQuarantine(seq=seq, reason=reason[:500]))

    def quarantined(self) -> list[dict[str, Any]]:
        """The quarantined entries, each with its reason and its record."""
        with self._session(False) as s:
            rows = list(s.scalars(select(ForwardQuarantine).order_by(ForwardQuarantine.seq)))
            out = []
            for q in rows:
                e = s.get_one(FeedEntry, q.seq)
                out.append({"seq": e.seq, "kind": e.kind, "at": e.at.isoformat(),
                            "record": _record(s, e.kind, e.ref), "reason": q.reason,
                            "quarantined_at": q.at.isoformat()})
            return out

    def release(self, seq: int) -> None:
        """A quarantined entry the line database took on a retry."""
        with self._session(True) as s:
            row = s.get(ForwardQuarantine, seq)
            if row is not None:
                s.delete(row)

    def last_seq(self) -> int:
        with self._session(False) as s:
            return int(s.scalar(select(func.max(FeedEntry.seq))) or 0)

    def results_in(self, after: int, last: int) -> int:
        """How many results (:func:`is_result`) the feed holds after the sequence number
        ``after`` up to ``last``: what a request for them is told it gets."""
        with self._session(False) as s:
            return int(s.scalar(select(func.count()).select_from(FeedEntry).where(
                FeedEntry.seq > after, FeedEntry.seq <= last, _results())) or 0)

    def since(self, seq: int, limit: int = FEED_LIMIT) -> list[dict[str, Any]]:
        """The feed after ``seq``, in order, each entry with its record (at most ``limit``)."""
        limit = max(1, min(int(limit), FEED_LIMIT))
        with self._session(False) as s:
            return _entries(s, list(s.scalars(select(FeedEntry).where(FeedEntry.seq > seq)
                                              .order_by(FeedEntry.seq).limit(limit))))

    # -- acknowledged over OPC UA (AcknowledgeResults / RequestUnacknowledgedResults) ---------
    def seq_before(self, at: datetime) -> int:
        """The last sequence number recorded before ``at`` (0: none): where a reader that
        wants the records from ``at`` on starts."""
        with self._session(False) as s:
            return int(s.scalar(select(func.max(FeedEntry.seq)).where(FeedEntry.at < at)) or 0)

    def acknowledge(self, seqs: list[int], by: str) -> set[int]:
        """Mark the results ``seqs`` acknowledged by ``by`` (already acknowledged ones stay
        as they were); the ones that are results of this database (:func:`is_result`),
        acknowledged now or before, are returned, the others are unknown."""
        wanted = sorted(set(seqs))
        with self._session(True) as s:
            known = set(s.scalars(select(FeedEntry.seq).where(
                FeedEntry.seq.in_(wanted), _results())))
            done = set(s.scalars(select(OpcUaAcknowledged.seq)
                                 .where(OpcUaAcknowledged.seq.in_(known))))
            for seq in sorted(known - done):
                s.add(OpcUaAcknowledged(seq=seq, acknowledged_by=by[:64]))
            return known

    def _unacknowledged(self) -> Any:
        return (select(FeedEntry)
                .outerjoin(OpcUaAcknowledged, OpcUaAcknowledged.seq == FeedEntry.seq)
                .where(_results(), OpcUaAcknowledged.seq.is_(None)))

    def unacknowledged(self, after: int, limit: int = FEED_LIMIT) -> list[dict[str, Any]]:
        """The results (:func:`is_result`) after ``after`` nobody acknowledged, in order
        (at most ``limit``), each as :meth:`since` gives it."""
        limit = max(1, min(int(limit), FEED_LIMIT))
        with self._session(False) as s:
            entries = list(s.scalars(self._unacknowledged().where(FeedEntry.seq > after)
                                     .order_by(FeedEntry.seq).limit(limit)))
            return [{"seq": e.seq, "kind": e.kind, "at": e.at.isoformat(),
                     "record": _record(s, e.kind, e.ref)} for e in entries]

    def unacknowledged_count(self) -> int:
        with self._session(False) as s:
            sub = self._unacknowledged().subquery()
            return int(s.scalar(select(func.count()).select_from(sub)) or 0)



def _series_in(s: Session) -> Series:
    """:meth:`Ledger.series` in the caller's transaction."""
    meta = {key: value for key, value in s.execute(select(Meta.key, Meta.value).where(
        Meta.key.in_(("db_id", DB_ID_FROM, DB_ID_BEFORE, DB_ID_EARLIER))))}
    start = meta.get(DB_ID_FROM)
    earlier = tuple((int(f), str(i)) for f, i in json.loads(meta.get(DB_ID_EARLIER) or "[]"))
    return Series(meta["db_id"], int(start) if start else 1, meta.get(DB_ID_BEFORE), earlier)


def commands_in(s: Session, vin: str | None = None, *, since: datetime | None = None,
                until: datetime | None = None) -> list[CommandEntry]:
    """:meth:`Ledger.commands` in the caller's transaction (a vehicle's close reads its
    holds with the commands that ended them, under its own write lock)."""
    q = select(CommandRecord).order_by(CommandRecord.id)
    if vin is not None:
        q = q.where(CommandRecord.vin == vin)
    if since is not None:
        q = q.where(CommandRecord.at >= since)
    if until is not None:
        q = q.where(CommandRecord.at < until)
    return [_command(r) for r in s.scalars(q)]


def open_locks(commands: Iterable[CommandEntry], since: datetime | None,
               ends: frozenset[str]) -> frozenset[str]:
    """The bolts a lock among ``commands`` (oldest first) left locked: locked by the NOK
    policy at or after ``since`` (the vehicle's last opening: a rework starts afresh) and
    ended by no command of ``ends`` (a release, a skip) since.  One rule for the station's
    start (:meth:`Ledger.locked`) and for the reports that show the locks."""
    last: dict[str, str] = {}
    for c in commands:
        if c.bolt is not None and c.kind in (LOCK, *ends) and (since is None or c.at >= since):
            last[c.bolt] = c.kind
    return frozenset(b for b, kind in last.items() if kind == LOCK)


def _command(r: CommandRecord) -> CommandEntry:
    return CommandEntry(r.id, r.at, r.user, r.source, r.kind, r.vin, r.bolt, r.comment)


def _iso(t: datetime | None) -> str | None:
    return None if t is None else t.isoformat()


def _version(p: ProcessParameters) -> dict[str, Any]:
    """The parameter version a rundown was tightened with, as plain values: the line keeps
    them beside the rundown, so two stations' bolts of one code (each its own table, or
    one table shared by a model) are told apart by what they were tightened to."""
    def window(target: float | None, lo: float | None, hi: float | None
               ) -> dict[str, float | None] | None:
        return None if target is None and lo is None and hi is None else \
            {"target": target, "min": lo, "max": hi}
    return {"version": p.version, "pset": p.pset,
            "torque": window(p.torque_target, p.torque_min, p.torque_max),
            "angle": window(p.angle_target, p.angle_min, p.angle_max)}


def _loosened_with(p: ProcessParameters, sent: Mapping[str, Any] | None) -> dict[str, Any]:
    """What a loosening ran: the loosen pset sent (the controller's own program: its limits
    are the controller's, not the bolt's tightening window, which would read a loosening at
    13 Nm as a NOK of a 45-55 Nm joint) and the bolt's version it belongs to."""
    return {"version": p.version, "pset": (sent or {}).get("pset"), "torque": None,
            "angle": None}


def _curve(s: Session, c: TighteningCurve) -> dict[str, Any]:
    """A curve as the feed carries it: whole (the line database has no other way to its
    samples), with the rundown it belongs to when that was known when it was stored
    (``record_id``, the vehicle and bolt); else the tightening id is the link, as for the
    rundown's own entry, which carries it too."""
    vin = bolt = None
    if c.record_id is not None:
        row = s.execute(select(Vehicle.vin, Bolt.code)
                        .join(TighteningRecord, TighteningRecord.vehicle_id == Vehicle.id)
                        .join(Bolt, TighteningRecord.bolt_id == Bolt.id)
                        .where(TighteningRecord.id == c.record_id)).first()
        if row is not None:
            vin, bolt = row
    return {"id": c.id, "record_id": c.record_id, "tightening_id": c.tightening_id,
            "vin": vin, "bolt": bolt, "trace_type": c.trace_type, "unit": c.unit,
            "sample_period_s": c.sample_period_s, "values": list(c.values),
            "times_s": None if c.times_s is None else list(c.times_s),
            "result_at": _iso(c.result_at), "recorded_at": _iso(c.recorded_at)}


def _rundowns(s: Session, refs: list[int]) -> dict[int, dict[str, Any]]:
    """The rundowns ``refs`` as plain values, by id, read in one query: a reader catching up
    (a forwarder draining a backlog) reads hundreds at once, and a query per rundown made
    the reading, not the line database, what limited the drain."""
    out: dict[int, dict[str, Any]] = {}
    if not refs:
        return out
    q = (select(TighteningRecord, Vehicle.vin, Bolt.code, VehicleModel.name, ProcessParameters)
         .join(Vehicle, TighteningRecord.vehicle_id == Vehicle.id)
         .join(Bolt, TighteningRecord.bolt_id == Bolt.id)
         .join(VehicleModel, Bolt.model_id == VehicleModel.id)
         .join(ProcessParameters, TighteningRecord.parameters_id == ProcessParameters.id)
         .where(TighteningRecord.id.in_(sorted(set(refs)))))
    for rec, vin, bolt, model, version in s.execute(q):
        out[rec.id] = {
            "id": rec.id, "vin": vin, "bolt": bolt, "status": rec.status,
            "rundown": rec.kind, "model": model,
            "parameters": _version(version) if rec.kind != LOOSENING
            else _loosened_with(version, rec.params_sent),
            "torque_nm": rec.torque_nm, "angle_deg": rec.angle_deg,
            "tightening_id": rec.tightening_id, "params_sent": rec.params_sent,
            "position_mm": [rec.x_mm, rec.y_mm, rec.z_mm],
            "match_distance_mm": rec.match_distance_mm, "tilt_deg": rec.tilt_deg,
            "sent_at": _iso(rec.sent_at), "result_at": _iso(rec.result_at),
            "recorded_at": _iso(rec.recorded_at), "operator": rec.operator,
            # an outcome a person entered from the controller's screen (None: measured):
            # who, why, and the unreadable result it resolves
            "entered_by": rec.entered_by, "entered_comment": rec.entered_comment,
            "unreadable_id": rec.unreadable_id,
            # fetched after a link cut: made while the link was down, taken at the reconnect
            "offline": rec.offline}
    return out


def _entries(s: Session, entries: list[FeedEntry]) -> list[dict[str, Any]]:
    """Feed entries with their records (the rundowns among them read at once)."""
    rundowns = _rundowns(s, [e.ref for e in entries if e.kind == RUNDOWN])
    return [{"seq": e.seq, "kind": e.kind, "at": e.at.isoformat(),
             "record": rundowns[e.ref] if e.kind == RUNDOWN else _record(s, e.kind, e.ref)}
            for e in entries]


def _record(s: Session, kind: str, ref: int) -> dict[str, Any]:
    """One record of the feed as plain values."""
    if kind == RUNDOWN:
        return _rundowns(s, [ref])[ref]
    if kind == UNATTRIBUTED:
        u = s.get_one(UnattributedResult, ref)
        return {"id": u.id, "vin": u.vin, "controller_vin": u.controller_vin,
                "tightening_id": u.tightening_id, "pset": u.pset, "status": u.status,
                "torque_nm": u.torque_nm, "angle_deg": u.angle_deg,
                "result_at": _iso(u.result_at), "recorded_at": _iso(u.recorded_at),
                "reason": u.reason, "result_type": u.result_type}
    if kind == CONTROLLER_EVENT:
        ev = s.get_one(ControllerEvent, ref)
        return {"id": ev.id, "result_type": ev.result_type, "what": ev.what, "vin": ev.vin,
                "bolt": ev.bolt, "controller_vin": ev.controller_vin,
                "tightening_id": ev.tightening_id, "pset": ev.pset, "status": ev.status,
                "torque_nm": ev.torque_nm, "angle_deg": ev.angle_deg,
                "result_at": _iso(ev.result_at), "recorded_at": _iso(ev.recorded_at),
                # why a bolt is held where no result says it (a link cut, a lost push: which
                # tightening may be its own); without it the line database had the hold but
                # not its reason (an MES integrator's trial)
                "note": ev.note}
    if kind == UNREADABLE:
        x = s.get_one(UnreadableRecord, ref)
        return {"id": x.id, "mid": x.mid, "revision": x.revision, "raw": x.raw,
                "error": x.error, "vin": x.vin, "bolt": x.bolt,
                "controller_vin": x.controller_vin, "tightening_id": x.tightening_id,
                "pset": x.pset, "result_at": _iso(x.result_at),
                "recorded_at": _iso(x.recorded_at)}
    if kind == GAP:
        g = s.get_one(ResultGap, ref)
        return {"id": g.id, "first_id": g.first_id, "last_id": g.last_id, "vin": g.vin,
                "reason": g.reason, "found_at": _iso(g.found_at)}
    if kind == CURVE:
        return _curve(s, s.get_one(TighteningCurve, ref))
    if kind == CLOSING:
        v = s.get_one(VehicleClosing, ref)
        return {"id": v.id, "vin": v.vehicle.vin, "model": v.vehicle.model.name,
                "closed_at": v.closed_at.isoformat(), "how": v.how, "bolts": v.bolts,
                "ok": v.ok, "nok": v.nok, "missing": v.missing, "skipped": v.skipped,
                "loosen": v.loosen, "not_ok": v.not_ok}
    if kind == CHECK:
        k = s.get_one(CalibrationCheck, ref)
        return {"id": k.id, "at": k.at.isoformat(), "pair": k.pair, "verdict": k.verdict,
                "reference": k.reference, "offset_mm": k.offset_mm,
                "tolerance_mm": k.tolerance_mm, "reason": k.reason,
                "references": k.references, "recorded_at": _iso(k.recorded_at)}
    c = _command(s.get_one(CommandRecord, ref))
    return {"id": c.id, "at": c.at.isoformat(), "user": c.user, "source": c.source,
            "kind": c.kind, "vin": c.vin, "bolt": c.bolt, "comment": c.comment}


__all__ = [
    "CHECK",
    "CLOSING",
    "COMMAND",
    "CONTROLLER_EVENT",
    "CURVE",
    "GAP",
    "LOWERED",
    "RESULT_KINDS",
    "RUNDOWN",
    "UNATTRIBUTED",
    "UNREADABLE",
    "UNSEEN",
    "CommandEntry",
    "Ledger",
    "add_command",
    "append",
    "commands_in",
    "is_result",
    "put_meta",
]
