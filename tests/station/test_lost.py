"""Results heard late (:mod:`stationd.station.lost`): which enable a result fetched late was
made under, and the bolts held where nothing can tell (found by an independent review)."""

from __future__ import annotations

import pytest

from db.kinds import CHECK_NOTE_HEAD, LOST_UNKNOWN
from stationd.station.actions import CheckNewest, Record, SendParams, StoreCutUnknown
from stationd.station.inputs import NewestChecked, ResultIn, ResultsMissed, ResultsSkipped, Tick
from stationd.station.state import CHECK_WAIT_S
from tests.station.test_core import Driver, _on, _ready
from tests.station.test_result_types import _enabled, res


def _window_ends(d: Driver, bolt: int, after: float) -> CheckNewest:
    """The tool on for ``bolt``, the wrench leaving it ``after`` s later (to B2), its
    late-result window ending without a result: the controller's newest asked for (the test
    answers)."""
    d.answer_checks = False
    _enabled(d, bolt)
    d.t += after
    _on(d, 2, 3)
    d.t += d.core.late_result_s + 1.0
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    return check


def test_gap_holds_the_bolt_whose_enable_began_before_an_event_judged_during_it():
    """B1 enabled; 5 s later a line lead's batch increment (40, an event) is pushed, B1's
    tool staying on.  The operator then tightens B1 (41, its push lost) and leaves; B1's
    window ends, the check finds nothing; B3's 42 skips 41, which the controller does not
    give (a gap with the link up).  41 may be B1's: B1 held (a reviewer: only the enables
    since 40 came were candidates, B1 left open to be tightened twice)."""
    d = _ready()
    d.answer_checks = True
    _enabled(d, 1)
    d.t += 5.0
    d.feed(ResultIn(d.t, res(40, 1, True, 3)))        # batch increment: B1's tool stays on
    assert d.core.tool_on
    d.t += 2.0                                        # B1 tightened: 41, its push lost
    _on(d, 3, 3)                                      # the wrench leaves B1
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))                                 # the check: nothing read (refused)
    _enabled(d, 3)
    d.feed(ResultsSkipped(d.t, 42))
    acts = d.feed(ResultsMissed(d.t, 41, 41, "the controller no longer has it", live=True))
    assert [a.bolt for a in acts if isinstance(a, StoreCutUnknown)] == ["B1"]
    assert "B1" in d.core.matcher.held


def test_a_check_that_fetches_two_results_of_an_earlier_enable_puts_the_second_on_its_bolt():
    """The controller's clock not known (results placed by their ids only).  B3 enabled, the
    operator pulls twice, 41 NOK then 42 OK, both pushes lost, and leaves; B3's check void.
    B1 enabled, never tightened; its window ends and the check fetches 41 and 42.  41 is not
    proved B1's, and proves nothing of the order for B1's enable: 42 is not B1's either (a
    reviewer: 41 taken as judged during B1's enable put 42, B3's, on B1, a bolt never
    tightened counted done)."""
    d = _ready()
    _window_ends(d, 3, 3.0)                           # 41, 42 made: pushes lost
    d.feed(NewestChecked(d.t))                        # void: the controller did not answer
    _window_ends(d, 1, 1.0)                           # B1 left untightened
    acts = d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                           made_at=None, live=True))
    acts += d.feed(ResultIn(d.t, res(42, 1, True, 1), fetched=True, follows=40,
                            made_at=None, live=True))
    d.feed(NewestChecked(d.t))
    recorded = [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)]
    assert recorded == [], f"recorded {recorded}: nothing proves 42 was made under B1"


