"""A link cut during which the tool, still enabled on the controller (the station cannot turn
it off), ran more than once: the cut's rundown, proved by the controller's data and recorded
to its bolt, then a loosening of that bolt's pset.  Which bolt it loosened is not known; the
cut's bolt, the one the operator was at, may be it: never left done without a word."""

from __future__ import annotations

from drivers.keeper import FaultKind
from stationd.station.actions import Record, StoreCutUnknown, StoreUnattributed
from stationd.station.inputs import CaughtUp, DeviceBack, DeviceFault, ResultIn
from tests.station.test_core import Driver, _ready
from tests.station.test_result_types import _enabled, res


def _cut_with_its_rundown(d: Driver) -> float:
    """40 pushed; B1 (pset 1) enabled; the link dies unnoticed and the operator runs B1
    down (41, 3 s after the enable); the station sees the cut 10 s after the enable, the
    link comes back and the catch-up fetches 41 (proved: recorded to B1).  The enable's
    time."""
    d.feed(ResultIn(d.t, res(40, 2, True, 1)))
    _enabled(d, 1)
    t0 = d.t
    d.t += 10.0
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "link lost"))
    d.t += 5.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    d.t += 0.1
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=t0 + 3.0))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts
            if isinstance(a, Record)] == [("B1", 41)]
    assert d.core.matcher is not None and "B1" in d.core.matcher.done
    return t0


def test_a_loosening_made_during_the_cut_after_its_rundown_holds_the_cut_s_bolt():
    """After 41, the operator reversed (42, a loosening of pset 1, made 6 s after the
    enable, still within the cut): fetched by the same catch-up, not proved to be any
    bolt's (stored unattributed).  B1 may be loose: held for a person, stored so (its hold
    outlives a restart).  Before: B1 left done OK, the loosening said only as a result of
    no bolt."""
    d = _ready()
    t0 = _cut_with_its_rundown(d)
    acts = d.feed(ResultIn(d.t, res(42, 1, True, 2), fetched=True, follows=40,
                           made_at=t0 + 6.0))
    acts += d.feed(CaughtUp(d.t, True, "", 1))
    assert any(isinstance(a, StoreUnattributed) for a in acts)
    assert [(a.vin, a.bolt) for a in acts if isinstance(a, StoreCutUnknown)] == [
        ("VIN1", "B1")]
    assert d.core.matcher is not None and "B1" in d.core.matcher.held
    assert "tightening 42" in d.core.matcher.held["B1"]


def test_a_tightening_or_another_pset_s_loosening_after_the_cut_s_rundown_holds_nothing():
    """Guards: a second tightening of that pset (B1 hit again, or another bolt: no bolt of
    it loosened), or a loosening of another pset (not the cut's enable's), stored
    unattributed as before, B1 done."""
    for second in (res(42, 1, True, 1), res(42, 2, True, 2)):
        d = _ready()
        t0 = _cut_with_its_rundown(d)
        acts = d.feed(ResultIn(d.t, second, fetched=True, follows=40, made_at=t0 + 6.0))
        acts += d.feed(CaughtUp(d.t, True, "", 1))
        assert not any(isinstance(a, StoreCutUnknown) for a in acts)
        assert d.core.matcher is not None and "B1" in d.core.matcher.done
        assert "B1" not in d.core.matcher.held


def test_a_refused_command_during_the_catch_up_keeps_the_loosening_s_hold():
    """A command the controller refuses between the cut's rundown and the loosening (a
    refusal keeps the link: no cut, no new catch-up, its results go on coming) does not end
    the catch-up's watch for a loosening after the rundown: B1 held as without it (a
    reviewer: any fault of the wrench ended it)."""
    d = _ready()
    t0 = _cut_with_its_rundown(d)
    d.feed(DeviceFault(d.t, "wrench", FaultKind.REFUSED, "MID 0042 refused"))
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts = d.feed(ResultIn(d.t, res(42, 1, True, 2), fetched=True, follows=40,
                           made_at=t0 + 6.0))
    acts += d.feed(CaughtUp(d.t, True, "", 1))
    assert [(a.vin, a.bolt) for a in acts if isinstance(a, StoreCutUnknown)] == [
        ("VIN1", "B1")]
    assert d.core.matcher is not None and "B1" in d.core.matcher.held
