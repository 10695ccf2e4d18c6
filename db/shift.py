"""A shift's hand-over: the vehicles at the station during a time window, each with its
report, and the commands people gave in it (releases, skips, reopens, loosenings, entered
outcomes).  Why: a supervisor at the end of a shift asked how many vehicles passed, which
left with bolts not OK, who released a lock and why, what was reworked; the screens list the
newest 200 vehicles and ``db report`` one vehicle, so the answer was a count of VINs in an
export (a shift supervisor's trial)."""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime
from itertools import pairwise

from sqlalchemy import func, or_, select
from sqlalchemy.orm import Session

from db.kinds import ENTER_OUTCOME, LOOSENING, REFUSED
from db.ledger import CommandEntry
from db.models import Bolt, CommandRecord, TighteningRecord, Vehicle, VehicleClosing
from db.report import VehicleReport
from db.repository import Repository

#: the commands a hand-over names (sign-in, teach and calibration checks are no vehicle's),
#: and the refused ones among them (a supervisor's trial: a release refused for a mistyped
#: VIN was kept, but under a VIN no report finds, and the hand-over named no refusal)
HANDOVER_KINDS = ("release", "skip", "reopen", "loosen", ENTER_OUTCOME, REFUSED)


@dataclass(frozen=True)
class Shift:
    """What happened at the station from ``since`` to ``until``."""

    since: datetime
    until: datetime
    #: each vehicle at the station at some time in the window (started before its end, not
    #: left before its start; reopened for rework in it), oldest first
    vehicles: tuple[VehicleReport, ...]
    #: the hand-over's commands given in the window, oldest first
    commands: tuple[CommandEntry, ...]
    #: what each entered outcome entered (command id -> "OK 25.1 Nm, 31.0 deg"; a
    #: supervisor's trial: the hand-over gave the comment alone, not the verdict)
    entered: dict[int, str] = field(default_factory=dict, hash=False)


def shift(repo: Repository, since: datetime, until: datetime) -> Shift:
    """The vehicles and commands of the window [``since``, ``until``)."""
    with Session(repo.engine) as s:
        rows = list(s.execute(select(Vehicle.id, Vehicle.vin, Vehicle.started_at,
                                     Vehicle.reopened_at).where(
            Vehicle.started_at < until,
            or_(Vehicle.ended_at.is_(None), Vehicle.ended_at >= since,
                Vehicle.reopened_at >= since))
            .order_by(Vehicle.started_at, Vehicle.id)))
        vins = [vin for vid, vin, started, reopened in rows
                if reopened is None
                or _open_in(s, vid, vin, started, reopened, since, until)]
    held = repo.may_hold(vins)
    reports = tuple(repo.vehicle_report(vin, held=vin in held) for vin in vins)
    commands = tuple(c for c in repo.ledger.commands(since=since, until=until)
                     if c.kind in HANDOVER_KINDS)
    with Session(repo.engine) as s:
        entered = {c.id: words for c in commands if c.kind == ENTER_OUTCOME
                   and (words := _entered(s, c)) is not None}
    return Shift(since, until, reports, commands, entered)


def _entered(s: Session, c: CommandEntry) -> str | None:
    """What the entered outcome ``c`` entered, in words ("OK 25.1 Nm, 31.0 deg"; "loosening
    NOK ..."): its rundown, stored with it (the person, the vehicle, the bolt and the time
    are the command's)."""
    r = s.execute(select(TighteningRecord.status, TighteningRecord.torque_nm,
                         TighteningRecord.angle_deg, TighteningRecord.kind)
                  .join(Vehicle, Vehicle.id == TighteningRecord.vehicle_id)
                  .join(Bolt, Bolt.id == TighteningRecord.bolt_id)
                  .where(Vehicle.vin == c.vin, Bolt.code == c.bolt,
                         TighteningRecord.entered_by == c.user,
                         TighteningRecord.result_at == c.at)
                  .order_by(TighteningRecord.id.desc()).limit(1)).first()
    if r is None:
        return None
    status, torque, angle, kind = r
    return ("loosening " if kind == LOOSENING else "") + \
        f"{str(status).upper()} {torque:.1f} Nm, {angle:.1f} deg"


def _open_in(s: Session, vehicle_id: int, vin: str, started: datetime, reopened: datetime,
             since: datetime, until: datetime) -> bool:
    """Whether a vehicle reopened for rework was open (at the station, or reopened and not
    closed again) at some time in [``since``, ``until``): from its start and each reopen to
    the close that followed it.  Its ``ended_at`` and ``reopened_at`` are its last ones: a
    vehicle that left before a shift and was reopened after it read as open in it (an
    auditor reading yesterday's hand-over today).  Without a close kept (closed before
    closes were kept) it counts, as before.  A reopening the station made itself (its
    rework rule: a closed VIN back at the lift, ``start_vehicle(reopen=True)``) leaves no
    reopen command: its last one is ``reopened``, and a close with no opening known since
    the close before it had one, at the latest at the vehicle's first rundown after that
    close, else at that close itself (the vehicle left the station then)."""
    closes = sorted(s.scalars(select(VehicleClosing.closed_at)
                              .where(VehicleClosing.vehicle_id == vehicle_id)))
    if not closes:
        return True
    known = {started, reopened, *s.scalars(select(CommandRecord.at).where(
        CommandRecord.vin == vin, CommandRecord.kind == "reopen"))}
    for before, close in pairwise(closes):
        if not any(before < o <= close for o in known):
            first = s.scalar(select(func.min(TighteningRecord.recorded_at)).where(
                TighteningRecord.vehicle_id == vehicle_id,
                TighteningRecord.recorded_at > before, TighteningRecord.recorded_at <= close))
            known.add(close if first is None else first)
    opens = sorted(known)
    for k, opened in enumerate(opens):
        if opened >= until:
            break
        closed = next((c for c in closes if c >= opened), None)
        if k + 1 < len(opens) and (closed is None or closed > opens[k + 1]):
            closed = opens[k + 1]   # no close kept before the next opening: open until it
        if closed is None or closed >= since:
            return True
    return False


def list_status(report: VehicleReport) -> str:
    """A vehicle's word in a list of vehicles: reopened (for rework, not back at the station
    yet), open (at the station, not done), complete, NOK (a bolt ending NOK), incomplete
    (left with bolts missing, skipped or held)."""
    v = report.vehicle
    return ("reopened" if v.waiting else
            "open" if v.ended_at is None and not report.complete
            else "complete" if report.complete else "NOK" if report.nok else "incomplete")
