"""A gap's ids may be the rundown of an enable whose bolt's tool went on again since
(``CoreState._again``, :meth:`LostRules._gap_again`; the tester's finding:
tests/station/test_refused_gap_same_bolt.py): that bolt is held once the pushed result that
revealed the gap is recorded to it, not where the order of ids proves the gap is not its."""

from __future__ import annotations

from typing import Any

from drivers.keeper import FaultKind
from stationd.station.actions import Record, StoreCutUnknown
from stationd.station.commands import ReleaseBolt
from stationd.station.inputs import (
    CaughtUp,
    DeviceBack,
    DeviceFault,
    NewestChecked,
    ResultIn,
    ResultsMissed,
    ResultsSkipped,
)
from stationd.station.policy import NokPolicy, NokRule
from tests.station.test_commands import SUPERVISOR
from tests.station.test_core import Driver, _on, _ready
from tests.station.test_lost import _window_ends
from tests.station.test_result_types import _enabled, res

GAP = "the controller refused to give them (MID 0064)"


def _again_and_revealed(d: Driver) -> list[Any]:
    """B1's tool on again, run down (42), its push skipping 41 that the controller does not
    give (a live gap, as the shell tells it): the actions."""
    _on(d, 1, 4)
    d.step(("ack", 0.01, True))
    _on(d, 1, 2)
    assert d.core.tool_on
    acts = d.feed(ResultsSkipped(d.t, 42))
    acts += d.feed(ResultsMissed(d.t, 41, 41, GAP, live=True))
    return acts + d.feed(ResultIn(d.t, res(42, 1, True, 1)))


def test_the_bolt_run_down_again_is_held_after_its_record_and_the_hold_names_the_gap():
    d = _ready()
    check = _window_ends(d, 1, 3.0)
    d.feed(NewestChecked(d.t, serial=check.serial))     # nothing asked (no history)
    acts = _again_and_revealed(d)
    kinds = [(type(a).__name__, a.bolt) for a in acts if isinstance(a, Record | StoreCutUnknown)]
    # 42 recorded to B1 first: a hold stored before a rundown ends with it (db.holds)
    assert kinds == [("Record", "B1"), ("StoreCutUnknown", "B1")], kinds
    assert "tightening 41" in d.core.matcher.held["B1"]


def test_no_hold_where_the_window_end_check_found_nothing_made():
    """The controller answers the window-end check: nothing made since 40, so 41 was made
    after B1's first enable's window: not its (the order of ids), B1 closed by 42."""
    d = _ready()
    check = _window_ends(d, 1, 3.0)
    d.feed(NewestChecked(d.t, nothing_made=True, serial=check.serial))
    acts = _again_and_revealed(d)
    assert not [a for a in acts if isinstance(a, StoreCutUnknown)]
    assert "B1" not in d.core.matcher.held and "B1" in d.core.matcher.done


def test_the_bolt_enabled_again_within_its_window_is_held_too():
    """B1 run down (41, its push lost), the wrench off it and back before its late-result
    window ended: the tool on again for B1 (its first enable still owed), run down (42)."""
    d = _ready()
    _enabled(d, 1)
    d.t += 3.0
    _on(d, 2, 3)                                  # the wrench leaves B1: the tool off
    assert not d.core.tool_on
    acts = _again_and_revealed(d)
    assert [a.bolt for a in acts if isinstance(a, StoreCutUnknown)] == ["B1"]


def test_released_after_its_ok_the_bolt_is_not_left_to_loosen_under_the_loosen_strategy():
    """Held after its OK was recorded, B1 is done: its release leaves it so (its loosen pset
    would never be selected; a loosen command reworks it)."""
    d = _ready(nok=NokPolicy(NokRule(max_nok=2, strategy="loosen", loosen_pset=91)))
    check = _window_ends(d, 1, 3.0)
    d.feed(NewestChecked(d.t, serial=check.serial))
    _again_and_revealed(d)
    assert "B1" in d.core.matcher.held
    d.command(1, ReleaseBolt("VIN1", "B1", "checked on the controller"), SUPERVISOR)
    assert "B1" not in d.core.matcher.held and "B1" in d.core.matcher.done
    assert "B1" not in d.core._loosen


def test_a_result_made_under_the_first_of_two_unanswered_enables_of_a_bolt_still_holds_it():
    """Weakness C (a review): B1 enabled and run down (41, its push lost), left; its
    window's check asks nothing (no history).  The operator comes back to B1 (still open:
    its first enable moves to ``_again``), its tool goes on again, and leaves it without a
    rundown; that window ends unanswered too.  ``_unanswered_after`` then drops the first
    enable (``_answered_bolt``) and keeps only the second: more than the hold's note is
    lost.  After a reconnect the catch-up fetches 41, made (by the controller's own time)
    under B1's first enable: held against nothing -- B1 left open, tightened twice where 41
    was its rundown.  Control: without the second enable B1 is held."""
    held = {}
    for again in (False, True):
        d = _ready()
        d.feed(ResultIn(d.t, res(40, 2, True, 1)))
        check = _window_ends(d, 1, 3.0)
        made = d.core._enabled_at + 1.0             # 41: B1's first rundown
        d.feed(NewestChecked(d.t, serial=check.serial))   # nothing asked
        if again:
            check = _window_ends(d, 1, 3.0)            # B1 again, left without a rundown
            d.feed(NewestChecked(d.t, serial=check.serial))
        d.t += 5.0
        d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "link lost"))
        d.t += 5.0
        d.feed(DeviceBack(d.t, "wrench", reconnects=1))
        acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                               made_at=made))
        acts += d.feed(CaughtUp(d.t, True, "", 1))
        assert not [a for a in acts if isinstance(a, Record)]
        held[again] = d.core.matcher.held.get("B1")
    assert held[False] is not None, held
    assert held[True] is not None, f"B1 left open after its second enable: {held}"
