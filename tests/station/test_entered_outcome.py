"""A held bolt (its result could not be read) resolved by the outcome a supervisor read on the
controller's own screen: the core's rules for the ``enter-outcome`` command (who may, for
which bolt, and what OK and NOK do)."""

from __future__ import annotations

from typing import Any

from db.kinds import LOOSENING, NOK, OK, TIGHTENING, HeldUnder
from stationd.reasons import Reason, Why
from stationd.station.actions import RecordCommand
from stationd.station.commands import (
    KIND,
    RIGHT,
    EnterOutcome,
    Issuer,
    ReleaseBolt,
    Right,
    SkipBolt,
)
from stationd.station.core import StationCore
from stationd.station.events import (
    Because,
    BoltLocked,
    BoltToLoosen,
    Notice,
    ResultRecorded,
    Said,
    State,
    StateChanged,
    StateReason,
    ToolDisabled,
)
from stationd.station.inputs import CommandDone, CommandIn, ResultIn, UnreadableIn, VehicleLoaded
from stationd.station.lift import held_a_loosening
from stationd.station.policy import NokPolicy, NokRule, Strategy
from stationd.words import answer_words, notice_words, reason_words, state_words
from tests.station.test_commands import OPERATOR, SUPERVISOR, _answer
from tests.station.test_core import BOLTS, PARAMS, Driver, _on, _ready, published
from tests.station.test_loosen import _rundown
from tests.station.test_result_types import _enabled, res, unreadable

#: a role with the release right and nothing else
RELEASER = Issuer("lea", frozenset({Right.RELEASE}), "cli")


def _held(d: Driver, bolt: int = 1, tid: int = 7) -> None:
    """``B<bolt>`` held: the tool on it, its result (tightening ``tid``) unreadable."""
    _enabled(d, bolt)
    d.feed(UnreadableIn(d.t, unreadable(tid=tid, pset=d.core._specs[f"B{bolt}"].pset)))
    assert d.core.matcher is not None and f"B{bolt}" in d.core.matcher.held


def ok(bolt: str = "B1", comment: str = "read on the controller: OK") -> EnterOutcome:
    return EnterOutcome("VIN1", bolt, True, 49.6, 31.0, comment)


def nok(bolt: str = "B1") -> EnterOutcome:
    return EnterOutcome("VIN1", bolt, False, 56.1, 29.0, "the controller shows NOK")


def _notices(acts: list[Any]) -> list[str]:
    return [notice_words(e) for e in published(acts, Notice)]


def test_the_command_needs_the_release_right_and_is_named_enter_outcome():
    assert RIGHT[EnterOutcome] is Right.RELEASE and KIND[EnterOutcome] == "enter-outcome"


def test_an_ok_entered_by_a_supervisor_closes_the_held_bolt():
    d = _ready()
    _held(d)
    acts = d.command(1, ok(), SUPERVISOR)
    reply = _answer(acts)
    assert reply.answer.accepted
    assert answer_words(reply.answer) == (
        "command enter-outcome B1 of VIN1: OK 49.6 Nm, 31.0 deg ('read on the controller: "
        "OK') by sam (screen 10.0.0.7): accepted")
    [rec] = published(acts, ResultRecorded)
    assert (rec.bolt, rec.ok, rec.torque_nm, rec.angle_deg, rec.entered_by, rec.kind) == (
        "B1", True, 49.6, 31.0, "sam", "tightening")
    assert "B1: OK 49.6 Nm, 31.0 deg entered by sam from the controller's screen (the result " \
        "that could not be read: tightening 7): B1 done" in _notices(acts)
    [said] = published(acts, Notice)
    assert (said.said, said.bolt, said.torque_nm, said.angle_deg, said.user, said.note) == (
        Said.ENTERED_OK, "B1", 49.6, 31.0, "sam", "tightening 7") and said.level == "info"
    assert not d.core.matcher.held and "B1" in d.core.matcher.done
    # done: never selected again
    sends = len(d.sends)
    _on(d, 1, 4)
    assert len(d.sends) == sends


