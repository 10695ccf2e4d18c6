"""A vehicle closing while a result is still due from the controller (:mod:`stationd.station.lift`):
the close names those bolts (neither missing nor NOK yet), and the verdict is asked again
once each is settled: its result written to the database, or no longer to come."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from drivers.keeper import FaultKind
from drivers.wrench.base import Status, TighteningResult
from stationd.station.actions import CloseVehicle, Publish, Record, SettleClosing
from stationd.station.events import ClosingSettled, VehicleClosed
from stationd.station.inputs import (
    CaughtUp,
    DeviceBack,
    DeviceFault,
    NotStored,
    ResultIn,
    ResultsSkipped,
    VehicleEnded,
    Written,
)
from tests.station.test_core import Driver, _ready, published
from tests.station.test_result_types import _enabled


def res(tid: int, pset: int, ok: bool = True) -> TighteningResult:
    """A whole result, a tightening (what a Written publishes needs its limits)."""
    st = Status.OK if ok else Status.LOW
    return TighteningResult(ok, 50.0 if ok else 20.0, 30.0, st, Status.OK, tid, pset, "",
                            datetime(2026, 12, 1, 8, 0, 0), 45.0, 55.0, 50.0, 15.0, 60.0,
                            30.0)


def _down(d: Driver) -> CloseVehicle:
    """The lift goes down: the close the core asks for."""
    n = len(d.log)
    d.step(("lift", 0.2, False, False, "VIN1"))
    [close] = [a for _, acts in d.log[n:] for a in acts if isinstance(a, CloseVehicle)]
    return close


def _settles(acts: list[Any]) -> list[tuple[str, tuple[str, ...], tuple[str, ...]]]:
    return [(a.vin, a.settled, a.due) for a in acts if isinstance(a, SettleClosing)]


def test_the_close_names_the_bolt_whose_result_is_due_and_the_verdict_waits_for_its_record():
    """B1's tool on as the lift goes down: B1 due.  Its result comes (recorded to B1 of
    VIN1); the verdict is asked again only once the database has it (after an outage that
    refused it, when it is written)."""
    d = _ready()
    _enabled(d, 1)
    assert _down(d).due == ("B1",)
    acts = d.feed(VehicleEnded(d.t, "VIN1", ("B2", "B3"), (), ("B1",)))
    assert published(acts, VehicleClosed) == [VehicleClosed("VIN1", ("B2", "B3"), (), ("B1",),
                                                            t=d.t)]
    d.t += 0.5
    acts = d.feed(ResultIn(d.t, res(41, 1, True)))
    [rec] = [a for a in acts if isinstance(a, Record)]
    assert (rec.vin, rec.bolt) == ("VIN1", "B1") and not _settles(acts)
    assert not _settles(d.feed(NotStored(d.t, 41, "B1", "disk full")))
    d.t += 60.0
    assert not _settles(d.feed(ResultIn(d.t, res(43, 2, True))))   # no one's
    assert _settles(d.feed(Written(d.t, rec))) == [("VIN1", ("B1",), ())]
    acts = d.feed(VehicleEnded(d.t, "VIN1", ("B2", "B3"), (), (), ("B1",)))
    assert [(e.vin, e.missing, e.nok, e.due, e.settled) for e in
            published(acts, ClosingSettled)] == [("VIN1", ("B2", "B3"), (), (), ("B1",))]
    assert not published(acts, VehicleClosed)
    assert not _settles(d.feed(ResultIn(d.t, res(44, 1, True))))   # said once


def test_nothing_is_due_where_the_result_came_and_was_written_before_the_lift_went_down():
    d = _ready()
    _enabled(d, 1)
    [rec] = [a for a in d.feed(ResultIn(d.t, res(41, 1, False))) if isinstance(a, Record)]
    d.feed(Written(d.t, rec))
    assert _down(d).due == ()


def test_a_result_the_database_has_not_taken_yet_is_due_until_it_is_written():
    """B1's result came, the database refused it (kept in memory by the shell), and the lift
    goes down: its records do not have it yet, B1 is due; written once the database is
    back, the verdict follows."""
    d = _ready()
    _enabled(d, 1)
    [rec] = [a for a in d.feed(ResultIn(d.t, res(41, 1, True))) if isinstance(a, Record)]
    d.feed(NotStored(d.t, 41, "B1", "disk full"))
    assert _down(d).due == ("B1",)
    d.t += 120.0
    assert _settles(d.feed(Written(d.t, rec))) == [("VIN1", ("B1",), ())]


def test_a_lost_push_and_the_pushed_one_settle_after_both_are_written():
    """B1's 42 pushed as the lift goes down skipped 41 (its push lost): both B1's; the
    verdict waits for both records."""
    d = _ready()
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 3.0
    d.feed(ResultsSkipped(d.t, 42))
    assert _down(d).due == ("B1",)
    acts = d.feed(ResultIn(d.t, res(41, 1, False), fetched=True, follows=40,
                           made_at=enabled_at + 2.0, live=True, before=42))
    acts += d.feed(ResultIn(d.t, res(42, 1, True)))
    recs = [a for a in acts if isinstance(a, Record)]
    assert [int(a.result.tightening_id) for a in recs] == [41, 42]
    assert not _settles(acts) and not _settles(d.feed(Written(d.t, recs[0])))
    assert _settles(d.feed(Written(d.t, recs[1]))) == [("VIN1", ("B1",), ())]


def test_a_link_cut_s_bolt_is_due_until_the_catch_up_settles_it():
    d = _ready()
    _enabled(d, 1)
    d.t += 0.1
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "wrench gone"))
    assert _down(d).due == ("B1",)
    d.t += 10.0
    assert not _settles(d.feed(DeviceBack(d.t, "wrench", reconnects=1)))
    assert _settles(d.feed(CaughtUp(d.t, True, "", 1))) == [("VIN1", ("B1",), ())]


def test_a_vehicle_back_for_rework_owes_its_close_nothing():
    """VIN1 leaves with B1 due and comes back at once (a rework, reopened): open again, its
    result is the open vehicle's; no verdict of a close is asked."""
    d = _ready()
    _enabled(d, 1)
    assert _down(d).due == ("B1",)
    d.step(("lift", 0.2, True, True, "VIN1"))
    assert d.core.vin == "VIN1"
    acts = d.feed(ResultIn(d.t, res(41, 1, True)))
    [rec] = [a for a in acts if isinstance(a, Record)]
    assert not _settles(acts) and not _settles(d.feed(Written(d.t, rec)))
    assert not any(isinstance(a, Publish) and isinstance(a.event, ClosingSettled)
                   for _, acts in d.log for a in acts)
