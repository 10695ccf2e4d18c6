"""The check of the controller's newest result as an enable's late-result window ends
(:mod:`stationd.station.lost`): scenarios an independent review found, each a bolt that
could be tightened twice or a hold that would not end."""

from __future__ import annotations

from typing import Any

import pytest

from stationd.station.actions import CheckNewest, EnableTool, Record, SendParams, StoreCutUnknown
from stationd.station.commands import ReleaseBolt
from stationd.station.events import Because, Notice, ToolDisabled
from stationd.station.inputs import NewestChecked, ResultIn, Tick
from stationd.station.policy import NokPolicy, NokRule
from stationd.station.state import CHECK_ON_S, CHECK_WAIT_S
from stationd.words import notice_words, state_words
from tests.station.test_commands import SUPERVISOR, _answer
from tests.station.test_core import Driver, _on, _ready, published
from tests.station.test_lost import _window_ends
from tests.station.test_result_types import _enabled, res


@pytest.mark.parametrize("back", [False, True])
@pytest.mark.parametrize("made", ["clock unknown", "pulled 1 s after the enable"])
def test_a_result_the_check_fetched_but_cannot_place_holds_the_bolt_selected_again(back, made):
    """B1 enabled, tightened (41, its push lost), the operator leaves to B2; B1's window
    ends and the check starts.  Meanwhile the wrench is back on B1 (selected, parameters
    acknowledged, its tool waiting for the check).  The check fetches 41, which nothing
    proves B1's (no earlier result judged, the controller's clock not known): stored
    unattributed.  B1 may be tightened: it must be held (or at least its tool must not go
    on again) -- as the commit does where the controller could not tell."""
    d = _ready()
    check = _window_ends(d, 1, 3.0)
    made_at = None if made == "clock unknown" else d.core._enabled_at + 1.0
    if back:
        _on(d, 1, 4)                                   # back on B1 during the check
        d.step(("ack", 0.01, True))
        _on(d, 1, 2)
    assert not d.core.tool_on, "no tool on during the check"
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=made_at, live=True))
    assert not [a for a in acts if isinstance(a, Record)], "not proved B1's"
    acts += d.feed(NewestChecked(d.t, serial=check.serial))   # nid > last: fetched, told
    n = len(d.log)
    _on(d, 1, 4)
    d.step(("ack", 0.01, True))
    _on(d, 1, 2)
    enabled = [a for _, aa in d.log[n:] for a in aa if isinstance(a, EnableTool)]
    held = [a.bolt for a in acts if isinstance(a, StoreCutUnknown)]
    assert "B1" in d.core.matcher.held or not enabled, (
        f"B1 neither held ({held}) nor kept off: its tool went on again "
        f"({[a.bolt for a in enabled]}) though 41 may be its rundown")


def test_the_state_s_reason_no_longer_says_held_after_the_release_of_a_checks_hold():
    """B1 selected during the check, the check cannot tell: held, the selection dropped with
    the reason UNKNOWN_HELD.  A supervisor releases B1: the state's reason must no longer say
    it is held (as for UNREADABLE_HELD / NOT_TAKEN_HELD: `_unhold`)."""
    d = _ready()
    check = _window_ends(d, 1, 1.0)
    _on(d, 1, 4)
    d.step(("ack", 0.01, True))
    _on(d, 1, 2)
    d.feed(NewestChecked(d.t, unknown="refused", serial=check.serial))
    assert d.core.reason.kind is Because.UNKNOWN_HELD and "B1" in d.core.matcher.held
    acts = d.command(1, ReleaseBolt("VIN1", "B1", "checked on the controller"), SUPERVISOR)
    assert _answer(acts).answer.accepted and "B1" not in d.core.matcher.held
    assert state_words(d.core.reason) == "tracking the wrench", state_words(d.core.reason)


