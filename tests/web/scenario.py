"""A realistic event sequence for the screens' tests, and a real results database."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from db.kinds import LOOSENED, LOOSENING, NOK, OK, PENDING, SKIPPED, BoltStatus
from db.repository import Repository
from stationd.boltfile import import_bolts
from stationd.reasons import Reason, Why
from stationd.station.events import (
    Because,
    BoltLocked,
    BoltsChanged,
    BoltSelected,
    BoltSkipped,
    BoltView,
    DeviceHealth,
    Localized,
    ParamsSent,
    Refused,
    ResultRecorded,
    State,
    StateChanged,
    StateReason,
    StationEvent,
    ToolEnabled,
    VehicleOpened,
)

VIN = "WVWZZZ1JZ3W386752"
BOLTS_YAML = """\
psets:
  - id: 1
    name: M10
    torque: {target: 50, min: 45, max: 55}
    angle: {target: 30, min: 15, max: 60}
models:
  SEDAN:
    code: 12
    bolts:
      - {id: B1, name: front left, position: [0, 0, 0], pset: 1}
      - {id: B2, name: front right, position: [400, 0, 0], pset: 1}
      - {id: B3, name: rear left, position: [0, 300, 0], pset: 1}
      - {id: B4, name: rear right, position: [400, 300, 0], pset: 1}
"""


#: the vehicle's bolts: name -> (x, y) mm, in the table's order
AT = {"B1": (0.0, 0.0), "B2": (400.0, 0.0), "B3": (0.0, 300.0), "B4": (400.0, 300.0)}


def bolt(name: str, status: BoltStatus = PENDING, **core: Any) -> BoltView:
    """Bolt ``name`` as a core would hold it: ``status`` and the ``core``'s other fields
    (``locked``, ``held``, ``ran``, ``last_nok``, ``check_first``, ``loosen_pset``)."""
    x, y = AT[name]
    return BoltView(name, x, y, 0.0, 1, order=list(AT).index(name) + 1, status=status, **core)


def changed(*bolts: BoltView) -> BoltsChanged:
    """The core's change of ``bolts`` (each as it holds it now)."""
    return BoltsChanged(VIN, bolts)


def ran(name: str, ok: bool, tid: int, **core: Any) -> list[StationEvent]:
    """A tightening of ``name`` as the screens hear it: the core's change (its status now:
    OK, or NOK and open again, ``core``: more of its fields), then the result recorded."""
    return [changed(bolt(name, OK if ok else NOK, ran=True, last_nok=not ok, **core)),
            result(name, ok, tid)]


def told(news: ResultRecorded | BoltSkipped, vehicle: VehicleOpened | None = None
         ) -> list[StationEvent]:
    """``news`` of a bolt of ``vehicle`` (the scenario's by default) as the screens hear it:
    the core's change of that bolt first (a rundown's status, or skipped), then the news."""
    bolts = {b.bolt: b for b in (vehicle.bolts if vehicle is not None
                                 else (bolt(b) for b in AT))}
    was = bolts[news.bolt]
    if isinstance(news, BoltSkipped):
        now = replace(was, status=SKIPPED)
    elif news.kind == LOOSENING:
        now = replace(was, status=LOOSENED if news.ok else BoltStatus.TO_LOOSEN, ran=True,
                      last_nok=not news.ok)
    else:
        now = replace(was, status=OK if news.ok else NOK, ran=True, last_nok=not news.ok)
    vin = vehicle.vin if vehicle is not None else VIN
    return [BoltsChanged(vin, (now,)), news]


def skipped(name: str, reason: str, **core: Any) -> list[StationEvent]:
    """A skip of ``name`` as the screens hear it: the core's change, then the news."""
    return [changed(bolt(name, SKIPPED, **core)), BoltSkipped(bolt=name, reason=reason)]


def locked(name: str, count: int, **core: Any) -> list[StationEvent]:
    """``name`` locked after ``count`` NOKs in a row, as the core says it (``core``: more of
    its fields; by default its last rundown a NOK)."""
    now = {"ran": True, "last_nok": True, **core}
    return [changed(bolt(name, NOK, locked=count, **now)), BoltLocked(name, count)]


def held(name: str, note: str, **core: Any) -> list[StationEvent]:
    """``name`` held (its result not known: ``note``), as the core says it."""
    return [changed(bolt(name, held=note, **core)), BoltLocked(name, 0, held=note)]


def opened() -> list[StationEvent]:
    bolts = tuple(bolt(b) for b in AT)
    return [
        DeviceHealth(device="lift", ok=True), DeviceHealth(device="wrench", ok=True),
        StateChanged(state=State.TRACKING, reason=StateReason(Because.TRACKING)),
        VehicleOpened(vin=VIN, model="SEDAN", bolts=bolts),
    ]


def result(bolt: str, ok: bool, tid: int) -> ResultRecorded:
    return ResultRecorded(vin=VIN, bolt=bolt, ok=ok, torque_nm=50.2 if ok else 41.0,
                          angle_deg=31.0, tightening_id=tid, pset=1, torque_min=45.0,
                          torque_max=55.0, angle_min=15.0, angle_max=60.0)


