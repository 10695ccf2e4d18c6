"""The periodic check of the controller's newest with the tool on (``CheckNewest.tool_on``),
as an independent review found it: what it cannot place holds the bolt though the operator
lifted the wrench meanwhile; a push after the check fetched its result is a copy."""

from __future__ import annotations

import pytest

from stationd.station.actions import CheckNewest, Record, StoreCutUnknown
from stationd.station.inputs import NewestChecked, ResultIn, Tick
from stationd.station.state import CHECK_ON_S
from tests.station.test_check import found_by_the_check
from tests.station.test_core import Driver, _on, _ready
from tests.station.test_result_types import _enabled, res


def on_and_checked() -> tuple[Driver, CheckNewest, float]:
    """B1's tool on (enabled at the time returned), the checks answered by the test, and
    the periodic check with the tool on asked, CHECK_ON_S later."""
    d = _ready()
    d.answer_checks = False
    _enabled(d, 1)
    at = d.t
    d.t += CHECK_ON_S
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    assert check.tool_on
    return d, check, at


@pytest.mark.parametrize("found", ["a result not proved its own", "a gap"])
def test_what_the_tool_on_check_cannot_place_after_the_operator_left_holds_the_bolt(found):
    """As tests/station/test_check.py::test_what_a_periodic_check_cannot_place_turns_the_
    tool_off_and_holds_the_bolt, but the operator lifts the wrench off B1 (the tool off,
    NOT_CONFIRMED) between the check being asked and its fetched 41 coming in -- the usual
    moment: the rundown ended (its push lost), the operator moves on.  41 (B1's pset, not
    proved B1's) is stored unattributed; _doubt_while_on asks tool_on and holds nothing; B1
    is not in _unanswered yet, so _lost_enables holds nothing either.  The shell's
    _accounted is now 41: the window-end check finds the newest == last heard (nothing
    made) and B1 is left open -- tightened twice if 41 was its rundown."""
    d = _ready()
    d.answer_checks = False
    _enabled(d, 1)
    d.t += CHECK_ON_S
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    assert check.tool_on
    _on(d, 2, 3)                                     # the operator leaves B1: tool off
    assert not d.core.tool_on
    acts = found_by_the_check(d, found)
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    # the window-end check: the shell's _accounted is 41, the newest 41: nothing made
    d.t += d.core.late_result_s + 1.0
    ends = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    for c in ends:
        acts += d.feed(NewestChecked(d.t, nothing_made=True, serial=c.serial))
    assert [a.bolt for a in acts if isinstance(a, StoreCutUnknown)] == ["B1"], \
        "41 may be B1's rundown: B1 left open"
    assert "B1" in d.core.matcher.held and "B1" not in d.core.allowed()


def test_a_push_after_the_tool_on_check_fetched_its_result_is_not_recorded_twice():
    """The rundown 41 of B1 ends just before the periodic check (CHECK_ON_S after the
    enable); its push is on its way, not lost.  The check fetches 41 (MID 0065 at a revision
    without a result type, as oldresults.py agrees with controllers that refuse higher ones)
    and records it to B1 (lost=True: the enable is kept owed until NewestChecked).  The shell
    feeds the push of 41 (MID 0061 rev 3+, type 1) before NewestChecked (_until(not
    received)); with the database refusing (copy_input raises: checked() passes the
    ResultIn through) the core's only guard is _recorded == _said, which differs by the
    type code: the push is attributed to the enable still owed -- 41 recorded twice to B1,
    its NOK counted twice."""
    d, check, at = on_and_checked()
    acts = d.feed(ResultIn(d.t, res(41, 1, False, None), fetched=True, follows=40,
                           made_at=at + 2.2, live=True))
    acts += d.feed(ResultIn(d.t, res(41, 1, False, 1), made_at=at + 2.2))   # its push
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)] \
        == [("B1", 41)], "one rundown recorded twice"
    assert d.core._noks.get("B1") == 1