@pytest.mark.parametrize("live", [True, False])
def test_a_gap_the_shell_tells_after_a_refused_catch_up_holds_the_bolt_left_since(live):
    """The core's side of tests/shell/test_check_newest.py: a controller whose catch-up
    refused MID 0064.  B1 enabled and tightened (41, its push lost), left; the check asks
    nothing (NewestChecked without a word).  B3 enabled; its push 42 reveals 41 as the shell
    tells it (a refused catch-up's gap: live=False).  41 may be B1's: B1 must be held, not
    left open to be tightened twice."""
    from stationd.station.inputs import ResultsMissed
    d = _ready()
    check = _window_ends(d, 1, 3.0)
    d.feed(NewestChecked(d.t, serial=check.serial))          # _no_history: nothing said
    _on(d, 3, 4)
    d.step(("ack", 0.01, True))
    _on(d, 3, 2)
    assert d.core.tool_on
    acts = d.feed(ResultsMissed(d.t, 41, 41, "the controller refused to give them (MID 0064)",
                                live=live))
    acts += d.feed(ResultIn(d.t, res(42, 1, True, 1)))
    assert "B1" in d.core.matcher.held, (
        f"B1 left open: {[a for a in acts if isinstance(a, StoreCutUnknown)]}")


def test_a_gap_the_check_finds_holds_the_bolt_selected_again():
    """As the first test, the controller no longer giving 41 (a live gap told by the
    check's fetch, ``_fetch``: then NewestChecked without a word): B1, selected again during
    the check, is not held and its tool goes on -- tightened twice where 41 was B1's."""
    from stationd.station.inputs import ResultsMissed
    d = _ready()
    check = _window_ends(d, 1, 3.0)
    _on(d, 1, 4)
    d.step(("ack", 0.01, True))
    _on(d, 1, 2)
    acts = d.feed(ResultsMissed(d.t, 41, 41, "the controller no longer has it", live=True))
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    n = len(d.log)
    _on(d, 1, 4)
    d.step(("ack", 0.01, True))
    _on(d, 1, 2)
    enabled = [a.bolt for _, aa in d.log[n:] for a in aa if isinstance(a, EnableTool)]
    assert "B1" in d.core.matcher.held or not enabled, f"B1 not held, tool on: {enabled}"


def test_a_result_the_check_places_on_the_bolt_selected_again_keeps_its_tool_off():
    """Control: 41 proved B1's (pulled 3 s after the enable) is recorded to B1 during the
    check while B1 is selected again: B1 done, its tool must not go on."""
    d = _ready()
    check = _window_ends(d, 1, 3.0)
    made_at = d.core._enabled_at + 2.5
    _on(d, 1, 4)
    d.step(("ack", 0.01, True))
    _on(d, 1, 2)
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=made_at, live=True))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B1"]
    d.feed(NewestChecked(d.t, serial=check.serial))
    n = len(d.log)
    _on(d, 1, 4)
    d.step(("ack", 0.01, True))
    _on(d, 1, 2)
    enabled = [a.bolt for _, aa in d.log[n:] for a in aa if isinstance(a, EnableTool)]
    assert not enabled, enabled