def test_the_state_stops_saying_held_when_the_hold_ends():
    """Released, skipped or its outcome entered: the state's reason no longer says the bolt
    is held for a supervisor (`stationd status` kept saying it until the next change: a
    supervisor's trial)."""
    for end in (ok(), ReleaseBolt("VIN1", "B1", "checked"), SkipBolt("VIN1", "B1", "done")):
        d = _ready()
        _held(d)
        assert d.core.reason == StateReason(Because.UNREADABLE_HELD, bolt="B1")
        acts = d.command(1, end, SUPERVISOR)
        assert _answer(acts).answer.accepted
        assert [(e.state, e.reason) for e in published(acts, StateChanged)] == [
            (State.TRACKING, StateReason(Because.TRACKING))]
        assert state_words(d.core.reason) == "tracking the wrench"


def test_a_release_says_what_it_ended():
    """A hold (which result) or a lock after NOKs: "accepted" alone answered a second release
    that ended a new hold rather than the lock it was meant for (a supervisor's trial)."""
    d = _ready()
    _held(d)
    words = answer_words(_answer(d.command(1, ReleaseBolt("VIN1", "B1", "checked"),
                                           SUPERVISOR)).answer)
    assert words.endswith(": accepted: its hold (tightening 7) ended: B1 is open to be "
                          "tightened again, but it may be tightened already: check the "
                          "controller before tightening it again"), words
    d.core.matcher.locked["B2"] = 3
    words = answer_words(_answer(d.command(2, ReleaseBolt("VIN1", "B2", "thread chased"),
                                           SUPERVISOR)).answer)
    assert words.endswith(": accepted: its lock after 3 NOK in a row ended"), words


def test_releasing_a_hold_ends_the_nok_row_as_the_records_count_it():
    """A NOK, then a result that could not be read (held), then a release: the NOKs in a row
    start again, as ``Repository.nok_streaks`` counts them after a reload (a supervisor's
    trial: the live count went on, and the next NOK locked at "3 in a row")."""
    d = _ready()
    _enabled(d, 1)
    d.feed(ResultIn(d.t, res(6, d.core._specs["B1"].pset or 0, False, 1)))
    assert d.core._noks.get("B1") == 1
    _held(d)
    assert _answer(d.command(1, ReleaseBolt("VIN1", "B1", "checked"), SUPERVISOR)).answer.accepted
    assert "B1" not in d.core._noks


def test_the_release_right_is_what_it_takes_and_an_operator_is_refused():
    d = _ready()
    _held(d)
    refused = _answer(d.command(1, ok(), OPERATOR)).answer
    assert refused.reason == Reason(Why.NO_RIGHT, right="release", asked="enter-outcome")
    # the command asked named (a supervisor's trial read "no right to release" of it)
    assert reason_words(refused.reason) == \
        "your role does not have the right to release (enter-outcome needs it)"
    assert "B1" in d.core.matcher.held
    assert _answer(d.command(2, ok(), RELEASER)).answer.accepted


def test_a_bolt_that_is_not_held_is_refused_with_why():
    d = _ready()
    acts = d.feed(CommandIn(d.t, 1, ok("B2"), SUPERVISOR))
    refused = _answer(acts).answer
    assert not any(isinstance(a, RecordCommand) for a in acts)   # nothing recorded
    assert refused.reason == Reason(Why.NOT_HELD, bolt="B2")
    assert reason_words(refused.reason) == (
        "B2 is not held: an outcome is entered only for a held bolt (its result could not be "
        "read, or is not known)")
    # a bolt locked after NOKs is released, not entered: its results were read (said so: a
    # supervisor's trial read only that it was not held)
    d.core.matcher.locked["B2"] = 3
    refused = _answer(d.command(2, ok("B2"), SUPERVISOR)).answer
    assert refused.reason == Reason(Why.NOT_HELD, bolt="B2", count=3)
    assert reason_words(refused.reason) == (
        "B2 is not held but locked after 3 NOK in a row: its results were read; it is "
        "released (the screen's Release form, or stationd release), not entered")
    assert _answer(d.command(3, ok("B9"), SUPERVISOR)).answer.reason == \
        Reason(Why.UNKNOWN_BOLT, bolt="B9", vin="VIN1")
    other = EnterOutcome("VIN2", "B1", True, 1.0, 1.0, "x")
    assert _answer(d.command(4, other, SUPERVISOR)).answer.reason == \
        Reason(Why.OTHER_VEHICLE, vin="VIN2", here="VIN1")


