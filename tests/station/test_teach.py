"""Teach mode in the pure core: only with the teach right, the normal cycle off (nothing is
sent, the tool goes off), a bolt end measured from steady frames exposed after the request,
refused when the wrench moved; stopping it brings the cycle back; a bolt that cannot be
measured (pairs in fault, no frames) is answered with why, within a bounded time."""

from __future__ import annotations

from typing import Any

import pytest

from drivers.keeper import FaultKind
from stationd.reasons import Reason, Why
from stationd.station.actions import DisableTool, Reply, SendParams
from stationd.station.commands import Issuer, Right, SkipBolt, TeachPoint, TeachStart, TeachStop
from stationd.station.events import Because, State, StateReason
from stationd.station.inputs import CommandDone, CommandIn, DeviceFault, LocalizedIn, Tick
from stationd.station.teaching import TEACH_FRAMES, TEACH_WAIT_S
from tests.station.test_commands import OPERATOR, _answer
from tests.station.test_core import _on, _ready

ENGINEER = Issuer("ed", frozenset({Right.TEACH}), "cli")


def _do(d: Any, request: int, command: Any, who: Issuer = ENGINEER) -> list[Any]:
    acts: list[Any] = d.alone(CommandIn(d.t, request, command, who))
    if any(type(a).__name__ == "RecordCommand" for a in acts):
        acts = d.alone(CommandDone(d.t, request))
    return acts


def _frames(d: Any, x: float, n: int, jitter: float = 0.05) -> list[Any]:
    acts: list[Any] = []
    for k in range(n):
        d.t += 0.1
        acts += d.alone(LocalizedIn(d.t, d.t - 0.05, (x + jitter * (k % 3), 0.0, 0.0)))
    return acts


def test_teach_mode_turns_the_cycle_off_and_measures_a_steady_bolt_end():
    d = _ready()
    _on(d, 2)
    assert d.core.state.value == "bolt selected"
    assert _answer(_do(d, 1, TeachStart("M"), OPERATOR)).answer.reason.kind is Why.NO_RIGHT
    acts = _do(d, 2, TeachStart("M"))
    assert _answer(acts).answer.accepted and d.core.state is State.TEACHING
    assert d.core.bolt is None                                   # the selection dropped
    assert [a.reason for a in acts if isinstance(a, DisableTool)] == \
        [StateReason(Because.TEACH_MODE)]
    assert d.core.reason == StateReason(Because.TEACHING, model="M", user="ed")
    assert _answer(_do(d, 3, SkipBolt("VIN1", "B1"), OPERATOR)).answer.reason == \
        Reason(Why.TEACHING, note="M", user="ed")                # other commands wait
    before = len(d.sends)
    _on(d, 1, 4)
    assert len(d.sends) == before                                # nothing is sent
    assert not any(isinstance(a, SendParams | Reply) for _, acts in d.log[-4:] for a in acts)
    acts = _do(d, 4, TeachPoint("B7"))
    assert not any(isinstance(a, Reply) for a in acts)           # answered once measured
    assert d.core.reason == StateReason(Because.TEACHING, model="M", user="ed", bolt="B7")
    assert _answer(_do(d, 6, TeachPoint("B8"))).answer.reason == \
        Reason(Why.TEACHING, note="M", user="ed", bolt="B7")   # one bolt at a time
    acts = _frames(d, 500.0, TEACH_FRAMES)
    [reply] = [a for a in acts if isinstance(a, Reply)]
    r = reply.answer.result
    assert reply.answer.accepted and r is not None
    assert r["position_mm"][0] == pytest.approx(500.05, abs=0.05) and r["dispersion_mm"] < 0.2
    assert d.core.reason == StateReason(Because.TEACHING, model="M", user="ed")
    acts = _do(d, 5, TeachStop())
    assert _answer(acts).answer.accepted
    # the vehicle at height works on at once, not "waiting for the lift" until its next read
    assert (d.core.state, d.core.reason) == (State.TRACKING,
                                             StateReason(Because.TEACH_ENDED_TRACKING))