def test_a_check_the_core_gave_up_on_that_fetches_during_the_next_window_leaves_no_bolt_open():
    """B1's check is overdue (the shell waits for a long catch-up: 4467d86 waits instead of
    giving up): after CHECK_WAIT_S B1 is held and the tool may go on.  B3 is enabled,
    tightened (41, its push lost) and left.  Within B3's window the stale check (B1's) runs
    on: the controller's newest is 41, after the last heard (40): fetched, live, before=None
    -- not B3's (no check of B3 runs, no push revealed it): stored unattributed, B3 not yet
    an unanswered enable.  B3's window ends; its own check finds the newest (41) is the last
    accounted for: nothing made.  B3 is then open, untightened by the core's account, and
    its tool goes on again: tightened twice."""
    d = _ready()
    first = _window_ends(d, 1, 1.0)
    d.t += CHECK_WAIT_S + 0.5
    d.feed(Tick(d.t))                                   # overdue: B1 held
    assert "B1" in d.core.matcher.held
    _enabled(d, 3)
    enabled_at = d.core._enabled_at
    d.t += 3.0                                          # 41 made, its push lost
    _on(d, 2, 3)                                        # the wrench leaves B3
    assert not d.core.tool_on
    d.t += 1.0
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=enabled_at + 3.0, live=True))   # the stale check's fetch
    acts += d.feed(NewestChecked(d.t, nothing_made=False, serial=first.serial))
    d.t += d.core.late_result_s
    [second] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    # the shell: newest 41 == _accounted 41 (advanced by the stale check), nothing received
    acts += d.feed(NewestChecked(d.t, nothing_made=True, serial=second.serial))
    n = len(d.log)
    _on(d, 3, 4)
    d.step(("ack", 0.01, True))
    _on(d, 3, 2)
    enabled = [a.bolt for _, aa in d.log[n:] for a in aa if isinstance(a, EnableTool)]
    recorded = [a.bolt for a in acts if isinstance(a, Record)]
    assert "B3" in d.core.matcher.held or "B3" in recorded or not enabled, (
        f"41 (made under B3 alone) stored unattributed, B3 neither recorded nor held, and "
        f"its tool went on again: {enabled}")


def test_a_result_after_a_check_that_found_nothing_is_the_next_enables():
    """A supervisor's trial: B2's result 40 came; B1 enabled, left untightened; its window's
    check found nothing made.  B3 enabled and tightened (41, its push lost), the controller's
    clock not known: its own check fetches 41.  Nothing was made between 40 and B1's window's
    end, and the tool went on for B3 alone since: 41 is B3's, recorded (it was held as
    "other enables came between", released, and B3 tightened twice)."""
    d = _ready()
    _enabled(d, 2)
    d.feed(ResultIn(d.t, res(40, 2, True, 1)))
    d.t += 3.0
    first = _window_ends(d, 1, 1.0)
    d.feed(NewestChecked(d.t, nothing_made=True, serial=first.serial))
    second = _window_ends(d, 3, 3.0)
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=None, live=True))
    acts += d.feed(NewestChecked(d.t, serial=second.serial))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B3"]
    assert not [a for a in acts if isinstance(a, StoreCutUnknown)]
    assert "B3" in d.core.matcher.done and "B3" not in d.core.matcher.held


def _loosen_done_then_enabled(d: Any) -> None:
    """B1 (NOK policy loosen) tightened NOK (40, pushed), loosened (41, pushed), then the
    tool on again for its tightening pset."""
    for tid, ok, code in ((40, False, 1), (41, True, 2)):
        sent = _enabled(d, 1)
        assert sent.loosen == (code == 2)
        d.feed(ResultIn(d.t, res(tid, sent.selection.pset or 0, ok, code)))
        assert not d.core.tool_on
        d.t += 1.0
    sent = _enabled(d, 1)
    assert not sent.loosen and sent.selection.pset == 1


