"""Commands in the pure core: checked against the rules and the issuer's rights, effective only
once recorded, answered with a typed reason; every input type has its handler."""

from __future__ import annotations

import typing

import pytest

from stationd.reasons import Reason, Skip, SkipKind, Why
from stationd.station import core as core_module
from stationd.station.actions import DisableTool, Publish, RecordCommand, RecordRefusal, Reply
from stationd.station.commands import Issuer, ReopenVehicle, Right, SkipBolt, TeachStop
from stationd.station.core import StationCore
from stationd.station.events import (
    Because,
    BoltSkipped,
    State,
    StateReason,
    VehicleReopened,
)
from stationd.station.inputs import CommandDone, CommandIn, LiftRead, VehicleLoaded, VehicleRejected
from stationd.words import answer_words, reason_words, skip_words, state_words
from tests.station.test_core import BOLTS, _on, _ready

SUPERVISOR = Issuer("sam", frozenset(Right), "screen 10.0.0.7")
OPERATOR = Issuer("olga", frozenset({Right.SKIP}), "cli")
NOBODY = Issuer("nina", frozenset(), "screen 10.0.0.8")


def _answer(acts: list[typing.Any]) -> Reply:
    replies = [a for a in acts if isinstance(a, Reply)]
    assert len(replies) == 1, acts
    return replies[0]


def test_every_input_type_has_its_case_in_the_dispatch():
    """The core dispatches by one ``match`` over the Event union: each member has its case
    (mypy's ``assert_never`` checks it too), and each case's handler exists."""
    import inspect
    import re

    source = inspect.getsource(StationCore._dispatch)
    cases = dict(re.findall(r"case (\w+)\(\)[^:]*:\s+return self\.(\w+)\(", source))
    for cls in typing.get_args(core_module.Event):
        assert cls.__name__ in cases, cls.__name__
        assert callable(getattr(StationCore, cases[cls.__name__], None)), cls.__name__


def test_a_skip_takes_effect_once_recorded_and_is_answered_accepted():
    d = _ready()
    acts = d.alone(CommandIn(d.t, 1, SkipBolt("VIN1", "B2", "no access"), OPERATOR))
    assert [type(a).__name__ for a in acts] == ["RecordCommand"]
    assert "B2" not in d.core.matcher.skipped          # not before it is on disk
    acts = d.alone(CommandDone(d.t, 1))
    assert _answer(acts).answer.accepted
    why = Skip(SkipKind.COMMAND, user="olga", comment="no access")
    assert d.core.matcher.skipped["B2"] == why
    assert skip_words(why) == "olga's command (no access)"
    assert any(type(a).__name__ == "Publish" and isinstance(a.event, BoltSkipped)
               for a in acts)
    _on(d, 2, 3)
    assert d.sends == []                               # never sent for a skipped bolt


def test_a_skip_of_the_selected_bolt_turns_the_tool_off():
    d = _ready()
    _on(d, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 1)
    assert d.tool and d.core.state is State.TIGHTENING
    # while the tool is on that bolt: refused
    acts = d.alone(CommandIn(d.t, 1, SkipBolt("VIN1", "B2"), SUPERVISOR))
    assert _answer(acts).answer.reason == Reason(Why.TOOL_ON_BOLT, bolt="B2")
    # selected, not yet enabled (a stale frame turned the tool off): accepted, dropped
    d.step(("loc", 0.1, 2, 0.9, 0.0))
    assert d.core.state is State.BOLT_SELECTED and not d.tool
    d.alone(CommandIn(d.t, 2, SkipBolt("VIN1", "B2"), SUPERVISOR))
    acts = d.alone(CommandDone(d.t, 2))
    assert _answer(acts).answer.accepted
    assert any(isinstance(a, DisableTool) for a in acts)
    assert d.core.state is State.TRACKING and d.core.bolt is None
    assert d.core.reason == StateReason(Because.SKIPPED, bolt="B2", skip=Skip(
        SkipKind.COMMAND, user=SUPERVISOR.user, comment=""))
    assert state_words(d.core.reason) == f"bolt B2 {SUPERVISOR.user}'s command"


