"""Every result from the controller counted right, in the pure core: only a tightening closes a
bolt (batch steps, bypasses, aborts, reference setups and unknown types are controller events
that close, open or count nothing); a result that could not be read is stored whole and holds
its bolt until a supervisor releases it; a result fetched after a link cut goes to the bolt
the tool was enabled for only when the controller's own data proves it was made there."""

from __future__ import annotations

import dataclasses
from dataclasses import replace
from datetime import datetime
from typing import Any

import pytest

from db.kinds import LOST_UNKNOWN, UNKNOWN_TYPE_HELD
from drivers.keeper import FaultKind
from drivers.wrench import ResultKind, UnreadableResult, result_kind
from stationd.reasons import Reason, Unattributed, UnattributedKind, Unproved, UnprovedKind, Why
from stationd.station.actions import (
    CheckNewest,
    DisableTool,
    Publish,
    Record,
    SendParams,
    StoreControllerEvent,
    StoreCutUnknown,
    StoreUnattributed,
    StoreUnreadable,
)
from stationd.station.commands import ReleaseBolt
from stationd.station.events import (
    Because,
    BoltLocked,
    BoltReleased,
    BoltSkipped,
    ControllerResultEvent,
    Notice,
    ResultUnreadable,
    Said,
    State,
    StateReason,
    ToolDisabled,
    VehicleOpened,
)
from stationd.station.inputs import (
    CaughtUp,
    DeviceBack,
    DeviceFault,
    NewestChecked,
    ResultCopy,
    ResultIn,
    ResultsMissed,
    ResultsSkipped,
    Tick,
    UnreadableIn,
    VehicleLoaded,
)
from stationd.station.policy import NokPolicy, NokRule
from stationd.station.state import CHECK_WAIT_S, PENDING_PUSH_S
from stationd.words import (
    answer_words,
    notice_words,
    reason_words,
    result_type_words,
    state_words,
    stored_what,
    unattributed_words,
    worded,
)
from tests.rundowns import rundown
from tests.station.test_commands import OPERATOR, SUPERVISOR, _answer
from tests.station.test_core import BOLTS, Driver, _kinds, _on, _ready, published

EVENT_TYPES = (3, 4, 5, 6, 8)


def res(tid: int, pset: int, ok: bool = True, code: int | None = None, vin: str = "",
        when: datetime | None = None) -> Any:
    return rundown(tid, pset, ok, code=code, vin=vin, when=when)


def _enabled(d: Driver, bolt: int = 1) -> SendParams:
    """The wrench on ``bolt`` until the tool is on for it."""
    n = len(d.log)
    _on(d, bolt)
    [sent] = [a for _, acts in d.log[n:] for a in acts if isinstance(a, SendParams)]
    d.step(("ack", 0.01, True))
    _on(d, bolt, 1)
    assert d.tool and d.core.tool_on, d.core.reason
    return sent


def _notices(acts: list[Any]) -> list[str]:
    return [notice_words(e) for e in published(acts, Notice)]


def test_the_kind_of_every_type_code():
    assert result_kind(1) is result_kind(7) is ResultKind.TIGHTENING
    assert result_kind(2) is ResultKind.LOOSENING
    assert {result_kind(c) for c in EVENT_TYPES} == {ResultKind.EVENT}
    assert result_kind(9) is result_kind(0) is result_kind(99) is ResultKind.UNKNOWN
    # a revision without a type: what the station sent decides
    assert result_kind(None) is ResultKind.TIGHTENING
    assert result_kind(None, sent_loosen=True) is ResultKind.LOOSENING
    assert result_kind(1, sent_loosen=True) is ResultKind.TIGHTENING   # the type wins


@pytest.mark.parametrize("code", EVENT_TYPES)
def test_a_result_that_is_not_a_tightening_never_closes_the_bolt_the_tool_is_on(code):
    d = _ready()
    sent = _enabled(d)
    acts = d.feed(ResultIn(d.t, res(7, sent.selection.pset or 0, True, code)))
    assert not [a for a in acts if isinstance(a, Record | DisableTool | StoreUnattributed)]
    [store] = [a for a in acts if isinstance(a, StoreControllerEvent)]
    # named by its type: the words are the shell's, as it stores it (the same text as before)
    assert (store.bolt, store.what, store.vin) == ("B1", None, "VIN1")
    assert stored_what(store) == result_type_words(code)
    [ev] = published(acts, ControllerResultEvent)
    assert (ev.result_type, ev.bolt, ev.tightening_id, ev.what) == (code, "B1", 7, "")
    said = worded(ev)
    assert isinstance(said, ControllerResultEvent) and said.what == result_type_words(code)
    assert _notices(acts) == [f"{result_type_words(code)} on the controller: not a "
                              "tightening, B1 still open"]
    assert "B1" not in d.core.matcher.done and d.core.tool_on      # the tool as it was
    assert d.core.state is State.TIGHTENING
    # the real tightening that follows closes it
    acts = d.feed(ResultIn(d.t, res(8, sent.selection.pset or 0, True, 1)))
    assert [(a.bolt, a.offline) for a in acts if isinstance(a, Record)] == [("B1", False)]
    assert "B1" in d.core.matcher.done


def test_a_batch_increment_with_the_tool_off_is_a_controller_event_of_no_bolt():
    d = _ready()
    acts = d.feed(ResultIn(d.t, res(3, 1, True, 3)))
    [store] = [a for a in acts if isinstance(a, StoreControllerEvent)]
    assert store.bolt is None and stored_what(store) == "batch increment"
    assert _notices(acts) == ["batch increment on the controller: not a tightening"]
    [n] = published(acts, Notice)
    assert (n.said, n.bolt, n.level) == (Said.CONTROLLER_EVENT, None, "info")
    assert not d.core.matcher.done


@pytest.mark.parametrize("code", [9, 0])
def test_a_type_the_station_does_not_know_under_the_enable_holds_its_bolt(code):
    """An MES integrator's trial: a result of type 9 (a real rundown, 49 Nm OK) made under
    B35's enable was stored as a controller event, B35 left open ("still open"), and it
    left missing.  Perhaps the bolt's tightening, perhaps none: never taken for one, never
    left open to be run down again: the tool off, the bolt held for a person, the enable
    answered, and the result stored as the station's own kind (an MES is sent it, not
    decided)."""
    d = _ready()
    sent = _enabled(d)
    acts = d.feed(ResultIn(d.t, res(7, sent.selection.pset or 0, True, code)))
    assert not [a for a in acts if isinstance(a, Record)]
    [store] = [a for a in acts if isinstance(a, StoreControllerEvent)]
    assert (store.what, store.bolt, store.selection) == (UNKNOWN_TYPE_HELD, "B1", sent.selection)
    assert stored_what(store) == UNKNOWN_TYPE_HELD
    [ev] = published(acts, ControllerResultEvent)
    assert (ev.result_type, ev.what, ev.bolt, ev.tightening_id) == (
        code, UNKNOWN_TYPE_HELD, "B1", 7)
    [n] = [n for n in published(acts, Notice) if n.said is Said.UNKNOWN_TYPE_HELD]
    assert (n.bolt, n.result_type, n.tightening_id, n.level) == ("B1", code, 7, "warning")
    assert notice_words(n) == (f"B1: result 7 of type {code}, a type the station does not "
                               "know: not taken as a tightening; check it on the controller, "
                               "then enter its outcome, or release it to tighten it again")
    assert [a for a in acts if isinstance(a, DisableTool)]
    assert not d.core.tool_on and "B1" not in d.core.matcher.done
    assert d.core.matcher.held == {"B1": f"a result of a type the station does not know "
                                         f"(type {code}, tightening 7)"}
    assert state_words(d.core.reason) == (f"bolt B1: a result of a type the station does not "
                                          f"know (type {code}, tightening 7); held for a "
                                          "supervisor")
    # the hold refuses it until a person's release
    _on(d, 1)
    assert not d.tool and "B1" not in d.core.allowed()


def test_a_type_the_station_does_not_know_with_the_tool_off_is_a_controller_event():
    d = _ready()
    acts = d.feed(ResultIn(d.t, res(7, 1, True, 9)))
    [store] = [a for a in acts if isinstance(a, StoreControllerEvent)]
    assert store.what is None and stored_what(store) == "result type 9 (unknown)"
    [n] = published(acts, Notice)
    assert (n.said, n.bolt, n.result_type) == (Said.UNKNOWN_TYPE, None, 9)
    assert not d.core.matcher.held and not d.core.matcher.done


def test_a_type_the_station_does_not_know_of_another_pset_holds_the_bolt_on():
    """A review: a known type of another pset while the tool is on for B1 holds B1 (the
    operator ran it down with another program); one of type 9 left the tool on and B1 open.
    The same: B1 held, the tool off, stored as a controller event naming B1."""
    d = _ready()
    sent = _enabled(d)
    acts = d.feed(ResultIn(d.t, res(7, (sent.selection.pset or 0) + 1, True, 9)))
    [store] = [a for a in acts if isinstance(a, StoreControllerEvent)]
    assert (store.what, store.bolt) == (None, "B1")
    assert not [a for a in acts if isinstance(a, StoreUnattributed | Record)]
    assert list(d.core.matcher.held) == ["B1"] and not d.core.tool_on


def test_a_type_the_station_does_not_know_made_during_a_cut_holds_its_bolt():
    """The integrator's reload cut: tightening 201, of B47's pset and VIN, made under its
    enable while the link was down, of type 9: the journal said "no tightening made while
    the link was down: B47 open as before".  Placed by the controller's data, it holds the
    bolt, and the catch-up's end says nothing more."""
    d = _ready()
    sent, enabled_at, _ = _cut_during_enable(d)
    d.t += 10.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0, True, 9, vin="VIN1"),
                           fetched=True, follows=40, made_at=enabled_at + 0.5))
    [store] = [a for a in acts if isinstance(a, StoreControllerEvent)]
    assert (store.what, store.bolt) == (UNKNOWN_TYPE_HELD, "B1")
    assert list(d.core.matcher.held) == ["B1"] and "B1" not in d.core.matcher.done
    said = [notice_words(n) for n in published(d.feed(CaughtUp(d.t, complete=True)), Notice)]
    assert not [w for w in said if "open as before" in w], said


