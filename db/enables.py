"""The tool enables the station noted: what it owes until each one's result is recorded.

Why noted before the tool goes on: a reload or a restart (kill -9 included) must know which
bolt a late result belongs to; the enable is settled in the transaction that stores its
result (:func:`settle`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from db.engine import Transactions
from db.models import TighteningRecord, ToolEnable, utcnow


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
class CutRundown:
    """The last tool enable, answered by a rundown made during a link cut and fetched after
    the reconnect (``tightening_id``, stored at ``recorded_at``): the last rundown stored.
    The catch-up that fetched it may have been cut short (a kill, a stop, a reload between
    two fetches): a rundown it had not fetched yet, made by then, may be that tool's again."""

    enable: OwedEnable
    tightening_id: int
    recorded_at: datetime


def settle(s: Session, enable_id: int | None,
           of: tuple[str | None, str | None] | None = None) -> None:
    """The tool enable ``enable_id`` answered (the station owes it nothing more); with ``of``
    (vin, bolt), only when it is an enable of that bolt of that vehicle."""
    if enable_id is not None:
        row = s.get(ToolEnable, enable_id)
        if row is not None and row.settled_at is None and (
                of is None or (row.vin, row.bolt) == of):
            row.settled_at = utcnow()


class ToolEnables:
    """The tool enables, through the repository's transactions (``Repository.enables``)."""

    def __init__(self, session: Transactions) -> None:
        self._session = session

    def note(self, vin: str, bolt: str, pset: int | None, parameters_id: int | None,
             selection: Mapping[str, Any], at: datetime) -> int:
        """The tool is about to be enabled for ``bolt`` of ``vin``: noted (committed) first, so
        that the next station (a reload, a restart) records a late result to that bolt."""
        with self._session(True) as s:
            row = ToolEnable(vin=vin, bolt=bolt, pset=pset, parameters_id=parameters_id,
                             selection=dict(selection), enabled_at=at)
            s.add(row)
            s.flush()
            return row.id

    def settle(self, enable_id: int) -> None:
        """The station owes tool enable ``enable_id`` nothing more without a record of it:
        every result the controller made since was fetched, and none was its."""
        with self._session(True) as s:
            settle(s, enable_id)

    def tool_off(self, enable_id: int, at: datetime) -> None:
        """The tool went off (the first time counts: the late-result window starts there)."""
        with self._session(True) as s:
            row = s.get(ToolEnable, enable_id)
            if row is not None and row.off_at is None:
                row.off_at = at

    def cut_rundown(self) -> CutRundown | None:
        """The last enable's rundown where it was made during a link cut (:class:`CutRundown`)
        and is the last rundown stored, of that enable's bolt and vehicle, stored after the
        enable; else None."""
        with self._session(False) as s:
            row = s.scalar(select(ToolEnable).order_by(ToolEnable.id.desc()).limit(1))
            rec = s.scalar(select(TighteningRecord).order_by(TighteningRecord.id.desc())
                           .limit(1))
            if row is None or row.settled_at is None or rec is None or not rec.offline \
                    or rec.tightening_id is None or rec.recorded_at < row.enabled_at \
                    or (rec.vehicle.vin, rec.bolt.code) != (row.vin, row.bolt):
                return None
            return CutRundown(_owed(row), rec.tightening_id, rec.recorded_at)

    def owed(self) -> OwedEnable | None:
        """The latest tool enable, if its result is not recorded (an older one was superseded
        by it: the tool can only have been enabled for the latest)."""
        with self._session(False) as s:
            row = s.scalar(select(ToolEnable).order_by(ToolEnable.id.desc()).limit(1))
            if row is None or row.settled_at is not None:
                return None
            return _owed(row)


def _owed(row: ToolEnable) -> OwedEnable:
    """A tool enable's row as the station reads it."""
    return OwedEnable(row.id, row.vin, row.bolt, row.pset, row.parameters_id,
                      dict(row.selection), row.enabled_at, row.off_at)
