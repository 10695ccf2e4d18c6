"""A held bolt (its result could not be read) resolved by the outcome a supervisor read on the
controller's own screen: the core's rules for the ``enter-outcome`` command (who may, for
which bolt, and what OK and NOK do)."""

from __future__ import annotations

from typing import Any

from stationd.reasons import Reason, Why
from stationd.station.actions import RecordCommand
from stationd.station.commands import KIND, RIGHT, EnterOutcome, Issuer, ReleaseBolt, Right
from stationd.station.events import BoltLocked, BoltToLoosen, Notice, ResultRecorded, Said
from stationd.station.inputs import CommandDone, CommandIn, UnreadableIn
from stationd.station.policy import NokPolicy, NokRule
from stationd.words import answer_words, notice_words, reason_words
from tests.station.test_commands import OPERATOR, SUPERVISOR, _answer
from tests.station.test_core import Driver, _on, _ready, published
from tests.station.test_result_types import _enabled, unreadable

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


def test_the_release_right_is_what_it_takes_and_an_operator_is_refused():
    d = _ready()
    _held(d)
    refused = _answer(d.command(1, ok(), OPERATOR)).answer
    assert refused.reason == Reason(Why.NO_RIGHT, right="release")
    assert reason_words(refused.reason) == "your role does not have the right to release"
    assert "B1" in d.core.matcher.held
    assert _answer(d.command(2, ok(), RELEASER)).answer.accepted


def test_a_bolt_that_is_not_held_is_refused_with_why():
    d = _ready()
    acts = d.feed(CommandIn(d.t, 1, ok("B2"), SUPERVISOR))
    refused = _answer(acts).answer
    assert not any(isinstance(a, RecordCommand) for a in acts)   # nothing recorded
    assert refused.reason == Reason(Why.NOT_HELD, bolt="B2")
    assert reason_words(refused.reason) == (
        "B2 is not held: an outcome is entered only for a bolt whose result the controller "
        "could not send readably")
    # a bolt locked after NOKs is released, not entered: its results were read
    d.core.matcher.locked["B2"] = 3
    assert _answer(d.command(2, ok("B2"), SUPERVISOR)).answer.reason == \
        Reason(Why.NOT_HELD, bolt="B2")
    assert _answer(d.command(3, ok("B9"), SUPERVISOR)).answer.reason == \
        Reason(Why.UNKNOWN_BOLT, bolt="B9", vin="VIN1")
    other = EnterOutcome("VIN2", "B1", True, 1.0, 1.0, "x")
    assert _answer(d.command(4, other, SUPERVISOR)).answer.reason == \
        Reason(Why.OTHER_VEHICLE, vin="VIN2")


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
    d = _ready(nok=NokPolicy(NokRule(3, "loosen", 90)))
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