@pytest.mark.parametrize("change", [{"follows": None}, {"tid": 43}, {"made": None}])
def test_a_type_the_station_does_not_know_fetched_after_a_cut_unproved_holds_the_bolt(change):
    """A review: fetched after a link cut during B1's enable, not proved B1's (the last id
    accounted for unknown, not the first id after it, the clock unknown), a type 1 holds
    B1 ("may be its own"); a type 9 was a controller event and the catch-up's end said "no
    tightening made while the link was down: B1 open as before".  Held the same."""
    d = _ready()
    sent, enabled_at, _ = _cut_during_enable(d)
    d.t += 10.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    made = None if "made" in change else enabled_at + 0.5
    acts = d.feed(ResultIn(d.t, res(change.get("tid", 41), sent.selection.pset or 0, True, 9,
                                    vin="VIN1"),
                           fetched=True, follows=change.get("follows", 40), made_at=made))
    assert [type(a) for a in acts if isinstance(a, StoreControllerEvent | StoreUnattributed
                                                 | Record)][:1] == [StoreControllerEvent]
    said = [notice_words(n) for n in published(d.feed(CaughtUp(d.t, complete=True)), Notice)]
    assert list(d.core.matcher.held) == ["B1"], said
    assert not [w for w in said if "open as before" in w], said


def test_a_synchronized_tightening_closes_the_bolt():
    d = _ready()
    sent = _enabled(d)
    acts = d.feed(ResultIn(d.t, res(7, sent.selection.pset or 0, True, 7)))
    assert [(a.bolt, a.kind) for a in acts if isinstance(a, Record)] == [("B1", "tightening")]
    assert "B1" in d.core.matcher.done


def test_a_controller_event_sent_again_is_acknowledged_not_stored_twice():
    d = _ready()
    d.feed(ResultIn(d.t, res(3, 1, True, 3)))
    acts = d.feed(ResultIn(d.t, res(3, 1, True, 3)))
    assert [type(a).__name__ for a in acts] == ["Acknowledge"]


# -- results that could not be read -------------------------------------------------------------
def unreadable(tid: int | None = 7, pset: int | None = 1, fetched: bool = False
               ) -> UnreadableResult:
    # its text says its id and pset (another result's message is another text)
    return UnreadableResult(raw=f"01230061007    {tid}/{pset}" + "x" * 40, mid=61, revision=7,
                            error="MID 0061 revision 7: parameter 01 missing",
                            tightening_id=tid, pset=pset, fetched=fetched)


def test_an_unreadable_result_is_stored_whole_and_holds_its_bolt_for_a_supervisor():
    d = _ready()
    sent = _enabled(d)
    assert sent.selection.pset == 1
    acts = d.feed(UnreadableIn(d.t, unreadable()))
    [store] = [a for a in acts if isinstance(a, StoreUnreadable)]
    assert (store.bolt, store.vin, store.selection) == ("B1", "VIN1", sent.selection)
    assert any(isinstance(a, DisableTool) for a in acts) and not d.core.tool_on
    assert [e.reason for e in published(acts, ToolDisabled)] == [
        StateReason(Because.UNREADABLE, bolt="B1"), StateReason(Because.UNREADABLE_HELD, bolt="B1")]
    assert d.core.reason == StateReason(Because.UNREADABLE_HELD, bolt="B1")
    [ev] = published(acts, ResultUnreadable)
    assert (ev.bolt, ev.tightening_id, ev.revision) == ("B1", 7, 7)
    [lock] = published(acts, BoltLocked)
    assert (lock.bolt, lock.held) == ("B1", "tightening 7")
    assert "B1: the controller's result could not be read (tightening 7): check it on the " \
        "controller, then enter its outcome, or release it to tighten it again" in _notices(acts)
    assert "B1" not in d.core.matcher.done and d.core.state is State.TRACKING
    # held: no new enable for it
    sends = len(d.sends)
    _on(d, 1, 4)
    assert len(d.sends) == sends and "B1" not in d.core.allowed()
    refusal = d.core.matcher.update(d.core.matcher.bolts["B1"], 0.01).reason
    assert refusal == Reason(Why.HELD, bolt="B1", note="tightening 7")
    assert reason_words(refusal).startswith("B1: the controller's result could not be read")
    # an operator may not release it; a supervisor may, and then it is tightened again
    refused = _answer(d.command(1, ReleaseBolt("VIN1", "B1", "checked"), OPERATOR))
    assert not refused.answer.accepted
    acts = d.command(2, ReleaseBolt("VIN1", "B1", "checked: NOK there"), SUPERVISOR)
    assert _answer(acts).answer.accepted
    # released as a hold: the screens tell the operator it may be tightened already
    assert [(e.bolt, e.unknown) for e in published(acts, BoltReleased)] == [("B1", True)]
    _enabled(d)


@pytest.mark.parametrize("first", [True, False], ids=["fetched first", "pushed first"])
@pytest.mark.parametrize("pushed_after", [7, 8], ids=["one id between", "two ids between"])
def test_the_one_id_fetched_between_two_read_is_the_unreadable_result_without_an_id(
        pushed_after, first):
    """A quality trial: B47's result could not be read, its id with it (held); the next
    result pushed skipped an id, which was fetched (the link up) and stored unattributed, no
    word of B47: one rundown twice in the records, never linked.  The one id between the
    results read before and after the unreadable message is that message, read: stored apart
    with its values, its reason naming the held bolt, which stays held for a person.  Two
    ids between: which one it was is not known, both stored unattributed as before.  The
    shell feeds the fetched ones first (in the order made), naming the pushed one after."""
    d = _ready()
    _enabled(d, 1)
    d.feed(ResultIn(d.t, res(5, 1, True, 1)))                      # B1, read
    _enabled(d, 3)
    acts = d.feed(UnreadableIn(d.t, unreadable(None, None)))       # B3's: held, id unread
    assert [e.bolt for e in published(acts, BoltLocked)] == ["B3"]
    _enabled(d, 2)
    pushed = ResultIn(d.t, res(pushed_after, 2, True, 1))          # B2, read
    if not first:
        d.feed(pushed)
    fetched = [d.feed(ResultIn(d.t, res(tid, 1, True, 1), fetched=True, follows=5, live=True,
                               before=pushed_after if first else None))
               for tid in range(6, pushed_after)]
    if first:
        assert [a.bolt for a in d.feed(pushed) if isinstance(a, Record)] == ["B2"]
    stored = [a for acts in fetched for a in acts if isinstance(a, StoreUnattributed)]
    assert len(stored) == pushed_after - 6
    assert not [a for acts in fetched for a in acts if isinstance(a, Record)]
    assert "B3" in d.core.matcher.held and "B3" not in d.core.matcher.done
    if pushed_after == 7:
        [why] = [a.why for a in stored]
        assert (why.kind, why.bolt, why.between) == (UnattributedKind.UNREAD_READ, "B3", (5, 7))
        assert stored[0].vin == "VIN1"
        assert ("result 6 (pset 1) fetched after a later one came, the link up: the result of "
                "B3 that could not be read (the one id between tightenings 5 and 7), now "
                "read; B3 stays held until its outcome is entered: stored apart with its "
                "values") in _notices(fetched[0])
    else:
        assert {a.why.kind for a in stored} == {UnattributedKind.FETCHED_LIVE}


@pytest.mark.parametrize("tid", [7, None], ids=["its id read", "its time read"])
def test_an_unreadable_result_sent_again_holds_no_other_bolt(tid):
    """The controller sends the same unreadable message again (its acknowledgement lost, or
    resent unacknowledged; another sequence number in its header) while another bolt of
    the same pset is enabled: acknowledged and said, stored and held against no other bolt;
    that bolt's own result still comes.  One the database has stored (after a reload) is
    taken so too."""
    d = _ready()
    _enabled(d, 1)
    first = replace(unreadable(tid), header_len=20,
                    timestamp=None if tid is not None else datetime(2026, 11, 29, 8, 0, 0))
    d.feed(UnreadableIn(d.t, first))
    assert list(d.core.matcher.held) == ["B1"]
    _enabled(d, 3)
    again = replace(first, raw=first.raw[:16] + "02" + first.raw[18:])
    assert again.raw != first.raw and again.body == first.body
    acts = d.feed(UnreadableIn(d.t, again))
    assert _kinds(acts) == ["Acknowledge"] and d.core.tool_on
    said = "result 7" if tid is not None else "a result"
    assert _notices(acts) == [f"{said} of B1 sent again by the controller: stored once"]
    assert list(d.core.matcher.held) == ["B1"]
    d.tool_bolt = "B3"
    acts = d.feed(ResultIn(d.t, res(8, 1)))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B3"]
    # stored by an earlier station (the shell asked the database before this core saw it)
    d2 = _ready()
    _enabled(d2, 3)
    acts = d2.feed(UnreadableIn(d2.t, again, stored=("VIN0", "B1")))
    assert _kinds(acts) == ["Acknowledge"] and d2.core.tool_on and not d2.core.matcher.held
    assert _notices(acts) == [f"{said} of B1 of VIN VIN0 sent again by the controller: "
                              "stored once"]


def test_two_unreadable_results_that_say_nothing_of_themselves_are_two():
    """Neither an id nor a time could be picked out (both cut short after the header): the
    same text is no proof of a copy, and the second holds its own bolt (a reviewer: taken for
    the first's copy, it was acknowledged and forgotten, its bolt left open)."""
    d = _ready()
    _enabled(d, 1)
    cut = replace(unreadable(None), header_len=20)
    d.feed(UnreadableIn(d.t, cut))
    _enabled(d, 3)
    acts = d.feed(UnreadableIn(d.t, cut))
    assert "StoreUnreadable" in _kinds(acts) and sorted(d.core.matcher.held) == ["B1", "B3"]


