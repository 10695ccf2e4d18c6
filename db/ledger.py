"""The append-only side of the database: the results feed, the commands people gave, and the
database's own id.

Why apart from the repository: the repository keeps the bolt tables and the vehicles' state;
this keeps what only grows and is read in order by others (a forwarder to a line database, an
MES, the audit trail).  :func:`append` is called by every writer of a record inside its own
transaction, so a record and its feed entry are committed together or not at all.
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from db.models import (
    Bolt,
    CalibrationCheck,
    CommandRecord,
    FeedEntry,
    ForwardQuarantine,
    Meta,
    OpcUaAcknowledged,
    ResultGap,
    TighteningRecord,
    UnattributedResult,
    Vehicle,
)

#: the kinds of records the feed carries, each in its own table
RUNDOWN, UNATTRIBUTED, COMMAND, GAP = "rundown", "unattributed", "command", "gap"
CHECK = "check"   # a camera pair's calibration check (db.checks)
FEED_LIMIT = 1000


def append(s: Session, kind: str, ref: int) -> None:
    """The next sequence number for the record ``ref`` of ``kind`` (in the caller's
    transaction)."""
    s.add(FeedEntry(kind=kind, ref=ref))


def add_command(s: Session, *, at: datetime, user: str, source: str, kind: str,
                vin: str | None, bolt: str | None, comment: str) -> int:
    """An accepted command and its feed entry, in the caller's transaction."""
    row = CommandRecord(at=at, user=user[:64], source=source[:100], kind=kind, vin=vin,
                        bolt=bolt, comment=comment[:500])
    s.add(row)
    s.flush()
    append(s, COMMAND, row.id)
    return row.id


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

    def __init__(self, session: Callable[[bool], AbstractContextManager[Session]]) -> None:
        self._session = session

    def db_id(self) -> str:
        """The id this database got when it was created."""
        with self._session(False) as s:
            return str(s.scalar(select(Meta.value).where(Meta.key == "db_id")))

    def record_command(self, *, at: datetime, user: str, source: str, kind: str,
                       vin: str | None, bolt: str | None, comment: str) -> int:
        """An accepted command, committed (with its feed entry) before it returns."""
        with self._session(True) as s:
            return add_command(s, at=at, user=user, source=source, kind=kind, vin=vin,
                               bolt=bolt, comment=comment)

    def commands(self, vin: str | None = None) -> list[CommandEntry]:
        """The accepted commands (on ``vin``, or all), oldest first: the audit trail."""
        with self._session(False) as s:
            q = select(CommandRecord).order_by(CommandRecord.id)
            if vin is not None:
                q = q.where(CommandRecord.vin == vin)
            return [_command(r) for r in s.scalars(q)]

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

    def get_meta(self, key: str) -> str | None:
        with self._session(False) as s:
            return s.scalar(select(Meta.value).where(Meta.key == key))

    def set_meta(self, key: str, value: str) -> None:
        with self._session(True) as s:
            row = s.get(Meta, key)
            if row is None:
                s.add(Meta(key=key, value=value))
            else:
                row.value = value

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

    def since(self, seq: int, limit: int = FEED_LIMIT) -> list[dict[str, Any]]:
        """The feed after ``seq``, in order, each entry with its record (at most ``limit``)."""
        limit = max(1, min(int(limit), FEED_LIMIT))
        with self._session(False) as s:
            entries = list(s.scalars(select(FeedEntry).where(FeedEntry.seq > seq)
                                     .order_by(FeedEntry.seq).limit(limit)))
            return [{"seq": e.seq, "kind": e.kind, "at": e.at.isoformat(),
                     "record": _record(s, e.kind, e.ref)} for e in entries]

    # -- acknowledged over OPC UA (AcknowledgeResults / RequestUnacknowledgedResults) ---------
    def seq_before(self, at: datetime) -> int:
        """The last sequence number recorded before ``at`` (0: none): where a reader that
        wants the records from ``at`` on starts."""
        with self._session(False) as s:
            return int(s.scalar(select(func.max(FeedEntry.seq)).where(FeedEntry.at < at)) or 0)

    def acknowledge(self, seqs: list[int], by: str) -> set[int]:
        """Mark the rundowns ``seqs`` acknowledged by ``by`` (already acknowledged ones stay
        as they were); the ones that are rundowns of this database, acknowledged now or
        before, are returned, the others are unknown."""
        wanted = sorted(set(seqs))
        with self._session(True) as s:
            known = set(s.scalars(select(FeedEntry.seq).where(FeedEntry.seq.in_(wanted),
                                                             FeedEntry.kind == RUNDOWN)))
            done = set(s.scalars(select(OpcUaAcknowledged.seq)
                                 .where(OpcUaAcknowledged.seq.in_(known))))
            for seq in sorted(known - done):
                s.add(OpcUaAcknowledged(seq=seq, acknowledged_by=by[:64]))
            return known

    def _unacknowledged(self) -> Any:
        return (select(FeedEntry)
                .outerjoin(OpcUaAcknowledged, OpcUaAcknowledged.seq == FeedEntry.seq)
                .where(FeedEntry.kind == RUNDOWN, OpcUaAcknowledged.seq.is_(None)))

    def unacknowledged(self, after: int, limit: int = FEED_LIMIT) -> list[dict[str, Any]]:
        """The rundowns after ``after`` nobody acknowledged, in order (at most ``limit``),
        each as :meth:`since` gives it."""
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