def test_the_same_through_a_push_that_reveals_them():
    """As above, B1's own 43 pushed revealing 41 and 42: 42 is not taken for B1 by the order
    of ids after 41, which was not B1's."""
    d = _ready()
    _window_ends(d, 3, 3.0)
    d.feed(NewestChecked(d.t))                        # void
    _enabled(d, 1)
    d.t += 1.0
    acts = d.feed(ResultsSkipped(d.t, 43))
    acts += d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                            made_at=None, live=True, before=43))
    acts += d.feed(ResultIn(d.t, res(42, 1, True, 1), fetched=True, follows=40,
                            made_at=None, live=True, before=43))
    recorded = [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)]
    assert ("B1", 42) not in recorded, recorded


def test_a_quick_second_hit_on_the_same_bolt_after_its_nok_is_still_that_bolts():
    """B1's NOK 40 pushed, its tool off; the tool goes on again for B1 at once (a retry) and
    the operator pulls: 41 NOK, its push lost, made 1.2 s after the tool-off; 42 OK pushed.
    Whichever of B1's enables made 41, it is B1's: recorded to it, its NOK counted (a
    reviewer: refused as perhaps 'the bolt before's' second hit, when that was B1 itself)."""
    d = _ready()
    _enabled(d, 1)
    d.feed(ResultIn(d.t, res(40, 1, False, 1)))       # B1's NOK: the tool off
    off = d.t
    assert not d.core.tool_on
    _enabled(d, 1)                                    # again, at once (a retry)
    assert d.t - off < 1.0
    d.t += 1.0
    acts = d.feed(ResultsSkipped(d.t, 42))
    acts += d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                            made_at=off + 1.2, live=True, before=42))
    acts += d.feed(ResultIn(d.t, res(42, 1, True, 1)))
    recorded = [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)]
    assert recorded == [("B1", 41), ("B1", 42)], recorded


def test_a_check_that_found_nothing_made_leaves_no_later_gap_to_its_bolt():
    """B1's window ends, the check finds the controller's newest is the last result heard:
    nothing made, B1 not tightened.  A later gap (B3's result skipping an id the controller
    does not give) holds B3's candidates only, not B1 (a reviewer: held beside them).  A check
    that could not read the controller leaves B1 a candidate."""
    for nothing_made, held in ((True, []), (False, ["B1"])):
        d = _ready()
        _window_ends(d, 1, 1.0)
        d.feed(NewestChecked(d.t, nothing_made=nothing_made))
        _enabled(d, 3)
        d.feed(ResultsSkipped(d.t, 42))
        acts = d.feed(ResultsMissed(d.t, 41, 41, "the controller no longer has it", live=True))
        assert [a.bolt for a in acts if isinstance(a, StoreCutUnknown)] == held, nothing_made


def test_a_push_that_comes_during_the_check_of_its_own_enable_is_its_bolt_s():
    """B1 tightened (41), its push late, not lost: B1's window ends and the check starts;
    41's push comes before the check's fetch.  Recorded to B1, as the check's fetch would
    have (a reviewer: stored unattributed, B1 neither recorded nor held, by which came
    first)."""
    d = _ready()
    _window_ends(d, 1, 3.0)
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1)))
    assert [(a.bolt, a.late) for a in acts if isinstance(a, Record)] == [("B1", True)]
    d.feed(NewestChecked(d.t, nothing_made=True))
    assert "B1" in d.core.matcher.done


@pytest.mark.parametrize("back", [False, True])
def test_a_check_the_controller_could_not_answer_holds_its_bolt(back):
    """B1 enabled, left; its window ends and the controller cannot say whether it made a
    rundown since (its answer refused).  B1 is held for a person, stored, and the tool does
    not go on for it again (a reviewer: left open, the operator went back to it and
    tightened it twice where its push had been lost).  ``back``: the wrench on B1 again while
    the check ran (selected, its tool waiting): held all the same."""
    d = _ready()
    check = _window_ends(d, 1, 1.0)
    if back:
        _on(d, 1, 4)
        d.step(("ack", 0.01, True))
        _on(d, 1, 2)
        assert not d.core.tool_on, "no tool on during the check"
    acts = d.feed(NewestChecked(d.t, unknown="refused by the controller: error 99",
                                serial=check.serial))
    [stored] = [a for a in acts if isinstance(a, StoreCutUnknown)]
    assert (stored.bolt, stored.what) == ("B1", LOST_UNKNOWN)
    assert stored.note.startswith(CHECK_NOTE_HEAD) and "error 99" in stored.note
    assert "B1" in d.core.matcher.held
    n = len(d.log)
    _on(d, 1, 4)
    d.step(("ack", 0.01, True))
    _on(d, 1, 2)
    assert not d.core.tool_on
    assert not [a for _, acts in d.log[n:] for a in acts if isinstance(a, SendParams)]