def test_a_readable_copy_of_an_unreadable_result_closes_no_other_bolt():
    """The controller sends again a result whose first copy was garbled on the line: it reads
    this time, under the id picked out of the first.  It is that result (stored whole, its
    bolt held), never the result of the bolt enabled since (a reviewer: recorded to B3)."""
    d = _ready()
    _enabled(d, 1)
    d.feed(UnreadableIn(d.t, unreadable(7, 1)))
    _enabled(d, 3)
    acts = d.feed(ResultIn(d.t, res(7, 1)))
    assert _kinds(acts) == ["Acknowledge"] and d.core.tool_on
    assert _notices(acts) == ["result 7 of B1 sent again by the controller: stored once"]
    assert list(d.core.matcher.held) == ["B1"] and "B3" not in d.core.matcher.done


def test_an_unreadable_result_of_another_pset_holds_nothing():
    d = _ready()
    _enabled(d)
    acts = d.feed(UnreadableIn(d.t, unreadable(pset=42)))
    [store] = [a for a in acts if isinstance(a, StoreUnreadable)]
    assert store.bolt is None and not published(acts, BoltLocked)
    assert d.core.tool_on and not d.core.matcher.held


def test_an_unreadable_result_with_the_tool_off_long_ago_holds_nothing():
    d = _ready()
    acts = d.feed(UnreadableIn(d.t, unreadable()))
    [store] = [a for a in acts if isinstance(a, StoreUnreadable)]
    assert store.bolt is None
    assert any("no bolt it could belong to" in m for m in _notices(acts))
    assert [(n.said, n.note) for n in published(acts, Notice)] == [
        (Said.UNREADABLE, "MID 0061 revision 7: parameter 01 missing")]


def test_a_hold_comes_back_with_the_vehicle():
    d = _ready()
    acts = d.feed(VehicleLoaded(d.t, "VIN1", "M", BOLTS, held={"B2": "tightening 9"}))
    assert [(e.bolt, e.held) for e in published(acts, BoltLocked)] == [("B2", "tightening 9")]
    assert "B2" not in d.core.allowed()


def test_a_released_hold_comes_back_with_the_vehicle_as_check_first():
    """A bolt whose hold a person released, not run down since (the records say so): open,
    and drawn "check first" after a restart as before it (it may be tightened already)."""
    d = _ready()
    acts = d.feed(VehicleLoaded(d.t, "VIN1", "M", BOLTS, released=frozenset({"B2"})))
    [opened] = published(acts, VehicleOpened)
    assert [b.bolt for b in opened.bolts if b.check_first] == ["B2"]
    assert "B2" in d.core.allowed() and not published(acts, BoltLocked)


# -- attribution after a link cut --------------------------------------------------------------
CUT_S = 4.0


def _cut_during_enable(d: Driver) -> tuple[SendParams, float, float]:
    """The tool on for B1, then the controller's link down: (what was sent, the enable's
    time, the cut's time)."""
    sent = _enabled(d)
    enabled_at = d.t
    d.t += 1.0
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "link lost"))
    cut_at = d.t
    assert not d.core.tool_on and d.core.state is State.FAULT
    return sent, enabled_at, cut_at


@pytest.mark.parametrize("after_s", [5.0, 30.0, 600.0])
def test_a_result_made_during_a_cut_is_recorded_to_its_bolt_when_the_controller_proves_it(
        after_s):
    d = _ready()
    sent, enabled_at, cut_at = _cut_during_enable(d)
    d.t += after_s
    d.feed(Tick(d.t))                       # long past the late-result window
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0, True, 1, vin="VIN1"),
                           fetched=True, follows=40, made_at=enabled_at + 0.5))
    [rec] = [a for a in acts if isinstance(a, Record)]
    assert (rec.bolt, rec.vin, rec.late, rec.selection) == ("B1", "VIN1", True, sent.selection)
    assert rec.offline     # made while the link was down (OPC UA's IsGeneratedOffline)
    assert "B1" in d.core.matcher.done
    assert any("made during the link cut" in m for m in _notices(acts))
    assert [(n.said, n.tightening_id, n.bolt) for n in published(acts, Notice)] == [
        (Said.CUT_RECORDED, 41, "B1")]
    # the second result of that cut: the cut's enable has its result, the tool ran again
    # (B1 held); said why (a quality trial: the reason said nothing; a supervisor's: it said
    # "no tool enable left" beside the hold that named it)
    acts = d.feed(ResultIn(d.t, res(42, sent.selection.pset or 0, True, 1, vin="VIN1"),
                           fetched=True, follows=40, made_at=cut_at - 0.2))
    assert [type(a) for a in acts if isinstance(a, Record | StoreUnattributed)] == \
        [StoreUnattributed]
    [loose] = [a for a in acts if isinstance(a, StoreUnattributed)]
    assert unattributed_words(loose.why) == (
        "result 42 (pset 1) fetched after a reconnect (made during the link cut after B1's "
        "rundown 41: the tool ran again, on B1 or another bolt; B1 held)")
    # after its catch-up, one fetched (a gap the next one fills) is said as before
    d.feed(CaughtUp(d.t, True, "", 1))
    acts = d.feed(ResultIn(d.t, res(43, sent.selection.pset or 0, True, 1, vin="VIN1"),
                           fetched=True, follows=42, made_at=cut_at - 0.1))
    [loose] = [a for a in acts if isinstance(a, StoreUnattributed)]
    assert unattributed_words(loose.why) == (
        "result 43 (pset 1) fetched after a reconnect (no tool enable left without its result "
        "by the link cut)")


@pytest.mark.parametrize("change, unproved, why", [
    ({"pset": 9}, Unproved(UnprovedKind.PSET, bolt="B1", pset=9, sent_pset=1),
     "pset 9, not 1 sent for B1"),
    ({"vin": "OTHER"}, Unproved(UnprovedKind.VIN, vin="OTHER", sent_vin="VIN1"),
     "VIN OTHER, not VIN1"),
    ({"tid": 43}, Unproved(UnprovedKind.NOT_FIRST, follows=40),
     "not the first tightening after 40"),
    ({"follows": None}, Unproved(UnprovedKind.FOLLOWS_UNKNOWN),
     "the last tightening id accounted for unknown"),
    ({"made": None}, Unproved(UnprovedKind.CLOCK_UNKNOWN), "the controller's clock is not known"),
    ({"made": +30.0}, Unproved(UnprovedKind.OUTSIDE_CUT, bolt="B1"),
     "made outside the enable of B1 and the link cut"),
    ({"made": -30.0}, Unproved(UnprovedKind.OUTSIDE_CUT, bolt="B1"),
     "made outside the enable of B1 and the link cut"),
])
def test_a_result_fetched_after_a_cut_that_the_data_does_not_place_stays_unattributed(
        change, unproved, why):
    d = _ready()
    sent, enabled_at, cut_at = _cut_during_enable(d)
    d.t += 10.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    made = change.get("made", 0.5)
    made_at = None if made is None else (cut_at + made if made > 0 else enabled_at + made)
    r = res(change.get("tid", 41), change.get("pset", sent.selection.pset),
            True, 1, vin=change.get("vin", ""))
    acts = d.feed(ResultIn(d.t, r, fetched=True, follows=change.get("follows", 40),
                           made_at=made_at))
    assert not [a for a in acts if isinstance(a, Record)]
    [store] = [a for a in acts if isinstance(a, StoreUnattributed)]
    tid = change.get("tid", 41)
    assert store.why == Unattributed(UnattributedKind.FETCHED, tid, r.pset, unproved)
    # the record's reason as the shell stores it: the text the core wrote before
    assert unattributed_words(store.why) == \
        f"result {tid} (pset {r.pset}) fetched after a reconnect ({why})"
    assert "B1" not in d.core.matcher.done
    # of the pset sent for B1, it may be B1's: B1 is held for a person, never left open;
    # of another pset, made under its enable, the tool ran with another program (as where
    # the link is up: an integrator's trial read "B1 open as before", its tool on again)
    if r.pset == sent.selection.pset:
        assert d.core.matcher.held["B1"] == (f"its result during the link cut not known: "
                                             f"tightening {tid} may be its own (not proved "
                                             f"by the controller's data){ENABLED_B1}")
        assert d.core.missed_since() is not None and "B1" not in d.core.allowed()
    else:
        assert d.core.matcher.held["B1"] == (
            f"its result during the link cut not known: tightening {tid} came under pset "
            f"{r.pset} while its tool was on for pset 1: run with another program, or not its "
            f"own{ENABLED_B1}")
        assert "B1" not in d.core.allowed()


#: the hold's words after a cut during B1's enable: its pset, and when the tool went on (the
#: driver's clock then: 1,000 s)
ENABLED_B1 = "; the tool was enabled for pset 1 at 1970-01-01 00:16:40 UTC"


def test_a_result_fetched_within_its_enable_s_window_after_a_short_cut_is_offline():
    """The link back 4 s after the cut, within the enable's late-result window: the result
    fetched then is the enable's as any late one, and made while the link was down (a
    reviewer: only the cut's proof marked it so)."""
    d = _ready()
    sent, _, cut_at = _cut_during_enable(d)
    d.t += 4.0
    assert d.t - cut_at < d.core.late_result_s
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0, True, 1), fetched=True,
                           follows=40, made_at=cut_at + 0.5))
    [rec] = [a for a in acts if isinstance(a, Record)]
    assert (rec.bolt, rec.late, rec.offline) == ("B1", True, True)
    # one made well before the link was lost, fetched by the catch-up all the same (its push
    # lost with the link up): B1's, not made offline (a reviewer)
    d = _ready()
    sent = _enabled(d)
    made = d.t + 1.0
    d.t += 6.0
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "link lost"))
    d.t += 2.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0, True, 1), fetched=True,
                           follows=40, made_at=made))
    assert [(a.bolt, a.offline) for a in acts if isinstance(a, Record)] == [("B1", False)]


