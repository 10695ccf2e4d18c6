"""The results no bolt's rundown owns, kept whole: results no bolt owns (unattributed),
controller events (a batch step, a bypass, an OK without a type outside its window, a hold
without a result), result messages that could not be read, and tightening ids the station
could not get (gaps).

Why apart from the rundowns: none of them closes a bolt; each is counted (the feed, the
exports, the holds) and each write asks the copy rules (:mod:`db.copies`) so a result sent
again is stored once."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import select

from db.copies import COPY_SLACK, opt_float, same_result, unreadable_copy
from db.enables import settle
from db.engine import Transactions
from db.kinds import HELD_WITHOUT_RESULT, verdict
from db.ledger import CONTROLLER_EVENT, GAP, UNATTRIBUTED, UNREADABLE, append
from db.models import (
    Bolt,
    ControllerEvent,
    ResultGap,
    TighteningRecord,
    UnattributedResult,
    UnreadableRecord,
    Vehicle,
    utcnow,
)


class OtherResults:
    """The results no bolt's rundown owns, through the repository's transactions
    (``Repository.others``)."""

    def __init__(self, session: Transactions) -> None:
        self._session = session

    def record_unattributed(self, *, vin: str | None, controller_vin: str | None,
                            tightening_id: int | None, pset: int | None, ok: bool,
                            torque_nm: float | None, angle_deg: float | None,
                            result_at: datetime | None, reason: str,
                            result_type: int | None = None) -> int | None:
        """Store a result no bolt owns (``result_type``: the code as the controller sent it,
        None: none); return its id, or None when this very result is
        already stored, attributed or not (a resent copy: the same tightening id, torque and
        angle, and the same controller timestamp ``result_at`` where both have
        one, :func:`same_result`)."""
        torque, angle = opt_float(torque_nm), opt_float(angle_deg)
        with self._session(True) as s:
            if tightening_id is not None:
                for model, at in ((TighteningRecord, TighteningRecord.controller_at),
                                  (UnattributedResult, UnattributedResult.result_at)):
                    same = s.scalar(select(model.id).where(*same_result(
                        model, at, tightening_id, torque, angle, result_at)).limit(1))
                    if same is not None:
                        return None
            row = UnattributedResult(
                vin=vin, controller_vin=controller_vin, tightening_id=tightening_id, pset=pset,
                status=verdict(ok), torque_nm=torque, angle_deg=angle,
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
        have one, :func:`same_result`).
        ``enable_id``: the tool enable it answers, settled in the same transaction (its bolt
        is held for a person instead, :data:`db.kinds.NOT_TAKEN`).  ``note``: why a bolt is
        held where there is no result (:data:`db.kinds.CUT_UNKNOWN`), whose ``ok`` is None
        (no verdict: status NULL)."""
        with self._session(True) as s:
            # (a hold names the result it may be, which holds each bolt it may be: not copies)
            if tightening_id is not None and what not in HELD_WITHOUT_RESULT:
                same = s.execute(select(ControllerEvent.vin, ControllerEvent.bolt).where(
                    ControllerEvent.result_type == int(result_type),
                    *same_result(ControllerEvent, ControllerEvent.result_at, tightening_id,
                                 torque_nm, angle_deg, result_at)).limit(1)).first()
                if same is not None:
                    # only its own bolt's enable: another bolt's is still owed (as a rundown)
                    settle(s, enable_id, of=(same[0], same[1]))
                    return None
            row = ControllerEvent(
                result_type=int(result_type), what=what[:32], vin=vin, bolt=bolt,
                controller_vin=controller_vin, tightening_id=tightening_id, pset=pset,
                status=None if ok is None else verdict(ok),
                torque_nm=opt_float(torque_nm), angle_deg=opt_float(angle_deg),
                result_at=result_at, recorded_at=utcnow(),
                note=None if note is None else note[:500])
            s.add(row)
            settle(s, enable_id)
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
        with self._session(True) as s:
            if unreadable_copy(s, mid, raw, header_len) is not None:
                return None
            row = UnreadableRecord(
                mid=int(mid), revision=int(revision), raw=raw, error=error[:500], vin=vin,
                bolt=bolt, controller_vin=controller_vin, tightening_id=tightening_id,
                pset=pset, result_at=result_at, recorded_at=utcnow())
            s.add(row)
            settle(s, enable_id)
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
        with self._session(False) as s:
            row = unreadable_copy(s, mid, raw, header_len)
            return None if row is None else (row.vin, row.bolt)

    def unreadable_of(self, *, tightening_id: int, pset: int | None, at: datetime | None,
                      made: datetime | None = None) -> tuple[str | None, str | None] | None:
        """The vehicle and bolt of a stored unreadable message a readable result is the
        copy of: its tightening id, and its pset and controller time where they could be
        picked out of it (and the result has one); else None.  Where a controller time is
        missing on either side, a result ``made`` (on the station's clock, where the
        controller's is known) after the message was stored is not its copy: another
        result under the same id, from a controller whose ids started again."""
        with self._session(False) as s:
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
        with self._session(False) as s:
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
        with self._session(False) as s:
            q = select(UnreadableRecord).order_by(UnreadableRecord.id)
            if vin is not None:
                q = q.where(UnreadableRecord.vin == vin)
            return [{"id": x.id, "mid": x.mid, "revision": x.revision, "raw": x.raw,
                     "error": x.error,
                     "vin": x.vin, "bolt": x.bolt, "controller_vin": x.controller_vin,
                     "tightening_id": x.tightening_id, "pset": x.pset,
                     "result_at": x.result_at, "recorded_at": x.recorded_at}
                    for x in s.scalars(q)]

    def record_gap(self, first_id: int, last_id: int, vin: str | None, reason: str) -> int:
        """Tightening ids the station could not get (the controller no longer has them)."""
        with self._session(True) as s:
            row = ResultGap(first_id=first_id, last_id=last_id, vin=vin, reason=reason[:200])
            s.add(row)
            s.flush()
            append(s, GAP, row.id, row.found_at)
            return row.id

    def gaps(self) -> list[dict[str, Any]]:
        with self._session(False) as s:
            return [{"first_id": g.first_id, "last_id": g.last_id, "vin": g.vin,
                     "reason": g.reason, "found_at": g.found_at}
                    for g in s.scalars(select(ResultGap).order_by(ResultGap.id))]

    def unattributed(self, vin: str | None = None) -> list[dict[str, Any]]:
        """The stored results no bolt owns (of ``vin``, or all), oldest first.  Each with
        ``entered_as``: the bolt and the person (``{"bolt", "by"}``) whose entered outcome is
        that result (the outcome of a bolt held because it may be its own, entered from the
        controller's screen; a quality trial: the one tightening read as two), else None."""
        with self._session(False) as s:
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
