"""Which bolts of a vehicle are held for a person, and which holds a supervisor released,
read back from the records: a hold outlives a restart, and so does the warning its release
leaves (the bolt may be tightened already).

Why apart from the repository: both answers fold the same three records (the holds stored,
each bolt's last rundown, the commands that end a hold) and nothing else in it does."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from db.kinds import (
    CUT_UNKNOWN,
    HELD_WITH_RESULT,
    HELD_WITHOUT_RESULT,
    NOT_TAKEN,
    UNKNOWN_TYPE_HELD,
    HeldUnder,
    not_taken_note,
    unknown_type_note,
    unreadable_note,
)
from db.ledger import CommandEntry
from db.models import Bolt, ControllerEvent, TighteningRecord, ToolEnable, UnreadableRecord, Vehicle

#: the commands that end a bolt's lock (its NOKs in a row) or its hold: a release, and a skip
#: (the station takes a skip of a locked or held bolt only from a user who may release it)
RELEASE = "release"
ENDS_A_HOLD = frozenset({RELEASE, "skip"})


@dataclass(frozen=True)
class _Stored:
    """A bolt's last hold as stored: its note, when, the pset it names, and whether it is an
    unreadable result's (its enable is looked up for what it came under)."""

    note: str
    at: datetime
    pset: int | None
    unreadable: bool


def open_holds(s: Session, vin: str, commands: Sequence[CommandEntry],
               since: datetime | None = None) -> dict[str, tuple[str, HeldUnder]]:
    """The bolts of ``vin`` held now (bolt -> its note and what its result came
    under): a hold stored after the bolt's last rundown and the last command that ended one
    (``commands``: the vehicle's, oldest first)."""
    held = _ended_by_rundowns(s, vin, _stored(s, vin, since))
    for c in commands:
        if c.kind in ENDS_A_HOLD and c.bolt in held and c.at >= held[c.bolt].at:
            del held[c.bolt]
    return {b: (h.note, _under(s, vin, b, h.at, h.pset) if h.unreadable
                else HeldUnder(False, h.pset)) for b, h in held.items()}


def released_holds(s: Session, vin: str, commands: Sequence[CommandEntry],
                   since: datetime | None = None) -> frozenset[str]:
    """The bolts of ``vin`` whose last hold a person released and that have no rundown
    since the release: open again, though they may be tightened already (the operator checks
    the controller first)."""
    held = _stored(s, vin, since)
    released: dict[str, datetime] = {}
    for c in commands:
        if c.bolt in held and c.at >= held[c.bolt].at and c.kind in ENDS_A_HOLD:
            if c.kind == RELEASE:
                released.setdefault(c.bolt, c.at)
            else:
                released.pop(c.bolt, None)
    last = _last_rundowns(s, vin)
    return frozenset(b for b, at in released.items() if b not in last or last[b] < at)


def _stored(s: Session, vin: str, since: datetime | None) -> dict[str, _Stored]:
    """Each bolt's last hold stored (since ``since``): an unreadable result of it, an OK
    without a type outside its window, a hold without a result."""
    q = select(UnreadableRecord.bolt, UnreadableRecord.recorded_at,
               UnreadableRecord.tightening_id, UnreadableRecord.mid,
               UnreadableRecord.revision, UnreadableRecord.pset).where(
        UnreadableRecord.vin == vin, UnreadableRecord.bolt.is_not(None))
    n = select(ControllerEvent.bolt, ControllerEvent.recorded_at,
               ControllerEvent.tightening_id, ControllerEvent.torque_nm,
               ControllerEvent.pset, ControllerEvent.what, ControllerEvent.note,
               ControllerEvent.result_type).where(
        ControllerEvent.vin == vin, ControllerEvent.bolt.is_not(None),
        ControllerEvent.what.in_((*HELD_WITH_RESULT, *HELD_WITHOUT_RESULT)))
    if since is not None:
        q = q.where(UnreadableRecord.recorded_at >= since)
        n = n.where(ControllerEvent.recorded_at >= since)
    holds = [(str(b), _Stored(unreadable_note(tid, mid, rev), at, pset, True))
             for b, at, tid, mid, rev, pset in s.execute(q.order_by(UnreadableRecord.id))]
    # an untyped OK came under the tightening pset; what a result of an unknown type (it may
    # be a loosening's, under a loosen pset: a review) and a link cut's enable came under is
    # looked up
    holds += [(str(b), _Stored(not_taken_note(torque, tid), at, pset, False)
               if what == NOT_TAKEN else
               _Stored(unknown_type_note(code, tid), at, pset, True)
               if what == UNKNOWN_TYPE_HELD else _Stored(note or CUT_UNKNOWN, at, pset, True))
              for b, at, tid, torque, pset, what, note, code
              in s.execute(n.order_by(ControllerEvent.id))]
    return dict(sorted(holds, key=lambda h: h[1].at))


def _last_rundowns(s: Session, vin: str) -> dict[str, datetime]:
    """Each bolt's last rundown recorded, when."""
    return {str(code): at for code, at in s.execute(
        select(Bolt.code, func.max(TighteningRecord.recorded_at))
        .join(Bolt, TighteningRecord.bolt_id == Bolt.id)
        .join(Vehicle, TighteningRecord.vehicle_id == Vehicle.id)
        .where(Vehicle.vin == vin).group_by(Bolt.code)) if at is not None}


def _ended_by_rundowns(s: Session, vin: str, held: dict[str, _Stored]
                       ) -> dict[str, _Stored]:
    """``held`` without the holds a rundown of their bolt came after."""
    if not held:
        return held
    last = _last_rundowns(s, vin)
    return {b: h for b, h in held.items() if b not in last or last[b] < h.at}


def _under(s: Session, vin: str, bolt: str, at: datetime, pset: int | None) -> HeldUnder:
    """What an unreadable result stored at ``at`` for ``bolt`` of ``vin`` came under: the
    latest tool enable of that bolt noted before it (its selection says whether it was the
    loosen pset: stored with every enable since loosen psets exist, so one without the flag
    was a tightening's); none: ``loosen`` unknown, the result's own ``pset``."""
    enable = s.scalar(select(ToolEnable).where(
        ToolEnable.vin == vin, ToolEnable.bolt == bolt, ToolEnable.enabled_at <= at)
        .order_by(ToolEnable.enabled_at.desc(), ToolEnable.id.desc()).limit(1))
    if enable is None:
        return HeldUnder(None, pset)
    return HeldUnder(bool((enable.selection or {}).get("loosen", False)),
                     enable.pset if enable.pset is not None else pset)