@pytest.mark.parametrize(("command", "issuer", "why"), [
    (SkipBolt("VIN1", "B2"), NOBODY, Reason(Why.NO_RIGHT, right="skip")),
    (ReopenVehicle("VIN9"), OPERATOR, Reason(Why.NO_RIGHT, right="reopen")),
    (SkipBolt("VIN9", "B2"), OPERATOR, Reason(Why.OTHER_VEHICLE, vin="VIN9", here="VIN1")),
    (SkipBolt("VIN1", "B9"), OPERATOR, Reason(Why.UNKNOWN_BOLT, bolt="B9", vin="VIN1")),
    # typed in another case: refused, with what was meant
    (SkipBolt("vin1", "B2"), OPERATOR, Reason(Why.OTHER_VEHICLE, vin="vin1", other="VIN1",
                                              here="VIN1")),
    (SkipBolt("VIN1", "b2"), OPERATOR, Reason(Why.UNKNOWN_BOLT, bolt="b2", vin="VIN1",
                                              other="B2")),
    (ReopenVehicle("VIN1"), SUPERVISOR, Reason(Why.ALREADY_OPEN, vin="VIN1")),
])
def test_a_command_against_the_rules_is_refused_with_its_reason_and_changes_nothing(
        command, issuer, why):
    d = _ready()
    before = dict(d.core.matcher.skipped)
    acts = d.alone(CommandIn(d.t, 7, command, issuer))
    reply = _answer(acts)
    assert reply.answer.reason == why and not reply.answer.accepted
    assert not any(isinstance(a, RecordCommand) for a in acts)
    assert d.core.matcher.skipped == before
    assert "refused" in answer_words(reply.answer) and issuer.user in answer_words(reply.answer)
    # kept in the records as a refusal, with why (a quality trial: the journal alone had it)
    assert [(a.command, a.issuer, a.reason) for a in acts if isinstance(a, RecordRefusal)] \
        == [(command, issuer, why)]


@pytest.mark.parametrize(("vin", "known", "why"), [
    # a VIN the database does not know: unknown, not "reopen it" (a supervisor's trial: the
    # advice to reopen a mistyped VIN led to a second refusal)
    ("VIN8", False, Reason(Why.UNKNOWN_VEHICLE, vin="VIN8")),
    # one it knows (a vehicle that left), or the database could not say: reopen is advice
    ("VIN8", True, Reason(Why.OTHER_VEHICLE, vin="VIN8", here="VIN1")),
    ("VIN8", None, Reason(Why.OTHER_VEHICLE, vin="VIN8", here="VIN1")),
    # the station's VIN in another case: what was meant, whatever the database says
    ("vin1", False, Reason(Why.OTHER_VEHICLE, vin="vin1", other="VIN1", here="VIN1")),
])
def test_a_vin_the_database_does_not_know_is_refused_as_unknown(vin, known, why):
    d = _ready()
    reply = _answer(d.alone(CommandIn(d.t, 7, SkipBolt(vin, "B2", "why"), SUPERVISOR, known)))
    assert reply.answer.reason == why
    assert ("reopen" in reason_words(why)) == (why.kind is Why.OTHER_VEHICLE
                                               and why.other is None)


def test_a_vin_known_in_another_case_is_refused_with_what_was_meant():
    """The database has VIN8, ``vin8`` was typed: "did you mean VIN8?" (a review: the
    records' refusal said it, the core's new one did not)."""
    d = _ready()
    reply = _answer(d.alone(CommandIn(d.t, 7, SkipBolt("vin8", "B2", "why"), SUPERVISOR,
                                      False, "VIN8")))
    why = Reason(Why.UNKNOWN_VEHICLE, vin="vin8", other="VIN8")
    assert reply.answer.reason == why
    assert reason_words(why) == "vehicle vin8 is not in the database (did you mean VIN8?)"


def test_a_refused_sign_in_or_teach_is_answered_and_not_kept_as_a_refusal():
    """Only the commands that change a bolt or a vehicle leave a refusal in the records."""
    d = _ready()
    acts = d.alone(CommandIn(d.t, 8, TeachStop(), NOBODY))
    assert not _answer(acts).answer.accepted
    assert not any(isinstance(a, RecordRefusal) for a in acts)


def test_a_case_slip_is_refused_in_words_that_say_what_was_meant():
    assert reason_words(Reason(Why.UNKNOWN_BOLT, bolt="b04", vin="VIN1", other="B04")) == \
        "b04 is not a bolt of vehicle VIN1 (did you mean B04?)"
    assert reason_words(Reason(Why.OTHER_VEHICLE, vin="vin1", other="VIN1",
                                              here="VIN1")) == \
        "vehicle vin1 is not the one at the station (did you mean VIN1?)"
    assert reason_words(Reason(Why.OTHER_VEHICLE, vin="VIN0", here="VIN1")) == (
        "vehicle VIN0 is not the one at the station (VIN1 is; if VIN0 has left the station, "
        "stationd reopen VIN0 opens it for rework)")
    assert reason_words(Reason(Why.OTHER_VEHICLE, vin="VIN0")) == (
        "vehicle VIN0 is not the one at the station (another is; if VIN0 has left the "
        "station, stationd reopen VIN0 opens it for rework)")
    assert reason_words(Reason(Why.UNKNOWN_BOLT, bolt="B9", vin="VIN1")) == \
        "B9 is not a bolt of vehicle VIN1"