def test_a_check_never_answered_holds_its_bolt_when_the_tool_waits_no_longer():
    """The shell never answers the check (its fault, or a catch-up it waits for runs long):
    after CHECK_WAIT_S the tool may go on again, and B1, its result not known, is held."""
    d = _ready()
    _window_ends(d, 1, 1.0)
    d.t += CHECK_WAIT_S + 0.5
    acts = d.feed(Tick(d.t))
    assert [a.bolt for a in acts if isinstance(a, StoreCutUnknown)] == ["B1"]
    assert "no answer" in d.core.matcher.held["B1"]
    _enabled(d, 3)


def test_an_earlier_checks_answer_does_not_end_a_later_one():
    """B1's check is answered void only after B3's window ended and B3's check began: that
    answer (B1's) does not end B3's, whose tool stays off until its own answer (a reviewer:
    ended early, the check's result could be taken by the next bolt's enable)."""
    d = _ready()
    first = _window_ends(d, 1, 1.0)
    d.feed(NewestChecked(d.t, serial=first.serial))
    second = _window_ends(d, 3, 1.0)
    assert second.serial != first.serial
    d.feed(NewestChecked(d.t, nothing_made=True, serial=first.serial))
    _on(d, 2, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 2)
    assert not d.core.tool_on
    d.feed(NewestChecked(d.t, nothing_made=True, serial=second.serial))
    _on(d, 2, 1)
    assert d.core.tool_on


def test_a_check_refused_then_the_bolt_tightened_again_is_not_possible():
    """A trial against an independent Open Protocol emulator (MID 0064 refused with error
    99): B1 tightened, its push lost; the check refused; the operator went back to B1, which
    got the tool again and was tightened twice, then counted OK beside the gap.  B1 is held
    by the check: the tool does not go on for it, and the later gap holds nothing more."""
    d = _ready()
    check = _window_ends(d, 1, 3.0)
    d.feed(NewestChecked(d.t, unknown="refused by the controller: error 99 (unknown MID)",
                         serial=check.serial))
    n = len(d.log)
    _on(d, 1, 4)                                      # the operator back on B1
    assert not [a for _, acts in d.log[n:] for a in acts if isinstance(a, SendParams)]
    assert "B1" in d.core.matcher.held and "B1" not in d.core.matcher.done


def test_a_check_cut_by_the_link_holds_its_bolt():
    """The same trial, the controller silent to MID 0064 (behind a proxy): the check's
    answer never came, the link was reset, and the bolt whose lost result was being looked
    for got the tool again a minute later.  The shell tells the check ended unknown (the
    link changed): B1 held."""
    d = _ready()
    check = _window_ends(d, 1, 3.0)
    d.step(("fault", 0.1, "wrench"))                  # the link reset during the check
    d.feed(NewestChecked(d.t, unknown="the link to the controller was down",
                         serial=check.serial))
    d.step(("back", 0.5, "", 3))
    d.step(("caught", 2.0, False))                    # its catch-up incomplete too
    assert "B1" in d.core.matcher.held