def _back_after_a_cut(d: Driver) -> SendParams:
    sent, _, _ = _cut_during_enable(d)
    d.t += 10.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    d.step(("lift", 0.1, True, True, "VIN1"))
    d.feed(Tick(d.t))
    return sent


@pytest.mark.parametrize("bolt", [2, 1])
def test_while_a_cut_result_is_owed_the_tool_stays_off_for_every_bolt(bolt):
    """The link went down with the tool on for B1: B1 may have been tightened meanwhile, its
    result comes only with the catch-up.  Until then no bolt gets the tool, B1 included (a
    reviewer: B2 enabled first, B1's fetched result then had no enable to prove it against,
    and B1 was tightened again)."""
    d = _ready()
    _back_after_a_cut(d)
    _on(d, bolt)
    d.step(("ack", 0.01, True))
    _on(d, bolt, 3)
    assert not d.tool and not d.core.tool_on
    assert d.core.reason == StateReason(Because.CUT_OWED, bolt=f"B{bolt}", owed="B1")
    assert state_words(d.core.reason) == (
        f"bolt B{bolt}: the tool stays off until the controller's results made during the "
        "link cut are fetched (bolt B1 was enabled)")
    acts = d.feed(CaughtUp(d.t, complete=False, reason="the controller refused MID 0064"))
    # with what the supervisor looks for on the controller: the pset and when it went on
    assert d.core.matcher.held == {"B1": "its result during the link cut not known: the "
                                         f"controller refused MID 0064{ENABLED_B1}"}
    assert [notice_words(n) for n in published(acts, Notice)] == [
        "B1: its result during the link cut not known: the controller refused MID 0064"
        f"{ENABLED_B1}: check it on the controller, then enter its outcome, or release it to "
        "tighten it again"]
    assert [(e.bolt, e.held) for e in published(acts, BoltLocked)] == [
        ("B1", "its result during the link cut not known: the controller refused MID 0064"
         f"{ENABLED_B1}")]
    if bolt != 1:
        _on(d, bolt, 2)     # the others go on
        assert d.tool and d.core.tool_on and d.core.bolt == f"B{bolt}"


def test_a_complete_catch_up_without_the_cut_result_leaves_its_bolt_open_as_before():
    d = _ready()
    _back_after_a_cut(d)
    acts = d.feed(CaughtUp(d.t, complete=True))
    assert [notice_words(n) for n in published(acts, Notice)] == [
        "no tightening made while the link was down (cut, or the station stopped; every "
        "result since fetched): B1 open as before"]
    assert not d.core.matcher.held and "B1" in d.core.allowed()
    assert d.core.missed_since() is not None
    _enabled(d, 1)
    assert not d.feed(CaughtUp(d.t, complete=False, reason="late"))  # no cut: nothing


def test_a_cut_result_the_controller_pushes_again_holds_its_bolt():
    """A controller that sends unacknowledged results again after the reconnect: B1's
    result, made during the cut, comes pushed, not fetched (nothing proves it B1's, and the
    catch-up then counts it as had): B1 is held, not left open to be tightened twice."""
    d = _ready()
    sent = _back_after_a_cut(d)
    acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0, True, 1, vin="VIN1")))
    assert [type(a) for a in acts if isinstance(a, Record | StoreUnattributed)] == \
        [StoreUnattributed]
    assert list(d.core.matcher.held) == ["B1"] and "B1" not in d.core.matcher.done
    assert not d.feed(CaughtUp(d.t, complete=True))   # the cut ended with the hold


def test_an_unreadable_result_fetched_after_a_reconnect_is_no_enable_s_made_since():
    """The link was lost with the tool off (no cut), B2 enabled since: an unreadable result
    the catch-up fetched was made before, never B2's (a reviewer: held against B2, its tool
    switched off).  One the renewal of the subscription fetched comes as pushed (the driver's
    ``ResultFeed.caught``): the enabled bolt's."""
    d = _ready()
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "link lost"))
    d.t += 1.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    d.step(("lift", 0.1, True, True, "VIN1"))
    _enabled(d, 2)
    acts = d.feed(UnreadableIn(d.t, unreadable(pset=2, fetched=True)))
    [store] = [a for a in acts if isinstance(a, StoreUnreadable)]
    assert store.bolt is None and d.core.tool_on and not d.core.matcher.held


def test_a_cut_s_unreadable_fetched_result_holds_its_bolt_whatever_pset_it_seems_to_have():
    """B1 enabled (pset 1), the link cut, a result fetched after it that does not read: the
    pset picked out of it (0, a job id read where a pset is, in an independent controller's
    trial) proves nothing.  B1 is held with the message, not left open "as before" by the
    catch-up (tightened during the cut, it would have been tightened twice)."""
    d = _ready()
    sent = _back_after_a_cut(d)
    assert sent.selection.pset == 1
    acts = d.feed(UnreadableIn(d.t, unreadable(42, pset=0, fetched=True)))
    [store] = [a for a in acts if isinstance(a, StoreUnreadable)]
    assert (store.bolt, store.vin) == ("B1", "VIN1")
    assert list(d.core.matcher.held) == ["B1"] and "B1" not in d.core.matcher.done
    acts = d.feed(CaughtUp(d.t, complete=True))
    assert not any(isinstance(a, Publish) and isinstance(a.event, Notice)
                   and a.event.said is Said.CUT_NOTHING for a in acts)
    assert list(d.core.matcher.held) == ["B1"]


def test_a_result_made_after_an_unreadable_one_under_its_id_is_not_its_copy():
    """A controller whose ids started again: a new result reuses the id of an unreadable one
    that carried no time.  Made after that one came (the controller's clock known), it is
    the result of the bolt enabled now (a reviewer: only acknowledged, lost, its bolt left
    open with the tool on)."""
    d = _ready()
    _enabled(d, 1)
    d.feed(UnreadableIn(d.t, unreadable(7, 1)))
    seen_at = d.t
    d.t += 30.0
    d.feed(Tick(d.t))
    _enabled(d, 3)
    acts = d.feed(ResultIn(d.t, res(7, 1), made_at=d.t - 0.5))
    [rec] = [a for a in acts if isinstance(a, Record)]
    assert rec.bolt == "B3" and "B3" in d.core.matcher.done and not d.core.tool_on
    assert d.t - 0.5 > seen_at


def test_a_pushed_result_after_the_window_is_not_placed_by_a_cut():
    d = _ready()
    sent, enabled_at, _ = _cut_during_enable(d)
    d.t += 10.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0), follows=40,
                           made_at=enabled_at + 0.5))     # pushed, not fetched
    assert [type(a) for a in acts if isinstance(a, Record | StoreUnattributed)] == \
        [StoreUnattributed]


def test_a_result_fetched_after_a_cut_never_goes_to_an_enable_made_since():
    d = _ready()
    sent, enabled_at, _ = _cut_during_enable(d)
    d.t += 2.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    d.feed(CaughtUp(d.t, complete=True))     # nothing made during the cut
    d.step(("lift", 0.1, True, True, "VIN1"))
    d.feed(Tick(d.t + 10))
    d.t += 10
    _enabled(d, 3)
    assert d.core.bolt == "B3" and BOLTS["B3"].pset == sent.selection.pset
    for made_at in (enabled_at + 0.5, None):     # the controller's clock known, or not
        # fetched later all the same (a push the controller lost, with the link up)
        acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0, True, 1),
                               fetched=True, follows=40, made_at=made_at, live=True))
        assert not [a for a in acts if isinstance(a, Record)]    # neither B1's nor B3's
        assert [type(a) for a in acts if isinstance(a, StoreUnattributed)]
        assert d.core.tool_on and not d.core.matcher.done


def test_seeded_walks_with_every_result_type_close_bolts_only_by_tightenings():
    """Walks with the realistic mix of test_core, where a result is of any type and now and
    then unreadable (and a held bolt now and then released by a supervisor): the core's
    invariants hold (test_core's Driver checks them on every action), a bolt is done only
    after a tightening recorded to it, a held bolt gets no parameters until released, and
    every result is stored somewhere exactly once."""
    import numpy as np

    from tests.station.test_core import decode, seeded_steps
    rng = np.random.default_rng(28)
    kinds = ["lift", "loc", "ack", "result", "fault", "back", "tick"]
    weights = np.array([0.02, 0.6, 0.25, 0.05, 0.01, 0.04, 0.03])
    seen = {"event": 0, "unreadable": 0, "record": 0, "held": 0, "unknown held": 0}
    released = 0
    for _ in range(400):
        d = _ready()
        tid = 1000
        for raw in seeded_steps(rng, kinds, weights, 100):
            op = decode(raw)
            if op[0] != "result":
                before = set(d.core.matcher.held) if d.core.matcher is not None else set()
                n = len(d.sends)
                d.step(op)
                assert not set(d.sends[n:]) & before, "parameters sent for a held bolt"
                if before and d.core.vin is not None and rng.random() < 0.1:
                    # a supervisor checked the held bolt on the controller and releases it
                    released += 1
                    d.command(released, ReleaseBolt(d.core.vin, sorted(before)[0],
                                                    "checked on the controller"), SUPERVISOR)
                if not d.tool or rng.random() < 0.6:
                    continue
                op = ("result", 0.05, True)         # the operator pulls the trigger
            d.t += op[1]
            tid += 1
            pset = BOLTS[d.tool_bolt].pset if d.tool_bolt and op[2] else 9
            done = set(d.core.matcher.done) if d.core.matcher is not None else set()
            if rng.random() < 0.1:
                acts = d.feed(UnreadableIn(d.t, unreadable(tid, pset)))
                stored = [a for a in acts if isinstance(a, StoreUnreadable)]
                seen["unreadable"] += 1
                seen["held"] += bool(published(acts, BoltLocked))
            else:
                code = int(rng.choice([1, 1, 1, 2, 3, 4, 5, 6, 7, 8, 9]))
                acts = d.feed(ResultIn(d.t, res(tid, pset or 0, bool(rng.random() < 0.8),
                                                code)))
                stored = [a for a in acts if isinstance(a, Record | StoreUnattributed
                                                         | StoreControllerEvent)]
                if result_kind(code) in (ResultKind.EVENT, ResultKind.UNKNOWN):
                    seen["event"] += 1
                    assert [type(a) for a in stored] == [StoreControllerEvent]
                    # a type the station does not know under its bolt's enable holds it
                    seen["unknown held"] += bool(published(acts, BoltLocked))
                seen["record"] += sum(isinstance(a, Record) for a in stored)
            assert len(stored) == 1, acts           # stored somewhere, exactly once
            if d.core.matcher is not None:
                newly = set(d.core.matcher.done) - done
                tightened = {a.bolt for a in stored if isinstance(a, Record)
                             and a.kind == "tightening" and a.result.ok}
                assert newly <= tightened, (newly, stored)
    assert min(seen.values()) > 10, seen


