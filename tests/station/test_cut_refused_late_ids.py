"""A review of a link cut whose catch-up timed out (weaknesses A and B): the cut's
tightening ids stored as a refused gap though the controller may still have them, and the
checks after it, which may fetch ids made during the cut with the link up.  Each: which
bolt a result that comes afterwards is taken for."""

from __future__ import annotations

from drivers.keeper import FaultKind
from stationd.station.actions import Record
from stationd.station.inputs import (
    CaughtUp,
    DeviceBack,
    DeviceFault,
    ResultIn,
    ResultsMissed,
    Tick,
)
from tests.station.test_core import Driver, _on, _ready
from tests.station.test_result_types import _enabled, res

TIMED_OUT = "the controller refused to give them (fetch tightening (newest): no answer to " \
            "MID 0064 within 2 s: taken as refused)"
GAP = "the controller refused to give them (MID 0064)"


def _cut_caught_up_late(d: Driver) -> float:
    """40 pushed (no enable); B1 (pset 1) enabled, the link cut, B1 run down during the cut
    (41, never pushed); the reconnect's catch-up times out (not complete): B1 held.  The
    enable's time."""
    d.feed(ResultIn(d.t, res(40, 2, True, 1)))
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 1.0
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "link lost"))
    d.t += 10.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    d.t += 2.0
    d.feed(CaughtUp(d.t, False, TIMED_OUT, 1))
    assert "B1" in d.core.matcher.held
    d.step(("lift", 0.1, True, True, "VIN1"))
    return enabled_at


def test_an_id_stored_as_the_cut_s_gap_is_not_taken_for_a_bolt_enabled_since():
    """Weakness A: the first push after the reconnect (42, B2's) tells 41 as the refused
    catch-up's gap.  The controller still had 41 and pushes it afterwards (it sends what it
    made during the cut; or a check, a later fetch, gives it) while B3, of B1's pset, has
    its tool on.  41 was made before 42 (the controller's ids grow with every tightening),
    so before B3's enable: it is never B3's rundown.  It was recorded to B3 and B3 closed OK
    though never tightened -- a result attributed to the wrong bolt."""
    d = _ready()
    _cut_caught_up_late(d)
    _enabled(d, 2)                                   # B2, pset 2
    d.t += 1.0
    d.feed(ResultsMissed(d.t, 41, 41, GAP))          # told by 42, the first push since
    d.feed(ResultIn(d.t, res(42, 2, True, 1)))
    assert "B2" in d.core.matcher.done
    _on(d, 0, 3)
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    _enabled(d, 3)                                   # B3, pset 1 (B1's)
    d.t += 0.5
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1)))   # 41 comes after all
    recorded = [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)]
    assert recorded == [] and "B3" not in d.core.matcher.done, (
        f"41, stored as the cut's gap before B3's enable, recorded as {recorded}")
