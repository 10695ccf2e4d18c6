"""A gap a check with the tool on tells decides the hold of the enable on at the check's end
(LostRules._gaps_on_check_decided, a3b683d); before, it held the bolt at once."""

from __future__ import annotations

from stationd.station.actions import CheckNewest, StoreCutUnknown
from stationd.station.inputs import NewestChecked, ResultsMissed, Tick
from tests.station.test_check_on import on_and_checked
from tests.station.test_closing import _down


def test_a_gap_the_tool_on_check_tells_holds_the_bolt_also_when_its_vehicle_leaves_meanwhile():
    """B1's tool on; the periodic check finds 41 gone (a gap, made with B1's tool on: maybe
    B1's rundown).  The lift goes down before the check ends (its last fetches, the push it
    waits for): at the check's end the enable's vehicle is no longer the one at the station,
    and _doubt_while_on holds nothing, so B1 of VIN1 is neither held nor stored as held: at
    a rework it is open, tightened twice if 41 was its rundown.  Held at once, as before
    a3b683d, it was stored for when VIN1 is back."""
    d, check, _ = on_and_checked()
    acts = d.feed(ResultsMissed(d.t, 41, 41, "the controller no longer has it", live=True))
    n = len(d.log)
    _down(d)                                       # VIN1 leaves as the check runs
    acts += [a for _, step in d.log[n:] for a in step]
    d.t += 0.5
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    for _ in range(5):                             # any check after it: nothing made
        d.t += 5.0
        for c in [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]:
            acts += d.feed(NewestChecked(d.t, nothing_made=True, serial=c.serial))
    assert ("VIN1", "B1") in {(a.vin, a.bolt) for a in acts if isinstance(a, StoreCutUnknown)}, \
        "41 may be B1's rundown: B1 of VIN1 not held, open at a rework"


def test_a_gap_the_tool_on_check_tells_holds_the_bolt_also_when_the_link_cut_ends_the_enable():
    """As above, the wrench's link cut instead, as the check runs: the tool off, the enable
    the cut's.  The reconnect's catch-up, complete and finding nothing after 41 (the gap was
    told: accounted for), settles the cut's enable past its late-result window (nothing
    made) before the check's answer comes (its own wait, or CHECK_WAIT_S): the check's end
    then finds no enable to hold and B1 is open, tightened twice if 41 was its rundown.
    Held at once, as before a3b683d."""
    from drivers.keeper import FaultKind
    from stationd.station.inputs import CaughtUp, DeviceBack, DeviceFault

    d, check, _ = on_and_checked()
    acts = d.feed(ResultsMissed(d.t, 41, 41, "the controller no longer has it", live=True))
    d.t += 0.1
    acts += d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "wrench gone"))
    d.t += d.core.late_result_s + 3.0              # a cut of some seconds
    acts += d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts += d.feed(CaughtUp(d.t, True, "", 1))
    d.t += 0.5
    acts += d.feed(NewestChecked(d.t, unknown="the link was cut", serial=check.serial))
    for _ in range(5):
        d.t += 5.0
        for c in [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]:
            acts += d.feed(NewestChecked(d.t, nothing_made=True, serial=c.serial))
    assert "B1" in d.core.matcher.held and "B1" not in d.core.allowed(), \
        "41 may be B1's rundown: B1 open after the cut's catch-up"