def test_a_result_under_an_id_seen_before_with_other_values_is_a_new_result():
    """A controller replaced or reset mid-vehicle numbers its tightenings from 1 again: a
    result under an id the station has seen, with other values, is not a resent copy."""
    d = _ready()
    sent = _enabled(d)
    first = res(1, sent.selection.pset or 0, True, 1)
    assert [a.bolt for a in d.feed(ResultIn(d.t, first)) if isinstance(a, Record)] == ["B1"]
    assert [type(a).__name__ for a in d.feed(ResultIn(d.t, first))] == ["Acknowledge"]
    sent = _enabled(d, 3)
    other = dataclasses.replace(first, torque_nm=47.5, timestamp=datetime(2026, 11, 29, 9))
    acts = d.alone(ResultIn(d.t, other))   # the Driver's check keys records by id alone
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B3"]
    assert any("ids started again" in m for m in _notices(acts))
    assert [(n.said, n.tightening_id) for n in published(acts, Notice)] == [
        (Said.IDS_AGAIN, 1)]


def test_since_when_results_may_have_been_missed_with_no_id_to_count_from():
    """What the shell fetches back from the controller's newest when the station has no
    tightening id of it recorded: since the enable a cut came during, else the link's loss
    (the station's start included); nothing before the station started."""
    from stationd.station.core import StationCore
    from tests.station.test_core import PARAMS

    assert StationCore(PARAMS).missed_since() is None     # not started: all history
    d = _ready()
    assert d.core.missed_since() == 1000.0                 # the start (Driver's clock)
    sent, enabled_at, cut_at = _cut_during_enable(d)
    assert d.core.missed_since() == enabled_at < cut_at
    d.t += 10.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    # the controller's first result ever (nothing before it: follows 0) proves itself
    acts = d.feed(ResultIn(d.t, res(1, sent.selection.pset or 0, True, 1), fetched=True,
                           follows=0, made_at=enabled_at + 0.5))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B1"]
    assert d.core.missed_since() == cut_at                 # the cut resolved: the link's loss


def test_a_cut_result_pushed_within_the_late_result_window_ends_the_cut():
    """The link is back within the late-result window and the controller pushes the result
    made during the cut: it is the enable's own (late), and the cut ends with it (the tool
    is not kept off for a catch-up that has nothing more to say)."""
    d = _ready()
    sent, _, cut_at = _cut_during_enable(d)
    d.t += 4.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0, True, 1),
                           made_at=cut_at + 0.5))
    [rec] = [a for a in acts if isinstance(a, Record)]
    assert rec.bolt == "B1" and rec.late and "B1" in d.core.matcher.done
    assert rec.offline      # made while the link was down, pushed after (a reviewer)
    assert not d.feed(CaughtUp(d.t, complete=True))      # nothing said: the cut had ended
    d.step(("lift", 0.1, True, True, "VIN1"))
    _enabled(d, 2)


def test_a_refused_command_keeps_the_link_and_makes_no_cut():
    """The controller refuses a command (its link kept: no reconnect, no catch-up) while a
    result is owed: no cut waits for a catch-up that never comes (a reviewer: the tool off
    for every bolt until the vehicle left)."""
    d = _ready()
    _enabled(d, 1)
    d.feed(DeviceFault(d.t, "wrench", FaultKind.REFUSED, "MID 0043 refused"))
    assert d.core.missed_since() is not None and d.core._cut is None
    d.t += 1.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=0))
    d.step(("lift", 0.1, True, True, "VIN1"))
    d.feed(Tick(d.t + 6))
    d.t += 6
    _enabled(d, 2)


def test_a_catch_up_of_the_connection_that_was_cut_says_nothing_of_the_cut():
    """A catch-up of an earlier connection, still feeding when a later cut came, ends with
    "complete": it says nothing of that cut, whose result the next connection's catch-up
    fetches (a reviewer: the cut ended as "none made", its result then unattributed)."""
    d = _ready()
    d.feed(DeviceBack(d.t, "wrench", reconnects=3))     # connection 3, its catch-up running
    sent = _enabled(d, 1)
    d.t += 1.0
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "link lost"))
    assert not d.feed(CaughtUp(d.t, complete=True, reconnects=3))   # stale: nothing said
    d.t += 10.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=4))
    acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0, True, 1, vin="VIN1"),
                           fetched=True, follows=40, made_at=d.t - 10.5))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B1"]
    assert not d.feed(CaughtUp(d.t, complete=True, reconnects=4))   # the cut had ended


def test_a_complete_catch_up_within_the_late_result_window_still_takes_the_pushed_result():
    """A restart during a rundown: the catch-up at the start finds nothing (the rundown was
    not over), then the result comes pushed within the late-result window: it is the enable's
    (a CI run: stored unattributed, the catch-up having cleared the enable)."""
    d = _ready()
    sent, _, _ = _cut_during_enable(d)
    d.t += 1.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts = d.feed(CaughtUp(d.t, complete=True))
    assert not [a for a in acts if type(a).__name__ == "SettleEnable"]   # still owed
    acts = d.feed(ResultIn(d.t + 0.5, res(41, sent.selection.pset or 0, True, 1)))
    assert [(a.bolt, a.late) for a in acts if isinstance(a, Record)] == [("B1", True)]


# -- a result whose push was lost with the link up -------------------------------------------------
def _b1_unanswered(d: Driver) -> float:
    """B1 enabled (and tightened, its result's push lost?); the wrench to B2 (pset 2), B1's
    late-result window over, B2 enabled and its result pushed (which skips B1's id, so the
    shell fetches it with the link up).  B1's enable's time."""
    _enabled(d, 1)
    enabled_at = d.t
    _on(d, 2, 3)                            # the wrench leaves B1: the tool off
    assert not d.core.tool_on
    d.t += d.core.late_result_s + 1.0       # B1's window ends without its result
    d.feed(Tick(d.t))
    _enabled(d, 2)
    acts = d.feed(ResultIn(d.t, res(42, 2, True, 1)))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B2"]
    return enabled_at


def test_a_result_whose_push_was_lost_holds_the_bolt_whose_enable_got_none():
    """Tightening 41, fetched because its push was lost, is of B1's pset and made within
    B1's enable, which got no result: it may be B1's (the data cannot prove it: B2 was
    enabled since, and another bolt of that pset could have been).  Never taken for B1, and
    B1 is never left open either (a quality trial: stored unattributed, B1 tightened twice;
    a reviewer: taken for B1 by its time, it closed a bolt never tightened): B1 is held for
    a person, and the hold is stored (it outlives a restart)."""
    d = _ready()
    enabled_at = _b1_unanswered(d)
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=enabled_at + 0.5, live=True))
    assert not [a for a in acts if isinstance(a, Record)]
    assert [a for a in acts if isinstance(a, StoreUnattributed)]
    [stored] = [a for a in acts if isinstance(a, StoreCutUnknown)]
    assert (stored.bolt, stored.what, stored.tightening_id) == ("B1", LOST_UNKNOWN, 41)
    note = ("tightening 41 may be its own (its push lost, fetched later; other enables came "
            "between); the tool was enabled for pset 1 at 1970-01-01 00:16:40 UTC")
    assert stored.note == note and d.core.matcher.held["B1"] == note
    assert f"B1: {note}: check it on the controller, then enter its outcome, or release it " \
        "to tighten it again" in _notices(acts)
    assert "B1" not in d.core.matcher.done and "B1" not in d.core.allowed()
    # a second late result of that pset holds nothing more
    acts = d.feed(ResultIn(d.t, res(43, 1, True, 1), fetched=True, follows=42,
                           made_at=enabled_at + 0.7, live=True))
    assert not [a for a in acts if isinstance(a, StoreCutUnknown)]


def test_releasing_a_lost_push_s_hold_says_the_bolt_may_be_tightened_already():
    """A supervisor's trial: the release of a lost push's hold answered "accepted: its hold
    (...) ended" as any hold's, and the bolt went back to be tightened, though the result
    fetched late (stored unattributed) may be its own: the joint torqued already.  The
    answer (the screens' form, stationd release and the journal all say it) names that
    result and to check the controller before tightening it again; an unreadable result's
    hold says what it did (test_entered_outcome)."""
    d = _ready()
    enabled_at = _b1_unanswered(d)
    d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                    made_at=enabled_at + 0.5, live=True))
    note = d.core.matcher.held["B1"]
    words = answer_words(_answer(d.command(1, ReleaseBolt("VIN1", "B1", "checked"),
                                           SUPERVISOR)).answer)
    assert words.endswith(
        f": accepted: its hold ({note}) ended: B1 is open to be tightened again, but it may "
        "be tightened already, by tightening 41 (stored unattributed): check the controller "
        "before tightening it again"), words
    assert "B1" not in d.core.matcher.held