def test_a_result_the_check_fetches_outside_its_enable_by_the_clock_holds_the_bolt():
    """The trial with a controller whose clock stepped (+60 s) between two of the station's
    measures: B1 tightened, its push lost; the check fetches it, of B1's pset, stamped 60 s
    after B1's window by that clock.  Not proved B1's, stored unattributed; B1 was left
    open and got the tool again.  The check fetches only what was made since the last
    result heard: B1, whose enable it checks, is held."""
    from stationd.station.actions import Record

    d = _ready()
    check = _window_ends(d, 1, 3.0)
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=d.t + 60.0, live=True))
    acts += d.feed(NewestChecked(d.t, serial=check.serial))
    recorded = [a.bolt for a in acts if isinstance(a, Record)]
    assert recorded == [] and [a.bolt for a in acts if isinstance(a, StoreCutUnknown)] == ["B1"]
    assert "B1" in d.core.matcher.held


def test_a_lost_push_after_an_unreadable_result_is_its_own_bolt_s_by_the_order_of_ids():
    """A new user's trial: B1's result 41 came unreadable (its id read; B1 held), then B3's
    push (42) was lost; the check as B3's window ended fetched 42, made 0.5 s after B3's tool
    went on, 3 s after B1's went off.  It was stored unattributed and B3 held "other enables
    came between", though none came: the unreadable 41, pushed under B1's enable, orders the
    ids as a read one does (B1's tool off after it), and 42 is B3's."""
    from stationd.station.inputs import UnreadableIn
    from tests.station.test_result_types import unreadable

    d = _ready()
    d.answer_checks = False
    _enabled(d, 3)
    d.feed(ResultIn(d.t, res(40, 1, False, 1)))       # B3's NOK, pushed: open again
    _enabled(d, 1)
    d.feed(UnreadableIn(d.t, unreadable(41, 1)))      # B1's, unreadable: held, tool off
    assert "B1" in d.core.matcher.held and not d.core.tool_on
    d.t += 3.0
    _enabled(d, 3)                                    # B3 again
    made = d.core._enabled_at + 0.5                   # B3 run down at once: 42, push lost
    d.t += 1.0
    _on(d, 2, 3)                                      # the wrench leaves B3
    d.t += d.core.late_result_s + 1.0
    [check] = [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    acts = d.feed(ResultIn(d.t, res(42, 1, True, 1), fetched=True, follows=41,
                           made_at=made, live=True))
    d.feed(NewestChecked(d.t, serial=check.serial))
    recorded = [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)]
    assert recorded == [("B3", 42)], recorded
    assert "B3" not in d.core.matcher.held and "B3" in d.core.matcher.done
    assert "B1" in d.core.matcher.held                # (its own hold stands)


@pytest.mark.parametrize("then", ["given", "refused"])
def test_a_lost_push_asked_for_again_after_the_link_dropped_still_holds_its_bolt(then):
    """B1 tightened (41, its push lost), its check told nothing; B3's 42 skips 41 and the
    link drops as 41 is asked for; 42 is fed (recorded to B3), the link comes back.  The
    shell's next catch-up asks for 41 first (``ControllerFeed._owed``) and feeds it as
    it would have (fetched with the link up, before 42), or, refused, a gap with the link
    up: B1 held, as without the cut (told as the cut's gap, not live, B1 was left open:
    tightened twice)."""
    d = _ready()
    d.answer_checks = True
    _enabled(d, 1)
    d.t += 2.0                                        # B1 tightened: 41, its push lost
    _on(d, 3, 3)
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))                                 # the check told nothing
    _enabled(d, 3)
    d.feed(ResultsSkipped(d.t, 42))
    d.step(("fault", 0.1, "wrench"))                  # the link drops as 41 is asked for
    d.feed(ResultIn(d.t, res(42, 1, True, 1)))        # fed all the same
    d.step(("back", 0.5, "", 1))                      # its catch-up asks for 41 first
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40, made_at=None,
                           live=True, before=42)) if then == "given" else \
        d.feed(ResultsMissed(d.t, 41, 41, "the controller refused to give them", live=True))
    assert not [a for a in acts if isinstance(a, Record)]
    assert "B1" in d.core.matcher.held and "B1" not in d.core.matcher.done


