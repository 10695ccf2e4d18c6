"""An independent tester's finding, reproduced first against dustywill/open-protocol-emulator
(legacy profile; it answers MID 0064 with error 99, so the catch-up's refusal sets the shell's
``_no_history`` and no check ever asks): B07 enabled, run down (its push lost), the operator
leaves; the window-end check asks nothing and says nothing (by design: "the next push
tells"), so B07 is left open.  The operator comes back to B07, its tool goes on again and it
is run down a second time; that push skips the lost id, which the controller refuses to
give: a live gap.  The gap *does* tell -- but it names only enables whose bolt is not
selected now (``LostRules._still_open``), and B07 is selected now.  So B07 is recorded as
one OK tightening, the gap is stored naming no bolt, and nothing says B07 may have been
tightened twice (journal of the run: "tightening 3 missed with the link up: a gap", then
"bolt B07 OK"; result_gaps 3-3, no hold, no controller event for B07).  Where the same gap
is revealed by another bolt's push, B07 is held ("its result may be tightening 5"):
tests/station/test_check.py::test_a_gap_the_shell_tells_after_a_refused_catch_up_holds_...
"""

from __future__ import annotations

from stationd.station.actions import Record, StoreCutUnknown
from stationd.station.inputs import NewestChecked, ResultIn, ResultsMissed, ResultsSkipped
from tests.station.test_core import _on, _ready
from tests.station.test_lost import _window_ends
from tests.station.test_result_types import res


def test_a_refused_gap_revealed_by_the_same_bolt_s_second_rundown_does_not_pass_unsaid():
    d = _ready()
    check = _window_ends(d, 1, 3.0)          # B1 run down (41, push lost), left to B2
    d.feed(NewestChecked(d.t, serial=check.serial))   # _no_history: nothing asked, nothing said
    assert "B1" not in d.core.matcher.held and "B1" not in d.core.matcher.done
    _on(d, 1, 4)                              # the operator back on B1 (left open)
    d.step(("ack", 0.01, True))
    _on(d, 1, 2)
    assert d.core.tool_on, "B1's tool on again: it is run down a second time (42)"
    # the shell (ControllerFeed._live_gap_alone): 42 pushed skips 41, which the controller
    # refuses to give -- ResultsSkipped, the live gap, then 42 itself
    acts = d.feed(ResultsSkipped(d.t, 42))
    acts += d.feed(ResultsMissed(d.t, 41, 41, "the controller refused to give them (MID 0064)",
                                 live=True))
    acts += d.feed(ResultIn(d.t, res(42, 1, True, 1)))
    recorded = [a for a in acts if isinstance(a, Record)]
    held = [a.bolt for a in acts if isinstance(a, StoreCutUnknown)]
    # 41 was made under B1's first enable (the only enable since 40): B1 may have been
    # tightened twice -- held for a person (or at least said), not closed as one OK
    assert "B1" in d.core.matcher.held or "B1" in held, (
        f"B1 closed by 42 ({[(r.bolt if hasattr(r, 'bolt') else r) for r in recorded]}) "
        f"with the gap 41 of its first enable said of no bolt: held {held}")
