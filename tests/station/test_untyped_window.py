"""An OK result without a result type (a controller revision that reports none) whose torque
lies outside its bolt's torque window, in the pure core: never taken as the bolt done (at such
a revision a batch increment reads as an OK of 0 Nm), but stored as a controller event, the
enable it answers settled, and the bolt held for a supervisor with a notice that says what
and where to look; released or its outcome entered, the bolt goes on as any held one."""

from __future__ import annotations

from dataclasses import replace
from datetime import datetime
from typing import Any

import pytest

from db.bolts import Parameters, Window
from db.kinds import NOT_TAKEN, not_taken_note
from drivers.keeper import FaultKind
from drivers.wrench import TorqueUnit
from stationd.reasons import Reason, Why
from stationd.station.actions import DisableTool, Record, StoreControllerEvent
from stationd.station.commands import EnterOutcome, ReleaseBolt
from stationd.station.events import (
    Because,
    BoltLocked,
    ControllerResultEvent,
    Notice,
    Said,
    State,
    StateReason,
    ToolDisabled,
)
from stationd.station.inputs import DeviceBack, DeviceFault, ResultIn, Tick, VehicleLoaded
from stationd.words import notice_words, reason_words
from tests.rundowns import rundown
from tests.station.test_commands import SUPERVISOR, _answer
from tests.station.test_core import BOLTS, Driver, _on, _ready, published
from tests.station.test_result_types import _enabled

#: the test bolts with their process parameters: B1 and B3 (pset 1) 20-25 Nm, B2 40-50 Nm
WINDOWED = {k: replace(b, parameters=Parameters(b.pset, Window(22.5, 20.0, 25.0)
                                                if b.pset == 1 else Window(45.0, 40.0, 50.0)))
            for k, b in BOLTS.items()}


def res(tid: int, pset: int, torque: float, ok: bool = True, code: int | None = None,
        unit: TorqueUnit | None = None, when: datetime | None = None) -> Any:
    return rundown(tid, pset, ok, code=code, torque_nm=torque, unit=unit,
                   when=when or datetime(2026, 11, 29, 8))


def _windowed() -> Driver:
    d = _ready()
    d.feed(VehicleLoaded(d.t, "VIN1", "M", WINDOWED))
    assert d.core.state is State.TRACKING
    return d


def _notices(acts: list[Any]) -> list[str]:
    return [notice_words(e) for e in published(acts, Notice)]


@pytest.mark.parametrize("torque", [0.0, 12.0, 25.5])
def test_an_untyped_ok_outside_the_torque_window_holds_the_bolt_and_closes_nothing(torque):
    d = _windowed()
    sent = _enabled(d)
    acts = d.feed(ResultIn(d.t, res(7, 1, torque)))
    assert not [a for a in acts if isinstance(a, Record)]
    [store] = [a for a in acts if isinstance(a, StoreControllerEvent)]
    assert (store.what, store.bolt, store.vin, store.selection) == (
        NOT_TAKEN, "B1", "VIN1", sent.selection)        # the enable settled with it
    [ev] = published(acts, ControllerResultEvent)
    assert (ev.result_type, ev.what, ev.bolt, ev.tightening_id) == (0, NOT_TAKEN, "B1", 7)
    assert any(isinstance(a, DisableTool) for a in acts) and not d.core.tool_on
    assert [e.reason for e in published(acts, ToolDisabled)] == [
        StateReason(Because.NOT_TAKEN, bolt="B1"), StateReason(Because.NOT_TAKEN_HELD, bolt="B1")]
    assert d.core.reason == StateReason(Because.NOT_TAKEN_HELD, bolt="B1")
    assert _notices(acts) == [
        f"B1: an OK result without a result type, {torque:.1f} Nm outside 20.0-25.0 Nm "
        "(tightening 7): not taken as a tightening; check it on the controller, then "
        "enter its outcome, or release it to tighten it again"]
    [said] = published(acts, Notice)
    assert (said.said, said.bolt, said.torque_nm, said.torque_min, said.torque_max,
            said.tightening_id, said.level) == (Said.NOT_TAKEN, "B1", torque, 20.0, 25.0, 7,
                                                "warning")
    [lock] = published(acts, BoltLocked)
    assert (lock.bolt, lock.held) == ("B1", not_taken_note(torque, 7))
    assert "B1" not in d.core.matcher.done and d.core.state is State.TRACKING
    # held: no new parameters for it, and the refusal says why in words
    sends = len(d.sends)
    _on(d, 1, 4)
    assert len(d.sends) == sends and "B1" not in d.core.allowed()
    refusal = d.core.matcher.update(d.core.matcher.bolts["B1"], 0.01).reason
    assert refusal == Reason(Why.HELD, bolt="B1", note=not_taken_note(torque, 7))
    assert reason_words(refusal) == (
        f"B1: an OK result without a result type, {torque:.1f} Nm outside the bolt's torque "
        "window (tightening 7): not taken as a tightening; check it on the controller, then "
        "enter its outcome, or release it to tighten it again")
    # the same result sent again: acknowledged once more, nothing else
    assert [type(a).__name__ for a in d.feed(ResultIn(d.t, res(7, 1, torque)))] == [
        "Acknowledge"]
    # a supervisor checked it (a batch increment there): released, the bolt is tightened
    acts = d.command(2, ReleaseBolt("VIN1", "B1", "a batch increment on the controller"),
                     SUPERVISOR)
    assert _answer(acts).answer.accepted
    sent = _enabled(d)
    acts = d.feed(ResultIn(d.t, res(8, sent.selection.pset or 0, 22.4)))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B1"]
    assert "B1" in d.core.matcher.done


