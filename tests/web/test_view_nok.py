"""The NOK policy on the operator screen's view model: a locked bolt is its own state with the
station's words, the refusal on it is one the operator acts on, a release unlocks it (to be
loosened first again when it was); the loosen step says its loosen pset, never "tighten"; the
screens' snapshot names the roles that may release."""

from __future__ import annotations

import json

from stationd.access import AccessConfig
from stationd.bus import EventBus
from stationd.reasons import Reason, Why
from stationd.station.commands import Right
from stationd.station.events import (
    BoltLocked,
    BoltReleased,
    BoltSelected,
    BoltToLoosen,
    Localized,
    ParamsSent,
    Refused,
    ResultRecorded,
    StationEvent,
    ToolEnabled,
    VehicleClosed,
)
from stationd.web.server import WebServer
from stationd.web.view import View, fold
from tests.web.scenario import VIN, opened, result

LOCKED = "B2 locked after 3 NOK in a row: a supervisor releases it"


def _loosen(bolt: str = "B2", pset: int = 90) -> BoltToLoosen:
    return BoltToLoosen(bolt, Reason(Why.LOOSEN_FIRST, bolt=bolt, pset=pset))


def _loosening(bolt: str, ok: bool, tid: int) -> ResultRecorded:
    r = result(bolt, ok, tid)
    return ResultRecorded(**{**r.__dict__, "kind": "loosening"})


def _on(bolt: str, x: float, *, loosen_pset: int | None = None) -> list[StationEvent]:
    """The wrench on ``bolt`` at ``x``: selected (with its loosen pset), the tool on."""
    pset = loosen_pset if loosen_pset is not None else 1
    return [Localized(point_mm=(x, 0.0, 0.0), tilt_deg=1.0, reason=None, candidate=bolt,
                      distance_mm=1.0, age_ms=30.0, allowed=(bolt,)),
            BoltSelected(bolt=bolt, pset=pset, point_mm=(x, 0.0, 0.0), distance_mm=1.0,
                         tilt_deg=1.0, loosen=loosen_pset is not None),
            ParamsSent(bolt=bolt, pset=pset), ToolEnabled(bolt=bolt)]


def _locked() -> View:
    """B2: NOK, loosened NOK twice: locked, the wrench still near it."""
    return fold([*opened(), *_on("B2", 400.0), result("B2", False, 1), _loosen(),
                 *_on("B2", 400.0, loosen_pset=90), _loosening("B2", False, 2), _loosen(),
                 *_on("B2", 400.0, loosen_pset=90), _loosening("B2", False, 3),
                 BoltLocked("B2", 3)])


def test_the_loosen_step_shows_its_loosen_pset_and_never_says_tighten():
    v = fold([*opened(), *_on("B2", 400.0), result("B2", False, 1), _loosen()])
    b2 = v.bolts["B2"].to_json()
    assert (b2["state"], b2["label"], b2["loosen_pset"]) == ("loosen", "loosen first", 90)
    assert b2["reason"] == "B2: loosen first (loosen pset 90), then tighten"
    v = fold([*opened(), *_on("B2", 400.0), result("B2", False, 1), _loosen(),
              *_on("B2", 400.0, loosen_pset=90)])
    assert v.headline() == "B2: loosen first (loosen pset 90)" and v.tone() == "go"
    assert v.bolts["B2"].to_json()["label"] == "loosen"   # the tool on for its loosen pset
    v.apply(_loosening("B2", True, 2))
    assert v.bolts["B2"].state == "loosened" and not v.bolts["B2"].loosen
    v.apply(BoltSelected(bolt="B2", pset=1, point_mm=(400.0, 0.0, 0.0), distance_mm=1.0,
                         tilt_deg=1.0))
    assert v.headline() == "B2 (pset 1): tighten"


def test_a_locked_bolt_says_so_until_released_then_it_is_loosened_first():
    v = _locked()
    b2 = v.bolts["B2"]
    assert (b2.state, b2.locked, b2.reason) == ("locked", True, LOCKED)
    assert v.locks() == [LOCKED] and v.to_json()["locks"] == [LOCKED]
    assert v.counters()["nok"] == 1   # its last rundown a NOK
    # the wrench on it: refused with the reason, amber (the operator calls a supervisor)
    v.apply(Refused(Reason(Why.LOCKED, bolt="B2", count=3), "B2"))
    assert v.headline() == LOCKED and v.tone() == "act"
    # frames that allow other bolts leave it locked
    v.apply(Localized(point_mm=(0.0, 0.0, 0.0), tilt_deg=1.0, reason=None, candidate="B1",
                      distance_mm=1.0, age_ms=30.0, allowed=("B1",)))
    assert v.bolts["B2"].state == "locked"
    v.apply(BoltReleased("B2", "sam"))
    v.apply(_loosen())   # the core: released, still to be loosened first
    assert (v.bolts["B2"].state, v.bolts["B2"].locked) == ("loosen", False)
    assert v.locks() == []


def test_a_vehicle_that_leaves_with_a_locked_bolt_shows_it_nok():
    v = _locked()
    v.apply(VehicleClosed(VIN, ("B1", "B3", "B4"), ("B2",)))
    assert v.bolts["B2"].state == "nok" and v.locks() == []


def test_the_snapshot_names_the_roles_that_may_release():
    server = WebServer(EventBus(), listen="127.0.0.1:0")
    assert server.release_by() == []           # no station running: nobody configured
    server.commands.access = AccessConfig()    # the default roles
    assert server.release_by() == ["supervisor"]
    server.commands.access = AccessConfig(roles={
        "operator": frozenset({Right.SKIP}), "lead": frozenset({Right.RELEASE}),
        "quality": frozenset({Right.RELEASE, Right.LOOSEN})})
    assert server.release_by() == ["lead", "quality"]
    doc = json.loads(server._encode()[len(b"data: "):])
    assert doc["release_by"] == ["lead", "quality"] and doc["locks"] == []