def test_a_quick_rundown_the_tool_on_check_fetches_after_the_operator_left_holds_the_bolt():
    """The same with a result before it (not only at a start): B2 tightened (40, pushed),
    B1 enabled right after; the operator runs B1 down at once (41 made 1 s after its
    enable, the controller's clock known: within CLOCK_SLACK_S of both the enable and B2's
    tool-off, so not proved B1's), its push lost; the periodic check asks, the operator
    lifts the wrench, 41 comes in with the tool off: stored unattributed, B1 not held, and
    the window-end check (newest == last heard) leaves B1 open."""
    d = _ready()
    d.answer_checks = False
    b2 = _enabled(d, 2).selection.pset or 0
    d.feed(ResultIn(d.t, res(40, b2, True, 1)))
    assert not d.core.tool_on and "B2" in d.core.matcher.done
    b1 = _enabled(d, 1).selection.pset or 0
    at = d.t
    d.t += CHECK_ON_S
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    _on(d, 3, 3)                                     # the operator leaves B1
    assert not d.core.tool_on
    acts = d.feed(ResultIn(d.t, res(41, b1, False, 1), fetched=True, follows=40,
                           made_at=at + 1.0, live=True))
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    d.t += d.core.late_result_s + 1.0
    for c in [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]:
        acts += d.feed(NewestChecked(d.t, nothing_made=True, serial=c.serial))
    recorded = [a.bolt for a in acts if isinstance(a, Record)]
    held = "B1" in d.core.matcher.held
    assert recorded == ["B1"] or held, "41 (perhaps B1's NOK) neither recorded nor held: B1 open"


@pytest.mark.parametrize("tool_on", [True, False], ids=["with the tool on", "as the window ended"])
def test_an_unreadable_result_a_check_fetches_holds_the_enable_s_bolt(tool_on):
    """A supervisor's trial: the periodic check fetched the controller's newest, B15's
    rundown whose push was lost, and it did not read: stored "no bolt it could belong to",
    B15 left open ("not tightened"), to be tightened twice.  Fetched by a check for the
    enable owed now (with the tool on, or as its window ended), it may be that enable's
    rundown: B1 is held and its tool goes off."""
    from stationd.station.actions import StoreUnreadable
    from stationd.station.inputs import UnreadableIn
    from tests.station.test_result_types import unreadable

    d = _ready()
    d.answer_checks = False
    _enabled(d, 1)
    if tool_on:
        d.t += CHECK_ON_S
    else:
        _on(d, 2, 3)                                  # the operator left B1
        d.t += d.core.late_result_s + 1.0
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    assert check.tool_on is tool_on
    acts = d.feed(UnreadableIn(d.t, unreadable(41, 1, fetched=True)))
    [stored] = [a for a in acts if isinstance(a, StoreUnreadable)]
    assert stored.bolt == "B1"
    assert "B1" in d.core.matcher.held and not d.core.tool_on
    acts = d.feed(NewestChecked(d.t, serial=check.serial))
    assert "B1" in d.core.matcher.held and "B1" not in d.core.allowed()


@pytest.mark.parametrize("gap_first", [True, False])
def test_a_gap_the_tool_on_check_tells_before_the_enable_s_fetched_rundown_holds_nothing(
        gap_first):
    """B1's tool on; the controller made 41 and 42, both pushes lost, and no longer has 41.
    Revealed by the push of 43 (the operator pulled again), 41 is a gap and 42, fetched,
    B1's: recorded to B1, and B1 not held (tests/shell/test_gaps_daemon.py).  Found instead by
    the periodic check with the tool on (it ran between two pulls: a loaded machine), the
    gap held B1 and 42, made under B1's enable alone, was stored as no bolt's -- the same
    facts decided two ways.  Decided at the check's end now: 42 recorded to B1 and nothing
    held.  Control: a gap after the rundown fetched (42 gone, 41 B1's) may be a second
    rundown of B1: held."""
    from stationd.station.inputs import ResultsMissed

    d, check, at = on_and_checked()
    gap, ran = (41, 42) if gap_first else (42, 41)
    found = [ResultsMissed(d.t, gap, gap, "the controller no longer has it", live=True),
             ResultIn(d.t, res(ran, 1, True, 1), fetched=True, follows=40,
                      made_at=at + 2.2, live=True)]
    acts = [a for ev in (found if gap_first else found[::-1]) for a in d.feed(ev)]
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)] \
        == [("B1", ran)]
    held = [a.bolt for a in acts if isinstance(a, StoreCutUnknown)]
    if gap_first:
        assert held == [] and "B1" not in d.core.matcher.held, \
            "42, B1's rundown after the gap, is its result: B1 held all the same"
    else:
        assert held == ["B1"] and "B1" in d.core.matcher.held, \
            "42, made after B1's rundown with its tool on, may be a second one: B1 open"