def test_an_ok_entered_outside_the_bolt_s_window_is_refused_a_nok_is_not():
    """A typo (4.974 for 49.74) closed a 45-55 Nm bolt as OK (a supervisor trial): an OK
    entered with a value outside the bolt's window is refused, nothing recorded, the bolt
    still held; a NOK with the same value is what the controller may show, and is taken."""
    from dataclasses import replace

    from db.bolts import Parameters, Window

    d = _ready()
    _held(d)
    spec = Parameters(1, Window(50.0, 45.0, 55.0), Window(30.0, 15.0, 60.0))
    d.core._specs["B1"] = replace(d.core._specs["B1"], parameters=spec)
    acts = d.command(1, EnterOutcome("VIN1", "B1", True, 4.974, 31.0, "typo"), SUPERVISOR)
    refused = _answer(acts).answer
    assert not refused.accepted and refused.reason is not None
    assert refused.reason.kind is Why.ENTERED_OUTSIDE
    assert not any(isinstance(a, RecordCommand) for a in acts)
    assert reason_words(refused.reason).startswith(
        f"B1: an OK with torque 4.974 Nm outside {spec.torque.min:g}-{spec.torque.max:g} Nm")
    # said to a person at the screen as well as at the command line: the screen's form has no
    # --nok (a supervisor's trial read only the command line's flag there)
    assert reason_words(refused.reason).endswith(
        "(a NOK is entered as a NOK: NOK in the screen's form, or --nok)")
    assert "B1" in d.core.matcher.held
    acts = d.command(2, EnterOutcome("VIN1", "B1", False, 4.974, 31.0, "NOK on screen"),
                     SUPERVISOR)
    assert _answer(acts).answer.accepted and "B1" not in d.core.matcher.held


def test_an_entered_outcome_the_database_refused_changes_nothing():
    d = _ready()
    _held(d)
    d.feed(CommandIn(d.t, 1, ok(), SUPERVISOR))
    acts = d.feed(CommandDone(d.t, 1, Reason(Why.NOT_RECORDED, note="disk full")))
    assert not _answer(acts).answer.accepted and not published(acts, ResultRecorded)
    assert "B1" in d.core.matcher.held and "B1" not in d.core.matcher.done


def test_a_second_entry_after_the_first_is_refused_the_bolt_no_longer_held():
    d = _ready()
    _held(d)
    assert _answer(d.command(1, ok(), SUPERVISOR)).answer.accepted
    assert _answer(d.command(2, ok(), SUPERVISOR)).answer.reason == \
        Reason(Why.NOT_HELD, bolt="B1")
    assert _answer(d.command(3, ReleaseBolt("VIN1", "B1"), SUPERVISOR)).answer.reason == \
        Reason(Why.NOT_LOCKED, bolt="B1")


def test_a_nok_entered_is_a_nok_under_the_policy_repeat_opens_the_bolt_again():
    d = _ready()
    _held(d)
    acts = d.command(1, nok(), SUPERVISOR)
    [rec] = published(acts, ResultRecorded)
    assert not rec.ok and rec.entered_by == "sam"
    assert any("a NOK of B1, the NOK policy applies" in m for m in _notices(acts))
    assert [(n.said, n.level) for n in published(acts, Notice)] == [
        (Said.ENTERED_NOK, "warning")]
    assert not d.core.matcher.held and "B1" not in d.core.matcher.done
    assert d.core._noks["B1"] == 1
    _enabled(d)     # open again (repeat): tightened again