def test_a_wrench_that_moves_while_measured_is_refused_and_frames_before_do_not_count():
    d = _ready()
    _do(d, 1, TeachStart("M"))
    _do(d, 2, TeachPoint("B7"))
    d.alone(LocalizedIn(d.t + 0.01, d.t - 1.0, (9999.0, 0.0, 0.0)))   # exposed before
    acts = _frames(d, 500.0, TEACH_FRAMES // 2) + _frames(d, 510.0, TEACH_FRAMES // 2)
    [reply] = [a for a in acts if isinstance(a, Reply)]
    assert reply.answer.reason is not None and reply.answer.reason.kind is Why.NOT_STEADY
    assert _answer(_do(d, 3, TeachStop())).answer.accepted
    assert _answer(_do(d, 4, TeachPoint("B7"))).answer.reason.kind is Why.NOT_TEACHING


def test_teach_mode_cannot_start_while_the_tool_is_on():
    d = _ready()
    _on(d, 2)
    d.step(("ack", 0.01, True))
    _on(d, 2, 1)
    assert d.tool
    assert _answer(_do(d, 1, TeachStart("M"))).answer.reason.kind is Why.TOOL_ON_BOLT
    assert not any(isinstance(a, DisableTool) for _, acts in d.log[-1:] for a in acts)


NO_WORLD = "no simulated world for pair 'pair1'"


def test_a_teach_point_with_pairs_in_fault_is_refused_with_the_stations_reason():
    """The cameras give no frames while their pairs are in fault: the point is refused at
    once with the faults (stationd teach said 'no daemon answers: timed out')."""
    from stationd.words import reason_words

    d = _ready()
    _do(d, 1, TeachStart("M"))
    d.alone(DeviceFault(d.t, "pair1", FaultKind.DOWN, NO_WORLD))
    reply = _answer(_do(d, 2, TeachPoint("B7")))
    assert reply.answer.reason is not None and reply.answer.reason.kind is Why.DEVICE_FAULT
    assert reason_words(reply.answer.reason) == f"a device is in fault: pair1: {NO_WORLD}"


def test_a_bolt_being_measured_is_answered_when_a_pair_faults():
    d = _ready()
    _do(d, 1, TeachStart("M"))
    assert not any(isinstance(a, Reply) for a in _do(d, 2, TeachPoint("B7")))
    _frames(d, 500.0, 2)
    acts = d.alone(DeviceFault(d.t, "pair1", FaultKind.DOWN, NO_WORLD))
    [reply] = [a for a in acts if isinstance(a, Reply)]
    assert reply.answer.reason is not None and reply.answer.reason.kind is Why.DEVICE_FAULT
    assert reply.answer.reason.faults == (("pair1", NO_WORLD),)
    assert _answer(_do(d, 3, TeachStop())).answer.accepted     # teach mode ends as usual


def test_a_bolt_without_frames_is_answered_within_the_wait_with_no_frames_or_not_steady():
    from stationd.words import reason_words

    d = _ready()
    _do(d, 1, TeachStart("M"))
    _do(d, 2, TeachPoint("B7"))
    asked = d.t
    assert not any(isinstance(a, Reply) for a in d.alone(Tick(asked + TEACH_WAIT_S - 0.5)))
    [reply] = [a for a in d.alone(Tick(asked + TEACH_WAIT_S)) if isinstance(a, Reply)]
    assert reply.answer.reason is not None and reply.answer.reason.kind is Why.NO_FRAMES
    assert reason_words(reply.answer.reason).startswith(
        f"no localization from the cameras in {TEACH_WAIT_S:g} s")
    d.t = asked + TEACH_WAIT_S + 1.0
    _do(d, 3, TeachPoint("B7"))                                 # again: a few frames only
    asked = d.t
    _frames(d, 500.0, 3)
    [reply] = [a for a in d.alone(Tick(asked + TEACH_WAIT_S)) if isinstance(a, Reply)]
    assert reply.answer.reason is not None and reply.answer.reason.kind is Why.NOT_STEADY
    assert (reply.answer.reason.count, reply.answer.reason.needed) == (3, TEACH_FRAMES)
    assert d.core.state is State.TEACHING


def test_a_teach_point_refused_while_the_cameras_give_no_wrench_names_what_they_said():
    """Issue 30, item 5: localizations that came without the wrench (a camera delivering no
    frame) made "not seen steadily (0 of 10 localizations)", which sent the engineer to hold
    the tool stiller; the refusal now says what the localizations said."""
    from stationd.reasons import Reason
    from stationd.words import reason_words

    d = _ready()
    _do(d, 1, TeachStart("M"))
    _do(d, 2, TeachPoint("B7"))
    asked = d.t
    silent = Reason(Why.NOT_LOCALIZED, per_pair=(("pair1", "left", "no frame for 120 s"),))
    for _ in range(5):
        d.t += 0.1
        d.alone(LocalizedIn(d.t, d.t - 0.05, None, reason=silent))
    [reply] = [a for a in d.alone(Tick(asked + TEACH_WAIT_S)) if isinstance(a, Reply)]
    why = reply.answer.reason
    assert why is not None and why.kind is Why.NOT_STEADY and why.count == 0
    assert reason_words(why) == (
        f"the wrench was not localized (5 localizations without it, none of the "
        f"{TEACH_FRAMES} needed): pair1: left: no frame for 120 s")


def test_teach_mode_ended_with_no_vehicle_at_height_waits_for_the_lift():
    d = _ready()
    _do(d, 1, TeachStart("M"))
    d.step(("lift", 0.1, False, False, None))     # the car lowered during teach mode
    _do(d, 2, TeachStop())
    assert (d.core.state, d.core.reason) == (State.WAITING_VEHICLE,
                                             StateReason(Because.TEACH_ENDED))
