"""A vehicle's report: each bolt of its model with its last result, and the bolts missing.

Why the *last* record decides a bolt's status: a bolt tightened OK and then hit again with a
NOK result (a double hit, a loosened joint) must not pass as OK; rework that ends OK clears a
NOK.  A bolt loosened last is not done (``loosened``), nor is one a loosen command reopened
since its last rundown (``loosen``: the rework ordered is not done yet).  Bolts retired from
the table after the vehicle was tightened still appear, with their records, so a report never
loses what was done.

A bolt never run down that a person skipped by a command since the vehicle's last opening
(its ``skip`` in the command ledger) is ``skipped``, with who skipped it and their comment,
not ``missing``: quality reads the export, and a bolt left out on purpose, with a reason and a
name, is not one forgotten.  Neither is tightened: the vehicle is not complete with either.
A bolt run down before it was skipped keeps its last rundown's status (a NOK stays a NOK).
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.counting import counted
from db.kinds import (
    LOOSENED,
    LOOSENING,
    MISSING,
    NOK,
    OK,
    SKIPPED,
    TIGHTENING,
    TO_LOOSEN,
    BoltStatus,
)
from db.models import (
    AT_STATION,
    Bolt,
    CommandRecord,
    Meta,
    ProcessParameters,
    TighteningRecord,
    Vehicle,
    VehicleClosing,
)

__all__ = ["LOOSENED", "MISSING", "NOK", "OK", "SKIPPED", "TO_LOOSEN", "BoltResult",
           "VehicleInfo", "VehicleReport", "build_report"]


@dataclass(frozen=True)
class VehicleInfo:
    vin: str
    model: str
    started_at: datetime
    ended_at: datetime | None
    reopened_at: datetime | None = None   # the last reopening for rework
    #: reopened for rework and not back at the station yet (open in the database, worked
    #: nowhere: "open" read as if it were on the lift, a newcomer's trial)
    waiting: bool = False
    #: when it first left the station (its first close, kept through reworks: ``ended_at`` is
    #: the last); None: never closed, or closed before closings were kept (migration 0021)
    first_closed_at: datetime | None = None
    #: when it last left the station (its last close kept): a vehicle reopened for rework
    #: and not back yet left then (``ended_at`` is None since the reopening)
    last_closed_at: datetime | None = None

    @property
    def rework(self) -> bool:
        """Reopened after it was closed: the bolts tightened now are rework."""
        return self.reopened_at is not None


@dataclass(frozen=True)
class BoltResult:
    bolt_id: str
    name: str
    status: BoltStatus               # ok | nok | missing | skipped | loosened | loosen
    attempts: int
    torque_nm: float | None = None   # of the last record
    angle_deg: float | None = None
    tightening_id: int | None = None
    recorded_at: datetime | None = None
    version: int | None = None       # the parameter version the last record was tightened with
    retired: bool = False            # no longer in the bolt table
    kind: str | None = None          # the last record's: tightening or loosening
    #: a skipped bolt's (or one skipped after its last rundown, its status that rundown's):
    #: who skipped it, and why
    skipped_by: str | None = None
    comment: str | None = None
    skipped_at: datetime | None = None   # ... and when

    def to_json(self) -> dict[str, Any]:
        return {"bolt": self.bolt_id, "name": self.name, "status": self.status,
                "kind": self.kind, "skipped_by": self.skipped_by, "comment": self.comment,
                "skipped_at": _iso(self.skipped_at),
                "attempts": self.attempts, "torque_nm": self.torque_nm,
                "angle_deg": self.angle_deg, "tightening_id": self.tightening_id,
                "recorded_at": _iso(self.recorded_at), "parameter_version": self.version,
                "retired": self.retired}


@dataclass(frozen=True)
class VehicleReport:
    vehicle: VehicleInfo
    bolts: tuple[BoltResult, ...]
    #: the vehicle's tightening rundowns, and those of them NOK (a loosening is neither): NOK
    #: results, which a bolt tightened again to OK keeps, beside the bolts ending NOK
    tightenings: int = 0
    nok_results: int = 0
    loosenings: int = 0
    #: the bolts held for a person (bolt -> which result: its result could not be read, an
    #: untyped OK outside its window, a link cut that left it unknown): whatever their
    #: status says, their last result is not known (a quality trial: "B47 MISSING" with no
    #: word of its hold but at the bottom of the report)
    held: tuple[tuple[str, str], ...] = ()
    #: the bolts the NOK policy locked since the vehicle's last opening and no release or
    #: skip ended (read with ``held``): they wait for a supervisor's check and release
    locked: tuple[str, ...] = ()

    @property
    def missing(self) -> list[str]:
        return [b.bolt_id for b in self.bolts if b.status == MISSING]

    @property
    def skipped(self) -> list[str]:
        """Bolts never run down because a person skipped them (module docstring)."""
        return [b.bolt_id for b in self.bolts if b.status == SKIPPED]

    @property
    def untightened(self) -> list[str]:
        """Bolts never run down, skipped or not (in the table's order): what a vehicle
        leaving now leaves undone."""
        return [b.bolt_id for b in self.bolts if b.status in (MISSING, SKIPPED)]

    @property
    def nok(self) -> list[str]:
        return [b.bolt_id for b in self.bolts if b.status == NOK]

    @property
    def ok(self) -> list[str]:
        return [b.bolt_id for b in self.bolts if b.status == OK]

    @property
    def loosen(self) -> list[str]:
        """Bolts loosened last or to be loosened: to be tightened again."""
        return [b.bolt_id for b in self.bolts if b.status in (LOOSENED, TO_LOOSEN)]

    @property
    def complete(self) -> bool:
        """Every bolt of the model tightened, and every last result an OK tightening."""
        return not self.untightened and not self.nok and not self.loosen

    def summary(self) -> str:
        """One line in the screens' words (a vehicle's page): the bolts by their last rundown,
        then the rundowns: "bolts: 5 OK, 0 ending NOK, 0 skipped, 45 missing; rundowns: 8
        tightenings, 3 NOK results".  Why both: "5 ok, 0 NOK" for a vehicle with 3 NOK
        results read as no NOK at all; the bolts ending NOK decide the vehicle, the NOK results
        are what quality counts."""
        v = self.vehicle
        state = "closed" if v.ended_at is not None else "open"
        state += ", reworked" if v.rework else ""
        if v.waiting and v.reopened_at is not None:
            state = f"reopened for rework at {v.reopened_at:%Y-%m-%d %H:%M:%S} UTC, not " \
                    "back at the station yet"
        return f"{v.vin} ({v.model}, {state}): {self.counts()}"

    def counts(self, due: tuple[str, ...] = ()) -> str:
        """The summary's counts alone ("bolts: 5 OK, ...; rundowns: ..."): also the
        journal's line of a vehicle that closes, so the journal and ``db report`` say one
        thing in one way.  ``due``: bolts whose result is still due from the controller (the
        station's word as a vehicle closes): counted apart, "1 result due (B07)", not by
        what their records say so far (a supervisor's trial: "ending NOK" for a bolt whose
        OK was recorded a moment later)."""
        ok = [b for b in self.ok if b not in due]
        text = f"bolts: {len(ok)} OK"
        nok = [b.bolt_id + (f" skipped by {b.skipped_by}" if b.skipped_by else "")
               for b in self.bolts if b.status == NOK and b.bolt_id not in due]
        text += f", {len(nok)} ending NOK ({', '.join(nok)})" if nok else ", 0 ending NOK"
        who = [f"{b.bolt_id} by {b.skipped_by}" + (f": {b.comment}" if b.comment else "")
               for b in self.bolts if b.status == SKIPPED and b.bolt_id not in due]
        text += f", {len(who)} skipped ({'; '.join(who)})" if who else ", 0 skipped"
        missing = [b for b in self.missing if b not in due]
        text += f", {len(missing)} missing ({_first(missing)})" if missing else ", 0 missing"
        loosen = [b for b in self.loosen if b not in due]
        if loosen:
            text += f", {len(loosen)} to tighten again ({', '.join(loosen)})"
        if due:
            text += f", {len(due)} result due ({', '.join(due)})"
        if self.held:
            text += f", {len(self.held)} held ({', '.join(b for b, _ in self.held)})"
        # the loosenings too, where there were any: the demo's line read-back counted them
        # beside the tightenings and a reader could not reconcile the two
        return text + (f"; rundowns: {counted(self.tightenings, 'tightening')}, "
                       f"{counted(self.nok_results, 'NOK result')}") + (
            f", {counted(self.loosenings, 'loosening')}" if self.loosenings else "")

    def to_json(self) -> dict[str, Any]:
        v = self.vehicle
        return {"vin": v.vin, "model": v.model, "started_at": _iso(v.started_at),
                "ended_at": _iso(v.ended_at), "reopened_at": _iso(v.reopened_at),
                "first_closed_at": _iso(v.first_closed_at),
                "waiting": v.waiting,
                "complete": self.complete, "ok": self.ok,
                "nok": self.nok, "missing": self.missing, "skipped": self.skipped,
                "loosen": self.loosen, "tightenings": self.tightenings,
                "nok_results": self.nok_results, "loosenings": self.loosenings,
                "held": dict(self.held), "locked": list(self.locked),
                "bolts": [b.to_json() for b in self.bolts]}


def _iso(t: datetime | None) -> str | None:
    return None if t is None else t.isoformat()


def _left_without_rundown(v: Vehicle, last: VehicleClosing | None
                          ) -> tuple[frozenset[str], bool] | None:
    """The bolts the vehicle left without a rundown (missing, skipped, held: named by its
    ``last`` close), and whether that close is its last word (closed, not reopened since);
    None for a vehicle never closed, or closed before closes were kept (its model's table as
    it is now)."""
    if last is None:
        return None
    left = frozenset(bolt for bolts in last.not_ok.values() for bolt in bolts)
    return left, v.ended_at is not None and last.closed_at == v.ended_at


def _of_vehicle(b: Bolt, v: Vehicle, left: tuple[frozenset[str], bool] | None) -> bool:
    """Whether bolt ``b``, with no rundown on ``v``, is one of its bolts.  A closed vehicle
    keeps the bolts it left with (``left``): a bolt the table took out after it left was
    still missing on it, one the table added after was never its own (a process engineer's
    trial: a vehicle that left with a bolt missing read complete for the next model year's
    table, a complete one incomplete).  An open vehicle goes by the table now: a bolt taken
    out is no longer to do (the station stops asking for it), unless its whole model was
    (renamed under the vehicle at the station: the vehicle keeps the bolts it was started
    with, or it left "complete" with most of them never tightened; not those taken out
    before it was started).  A vehicle reopened for rework (or being closed again) keeps
    too the bolts its last close left without a rundown: a bolt taken out of the table since
    is still not tightened on it (a reopening and a close made it read complete)."""
    if left is not None and left[1]:
        return b.code in left[0]
    return b.removed_at is None or (v.model.removed_at is not None
                                    and b.removed_at >= v.started_at) or (
        left is not None and b.code in left[0])


def build_report(s: Session, v: Vehicle) -> VehicleReport:
    records = s.execute(
        select(TighteningRecord, ProcessParameters.version)
        .join(ProcessParameters, TighteningRecord.parameters_id == ProcessParameters.id)
        .where(TighteningRecord.vehicle_id == v.id)
        .order_by(TighteningRecord.recorded_at, TighteningRecord.id)).all()
    by_bolt: dict[int, list[tuple[TighteningRecord, int]]] = {}
    for rec, version in records:
        by_bolt.setdefault(rec.bolt_id, []).append((rec, version))
    bolts = list(s.scalars(select(Bolt).where(Bolt.model_id == v.model_id)
                           .order_by(Bolt.seq, Bolt.code)))
    loosen_ordered: dict[str, datetime] = {}   # bolt -> its last loosen command
    for bolt, at in s.execute(select(CommandRecord.bolt, CommandRecord.at).where(
            CommandRecord.vin == v.vin, CommandRecord.kind == "loosen")
            .order_by(CommandRecord.id)):
        if bolt is not None:
            loosen_ordered[bolt] = at
    # bolt -> who skipped it, why and when, since opening
    skips: dict[str, tuple[str, str, datetime]] = {}
    for bolt, user, comment, at in s.execute(select(
            CommandRecord.bolt, CommandRecord.user, CommandRecord.comment, CommandRecord.at)
            .where(CommandRecord.vin == v.vin, CommandRecord.kind == "skip",
                   CommandRecord.at >= (v.reopened_at or v.started_at))
            .order_by(CommandRecord.id)):
        if bolt is not None:
            skips[bolt] = (user, comment, at)
    closes = list(s.scalars(select(VehicleClosing).where(VehicleClosing.vehicle_id == v.id)
                            .order_by(VehicleClosing.id)))
    left = _left_without_rundown(v, closes[-1] if closes else None)
    results = []
    for b in bolts:
        recs = by_bolt.get(b.id, [])
        if not recs and not _of_vehicle(b, v, left):
            continue
        if not recs:
            who = skips.get(b.code)
            results.append(BoltResult(b.code, b.name, MISSING, 0) if who is None else
                           BoltResult(b.code, b.name, SKIPPED, 0, skipped_by=who[0],
                                      comment=who[1] or None, skipped_at=who[2]))
            continue
        last, version = recs[-1]
        # skipped by a person after its last rundown (a bolt locked after its NOKs, a
        # supervisor deciding it is not to be tightened here): its status stays its last
        # rundown's (the joint is NOK, not untouched), with who skipped it and why (the
        # decision was only in the command list)
        who = skips.get(b.code)
        skipped = who is not None and who[2] >= last.recorded_at
        results.append(BoltResult(b.code, b.name, _status(last, loosen_ordered.get(b.code)),
                                  len(recs), last.torque_nm, last.angle_deg, last.tightening_id,
                                  last.recorded_at, version, b.removed_at is not None,
                                  last.kind or TIGHTENING,
                                  skipped_by=who[0] if skipped and who else None,
                                  comment=(who[1] or None) if skipped and who else None,
                                  skipped_at=who[2] if skipped and who else None))
    here = s.get(Meta, AT_STATION)
    waiting = v.ended_at is None and v.reopened_at is not None and (
        here is None or here.value != v.vin)
    first = min((c.closed_at for c in closes), default=None)
    last_close = max((c.closed_at for c in closes), default=None)
    info = VehicleInfo(v.vin, v.model.name, v.started_at, v.ended_at, v.reopened_at, waiting,
                       first, last_close)
    tightenings = [rec for rec, _ in records if (rec.kind or TIGHTENING) == TIGHTENING]
    return VehicleReport(info, tuple(results), len(tightenings),
                         sum(1 for rec in tightenings if rec.status == NOK),
                         len(records) - len(tightenings))


#: missing bolts named in a vehicle's line; the rest are counted (the report lists each
#: one below it: 45 names made the journal's and the report's line 700 characters long)
MISSING_NAMED = 10


def _first(names: list[str]) -> str:
    """``names`` joined, the first :data:`MISSING_NAMED` of them and how many more."""
    if len(names) <= MISSING_NAMED:
        return ", ".join(names)
    return f"{', '.join(names[:MISSING_NAMED])} and {len(names) - MISSING_NAMED} more"


def _status(last: TighteningRecord, loosen_at: datetime | None) -> BoltStatus:
    """A bolt's status from its last rundown and its last loosen command."""
    if loosen_at is not None and loosen_at >= last.recorded_at:
        return TO_LOOSEN
    if last.kind == LOOSENING:
        return LOOSENED if last.status == OK else NOK
    return BoltStatus(last.status)