def test_a_nok_entered_counts_in_the_row_and_locks_at_max_nok():
    d = _ready(nok=NokPolicy(NokRule(max_nok=1)))
    _held(d)
    acts = d.command(1, nok(), SUPERVISOR)
    [lock] = published(acts, BoltLocked)
    assert (lock.bolt, lock.count, lock.held) == ("B1", 1, None)
    assert "B1" in d.core.matcher.locked and not d.core.matcher.held
    # a locked bolt: released as usual
    assert _answer(d.command(2, ReleaseBolt("VIN1", "B1", "joint checked"),
                             SUPERVISOR)).answer.accepted


def test_a_nok_entered_under_loosen_sends_the_loosen_pset_next():
    d = _ready(nok=NokPolicy(NokRule(3, Strategy.LOOSEN, 90)))
    _held(d)
    acts = d.command(1, nok(), SUPERVISOR)
    [loosen] = published(acts, BoltToLoosen)
    assert loosen.bolt == "B1" and loosen.reason.pset == 90
    assert "B1" in d.core._loosen


def test_an_entered_ok_ends_a_nok_row():
    d = _ready(nok=NokPolicy(NokRule(max_nok=2)))
    _held(d)
    d.command(1, nok(), SUPERVISOR)
    assert d.core._noks["B1"] == 1
    _held(d, tid=8)
    d.command(2, ok(), SUPERVISOR)
    assert "B1" not in d.core._noks and "B1" in d.core.matcher.done


# -- a held loosening: the outcome entered is a loosening's -------------------------------------
LOOSEN = NokPolicy(NokRule(3, Strategy.LOOSEN, 90))


def _held_loosening(d: Driver, tid: int = 2) -> list[Any]:
    """B1 NOK under ``loosen``, then its loosen pset (90) enabled and its result unreadable:
    B1 held for a loosening's result; the actions of the unreadable result."""
    _rundown(d, 1, 1, ok=False)
    sent = _enabled(d)
    assert sent.loosen and sent.selection.pset == 90
    acts = d.feed(UnreadableIn(d.t, unreadable(tid=tid, pset=90)))
    assert d.core.matcher is not None and "B1" in d.core.matcher.held
    return acts


def test_a_loosening_held_says_it_is_a_loosening_s_result():
    d = _ready(nok=LOOSEN)
    acts = _held_loosening(d)
    [lock] = published(acts, BoltLocked)
    assert lock.held == "tightening 2, a loosening with loosen pset 90"
    assert "B1: the controller's result could not be read (tightening 2, a loosening with " \
        "loosen pset 90): check it on the controller, then enter its outcome, or release it " \
        "to tighten it again" in _notices(acts)
    assert [state_words(e.reason) for e in published(acts, ToolDisabled)] == [
        "bolt B1: its loosening's result could not be read",
        "bolt B1: its loosening's result could not be read; held for a supervisor"]
    # the refusal on the bolt says the same
    assert reason_words(Reason(Why.HELD, bolt="B1", note=d.core.matcher.held["B1"])) == (
        "B1: the controller's result could not be read (tightening 2, a loosening with "
        "loosen pset 90): check it on the controller, then enter its outcome, or release it "
        "to tighten it again")