def test_a_skip_without_a_vehicle_or_of_a_done_bolt_is_refused():
    core = StationCore()
    acts = core.feed(CommandIn(1.0, 1, SkipBolt("VIN1", "B1"), OPERATOR))
    assert _answer(acts).answer.reason == Reason(Why.NO_VEHICLE)
    d = _ready()
    d.core.matcher.mark_done("B1")
    acts = d.alone(CommandIn(d.t, 2, SkipBolt("VIN1", "B1"), OPERATOR))
    assert _answer(acts).answer.reason == Reason(Why.DONE, bolt="B1")


def test_a_command_the_database_refuses_is_answered_refused_and_has_no_effect():
    d = _ready()
    d.alone(CommandIn(d.t, 3, SkipBolt("VIN1", "B3"), OPERATOR))
    acts = d.alone(CommandDone(d.t, 3, Reason(Why.NOT_RECORDED, note="disk full")))
    assert _answer(acts).answer.reason == Reason(Why.NOT_RECORDED, note="disk full")
    assert "B3" not in d.core.matcher.skipped
    assert d.alone(CommandDone(d.t, 3)) == []      # answered once


def test_a_reopen_of_the_closed_vehicle_at_height_clears_its_fault_and_loads_it():
    core = StationCore(rework=False)
    core.feed(core_module.Started(1.0))
    core.feed(LiftRead(1.1, True, True, 7, "OLDVIN"))
    core.feed(VehicleRejected(1.2, "OLDVIN", "closed", closed=True))
    assert core.state is State.FAULT and "vehicle" in core.faults
    acts = core.feed(CommandIn(1.3, 4, ReopenVehicle("OLDVIN", "rework"), SUPERVISOR))
    assert [type(a).__name__ for a in acts] == ["RecordCommand"]
    acts = core.feed(CommandDone(1.4, 4))
    assert _answer(acts).answer.accepted and "vehicle" not in core.faults
    # what comes of it said with the answer ("accepted" alone: a supervisor's trial)
    assert answer_words(_answer(acts).answer).endswith(
        "accepted: it opens as a rework when it is at the station (its skips before no "
        "longer count)")
    reopened = [a.event for a in acts if isinstance(a, Publish)
                and isinstance(a.event, VehicleReopened)]
    assert reopened == [VehicleReopened("OLDVIN", "sam", t=1.4)]   # the screens say so
    acts = core.feed(LiftRead(1.5, True, True, 7, "OLDVIN"))
    assert [type(a).__name__ for a in acts if type(a).__name__ == "LoadVehicle"] \
        == ["LoadVehicle"]
    core.feed(VehicleLoaded(1.6, "OLDVIN", "M", BOLTS, rework=True))
    assert core.state is State.TRACKING


def test_a_command_for_a_vehicle_reopened_and_not_back_says_it_waits_for_it():
    """A skip right after a reopen, the vehicle not back at the station: the refusal says it
    is reopened and waits for it (a new user's trial: it told them to reopen it again)."""
    d = _ready()
    acts = d.alone(CommandIn(d.t, 4, ReopenVehicle("OLDVIN", "rework"), SUPERVISOR))
    acts = d.alone(CommandDone(d.t, 4))
    assert _answer(acts).answer.accepted
    acts = d.alone(CommandIn(d.t, 5, SkipBolt("OLDVIN", "B2"), SUPERVISOR))
    why = _answer(acts).answer.reason
    assert why == Reason(Why.OTHER_VEHICLE, vin="OLDVIN", reopened=True, here="VIN1")
    assert reason_words(why) == ("vehicle OLDVIN is not the one at the station: reopened for "
                                 "rework, it is worked when it is back at the station at "
                                 "height")
    # back at the station: open; another VIN keeps the plain words
    d.alone(VehicleLoaded(d.t, "OLDVIN", "M", BOLTS, rework=True))
    acts = d.alone(CommandIn(d.t, 6, SkipBolt("VIN1", "B2"), SUPERVISOR))
    assert _answer(acts).answer.reason == Reason(Why.OTHER_VEHICLE, vin="VIN1", here="OLDVIN")


def test_skips_recorded_before_a_reload_come_back_with_the_vehicle():
    d = _ready()
    d.alone(VehicleLoaded(d.t, "VIN1", "M", BOLTS, skipped={
        "B3": Skip(SkipKind.COMMAND, user="olga", comment="")}))
    _on(d, 3, 3)
    assert d.sends == []