def test_a_late_result_made_outside_the_unanswered_enable_or_of_another_pset_holds_nothing():
    """Made while B1's tool was off for good (its time known), or of another pset: not B1's,
    B1 stays open (a reviewer: any later lost push of its pset held it)."""
    for pset, made in ((1, 60.0), (1, -60.0), (2, 0.5)):
        d = _ready()
        enabled_at = _b1_unanswered(d)
        acts = d.feed(ResultIn(d.t, res(41, pset, True, 1), fetched=True, follows=40,
                               made_at=enabled_at + made, live=True))
        assert not [a for a in acts if isinstance(a, Record | StoreCutUnknown)]
        assert "B1" not in d.core.matcher.held and "B1" in d.core.allowed()


def test_a_late_result_with_its_time_unknown_holds_each_unanswered_bolt_of_its_pset():
    """B1 and B3 (both pset 1) each enabled and left without a result; a result of pset 1
    fetched late whose time is not known (the controller's clock not known) may be either's:
    both are held (a reviewer: only the last unanswered enable was kept, and the bolt
    tightened stayed open)."""
    d = _ready()
    _b1_unanswered(d)
    _enabled(d, 3)
    _on(d, 2, 3)
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40, made_at=None,
                           live=False))
    assert sorted(a.bolt for a in acts if isinstance(a, StoreCutUnknown)) == ["B1", "B3"]
    assert {"B1", "B3"} <= set(d.core.matcher.held)


def test_a_lost_push_fetched_once_its_bolt_is_enabled_again_is_not_taken_for_it():
    """The wrench back on B1 and the tool on for it before the lost result is fetched: what
    it makes now is its own; the fetched one is stored unattributed, as before."""
    d = _ready()
    enabled_at = _b1_unanswered(d)
    _enabled(d, 1)
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=enabled_at + 0.5, live=True))
    assert not [a for a in acts if isinstance(a, Record)]
    assert [a for a in acts if isinstance(a, StoreUnattributed)]
    assert "B1" not in d.core.matcher.held and d.core.tool_on and d.core.bolt == "B1"


# -- what the last bolt owes as its vehicle leaves -------------------------------------------------
def _last_bolt_then_the_lift_down(d: Driver) -> float:
    """B1 of VIN1 enabled, then the lift goes down with the tool on (its result not in):
    VIN1 closes.  B1's enable's time."""
    _enabled(d, 1)
    enabled_at = d.t
    d.step(("lift", 0.2, False, False, "VIN1"))
    assert d.core.vin is None and not d.core.tool_on and "VIN1" in d.closed_vins
    return enabled_at


def _next_car_waits(d: Driver, bolt: int) -> None:
    """VIN2 at height, the wrench on ``bolt`` and its parameters acknowledged: the tool
    stays off (the car that left still owes something)."""
    d.step(("lift", 0.2, True, True, "VIN2"))
    assert d.core.vin == "VIN2"
    _on(d, bolt)
    d.step(("ack", 0.01, True))
    _on(d, bolt, 1)
    assert not d.core.tool_on


def test_a_result_within_its_window_after_its_vehicle_left_is_recorded_to_that_vehicle():
    """The last bolt's result comes just after the lift went down: it is B1's of VIN1 (the
    tool was enabled for it, no other enable since), not a result of no vehicle (a
    supervisor's trial: stored unattributed, the bolt left open in the records)."""
    d = _ready()
    _last_bolt_then_the_lift_down(d)
    d.t += 0.5
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1)))
    [rec] = [a for a in acts if isinstance(a, Record)]
    assert (rec.vin, rec.bolt, rec.late) == ("VIN1", "B1", True)
    assert not [a for a in acts if isinstance(a, StoreUnattributed)]
    assert "result 41 came after the tool went off for B1 (within the late-result " \
        "window): recorded to B1 of VIN1 (gone from the station since)" in _notices(acts)


def test_the_next_car_waits_while_the_last_car_s_result_may_still_come():
    """The next vehicle at height before the last one's late-result window ended: its bolt's
    tool stays off until that result is in or can no longer come (a late result of B1 of
    VIN1 would otherwise be taken for VIN2's bolt of the same pset)."""
    d = _ready()
    _last_bolt_then_the_lift_down(d)
    _next_car_waits(d, 1)
    assert "until bolt B1 of VIN1's result is in" in state_words(d.core.reason)
    d.t += d.core.late_result_s
    _on(d, 1, 1)       # the window over: the controller's newest asked for, the tool waits
    assert not d.core.tool_on and "until bolt B1 of VIN1's result is in" in \
        state_words(d.core.reason)
    _on(d, 1, 1)       # answered (nothing more: the shell's check as the Driver plays it)
    assert d.core.tool_on and d.core.bolt == "B1"


def test_a_lost_push_of_a_car_that_left_is_held_against_that_car_and_filed_under_it():
    """B1 of VIN1, the last bolt, tightened as the lift went down and its push lost; VIN2 is
    at the station when a later result skips its id and it is fetched.  It may be B1's of
    VIN1: filed under VIN1 (not the car at the station), and B1 of VIN1 held, stored for
    when VIN1 is back; nothing of VIN2 held, and VIN2's own B1 enable answers nothing of
    VIN1's (a supervisor's trial: filed under the next car, VIN1's bolt neither recorded
    nor held)."""
    d = _ready()
    enabled_at = _last_bolt_then_the_lift_down(d)
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    d.step(("lift", 0.2, True, True, "VIN2"))
    assert d.core.vin == "VIN2"
    _enabled(d, 1)                         # VIN2's B1: its own, nothing of VIN1's
    d.feed(ResultIn(d.t, res(42, 1, True, 1)))
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=enabled_at + 0.5, live=True))
    assert not [a for a in acts if isinstance(a, Record)]
    [filed] = [a for a in acts if isinstance(a, StoreUnattributed)]
    assert filed.vin == "VIN1"
    [stored] = [a for a in acts if isinstance(a, StoreCutUnknown)]
    assert (stored.vin, stored.bolt, stored.what) == ("VIN1", "B1", LOST_UNKNOWN)
    assert not d.core.matcher.held
    [said] = [w for w in _notices(acts) if w.startswith("B1 of VIN1")]
    assert "(gone from the station)" in said and "stationd reopen" in said
    # a result made during VIN2's enable is no lost push of VIN1's
    d2 = _ready()
    enabled_at = _last_bolt_then_the_lift_down(d2)
    d2.t += d2.core.late_result_s + 1.0
    d2.feed(Tick(d2.t))
    d2.step(("lift", 0.2, True, True, "VIN2"))
    acts = d2.feed(ResultIn(d2.t, res(41, 1, True, 1), fetched=True, follows=40,
                            made_at=enabled_at + 60.0, live=True))
    assert not [a for a in acts if isinstance(a, StoreCutUnknown)]
    assert [a.vin for a in acts if isinstance(a, StoreUnattributed)] == ["VIN2"]


# -- a lost push under the bolt's own enable, the operator pulling again ---------------------------
def _pulled_twice(d: Driver, first_ok: bool, second_ok: bool, made: float = 3.0) -> list[Any]:
    """B1 enabled; tightening 41 made ``made`` s after (its push lost), 42 pushed: the shell
    tells the core, fetches 41 (the link up), then feeds 42.  The actions of all."""
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 5.0
    acts = d.feed(ResultsSkipped(d.t, 42))
    acts += d.feed(ResultIn(d.t, res(41, 1, first_ok, 1), fetched=True, follows=40,
                            made_at=enabled_at + made, live=True, before=42))
    return acts + d.feed(ResultIn(d.t, res(42, 1, second_ok, 1)))


def test_a_lost_push_made_under_the_bolt_s_own_enable_is_recorded_to_it_in_its_place():
    """The operator pulled again after a rundown whose push was lost: both rundowns were
    made while the tool was on for B1 alone, both are B1's, in the order made; two NOKs count
    two (a supervisor's trial: the first stored unattributed, a 4th NOK before the lock)."""
    d = _ready()
    acts = _pulled_twice(d, False, False)
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)] \
        == [("B1", 41), ("B1", 42)]
    assert not [a for a in acts if isinstance(a, StoreUnattributed)]
    assert d.core._noks["B1"] == 2
    assert ("tightening 41, its push lost, fetched when a later one came: made while the "
            "tool was on for B1 alone, recorded to B1") in _notices(acts)
    # an OK whose push was lost, then a NOK: the bolt's last rundown is NOK (as recorded)
    d = _ready()
    _pulled_twice(d, True, False)
    assert "B1" not in d.core.matcher.done and d.core._noks["B1"] == 1
    d = _ready()
    _pulled_twice(d, False, True)
    assert "B1" in d.core.matcher.done and "B1" not in d.core._noks


def test_a_lost_push_made_before_the_bolt_s_enable_or_of_unknown_time_is_not_taken_for_it():
    """Made before the tool went on for B1 (beyond the clock's slack), or its time not known:
    nothing proves it B1's; stored unattributed, and the pushed one is B1's as before."""
    for made in (-0.5, 1.5, None):
        d = _ready()
        _enabled(d, 1)
        enabled_at = d.t
        acts = d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                               made_at=None if made is None else enabled_at + made,
                               live=True, before=42))
        assert not [a for a in acts if isinstance(a, Record)], made
        assert [a for a in acts if isinstance(a, StoreUnattributed)]
        acts = d.feed(ResultIn(d.t, res(42, 1, False, 1)))
        assert [a.bolt for a in acts if isinstance(a, Record)] == ["B1"]
        assert d.core._noks["B1"] == 1