def test_an_ok_entered_for_a_held_loosening_loosens_the_bolt_never_closes_it():
    """The reviewer's case: the OK the controller shows for the loosen pset is the joint come
    loose; recorded as a loosening, the bolt then gets its tightening pset (it closed the bolt
    as an OK tightening, and dropped it off the loosen-first list)."""
    d = _ready(nok=LOOSEN)
    _held_loosening(d)
    acts = d.command(1, EnterOutcome("VIN1", "B1", True, 8.0, 400.0, "controller: OK"),
                     SUPERVISOR)
    [recorded] = [a for a in acts if isinstance(a, RecordCommand)]
    assert isinstance(recorded.command, EnterOutcome)
    assert (recorded.command.loosening, recorded.command.loosen_pset) == (True, 90)
    assert answer_words(_answer(acts).answer) == (
        "command enter-outcome B1 of VIN1: loosening OK 8.0 Nm, 400.0 deg ('controller: OK') "
        "by sam (screen 10.0.0.7): accepted")
    [rec] = published(acts, ResultRecorded)
    assert (rec.bolt, rec.ok, rec.kind, rec.pset, rec.entered_by) == (
        "B1", True, LOOSENING, 90, "sam")
    # the loosen pset's limits are the controller's, not the bolt's tightening window
    assert (rec.torque_min, rec.torque_max, rec.angle_min, rec.angle_max) == (None,) * 4
    assert [n.said for n in published(acts, Notice)] == [Said.ENTERED_LOOSENING_OK,
                                                         Said.LOOSENED]
    assert _notices(acts) == [
        "B1: loosening OK 8.0 Nm, 400.0 deg entered by sam from the controller's screen (the "
        "result that could not be read: tightening 2, a loosening with loosen pset 90): a "
        "loosening, not a tightening: B1 not done",
        "B1 loosened: its tightening pset goes next"]
    m = d.core.matcher
    assert "B1" not in m.done and not m.held and "B1" not in d.core._held_loosening
    assert d.core._noks == {"B1": 1}            # a loosening OK neither counts nor ends the row
    # its tightening pset goes next, and only that tightening closes the bolt
    sent, acts = _rundown(d, 1, 3, ok=True, rtype=1)
    assert not sent.loosen and sent.selection.pset == 1
    assert "B1" in m.done and "B1" not in d.core._noks


def test_a_result_of_an_unknown_type_under_the_loosen_pset_is_a_loosening_s_hold():
    """A review: a result of type 9 under B1's loosen pset held B1 as a tightening's, and an
    OK entered for it closed B1, only loosened, as tightened.  Held under its enable: the OK
    entered is a loosening, B1 not done."""
    d = _ready(nok=LOOSEN)
    _rundown(d, 1, 1, ok=False)
    sent = _enabled(d)
    assert sent.loosen and sent.selection.pset == 90
    acts = d.feed(ResultIn(d.t, res(2, 90, True, 9)))
    [lock] = published(acts, BoltLocked)
    assert lock.held == ("a result of a type the station does not know (type 9, tightening 2), "
                         "a loosening with loosen pset 90")
    acts = d.command(1, EnterOutcome("VIN1", "B1", True, 8.0, 400.0, "controller: OK"),
                     SUPERVISOR)
    [rec] = published(acts, ResultRecorded)
    assert (rec.bolt, rec.ok, rec.kind, rec.pset) == ("B1", True, LOOSENING, 90)
    assert "B1" not in d.core.matcher.done


def test_a_nok_entered_for_a_held_loosening_counts_as_a_loosening_nok():
    d = _ready(nok=LOOSEN)
    _held_loosening(d)
    acts = d.command(1, EnterOutcome("VIN1", "B1", False, 60.0, 2.0, "did not come loose"),
                     SUPERVISOR)
    [rec] = published(acts, ResultRecorded)
    assert (rec.ok, rec.kind, rec.pset) == (False, LOOSENING, 90)
    assert [(n.said, n.count, n.level) for n in published(acts, Notice)] == [
        (Said.ENTERED_LOOSENING_NOK, None, "warning"), (Said.LOOSENING_NOK, 2, "warning")]
    assert "a loosening NOK of B1, the NOK policy applies" in _notices(acts)[0]
    assert d.core._noks == {"B1": 2} and "B1" in d.core._loosen   # still to be loosened
    assert "B1" not in d.core.matcher.done
    sent = _enabled(d)                           # the loosen pset again
    assert sent.loosen and sent.selection.pset == 90


def test_a_nok_entered_for_a_held_loosening_locks_at_max_nok_as_a_measured_one():
    d = _ready(nok=NokPolicy(NokRule(2, Strategy.LOOSEN, 90)))
    _held_loosening(d)
    acts = d.command(1, EnterOutcome("VIN1", "B1", False, 60.0, 2.0, "stuck"), SUPERVISOR)
    [lock] = published(acts, BoltLocked)
    assert (lock.bolt, lock.count, lock.held) == ("B1", 2, None)
    assert "B1" in d.core.matcher.locked and "B1" in d.core._loosen
    # released: still to be loosened first
    acts = d.command(2, ReleaseBolt("VIN1", "B1", "joint checked"), SUPERVISOR)
    [to_loosen] = published(acts, BoltToLoosen)
    assert to_loosen.reason.pset == 90