@pytest.mark.parametrize("case", ["inside", "nok", "typed", "percent", "no window"])
def test_what_the_rule_does_not_touch_is_taken_as_before(case):
    """Inside the window (its limits included), a NOK (the NOK policy's), a result whose
    type says tightening (the controller owns its limits), a torque in percent of the tool
    (not Nm) and a bolt without parameters: recorded to the bolt as before."""
    d = _ready() if case == "no window" else _windowed()
    _enabled(d)
    torque, ok, code, unit = {"inside": (25.0, True, None, None),
                              "nok": (12.0, False, None, None),
                              "typed": (12.0, True, 1, None),
                              "percent": (80.0, True, None, TorqueUnit.PERCENT),
                              "no window": (0.0, True, None, None)}[case]
    acts = d.feed(ResultIn(d.t, res(7, 1, torque, ok, code, unit)))
    assert [a.bolt for a in acts if isinstance(a, Record)] == ["B1"]
    assert not [a for a in acts if isinstance(a, StoreControllerEvent)]
    assert not published(acts, BoltLocked)
    assert ("B1" in d.core.matcher.done) is ok


def test_a_late_untyped_ok_outside_the_window_is_not_taken_either():
    """The tool went off as the wrench left; the result within the late-result window."""
    d = _windowed()
    _enabled(d)
    _on(d, 0, 3)                                   # the wrench leaves: the tool goes off
    assert not d.core.tool_on
    acts = d.feed(ResultIn(d.t, res(7, 1, 0.0)))
    assert not [a for a in acts if isinstance(a, Record)]
    assert [(e.bolt, e.held) for e in published(acts, BoltLocked)] == [
        ("B1", not_taken_note(0.0, 7))]


def test_one_made_during_a_link_cut_and_fetched_after_it_is_held_not_recorded():
    d = _windowed()
    sent = _enabled(d)
    enabled_at = d.t
    d.t += 1.0
    d.feed(DeviceFault(d.t, "wrench", FaultKind.DOWN, "link lost"))
    d.t += 30.0
    d.feed(Tick(d.t))
    d.feed(DeviceBack(d.t, "wrench", reconnects=1))
    acts = d.feed(ResultIn(d.t, res(41, sent.selection.pset or 0, 3.0), fetched=True,
                           follows=40, made_at=enabled_at + 0.5))
    assert not [a for a in acts if isinstance(a, Record)]
    [store] = [a for a in acts if isinstance(a, StoreControllerEvent)]
    assert (store.what, store.bolt, store.selection) == (NOT_TAKEN, "B1", sent.selection)
    assert "B1" in d.core.matcher.held and "B1" not in d.core.matcher.done


def test_such_a_hold_comes_back_with_the_vehicle_and_an_entered_outcome_resolves_it():
    d = _ready()
    note = not_taken_note(0.0, 9)
    acts = d.feed(VehicleLoaded(d.t, "VIN1", "M", WINDOWED, held={"B2": note}))
    assert [(e.bolt, e.held) for e in published(acts, BoltLocked)] == [("B2", note)]
    assert "B2" not in d.core.allowed()
    acts = d.command(3, EnterOutcome("VIN1", "B2", True, 45.2, 31.0, "a tightening: OK on "
                                     "the controller's screen"), SUPERVISOR)
    assert _answer(acts).answer.accepted
    assert "B2" in d.core.matcher.done and "B2" not in d.core.matcher.held
    assert any(m.startswith("B2: OK 45.2 Nm, 31.0 deg entered by") and
               f"(the result not taken: {note})" in m for m in _notices(acts))


def test_an_untyped_ok_outside_the_window_after_its_vehicle_left_closes_nothing():
    """The lift went down with B1's tool on; an OK without a type at 0 Nm (a bypass or a
    batch increment at a revision without types) comes within the late-result window: not
    taken for B1 of the car that left either (a reviewer: its window was forgotten with the
    car, and it closed a bolt never tightened)."""
    d = _windowed()
    _enabled(d)
    d.step(("lift", 0.2, False, False, "VIN1"))
    assert d.core.vin is None
    d.t += 0.5
    acts = d.feed(ResultIn(d.t, res(41, 1, 0.0)))
    assert not [a for a in acts if isinstance(a, Record)]
    assert [(a.vin, a.bolt) for a in acts if isinstance(a, StoreControllerEvent)] == \
        [("VIN1", "B1")]