def test_a_link_cut_of_the_car_that_left_keeps_the_next_car_s_tool_off_until_settled():
    """VIN1's B1 enabled when the link was cut, then VIN1 left; the link is back, its
    catch-up not ended: VIN2's bolt is not enabled (a reviewer: it was, and a second cut
    during it went unrecorded, its bolt tightened and left open), until the catch-up ends
    the cut."""
    d = _ready()
    _enabled(d, 1)
    d.t += 0.1
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "wrench gone"))
    d.step(("lift", 0.2, False, False, "VIN1"))
    d.t += 1.0
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    _next_car_waits(d, 3)
    assert "B1 of VIN1" in state_words(d.core.reason)
    d.feed(CaughtUp(d.t, True, "", 1))
    _on(d, 3, 1)
    assert d.core.tool_on and d.core.bolt == "B3"


def test_the_tool_goes_off_when_a_push_reveals_lost_ones_and_the_result_stays_owed():
    """B1's result 42 pushed skips 41 (its push lost): the tool goes off at once (a
    reviewer: it stayed on through the fetches), and however long the fetch takes, 41 and
    then 42 are both B1's; an OK then a NOK leaves B1 NOK, and a Tick meanwhile forgets
    nothing."""
    d = _ready()
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 5.0
    acts = d.feed(ResultsSkipped(d.t, 42))
    assert [a for a in acts if isinstance(a, DisableTool)] and not d.core.tool_on
    assert state_words(d.core.reason) == ("bolt B1: a rundown's result came after others the "
                                          "controller did not push: those first")
    d.t += 3 * d.core.late_result_s
    d.feed(Tick(d.t))
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=enabled_at + 3.0, live=True, before=42))
    d.t += 2 * d.core.late_result_s
    d.feed(Tick(d.t))
    acts += d.feed(ResultIn(d.t, res(42, 1, False, 1)))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)] \
        == [("B1", 41), ("B1", 42)]
    assert "B1" not in d.core.matcher.done and d.core._noks["B1"] == 1
    assert not d.core._unanswered


def test_a_lost_nok_answered_by_a_pushed_ok_locks_nothing():
    """max_nok 1: 41 (NOK, its push lost) and then 42 (OK, pushed), both B1's: the NOK policy
    follows the later one; B1 done, not locked (a reviewer: locked and done both)."""
    d = _ready(nok=NokPolicy(NokRule(max_nok=1)))
    acts = _pulled_twice(d, False, True)
    assert not published(acts, BoltLocked)
    assert "B1" in d.core.matcher.done and "B1" not in d.core.matcher.locked
    d = _ready(nok=NokPolicy(NokRule(max_nok=2)))
    acts = _pulled_twice(d, False, False)
    assert [e.bolt for e in published(acts, BoltLocked)] == ["B1"]


def test_the_last_car_s_late_result_leaves_the_next_car_s_bolt_of_that_name_selected():
    """VIN1's B1 owed as it left; VIN2's B1 selected; VIN1's result comes: recorded to B1 of
    VIN1, and VIN2's B1 stays selected (a reviewer: cleared, 'bolt B1 OK; tracking')."""
    d = _ready()
    _enabled(d, 1)
    d.step(("lift", 0.2, False, False, "VIN1"))
    d.step(("lift", 0.2, True, True, "VIN2"))
    _on(d, 1)
    d.step(("ack", 0.01, True))
    _on(d, 1, 1)
    assert d.core.bolt == "B1" and not d.core.tool_on
    d.t += 0.5
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1)))
    assert [(a.vin, a.bolt) for a in acts if isinstance(a, Record)] == [("VIN1", "B1")]
    assert d.core.bolt == "B1" and d.core.state is State.BOLT_SELECTED
    assert "B1" not in d.core.matcher.done


def _lost_nok_then(d: Driver, pushed: Any) -> list[Any]:
    """B1 enabled; its NOK 41 (push lost) fetched after the core was told 42 skipped it,
    then ``pushed`` (id 42) fed.  The actions of all."""
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 5.0
    acts = d.feed(ResultsSkipped(d.t, 42))
    acts += d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                            made_at=enabled_at + 3.0, live=True, before=42))
    return acts + d.feed(ResultIn(d.t, pushed))


@pytest.mark.parametrize("strategy", ["repeat", "skip"])
def test_a_lost_nok_revealed_by_no_rundown_of_its_bolt_gets_its_nok_policy(strategy):
    """The push that revealed B1's lost NOK is a batch increment (no rundown): the NOK
    policy waiting for it applies then (a reviewer: B1 neither locked nor skipped)."""
    d = _ready(nok=NokPolicy(NokRule(max_nok=1 if strategy == "repeat" else 3,
                                     strategy=strategy)))
    acts = _lost_nok_then(d, res(42, 1, True, 3))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)] \
        == [("B1", 41)]
    if strategy == "repeat":
        assert [e.bolt for e in published(acts, BoltLocked)] == ["B1"]
        assert d.core.matcher.locked["B1"] == 1
    else:
        assert [e.bolt for e in published(acts, BoltSkipped)] == ["B1"]
    assert "B1" not in d.core.allowed()


def test_the_pushed_result_after_skipped_ones_is_no_late_result():
    """Its tool went off when the core was told ids were skipped, not because the operator
    left: the pushed one is recorded as the rundown's own (not late), and the state says its
    result (a reviewer: 'late result', the reason left on the skipped ones)."""
    d = _ready()
    acts = _lost_nok_then(d, res(42, 1, True, 1))
    recs = [a for a in acts if isinstance(a, Record)]
    assert [(int(a.result.tightening_id), a.late) for a in recs] == [(41, True), (42, False)]
    assert not [n for n in published(acts, Notice) if n.said is Said.LATE_RESULT]
    assert d.core.reason == StateReason(Because.RESULT, bolt="B1", ok=True)


def test_a_pushed_result_waited_for_is_only_ended_by_itself_or_in_time():
    """Told 43 skipped ids: a copy of another id (42) ends nothing (a reviewer: it ended the
    wait, 43 then unattributed and B1 left open); 43 never fed (a fault of the shell), the
    wait ends after PENDING_PUSH_S (or at the catch-up's end), and no tool stays off for
    good."""
    d = _ready()
    _enabled(d, 1)
    d.t += 1.0
    d.feed(ResultsSkipped(d.t, 43))
    d.feed(ResultCopy(d.t, res(42, 1, True, 1), "VIN1", "B1"))
    d.t += d.core.late_result_s + 1
    d.feed(Tick(d.t))
    acts = d.feed(ResultIn(d.t, res(43, 1, True, 1)))
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts if isinstance(a, Record)] \
        == [("B1", 43)]
    d = _ready()
    _enabled(d, 1)
    d.feed(ResultsSkipped(d.t, 43))
    d.feed(CaughtUp(d.t, True, "", 0))
    assert d.core._pending_push is None          # a catch-up's end: no longer waited for
    d.feed(ResultsSkipped(d.t, 43))
    d.t += PENDING_PUSH_S - 1
    d.feed(Tick(d.t))
    _on(d, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 1)
    assert not d.core.tool_on                   # still waited for
    d.t += 2.0
    d.feed(Tick(d.t))
    d.t += d.core.late_result_s
    _on(d, 2, 1)
    assert d.core.tool_on and d.core.bolt == "B2"


def test_a_lost_push_of_a_car_two_cars_back_still_holds_its_bolt():
    """VIN1's last bolt, its push lost; VIN2 comes and goes; VIN3's first push reveals the
    lost one, made within B1's enable: B1 of VIN1 is held, stored for when VIN1 is back (a
    reviewer: forgotten when VIN2 left)."""
    d = _ready()
    enabled_at = _last_bolt_then_the_lift_down(d)
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    for vin, up in (("VIN2", True), ("VIN2", False), ("VIN3", True)):
        d.step(("lift", 30.0, up, up, vin))
    assert d.core.vin == "VIN3"
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40,
                           made_at=enabled_at + 0.5, live=True))
    assert [(a.vin, a.bolt) for a in acts if isinstance(a, StoreCutUnknown)] == \
        [("VIN1", "B1")]


def _after_b2(d: Driver, moving: float, made: float | None) -> list[Any]:
    """B2's result 40 came (its tool off after it); the wrench took ``moving`` s to B1, which
    was enabled; 41 (its push lost, made ``made`` s after B1's enable, None: its time not
    known) then 42 pushed.  The actions from the skip on."""
    _enabled(d, 2)
    d.feed(ResultIn(d.t, res(40, 2, True, 1)))
    d.t += moving
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 1.0
    acts = d.feed(ResultsSkipped(d.t, 42))
    acts += d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                            made_at=None if made is None else enabled_at + made,
                            live=True, before=42))
    return acts + d.feed(ResultIn(d.t, res(42, 1, True, 1)))


def test_a_lost_push_is_placed_by_the_order_of_ids_when_its_time_cannot_tell():
    """B2's result 40 came (its tool off after it), then B1 enabled; 41 (its push lost, made
    within the clock's slack of the enable) then 42 pushed: no enable but B1's came after
    40, and 41 was made after B2's tool went off, so 41 is B1's (a supervisor's trial: the
    operator pulled again at once, the NOK stored unattributed).  Where the tool stayed on
    after 40 (a batch increment during B2's enable) B2's enable may have made 41: not taken
    for B1."""
    d = _ready()
    acts = _after_b2(d, 3.0, 0.5)
    assert [(a.bolt, int(a.result.tightening_id)) for a in acts
            if isinstance(a, Record)] == [("B1", 41), ("B1", 42)]
    d = _ready()
    _enabled(d, 2)
    d.feed(ResultIn(d.t, res(40, 2, True, 3)))        # an event: B2's tool stays on
    assert d.core.tool_on
    _on(d, 3, 3)                                       # the wrench leaves B2
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 1.0
    d.feed(ResultsSkipped(d.t, 42))
    acts = d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                           made_at=enabled_at + 0.5, live=True, before=42))
    assert not [a for a in acts if isinstance(a, Record)]


