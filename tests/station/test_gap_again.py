"""A gap's ids may be the rundown of an enable whose bolt's tool went on again since
(``CoreState._again``, :meth:`LostRules._gap_again`; the tester's finding:
tests/station/test_refused_gap_same_bolt.py): that bolt is held once the pushed result that
revealed the gap is recorded to it, not where the order of ids proves the gap is not its."""

from __future__ import annotations

from typing import Any

from stationd.station.actions import Record, StoreCutUnknown
from stationd.station.commands import ReleaseBolt
from stationd.station.inputs import NewestChecked, ResultIn, ResultsMissed, ResultsSkipped
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
