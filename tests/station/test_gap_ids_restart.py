"""A review of ``CoreState._gaps_told`` (weakness A's fix): an id in a gap told before the
enable owed now is taken for a result made before that enable.  That holds only while the
controller's ids grow; a controller whose count started again (its memory cleared, replaced,
restored: ids from 1 or a low number again) makes new rundowns under ids a remembered gap
holds."""

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

CLEARED = "the controller has no results, though tightening 46 was recorded: cleared " \
          "(restarted or replaced), what it made before is not known"


def _next(d: Driver) -> None:
    """The wrench away from the bolt on now, its late-result window over."""
    _on(d, 0, 3)
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))



def _replaced_after_a_gap(restarted: bool) -> Driver:
    """A station that told 41-45 as a gap with the link up (40 and 46 pushed, no enable),
    then lost its controller (replaced) and caught up on the new one: its results cleared,
    the count's restart said (``restarted``) or not."""
    d = _ready()
    d.feed(ResultIn(d.t, res(40, 2, True, 1)))               # (no enable)
    d.feed(ResultsMissed(d.t, 41, 45, "the controller no longer has it", live=True))
    d.feed(ResultIn(d.t, res(46, 2, True, 1)))
    d.t += 1.0
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "link lost"))   # replaced
    d.t += 60.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    d.t += 1.0
    d.feed(CaughtUp(d.t, False, CLEARED, 1, restarted=restarted))
    return d

def test_a_rundown_of_a_controller_whose_ids_restarted_is_not_left_open_in_an_old_gap():
    """Ids 41-45 told as a gap (the link up: the controller no longer had them), 46 pushed.
    The controller is then replaced (or its memory cleared): the link drops, the catch-up
    finds no results on it.  Its new count reaches 40 (B2's rundown, recorded to B2), then
    41 -- B3's own rundown, pushed at once while B3's tool is on.  41 lies in the old gap,
    told before B3's enable, so ``_before_enable`` says it was made before B3's enable: it
    is stored unattributed, and B3 stays open with its tool on.  The operator, seeing no
    result, runs B3 down again: a bolt tightened twice.  A result pushed with the tool on
    for its pset is that bolt's (recorded), or, where the core doubts it, the bolt is held
    with its tool off -- never left open after its rundown."""
    d = _replaced_after_a_gap(restarted=False)
    d.step(("lift", 0.1, True, True, "VIN1"))
    _enabled(d, 2)                                            # B2, pset 2
    d.t += 0.5
    acts = d.feed(ResultIn(d.t, res(40, 2, True, 1)))        # the new count's 40
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B2"]
    _next(d)
    _enabled(d, 3)                                            # B3, pset 1
    d.t += 0.5
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1)))        # B3's own rundown
    recorded = [a.bolt for a in acts if isinstance(a, Record)]
    m = d.core.matcher
    assert m is not None
    closed = "B3" in m.done or "B3" in m.held
    assert recorded == ["B3"] or (closed and not d.core.tool_on), (
        f"B3's rundown 41 (a restarted count) recorded to {recorded}; B3 done "
        f"{'B3' in m.done}, held {'B3' in m.held}, its tool on {d.core.tool_on}: "
        "left open to be tightened twice")


def test_a_restarted_count_s_first_rundown_in_an_old_gap_is_not_left_open():
    """As above, but the new count's first rundown falls in the old gap itself (a controller
    restored or replaced with its count near the old one; or ids from 1 where a gap began
    at 1): no push below the gap says the count restarted first.  The shell's catch-up
    found it (the controller has no results though 46 was recorded; or
    ``_count_restarted``) and says so (``CaughtUp.restarted``): the gaps told are the old
    count's, forgotten.  B3's own 41 is recorded to B3, not left open with its tool on."""
    d = _replaced_after_a_gap(restarted=True)
    d.step(("lift", 0.1, True, True, "VIN1"))
    _enabled(d, 3)                                            # B3, pset 1
    d.t += 0.5
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1)))        # B3's own rundown
    m = d.core.matcher
    assert m is not None
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B3"] or (
        "B3" in m.held and not d.core.tool_on), (
        f"B3's rundown 41 (a restarted count) not recorded; held {list(m.held)}, "
        f"its tool on {d.core.tool_on}")
