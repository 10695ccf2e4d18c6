"""A result of another pset than the one sent, pushed while the tool is on for a bolt (or
within its late-result window): a rundown with another program where the operator was, or
none of that bolt at all.  Never recorded to it, never "outside any tightening" either: the
tool off, the bolt held for a person, the result stored naming it (an integrator's trial:
the tool stayed on, the bolt was run down again and closed OK, the other program's rundown
in no bolt's history)."""

from __future__ import annotations

import pytest

from stationd.reasons import UnattributedKind
from stationd.station.actions import DisableTool, Publish, Record, StoreUnattributed
from stationd.station.events import Notice
from stationd.station.inputs import ResultIn
from stationd.words import notice_words, unattributed_words
from tests.station.test_core import _on, _ready
from tests.station.test_result_types import _enabled, res


def _said(acts: list[object]) -> list[str]:
    return [notice_words(a.event) for a in acts
            if isinstance(a, Publish) and isinstance(a.event, Notice)]


@pytest.mark.parametrize("left", [False, True], ids=["tool on", "late-result window"])
def test_a_result_of_another_pset_during_a_tightening_holds_its_bolt(left):
    d = _ready()
    _enabled(d, 1)                                        # pset 1 sent for B1
    if left:
        d.t += 0.5
        _on(d, 2, 3)                                      # the wrench leaves B1: tool off
        assert not d.core.tool_on
        d.t += 1.0
    acts = d.feed(ResultIn(d.t, res(12, 9, True, 1)))
    said = _said(acts)
    assert not [a for a in acts if isinstance(a, Record)], "recorded to a bolt it may not be"
    assert not any("outside any tightening" in s for s in said), said
    assert "B1" in d.core.matcher.held, f"B1 not held; said {said}"
    assert "another program" in d.core.matcher.held["B1"]
    assert not d.core.tool_on and not d.tool
    assert left or any(isinstance(a, DisableTool) for a in acts)
    [stored] = [a for a in acts if isinstance(a, StoreUnattributed)]
    assert stored.why.kind is UnattributedKind.OTHER_PSET and stored.why.bolt == "B1"
    assert "pushed while the tool was on for B1" in unattributed_words(stored.why)


def test_its_own_pset_after_it_is_the_bolts_and_another_pset_after_the_window_is_outside():
    """The same pset as sent: recorded to B1 as ever.  Another pset once B1's late-result
    window is over: outside any tightening as before (nothing was owed)."""
    d = _ready()
    _enabled(d, 1)
    acts = d.feed(ResultIn(d.t, res(12, 1, True, 1)))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts
            if isinstance(a, Record)] == [("B1", 12)]
    d.t += d.core.late_result_s + 1.0
    acts = d.feed(ResultIn(d.t, res(13, 9, True, 1)))
    assert any("outside any tightening" in s for s in _said(acts))
    assert "B1" not in d.core.matcher.held


@pytest.mark.parametrize(("after", "held"), [(1.5 + 2.0, True), (None, False)],
                         ids=["its time after the tool went on", "its time not known"])
def test_a_result_of_another_pset_fetched_with_the_link_up_holds_the_bolt_on(after, held):
    """The same rundown under another program, its push lost, fetched with the tool on for
    B1 (a later push skipped its id): made after B1's tool went on, only B1's tool was on
    since: B1 held, the tool off (a reviewer: stored outside any tightening, the tool left
    on).  Its time not known: stored as before, nothing proved."""
    d = _ready()
    _enabled(d, 1)
    on_at = d.core._enabled_at
    assert on_at is not None
    d.t += 4.0
    acts = d.feed(ResultIn(d.t, res(12, 9, True, 1), fetched=True, live=True, before=13,
                           made_at=None if after is None else on_at + after))
    assert not [a for a in acts if isinstance(a, Record)]
    assert d.core.matcher is not None
    assert ("B1" in d.core.matcher.held) is held
    assert (not d.core.tool_on) is held
