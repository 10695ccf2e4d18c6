"""The journal lines the shell writes for the core's events (stationd/shell/effects.py
``Effects.publish``), fed by the real core: the station's fault line is written when the
faulty devices change, not again at each new reason of one of them (a reconnect's retries
changed the reason three times in half a second, and the journal said "state: fault (lift,
wrench)" three times; each device's own line says its reason)."""

from __future__ import annotations

import logging
from typing import Any

from drivers.keeper import FaultKind
from stationd.bus import EventBus
from stationd.shell.effects import Effects
from stationd.shell.sdnotify import Notifier
from stationd.station.actions import Publish
from stationd.station.core import StationCore
from stationd.station.inputs import (
    DeviceBack,
    DeviceFault,
    LiftRead,
    ParamsRefused,
    Started,
    VehicleLoaded,
)
from tests.rundowns import rundown
from tests.station.test_core import BOLTS, PARAMS


def _effects(core: StationCore) -> Effects:
    none: Any = None    # publishing a core's event needs no device, record or call
    return Effects(core, none, none, none, EventBus(), Notifier({}), none, none)


def test_the_fault_line_is_written_when_the_faulty_devices_change_only(caplog):
    core = StationCore(PARAMS)
    effects = _effects(core)
    inputs = [Started(1.0),
              DeviceFault(2.0, "lift", FaultKind.DOWN, "connection refused"),
              DeviceFault(2.1, "wrench", FaultKind.DOWN, "connection refused"),
              DeviceFault(2.2, "wrench", FaultKind.TIMEOUT, "reconnect: timed out"),
              DeviceFault(2.3, "lift", FaultKind.DOWN, "reconnect: connection refused"),
              DeviceBack(3.0, "lift"),
              DeviceFault(4.0, "lift", FaultKind.DOWN, "connection refused")]
    with caplog.at_level(logging.INFO, logger="stationd"):
        for ev in inputs:
            for a in core.feed(ev):
                if isinstance(a, Publish):
                    effects.publish(a.event)
    said = [r.getMessage() for r in caplog.records if r.getMessage().startswith("state: ")]
    assert said == ["state: fault (lift)", "state: fault (lift, wrench)",
                    "state: fault (wrench)", "state: fault (lift, wrench)"], said
    # each device's own line still says every new reason
    devices = [r.getMessage() for r in caplog.records if r.getMessage().startswith("fault: ")]
    assert "fault: wrench (timeout): reconnect: timed out" in devices
    assert "fault: lift (down): reconnect: connection refused" in devices


def test_a_notice_goes_to_the_journal_at_its_own_level(caplog):
    """A result not stored is an error in the journal (it went as info), a lock a warning."""
    from stationd.station.events import Notice, Said

    effects = _effects(StationCore(PARAMS))
    with caplog.at_level(logging.INFO, logger="stationd"):
        effects.publish(Notice(Said.NOT_STORED, bolt="B05", tightening_id=12, note="disk full"))
        effects.publish(Notice(Said.LOCKED, bolt="B05", count=3))
        effects.publish(Notice(Said.LOOSENED, bolt="B05"))
    assert [(r.levelname, r.getMessage()[:28]) for r in caplog.records] == [
        ("ERROR", "tightening 12 of B05 not sto"), ("WARNING", "B05 locked after 3 NOK in a "),
        ("INFO", "B05 loosened: its tightening")]


def test_what_the_core_decided_typed_is_published_in_words(caplog):
    """A refused parameter set: the core decides the skip and its own fault typed and says
    no words; the publication writes them, so the bus (the screens, OPC UA) and the journal
    read what they read when the core wrote the text."""
    from stationd.station.events import BoltSkipped, DeviceHealth

    core = StationCore(PARAMS)
    effects = _effects(core)
    inputs = [Started(1.0), LiftRead(1.1, True, True, 7, "VIN1"),
              VehicleLoaded(1.2, "VIN1", "M", BOLTS), ParamsRefused(1.3, "B1", "pset unknown")]
    with caplog.at_level(logging.INFO, logger="stationd"):
        for ev in inputs:
            for a in core.feed(ev):
                if isinstance(a, Publish):
                    effects.publish(a.event)
    assert [(e.bolt, e.reason) for e in effects.bus.of(BoltSkipped)] == [
        ("B1", "controller refused its parameters (pset unknown)")]
    assert [(e.device, e.reason) for e in effects.bus.of(DeviceHealth)] == [
        ("wrench", "controller refused the parameters for B1: pset unknown")]
    assert "fault: wrench (refused): controller refused the parameters for B1: pset unknown" \
        in [r.getMessage() for r in caplog.records]


def test_a_controller_event_is_published_and_said_by_its_type_s_name(caplog):
    """A batch increment: the core publishes its type code and no name; the bus and the
    journal read the name the core wrote before ("batch increment")."""

    from stationd.station.events import ControllerResultEvent
    from stationd.station.inputs import ResultIn

    core = StationCore(PARAMS)
    effects = _effects(core)
    result = rundown(3, 1, code=3, torque_nm=0.0, angle_deg=0.0)
    with caplog.at_level(logging.INFO, logger="stationd"):
        for ev in (Started(1.0), ResultIn(1.1, result)):
            for a in core.feed(ev):
                if isinstance(a, Publish):
                    effects.publish(a.event)
    assert [(e.result_type, e.what) for e in effects.bus.of(ControllerResultEvent)] == [
        (3, "batch increment")]
    assert "batch increment on the controller: not a tightening" in \
        [r.getMessage() for r in caplog.records]


def test_a_pair_being_checked_for_a_vehicle_is_info_a_pair_moved_a_warning(caplog):
    """Every vehicle's arrival journaled a WARNING "front not checked against the references:
    checking for vehicle ..." (a line engineer read routine work as a problem)."""
    from stationd.reasons import Reason, Unchecked, UncheckedKind, Why
    from stationd.station.events import PairChecked

    def unchecked(kind: UncheckedKind, **kw: Any) -> PairChecked:
        return PairChecked("front", "not checked", why=Reason(
            Why.PAIR_UNCHECKED, pair="front", unchecked=Unchecked(kind, **kw)))

    effects = _effects(StationCore(PARAMS))
    with caplog.at_level(logging.INFO, logger="stationd"):
        effects.publish(unchecked(UncheckedKind.ARRIVAL, vin="VIN1"))
        effects.publish(unchecked(UncheckedKind.SINCE_START))
        effects.publish(unchecked(UncheckedKind.NOT_MEASURED, reference="R1",
                                  measure="not found"))
        effects.publish(PairChecked("front", "moved", "R1", 5.5, 2.0, {"R1": 5.5},
                                    why=Reason(Why.PAIR_MOVED, pair="front")))
        effects.publish(PairChecked("front", "ok", "R1", 0.1, 2.0, {"R1": 0.1}, trusted=True))
    assert [r.levelname for r in caplog.records] == ["INFO", "INFO", "WARNING", "WARNING",
                                                     "INFO"], [
        (r.levelname, r.getMessage()) for r in caplog.records]