def test_a_hold_s_loosening_ends_with_it_the_next_hold_is_its_own():
    """Released, then loosened and tightened under a new hold: the entered OK is the
    tightening's (a loosening remembered from the first hold would leave the bolt open)."""
    d = _ready(nok=LOOSEN)
    _held_loosening(d)
    assert _answer(d.command(1, ReleaseBolt("VIN1", "B1", "looked"), SUPERVISOR)).answer.accepted
    assert not d.core._held_loosening
    sent, _ = _rundown(d, 1, 3, ok=True, rtype=2)        # loosened, measured
    assert sent.loosen
    _held(d, tid=4)                                      # its tightening pset, unreadable
    assert d.core.matcher.held["B1"] == "tightening 4"
    acts = d.command(2, ok(), SUPERVISOR)
    [rec] = published(acts, ResultRecorded)
    assert (rec.kind, rec.pset) == (TIGHTENING, 1) and "B1" in d.core.matcher.done


def test_a_held_loosening_comes_back_with_the_vehicle_from_its_enable():
    """After a reload or a restart the records say what the held result came under (the
    tool enable it answered): an OK entered then is still a loosening."""
    core = StationCore(PARAMS, leave_frames=2, nok=LOOSEN)
    acts = core.feed(VehicleLoaded(1.0, "VIN1", "M", BOLTS, noks={"B1": 1},
                                   held={"B1": "tightening 2", "B3": "tightening 5"},
                                   status={"B1": NOK, "B3": NOK},
                                   held_under={"B1": HeldUnder(True, 90),
                                               "B3": HeldUnder(False, 1)}))
    assert core.matcher is not None
    assert core.matcher.held == {"B1": "tightening 2, a loosening with loosen pset 90",
                                 "B3": "tightening 5"}
    assert {e.bolt: e.held for e in published(acts, BoltLocked)} == core.matcher.held
    assert core._held_loosening == {"B1": 90}
    for request, bolt, kind in ((1, "B1", LOOSENING), (2, "B3", TIGHTENING)):
        core.feed(CommandIn(2.0, request, ok(bolt), SUPERVISOR))
        [rec] = published(core.feed(CommandDone(2.0, request)), ResultRecorded)
        assert rec.kind == kind, bolt
    assert "B1" not in core.matcher.done and "B3" in core.matcher.done


def test_where_the_records_cannot_tell_a_hold_s_kind_it_leans_to_a_loosening():
    """No enable found for a held result (``loosen`` None): a pset it came under that is not
    the bolt's tightening pset is a loosening's; no pset known, what the station would send
    the bolt now decides (its loosen pset where it is to be loosened first)."""
    assert held_a_loosening(HeldUnder(True, 90), 1, to_loosen=False)
    assert not held_a_loosening(HeldUnder(False, 90), 1, to_loosen=True)   # the enable's word
    assert held_a_loosening(HeldUnder(None, 90), 1, to_loosen=False)
    assert held_a_loosening(HeldUnder(None, 77), 1, to_loosen=False)   # neither: in doubt
    assert not held_a_loosening(HeldUnder(None, 1), 1, to_loosen=True)
    assert held_a_loosening(HeldUnder(None, None), 1, to_loosen=True)
    assert not held_a_loosening(HeldUnder(None, None), 1, to_loosen=False)
    # through a load: B1 NOK under loosen (to be loosened), B3 OK last; neither enable known
    core = StationCore(PARAMS, leave_frames=2, nok=LOOSEN)
    core.feed(VehicleLoaded(1.0, "VIN1", "M", BOLTS, held={"B1": "MID 0061 revision 7",
                                                           "B3": "tightening 5"},
                            status={"B1": NOK, "B3": OK}))
    assert core._held_loosening == {"B1": 90}
    assert core.matcher is not None and core.matcher.held == {
        "B1": "MID 0061 revision 7, a loosening with loosen pset 90", "B3": "tightening 5"}
