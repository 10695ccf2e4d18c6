"""Each pair's trust on the screens (the devices panel, the cameras screen's pair health): the
view folds what the core publishes for the calibration check (``PairsUnchecked`` at a start
and a vehicle's arrival, ``PairChecked`` per check), so the screens say trusted, not checked
(why), or moved (the figure), and a pair that is up but moved reads as such."""

from __future__ import annotations

import json
from typing import Any

from stationd.station.actions import Publish
from stationd.station.events import (
    Because,
    DeviceHealth,
    PairsUnchecked,
    State,
    StateChanged,
    StateReason,
    StationEvent,
)
from stationd.station.inputs import Started
from stationd.station.trust import ReferencesChecked
from stationd.web.view import View, fold
from tests.station.test_trust import _core, _loaded, moved, ok

CONFIGURED = ("lift", "wrench", "pair1", "pair2")


def _published(acts: list[Any]) -> list[StationEvent]:
    return [a.event for a in acts if isinstance(a, Publish)]


def _view(events: list[StationEvent]) -> View:
    return fold([StateChanged(State.WAITING_VEHICLE, StateReason(Because.WAITING_LIFT)), *events],
                CONFIGURED)


def test_no_pair_is_trusted_after_a_start_until_checked_then_moved_shows_its_figure():
    core = _core()
    events = _published(core.feed(Started(1.0)))
    assert any(isinstance(e, PairsUnchecked) for e in events)
    v = _view(events)
    health = v.device_health()
    for p in ("pair1", "pair2"):
        assert health[p]["ok"] and health[p]["check"]["trusted"] is False
        assert health[p]["check"]["verdict"] == "not checked"
        assert health[p]["check"]["words"] == (f"{p} not checked against the references: not "
                                               "checked since the start")
    assert "check" not in health["lift"] and "check" not in health["wrench"]

    events += _published(core.feed(ReferencesChecked(2.0, (ok("pair1"), moved("pair2", 3.4)))))
    health = _view(events).device_health()
    assert health["pair1"]["check"] == {"trusted": True, "verdict": "ok", "words":
                                        "pair1 checked: reference R1 within 0.1 mm (<= 2 mm)"}
    assert health["pair2"]["check"] == {"trusted": False, "verdict": "moved", "words":
                                        "pair2 moved: reference R1 off by 3.4 mm (> 2 mm)"}
    # the snapshot the screens get (JSON as it is sent)
    doc = json.loads(json.dumps(_view(events).to_json()))
    assert doc["devices"]["pair2"]["check"]["verdict"] == "moved"


def test_a_vehicle_arriving_unchecks_the_pairs_but_a_moved_pair_stays_moved():
    core = _core()
    events = _published(core.feed(Started(1.0)))
    events += _published(core.feed(ReferencesChecked(2.0, (ok("pair1"), moved("pair2")))))
    arrival = _published(_loaded(core, 10.0))
    (unchecked,) = [e for e in arrival if isinstance(e, PairsUnchecked)]
    assert [r.pair for r in unchecked.reasons] == ["pair1"]   # pair2 stays moved
    events += arrival
    health = _view(events).device_health()
    assert health["pair1"]["check"]["words"] == ("pair1 not checked against the references: "
                                                 "checking for vehicle VIN1")
    assert health["pair2"]["check"]["verdict"] == "moved"
    # the arrival's check: pair2 put back meanwhile, both trusted again
    events += _published(core.feed(ReferencesChecked(13.0, (ok("pair1"), ok("pair2")))))
    health = _view(events).device_health()
    assert all(health[p]["check"]["trusted"] for p in ("pair1", "pair2"))


def test_a_pair_down_shows_its_fault_and_a_restart_forgets_the_last_checks():
    core = _core()
    events = _published(core.feed(Started(1.0)))
    events += _published(core.feed(ReferencesChecked(2.0, (ok("pair1"), moved("pair2")))))
    events.append(DeviceHealth(device="pair2", ok=False, kind="down", reason="no frames"))
    v = _view(events)
    assert v.device_health()["pair2"]["ok"] is False
    assert v.tone() == "stop"            # a device down is the station's fault, as before
    # a reload: the new station's checks, not the last one's
    v.apply(StateChanged(State.STARTING, StateReason(Because.OPENING)))
    assert all("check" not in h for h in v.device_health().values())
    # without references nothing is shown: no pair carries a check
    plain = fold([StateChanged(State.WAITING_VEHICLE, StateReason(Because.WAITING_LIFT)),
                  *_published(_core(trust=False).feed(Started(1.0)))], CONFIGURED)
    assert all("check" not in h for h in plain.device_health().values())


def test_a_moved_pair_is_not_a_station_fault_the_other_pairs_go_on():
    core = _core()
    events = _published(core.feed(Started(1.0)))
    events += _published(core.feed(ReferencesChecked(2.0, (ok("pair1"), moved("pair2")))))
    v = _view(events)
    assert v.tone() != "stop" and not v.headline().startswith("FAULT")