def test_a_push_lost_with_the_tool_on_is_found_by_the_periodic_check_and_the_tool_goes_off():
    """A new-user trial (``lose_push_every=7``, NOK policy loosen): B1 tightened NOK,
    loosened, enabled again for its tightening pset; the operator runs it down (42, NOK),
    its push lost.  The station heard nothing: the tool stayed on with the same pset and the
    operator ran the NOK bolt down again without its loosening.  Within CHECK_ON_S of
    tool-on the controller's newest is asked: 42 fetched (made under this enable: the id
    after the last result, judged under the enable before, of the same bolt), recorded to
    B1, the tool off, the NOK policy applied (loosen first): no second rundown under that
    enable."""
    d = _ready(nok=NokPolicy(NokRule(3, "loosen", 90)))
    d.answer_checks = False
    _loosen_done_then_enabled(d)
    d.t += 1.0                                         # 42 made: its push lost
    assert not [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    d.t += CHECK_ON_S
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    assert check.tool_on and d.core.tool_on
    acts = d.feed(ResultIn(d.t, res(42, 1, False, 1), fetched=True, follows=41,
                           made_at=None, live=True))
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    assert [(a.bolt, a.result.tightening_id) for a in acts if isinstance(a, Record)] == [
        ("B1", 42)]
    assert not d.core.tool_on and not d.tool, "the tool left on after the lost NOK was found"
    assert [e.reason.kind for e in published(acts, ToolDisabled)] == [Because.RUNDOWN]
    assert "B1" not in d.core.matcher.held
    assert any("fetched by a check of the controller's newest with the tool on for B1"
               in notice_words(e) for e in published(acts, Notice))
    # no second rundown under that enable: B1's next selection is its loosening
    n = len(d.log)
    _on(d, 1, 4)
    sent = [a for _, aa in d.log[n:] for a in aa if isinstance(a, SendParams)]
    assert [(s.loosen, s.selection.pset) for s in sent] == [(True, 90)]
    # the enable is owed nothing more: no window-end check of it, nothing held
    d.t += d.core.late_result_s + 1.0
    assert not [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    assert "B1" not in d.core.matcher.held


@pytest.mark.parametrize("answer", ["nothing made", "could not tell"])
def test_a_periodic_check_that_finds_nothing_or_cannot_tell_leaves_the_tool_on(answer):
    """The tool on for B1, no rundown yet: the periodic check finds the newest the last one
    accounted for (the tool stays on, nothing held, nothing said), or cannot tell (neither:
    the next period asks again; only the window-end check holds, as the operator leaves
    without a result)."""
    d = _ready()
    d.answer_checks = False
    _enabled(d, 1)
    for _ in range(3):
        d.t += CHECK_ON_S
        [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
        assert check.tool_on
        acts = d.feed(NewestChecked(d.t, nothing_made=answer == "nothing made",
                                    unknown="" if answer == "nothing made" else "refused",
                                    serial=check.serial))
        assert d.core.tool_on and d.tool and "B1" not in d.core.matcher.held
        assert not published(acts, Notice) and not published(acts, ToolDisabled)
    _on(d, 2, 3)                                       # the operator leaves B1
    d.t += d.core.late_result_s + 1.0
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    assert not check.tool_on
    d.feed(NewestChecked(d.t, unknown="refused", serial=check.serial))
    assert "B1" in d.core.matcher.held                 # the window-end rule holds it


@pytest.mark.parametrize("found", ["a result not proved its own", "a gap"])
def test_what_a_periodic_check_cannot_place_turns_the_tool_off_and_holds_the_bolt(found):
    """The tool on for B1, the first enable since the start (no result judged: the order of
    ids proves nothing), the controller's clock not known.  The periodic check fetches 41
    (of B1's pset) -- or finds the controller no longer has it (a gap).  It may be B1's
    rundown: left with its tool on, the operator runs it down again; and the window-end
    check, the newest then accounted for, would find nothing made and leave B1 open.  The
    tool goes off and B1 is held for a person."""
    d = _ready()
    d.answer_checks = False
    _enabled(d, 1)
    d.t += CHECK_ON_S
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    acts = found_by_the_check(d, found)
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    assert not d.core.tool_on and not d.tool, "the tool left on"
    assert "B1" in d.core.matcher.held
    assert [a.bolt for a in acts if isinstance(a, StoreCutUnknown)] == ["B1"]
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    assert "B1" in d.core.matcher.held and "B1" not in d.core.allowed()


def found_by_the_check(d: Driver, found: str) -> list[Any]:
    """What a check of the controller's newest found that it cannot place as B1's: ``a
    gap`` (41, no longer on the controller), else 41 of B1's pset, not proved B1's (no
    clock); nothing is recorded to a bolt."""
    from stationd.station.inputs import ResultsMissed

    if found == "a gap":
        acts = d.feed(ResultsMissed(d.t, 41, 41, "the controller no longer has it", live=True))
    else:
        acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=None,
                               made_at=None, live=True))
    assert not [a for a in acts if isinstance(a, Record)]
    return acts