def test_a_lost_push_made_as_the_bolt_before_went_off_is_not_taken_for_the_next():
    """B1 enabled within the clock's slack of B2's tool going off, 41 made within it too: the
    operator may have pulled again on B2 as its disable was sent (a rundown begun before
    the disable took effect ends after it; a reviewer: credited to B1, B2's second hit
    hidden).  Its time not known, nothing proves it either.  Stored unattributed, with
    why; B1's own result 42 closes B1."""
    for moving, made in ((0.0, 0.5), (0.5, -0.3), (3.0, None)):
        d = _ready()
        acts = _after_b2(d, moving, made)
        assert [(a.bolt, int(a.result.tightening_id)) for a in acts
                if isinstance(a, Record)] == [("B1", 42)], (moving, made)
        [stored] = [a for a in acts if isinstance(a, StoreUnattributed)]
        assert int(stored.result.tightening_id) == 41
        assert "B1" in d.core.matcher.done and "B2" in d.core.matcher.done
        assert "fetched after a later one came, the link up" in " ".join(_notices(acts))


def test_an_enable_left_without_its_result_asks_the_controller_for_its_newest():
    """B1's window ends with no result (the operator left it, or its car left): the core
    asks for the controller's newest result (its push may be lost), once."""
    d = _ready()
    _enabled(d, 1)
    _on(d, 2, 3)
    d.t += d.core.late_result_s + 1.0
    acts = d.feed(Tick(d.t))
    assert [a for a in acts if isinstance(a, CheckNewest)]
    d.t += 1.0
    assert not [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    # the window's end seen first by the next bolt's frame (no Tick since): asked then, and
    # the next bolt's tool waits for the answer (a trial: it went on 30 ms after the
    # window's end, before the tick, and the check never came; were it asked with the tool
    # on, its own rundown could be the newest, fetched before its push: a reviewer)
    d = _ready()
    d.answer_checks = False
    _enabled(d, 1)
    _on(d, 3, 3)                                   # the wrench leaves B1, no Tick since
    d.t += d.core.late_result_s + 1.0
    n = len(d.log)
    _on(d, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 2)
    assert len([a for _, acts in d.log[n:] for a in acts if isinstance(a, CheckNewest)]) == 1
    assert not d.core.tool_on
    d.feed(NewestChecked(d.t))
    _on(d, 2, 1)
    assert d.core.tool_on and d.core.bolt == "B2"


def _b1_window_ends(d: Driver) -> float:
    """B1 enabled, tightened 3 s later (its push lost: nothing comes), the wrench to B2; B1's
    window ends: the controller is asked for its newest (the test answers).  B1's enable's
    time."""
    d.answer_checks = False
    _enabled(d, 1)
    enabled_at = d.t
    d.t += 3.0
    _on(d, 2, 3)                                   # the wrench leaves B1: the tool off
    d.t += d.core.late_result_s + 1.0
    assert [a for a in d.feed(Tick(d.t)) if isinstance(a, CheckNewest)]
    return enabled_at


def _b2_waits(d: Driver) -> None:
    """The wrench on B2, its parameters acknowledged: the tool stays off, for B1."""
    _on(d, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 1)
    assert not d.core.tool_on
    assert state_words(d.core.reason) == ("bolt B2: the tool stays off until bolt B1's "
                                          "result is in, or can no longer come")


def test_a_push_lost_found_as_the_window_ends_is_recorded_to_its_bolt():
    """B1's window ends without its result; the controller's newest, asked for then, is 41
    (its push lost), made while the tool was on for B1 and no enable since: B1's, recorded
    to it (a trial: held for a supervisor, its words saying other enables came between, when
    none had).  The next bolt's tool waits for the check's answer (a trial: B2's enable, 30
    ms after the window's end, voided the check)."""
    d = _ready()
    enabled_at = _b1_window_ends(d)
    _b2_waits(d)
    acts = d.feed(ResultIn(d.t, res(41, 1, False, 1), fetched=True, follows=40,
                           made_at=enabled_at + 2.5, live=True))
    [rec] = [a for a in acts if isinstance(a, Record)]
    assert (rec.bolt, int(rec.result.tightening_id), rec.late) == ("B1", 41, True)
    assert not [a for a in acts if isinstance(a, StoreUnattributed | StoreCutUnknown)]
    assert ("tightening 41, its push lost, fetched as B1's late-result window ended: made "
            "while the tool was on for B1 alone, recorded to B1") in _notices(acts)
    assert d.core._noks["B1"] == 1
    _on(d, 2, 1)
    assert not d.core.tool_on                      # until the check has ended
    d.feed(NewestChecked(d.t))
    _on(d, 2, 1)
    assert d.core.tool_on and d.core.bolt == "B2"


def test_a_check_that_finds_nothing_or_never_answers_keeps_no_tool_off_for_long():
    """The check finds nothing more (B1's operator left it untightened): the tool goes on
    for B2 at once; B1's enable stays unanswered (a result found later may be its own, and
    holds it).  A check never answered (a fault of the shell) ends in CHECK_WAIT_S."""
    d = _ready()
    _b1_window_ends(d)
    _b2_waits(d)
    d.feed(NewestChecked(d.t))
    _on(d, 2, 1)
    assert d.core.tool_on and d.core.bolt == "B2"
    assert [u.selection.bolt for u in d.core._unanswered] == ["B1"]
    d = _ready()
    _b1_window_ends(d)
    _b2_waits(d)
    d.t += CHECK_WAIT_S
    d.feed(Tick(d.t))
    _on(d, 2, 1)
    assert d.core.tool_on and d.core.bolt == "B2"


def test_a_gap_with_the_link_up_holds_the_bolts_whose_result_may_be_in_it():
    """B2's result 40 came; B1 enabled, tightened (41, its push lost), left: its window ends,
    the check finds nothing (the controller gives no old results); B3 enabled, its 42 pushed
    skips 41, which the controller does not give (a gap with the link up).  B1's result may
    be 41: B1 held, never left open to be tightened twice (before: the gap stored, B1 open).
    An enable before the last result heard (B2's, answered) is no candidate."""
    d = _ready()
    _enabled(d, 2)
    d.feed(ResultIn(d.t, res(40, 2, True, 1)))
    d.t += 3.0
    _enabled(d, 1)
    _on(d, 3, 3)
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    _enabled(d, 3)
    d.feed(ResultsSkipped(d.t, 42))
    acts = d.feed(ResultsMissed(d.t, 41, 41, "the controller no longer has it", live=True))
    note = ("its result may be tightening 41 (its push lost, not given by the controller); "
            "the tool was enabled for pset 1 at ")
    [stored] = [a for a in acts if isinstance(a, StoreCutUnknown)]
    assert stored.bolt == "B1" and stored.note.startswith(note)
    assert d.core.matcher.held["B1"].startswith(note)
    acts = d.feed(ResultIn(d.t, res(42, 1, True, 1)))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B3"]
    # a gap after a reconnect (the link was down): the catch-up's end settles that enable
    # (and one left since the reconnect is not in it: none here)
    d = _ready()
    d.answer_checks = True
    _enabled(d, 1)
    _on(d, 3, 3)
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    d.step(("fault", 0.1, "wrench"))
    d.step(("back", 0.5, "", 2))
    acts = d.feed(ResultsMissed(d.t, 41, 41, "the controller no longer has it"))
    assert not [a for a in acts if isinstance(a, StoreCutUnknown)]


def test_an_older_id_judged_later_says_nothing_of_the_order():
    """The controller's clock not known.  B2's 40 came; B3 enabled, its 41's push lost, its
    window over; B1 enabled; a catch-up's old 39 is judged now; B1's 42 pushed skips 41.
    41 may be B3's (its enable came after 40): never taken for B1 by the order of ids, and
    B3 held (a reviewer: the last judged, 39, taken for the newest, put 41 on B1)."""
    d = _ready()
    _enabled(d, 2)
    d.feed(ResultIn(d.t, res(40, 2, True, 1)))
    _enabled(d, 3)
    _on(d, 2, 3)                                   # the wrench leaves B3
    d.t += d.core.late_result_s + 1.0
    d.feed(Tick(d.t))
    _enabled(d, 1)
    d.t += 1.0
    d.feed(ResultIn(d.t, res(39, 2, True, 1), fetched=True, follows=38))
    d.feed(ResultsSkipped(d.t, 42))
    acts = d.feed(ResultIn(d.t, res(41, 1, True, 1), fetched=True, follows=40, made_at=None,
                           live=True, before=42))
    assert not [a for a in acts if isinstance(a, Record)]
    assert [a.bolt for a in acts if isinstance(a, StoreCutUnknown)] == ["B3"]


def test_a_result_under_another_vin_is_recorded_to_its_bolt_and_said():
    """The controller's VIN in a result is another than the vehicle's (its VIN download did
    not take, or another program set it): the rundown is the bolt's the tool was on for,
    recorded so, and said as a warning naming both VINs (an integrator's trial: four such
    results recorded without a word).  Its own VIN, or none: nothing said."""
    for vin, said in (("WVWZZZ1JZ3W000001", True), ("VIN1", False), ("", False)):
        d = _ready("VIN1")
        _enabled(d, 1)
        acts = d.feed(ResultIn(d.t, res(41, 1, True, 1, vin=vin)))
        assert [(a.bolt, int(a.result.tightening_id)) for a in acts
                if isinstance(a, Record)] == [("B1", 41)]
        other = [n for n in published(acts, Notice) if n.said is Said.OTHER_VIN]
        assert bool(other) is said
        if said:
            assert other[0].level == "warning"
            words = notice_words(other[0])
            assert "WVWZZZ1JZ3W000001" in words and "VIN1" in words and "B1" in words