def _command(r: CommandRecord) -> CommandEntry:
    return CommandEntry(r.id, r.at, r.user, r.source, r.kind, r.vin, r.bolt, r.comment)


def _iso(t: datetime | None) -> str | None:
    return None if t is None else t.isoformat()


def _record(s: Session, kind: str, ref: int) -> dict[str, Any]:
    """One record of the feed as plain values."""
    if kind == RUNDOWN:
        row = s.execute(select(TighteningRecord, Vehicle.vin, Bolt.code)
                        .join(Vehicle, TighteningRecord.vehicle_id == Vehicle.id)
                        .join(Bolt, TighteningRecord.bolt_id == Bolt.id)
                        .where(TighteningRecord.id == ref)).one()
        rec, vin, bolt = row
        return {"id": rec.id, "vin": vin, "bolt": bolt, "status": rec.status,
                "rundown": rec.kind,
                "torque_nm": rec.torque_nm, "angle_deg": rec.angle_deg,
                "tightening_id": rec.tightening_id, "params_sent": rec.params_sent,
                "position_mm": [rec.x_mm, rec.y_mm, rec.z_mm],
                "match_distance_mm": rec.match_distance_mm, "tilt_deg": rec.tilt_deg,
                "sent_at": _iso(rec.sent_at), "result_at": _iso(rec.result_at),
                "recorded_at": _iso(rec.recorded_at)}
    if kind == UNATTRIBUTED:
        u = s.get_one(UnattributedResult, ref)
        return {"id": u.id, "vin": u.vin, "controller_vin": u.controller_vin,
                "tightening_id": u.tightening_id, "pset": u.pset, "status": u.status,
                "torque_nm": u.torque_nm, "angle_deg": u.angle_deg,
                "result_at": _iso(u.result_at), "recorded_at": _iso(u.recorded_at),
                "reason": u.reason}
    if kind == GAP:
        g = s.get_one(ResultGap, ref)
        return {"id": g.id, "first_id": g.first_id, "last_id": g.last_id, "vin": g.vin,
                "reason": g.reason, "found_at": _iso(g.found_at)}
    if kind == CHECK:
        k = s.get_one(CalibrationCheck, ref)
        return {"id": k.id, "at": k.at.isoformat(), "pair": k.pair, "verdict": k.verdict,
                "reference": k.reference, "offset_mm": k.offset_mm,
                "tolerance_mm": k.tolerance_mm, "reason": k.reason,
                "references": k.references, "recorded_at": _iso(k.recorded_at)}
    c = _command(s.get_one(CommandRecord, ref))
    return {"id": c.id, "at": c.at.isoformat(), "user": c.user, "source": c.source,
            "kind": c.kind, "vin": c.vin, "bolt": c.bolt, "comment": c.comment}


__all__ = ["CHECK", "COMMAND", "GAP", "RUNDOWN", "UNATTRIBUTED", "CommandEntry", "Ledger",
           "add_command", "append"]