@pytest.mark.parametrize("checked", [True, False], ids=["check found nothing", "check void"])
def test_a_late_push_made_before_the_enable_owed_now_is_never_that_bolts(checked):
    """B1 tightened (41, made while its tool was on), its push held back by the controller
    (an integrator's trial: 13 s late), the wrench leaving B1; B1's window ends, the check of
    the controller's newest finds nothing new (or cannot read it).  B3, of the same pset, is
    enabled 10 s later; 41 arrives then, its own time 10 s before B3's enable.  It is not
    B3's: B3 is not closed by it (an integrator's trial: B3 recorded OK with B1's result, B1
    left missing, B3's own result stored as no bolt's), and B3's tool stays on for its own
    rundown; B1, whose enable got no result, is held for a person."""
    d = _ready()
    d.answer_checks = False
    _enabled(d, 1)
    d.t += 1.0
    made = d.t                                        # B1 tightened: 41, pushed late
    _on(d, 3, 3)                                      # the wrench leaves B1
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    d.feed(NewestChecked(d.t, nothing_made=checked))
    d.t += 10.0
    _enabled(d, 3)
    d.t += 2.0
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), made_at=made))
    recorded = [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)]
    assert recorded == [], f"recorded {recorded}: 41 was made 12 s before B3's enable"
    assert d.core.tool_on and d.core.bolt == "B3"
    assert "B1" in d.core.matcher.held
    acts = d.feed(ResultIn(d.t + 1.0, res(42, 1, True, 1), made_at=d.t + 0.5))
    recorded = [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)]
    assert recorded == [("B3", 42)], recorded


def test_a_result_timed_before_its_enable_with_no_other_enable_there_is_its_own():
    """The controller's clock stepped back since it was measured: B1's own rundown pushed
    while its tool is on reads 5 s before B1's enable.  No other enable could have made it:
    recorded to B1 as ever (a reviewer: taken for "made before the enable", stored outside
    any tightening with B1's tool left on, for every bolt until the clock was measured)."""
    d = _ready()
    _enabled(d, 1)
    enabled = d.t
    d.t += 1.0
    acts = d.feed(ResultIn(d.t, res(41, 1, False, 1), made_at=enabled - 5.0))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts
            if isinstance(a, Record)] == [("B1", 41)]


def test_a_late_push_of_a_bolts_first_enable_while_it_is_on_again_is_its_own():
    """B1 enabled (its NOK 41 pushed late), then B2 (no result), then B1 again: 41 arrives,
    made during B1's first enable.  Whichever of B1's enables made it, it is B1's: recorded
    to B1, its NOK counted (a reviewer: stored outside any tightening, the NOK lost)."""
    d = _ready()
    d.answer_checks = False
    _enabled(d, 1)
    made = d.t + 0.5
    d.t += 1.0
    _on(d, 2, 3)                                      # the wrench leaves B1 for B2
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    d.feed(NewestChecked(d.t))                        # void
    _enabled(d, 1)                                    # back on B1
    d.t += 1.0
    acts = d.feed(ResultIn(d.t, res(41, 1, False, 1), made_at=made))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts
            if isinstance(a, Record)] == [("B1", 41)]


def test_a_late_push_with_no_enable_on_holds_the_bolt_its_time_places_it_in():
    """B1 tightened (41, its push held back), the wrench leaves it and rests; B1's window
    ends, the check finds nothing new.  41 comes with no tool on: its time places it in B1's
    enable: B1 held, never left open to be tightened twice (a reviewer)."""
    d = _ready()
    d.answer_checks = False
    _enabled(d, 1)
    made = d.t + 0.5
    d.t += 1.0
    d.step(("loc", 0.1, 0, 0.05, 0.0))                # the wrench leaves B1, on no bolt
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    d.feed(NewestChecked(d.t, nothing_made=True))
    d.t += 5.0
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), made_at=made))
    assert not [a for a in acts if isinstance(a, Record)]
    assert "B1" in d.core.matcher.held