def work() -> list[StationEvent]:
    """B1 tightened OK, B2 NOK, the wrench on B3 selected and tightening."""
    out: list[StationEvent] = []
    for i, (name, x, ok) in enumerate([("B1", 0.0, True), ("B2", 400.0, False)]):
        out += [
            Localized(point_mm=(x + 1, 1.0, 0.0), tilt_deg=2.0, reason=None, candidate=name,
                      distance_mm=1.4, age_ms=40.0, allowed=(name,)),
            BoltSelected(bolt=name, pset=1, point_mm=(x + 1, 1.0, 0.0), distance_mm=1.4,
                         tilt_deg=2.0),
            ParamsSent(bolt=name, pset=1), ToolEnabled(bolt=name), *ran(name, ok, 100 + i),
        ]
    out += [
        Localized(point_mm=(2.0, 299.0, 0.0), tilt_deg=1.0, reason=None, candidate="B3",
                  distance_mm=2.2, age_ms=35.0, allowed=("B2", "B3", "B4")),
        BoltSelected(bolt="B3", pset=1, point_mm=(2.0, 299.0, 0.0), distance_mm=2.2,
                     tilt_deg=1.0),
        ParamsSent(bolt="B3", pset=1), ToolEnabled(bolt="B3"),
    ]
    return out


LIFT_DOWN = (("lift", "no answer from 10.0.0.7:502 for 2.0 s"),)
#: the station's reason while the lift is low (the lift's own words)
LIFT_LOW = StateReason(Because.LIFT_NOT_READY, note="lift not at working height")


def fault_state(*faults: tuple[str, str]) -> StateChanged:
    """The station in fault: each device in fault with its own words, as the core says it."""
    return StateChanged(state=State.FAULT, reason=StateReason(Because.FAULT, faults=faults))


def fault() -> list[StationEvent]:
    return [
        DeviceHealth(device="lift", ok=False, kind="timeout",
                     reason="no answer from 10.0.0.7:502 for 2.0 s"),
        fault_state(*LIFT_DOWN),
        Refused(reason=Reason(Why.DEVICE_FAULT, faults=LIFT_DOWN)),
    ]


def results_db(tmp: Path) -> Repository:
    """A real sqlite database with the vehicle's rundowns: B1 OK, B2 NOK then OK (rework)."""
    (tmp / "bolts.yaml").write_text(BOLTS_YAML)
    repo = Repository.open(f"sqlite:///{tmp / 'station.db'}")
    import_bolts(repo, tmp / "bolts.yaml")
    repo.start_vehicle(VIN, "SEDAN")
    kw: dict[str, Any] = {"position_mm": (1.0, 1.0, 0.0), "match_distance_mm": 1.4, "tilt_deg": 2.0,
          "angle_deg": 31.0}
    repo.record_tightening(VIN, "B1", ok=True, torque_nm=50.2, tightening_id=100, **kw)
    repo.record_tightening(VIN, "B2", ok=False, torque_nm=41.0, tightening_id=101, **kw)
    repo.record_tightening(VIN, "B2", ok=True, torque_nm=49.7, tightening_id=102,
                           images=[str(tmp / "img" / "B2-left.jpg")], **kw)
    return repo


def long_fault() -> list[StationEvent]:
    """A fault naming every device with the long reasons a real station gives (URLs with
    query strings): the headline must wrap, the devices panel must fit."""
    cams = "gige://192.168.10.21/?exposure_us=800&gain_db=0.0&trigger=software&packet_size=9000"
    faults = [
        ("lift", "timeout", "no answer from modbus-tcp://10.0.0.7:502/?unit=1&timeout_s=2.0 "
                            "for 2.0 s (PLC off, or not in RUN)"),
        ("wrench", "refused", "connection refused by open-protocol://10.0.0.9:4545/?rev=3"),
        ("pair1", "down", f"left camera {cams}: no frames for 3.0 s"),
        ("pair2", "down", f"right camera {cams.replace('.21', '.24')}: no frames for 3.0 s"),
    ]
    each = tuple((d, r) for d, _, r in faults)
    return [*(DeviceHealth(device=d, ok=False, kind=k, reason=r) for d, k, r in faults),
            fault_state(*each),
            Refused(reason=Reason(Why.DEVICE_FAULT, faults=each))]


def sim_vehicle() -> VehicleOpened:
    """config/sim's 50-bolt vehicle (close clusters: B41/B13, B3x/B39), as the daemon opens it."""
    import yaml

    doc = yaml.safe_load((Path(__file__).resolve().parents[2] / "config/sim/bolts.yaml")
                         .read_text())
    (model, spec), = doc["models"].items()
    bolts = tuple(BoltView(b["id"], b["position"][0], b["position"][1], b["position"][2],
                           b.get("pset")) for b in spec["bolts"])
    return VehicleOpened(vin="SIMVIN0000000001", model=model, bolts=bolts)
