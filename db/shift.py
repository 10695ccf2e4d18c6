"""A shift's hand-over: the vehicles at the station during a time window, each with its
report, and the commands people gave in it (releases, skips, reopens, loosenings, entered
outcomes).  Why: a supervisor at the end of a shift asked how many vehicles passed, which
left with bolts not OK, who released a lock and why, what was reworked; the screens list the
newest 200 vehicles and ``db report`` one vehicle, so the answer was a count of VINs in an
export (a shift supervisor's trial)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import or_, select
from sqlalchemy.orm import Session

from db.ledger import CommandEntry
from db.models import Vehicle
from db.report import VehicleReport
from db.repository import Repository

#: the commands a hand-over names (sign-in, teach and calibration checks are no vehicle's)
HANDOVER_KINDS = ("release", "skip", "reopen", "loosen", "enter-outcome")


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


def shift(repo: Repository, since: datetime, until: datetime) -> Shift:
    """The vehicles and commands of the window [``since``, ``until``)."""
    with Session(repo.engine) as s:
        vins = list(s.scalars(select(Vehicle.vin).where(
            Vehicle.started_at < until,
            or_(Vehicle.ended_at.is_(None), Vehicle.ended_at >= since,
                Vehicle.reopened_at >= since))
            .order_by(Vehicle.started_at, Vehicle.id)))
    held = repo.may_hold(vins)
    reports = tuple(repo.vehicle_report(vin, held=vin in held) for vin in vins)
    commands = tuple(c for c in repo.ledger.commands()
                     if c.kind in HANDOVER_KINDS and since <= c.at < until)
    return Shift(since, until, reports, commands)


def list_status(report: VehicleReport) -> str:
    """A vehicle's word in a list of vehicles: reopened (for rework, not back at the station
    yet), open (at the station, not done), complete, NOK (a bolt ending NOK), incomplete
    (left with bolts missing, skipped or held)."""
    v = report.vehicle
    return ("reopened" if v.waiting else
            "open" if v.ended_at is None and not report.complete
            else "complete" if report.complete else "NOK" if report.nok else "incomplete")
