"""How a result the controller sent again is told from another result: the rules every
write of a result asks before storing it (a copy is stored once, and never taken for the
result of another bolt).

Why in one module: the rundowns (:mod:`db.repository`) and the results no bolt's rundown owns
(:mod:`db.others`) are checked against each other's tables by the same rule."""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import ColumnElement, null, or_, select
from sqlalchemy.orm import Session

from db.models import (
    Bolt,
    ControllerEvent,
    TighteningRecord,
    UnattributedResult,
    UnreadableRecord,
    Vehicle,
)

#: the controller stamps its results to the second, its clock's offset measured to the
#: second: a result made within this much of an unreadable message's arrival may be its copy
COPY_SLACK = timedelta(seconds=2)


@dataclass(frozen=True)
class StoredResult:
    """A stored result that a result from the controller is the very copy of
    (:meth:`Repository.stored_result`): its id, and the vehicle and bolt it is of (None: a
    result no bolt owns, stored unattributed, or a controller event of no bolt; ``vin`` None
    where no vehicle was at height)."""

    id: int
    vin: str | None
    bolt: str | None


def same_result(model: Any, at: Any, tightening_id: int, torque_nm: float | None,
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
    return [model.tightening_id == int(tightening_id), model.torque_nm == opt_float(torque_nm),
            model.angle_deg == opt_float(angle_deg)]


def _copy_of(model: Any, at: Any, vin: Any, tightening_id: int, torque_nm: float | None,
             angle_deg: float | None, controller_at: datetime | None,
             vins: Collection[str]) -> list[ColumnElement[bool]]:
    """:func:`stored_copy`'s rule on a row of ``model`` (``at``: its column of the
    controller's timestamp, ``vin``: of its vehicle): the same values, and the same
    timestamp on any vehicle, or where either lacks one, a vehicle of ``vins``."""
    within = vin.in_(list(vins))
    return [*_same_values(model, tightening_id, torque_nm, angle_deg),
            or_(at == controller_at, at.is_(None) & within) if controller_at is not None
            else within]


def unreadable_copy(s: Session, mid: int, raw: str, header_len: int
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


def stored_copy(s: Session, tightening_id: int, torque_nm: float | None,
                angle_deg: float | None, controller_at: datetime | None,
                vins: Collection[str], *, others: bool = True) -> StoredResult | None:
    """The tightening record a result is the very copy of: :func:`same_result`'s id and
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


def opt_float(v: float | None) -> float | None:
    return None if v is None else float(v)
