"""A copy the controller sends again is decided before the core attributes it
(stationd/shell/records.py ``copy_input``, over a real SQLite database): result 7 of B1 was
stored and its acknowledgement lost, B2 (B1's pset) was enabled, a reload came, and the
controller sent 7 again.  The new core owed B2's enable and took the copy for B2's result:
B2 was done without being tightened (the station refused it as done), its enable was
settled, and the journal said "result 7 of B2 sent again".  Now the shell finds the copy
stored first (across vehicles where both sides have the controller's time), the core
attributes nothing, and the repository's own check (the last guard) settles no other bolt's
enable and names the stored record's bolt."""

from __future__ import annotations

import dataclasses
import time
from datetime import datetime
from pathlib import Path

import pytest
from sqlalchemy import select

from db.models import TighteningRecord
from drivers.wrench.base import Status, TighteningResult
from stationd.config import StationConfig
from stationd.shell.records import Records
from stationd.station.actions import LoadVehicle, Publish, Record, Selection
from stationd.station.core import StationCore
from stationd.station.events import Notice, Said
from stationd.station.inputs import ResultCopy, ResultIn, Started, VehicleLoaded
from stationd.station.matching import MatchParams
from tests.db.conftest import url_of

BOLTS = """\
psets:
  - id: 1
    torque: {target: 50, min: 45, max: 55}
    angle: {target: 30, min: 15, max: 60}
models:
  SEDAN:
    code: 12
    bolts:
      - id: B1
        name: one
        position: [0, 0, 0]
        pset: 1
      - id: B2
        name: two
        position: [100, 0, 0]
        pset: 1
"""
PARAMS = MatchParams(tolerance_mm=8.0, margin_mm=6.0, stable_frames=2, max_age_s=0.5)
AT = datetime(2026, 12, 1, 8, 0, 0)   # the controller's own (local) time of tightening 7


def _result(tid: int = 7, *, clock: bool = True) -> TighteningResult:
    return TighteningResult(True, 50.0, 30.0, Status.OK, Status.OK, tid, 1, "", AT, 45.0,
                            55.0, 50.0, 15.0, 60.0, 30.0, controller_clock=clock)


def _sel(bolt: str, vin: str = "VIN1") -> Selection:
    x = 0.0 if bolt == "B1" else 100.0
    return Selection(bolt, 1, (x, 0.0, 0.0), 1.0, 0.4, time.time(), time.time(), None, vin)


def _records(tmp_path: Path) -> Records:
    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BOLTS)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"),
                                    bolts_path=bolts))
    records.open()
    return records


def _stored_then_reloaded(tmp_path: Path) -> tuple[Records, StationCore, Selection]:
    """B1's result 7 stored (its acknowledgement lost), B2 enabled, then a reload: the new
    station's records and core, owing B2's enable (its selection), VIN1 loaded again."""
    first = _records(tmp_path)
    assert isinstance(first.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    b1 = _sel("B1")
    first.note_enable(b1)
    u = first.unsaved_result(Record("VIN1", "B1", _result(), b1, t=time.time()), None)
    first.write(u)
    assert not u.again
    first.note_enable(_sel("B2"))
    assert first.repo is not None
    first.repo.close()
    records = _records(tmp_path)        # the reload
    owed = records.owed(late_result_s=60.0)
    assert owed is not None and owed.selection.bolt == "B2"
    core = StationCore(PARAMS, leave_frames=2)
    core.resume(owed)
    core.feed(Started(time.time()))
    loaded = records.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(loaded, VehicleLoaded) and loaded.done == {"B1"}
    core.feed(loaded)
    return records, core, owed.selection


def test_a_copy_is_found_stored_before_the_core_and_never_closes_the_owed_bolt(
        tmp_path: Path) -> None:
    records, core, _ = _stored_then_reloaded(tmp_path)
    repo = records.repo
    assert repo is not None
    came = ResultIn(time.time(), _result())
    ev = records.copy_input(came, core.status().vin)
    assert ev == ResultCopy(ev.t, _result(), "VIN1", "B1", came)
    acts = core.feed(ev)
    assert [type(a).__name__ for a in acts] == ["Publish", "Acknowledge"]
    [n] = [a.event for a in acts if isinstance(a, Publish)]
    assert isinstance(n, Notice) and (n.said, n.bolt, n.vin) == (Said.SENT_AGAIN, "B1", None)
    assert "B2" not in core.status().done and "B2" in core.allowed()
    owed = repo.enables.owed()
    assert owed is not None and owed.bolt == "B2"        # still owed its own result
    # another result (the next id) is no copy: it goes to the core as it came
    other = ResultIn(time.time(), _result(8))
    assert records.copy_input(other, "VIN1") is other
    repo.close()


def test_the_repository_s_last_guard_settles_no_other_bolt_s_enable(tmp_path: Path) -> None:
    """The race the shell's check cannot close (the copy stored between the check and the
    write): the copy attributed to B2 is written as B2's; the database answers it is B1's
    result, writes nothing, and leaves B2's enable owed."""
    records, _, b2 = _stored_then_reloaded(tmp_path)
    repo = records.repo
    assert repo is not None
    owed = repo.enables.owed()
    assert owed is not None
    u = records.unsaved_result(Record("VIN1", "B2", _result(), b2, t=time.time()), None)
    assert u.enable_id == owed.id
    records.write(u)
    assert (u.again, u.stored_vin, u.stored_bolt) == (True, "VIN1", "B1")
    assert repo.enables.owed() is not None                # B2's enable not settled
    with repo.engine.connect() as c:
        assert len(c.execute(select(TighteningRecord.id)).all()) == 1
    repo.close()


def test_the_same_tightening_after_the_vehicle_changed_is_a_copy_not_the_next_ones_ok(
        tmp_path: Path) -> None:
    """The same id, values and controller time, resent after VIN1 left: a copy of VIN1's
    B1 (it was stored again as VIN2's B1, an OK of a bolt never tightened).  Without the
    controller's time (a controller without a clock) the values alone do not reach across
    vehicles (only to the one at the station and the one of the enable it owes): it is
    taken as a result, as before."""
    records, _, _ = _stored_then_reloaded(tmp_path)
    repo = records.repo
    assert repo is not None
    records.close_vehicle("VIN1")
    assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN2")), VehicleLoaded)
    ev = records.copy_input(ResultIn(time.time(), _result()), "VIN2")
    assert isinstance(ev, ResultCopy) and (ev.vin, ev.bolt) == ("VIN1", "B1")
    again = repo.record_tightening_once(
        "VIN2", "B1", ok=True, position_mm=(0.0, 0.0, 0.0), match_distance_mm=0.0,
        tilt_deg=0.0, torque_nm=50.0, angle_deg=30.0, tightening_id=7,
        controller_at=AT.astimezone())
    assert (again.again, again.vin, again.bolt) == (True, "VIN1", "B1")
    assert "B1" in repo.vehicle_report("VIN2").missing
    records.note_enable(_sel("B1", "VIN2"))   # VIN2's B1 enabled: no enable of VIN1 owed
    no_clock = ResultIn(time.time(), _result(clock=False))
    assert records.copy_input(no_clock, "VIN2") is no_clock
    repo.close()


def test_a_copy_of_a_result_stored_unattributed_is_no_owed_bolts_result(tmp_path: Path) -> None:
    """A result stored as no bolt's (made during a link cut on a bolt never selected), its
    acknowledgement lost, sent again after a reload while B2's enable is owed: a copy, said
    as no bolt's; B2 stays open, its enable owed.  A controller event the same, naming its
    bolt."""
    records, core, _ = _stored_then_reloaded(tmp_path)
    repo = records.repo
    assert repo is not None
    stored = repo.others.record_unattributed(
        vin="VIN1", controller_vin=None, tightening_id=9, pset=1, ok=True, torque_nm=50.0,
        angle_deg=30.0, result_at=AT.astimezone(), reason="made during a link cut")
    assert stored is not None
    came = ResultIn(time.time(), _result(9))
    ev = records.copy_input(came, core.status().vin)
    assert ev == ResultCopy(ev.t, _result(9), "VIN1", None, came)
    acts = core.feed(ev)
    [n] = [a.event for a in acts if isinstance(a, Publish)]
    assert isinstance(n, Notice) and (n.said, n.bolt) == (Said.SENT_AGAIN, None)
    assert "B2" not in core.status().done and "B2" in core.allowed()
    assert repo.enables.owed() is not None
    event = repo.others.record_controller_event(
        result_type=3, what="batch increment", vin="VIN1", bolt="B1", controller_vin=None,
        tightening_id=10, pset=1, ok=True, torque_nm=50.0, angle_deg=30.0,
        result_at=AT.astimezone())
    assert event is not None
    ev = records.copy_input(ResultIn(time.time(), _result(10)), "VIN1")
    assert isinstance(ev, ResultCopy) and (ev.vin, ev.bolt) == ("VIN1", "B1")
    # the same id and values at another controller time: another result, not a copy
    later = ResultIn(time.time(), dataclasses.replace(_result(9), timestamp=AT.replace(hour=9)))
    assert records.copy_input(later, "VIN1") is later
    repo.close()


def test_a_controller_event_copy_settles_no_other_bolt_s_enable(tmp_path: Path) -> None:
    """The repository's last guard for a controller event, as for a rundown: a copy of B1's
    event written against B2's owed enable writes nothing and leaves B2's enable owed."""
    records, _, _ = _stored_then_reloaded(tmp_path)
    repo = records.repo
    assert repo is not None
    owed = repo.enables.owed()
    assert owed is not None and owed.bolt == "B2"

    def event(bolt: str, enable_id: int | None) -> int | None:
        return repo.others.record_controller_event(
            result_type=3, what="batch increment", vin="VIN1", bolt=bolt, controller_vin=None,
            tightening_id=11, pset=1, ok=True, torque_nm=50.0, angle_deg=30.0,
            result_at=AT.astimezone(), enable_id=enable_id)

    assert event("B1", None) is not None
    assert event("B2", owed.id) is None                  # a copy of B1's: stored once
    assert repo.enables.owed() is not None                # B2's enable not settled
    repo.close()


def test_a_vehicle_the_station_did_not_see_leave_is_closed_as_the_next_one_loads(tmp_path,
                                                                               caplog):
    """The station killed while VIN1 was lowered: started again with VIN2 at height, VIN1 is
    closed (it stayed open for good) and the journal says so in the report's words."""
    first = _records(tmp_path)
    assert isinstance(first.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    assert first.repo is not None
    first.repo.close()                   # killed, VIN1 never closed
    records = _records(tmp_path)
    with caplog.at_level("INFO", logger="stationd"):
        assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN2")), VehicleLoaded)
    assert records.repo is not None
    assert records.repo.vehicle_report("VIN1").vehicle.ended_at is not None
    assert records.repo.vehicle_report("VIN2").vehicle.ended_at is None
    said = [r.getMessage() for r in caplog.records if "left while the station" in
            r.getMessage()]
    assert said == ["vehicle VIN1 (SEDAN) closed: it left while the station did not see it "
                    "go; bolts: 0 OK, 0 ending NOK, 0 skipped, 2 missing (B1, B2); rundowns: "
                    "0 tightenings, 0 NOK results"], said


def test_a_close_after_a_lift_outage_says_how_to_reopen(tmp_path: Path,
                                                         caplog: pytest.LogCaptureFixture
                                                         ) -> None:
    """The journal's close line, when the lift PLC's first read after an outage said the
    lift down: tied to the outage, with the command that reopens the vehicle."""
    import logging

    records = _records(tmp_path)
    assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    caplog.set_level(logging.INFO, logger="stationd")
    records.close_vehicle("VIN1", after_lift_outage=True)
    assert records.repo is not None
    records.repo.close()
    [line] = [r.getMessage() for r in caplog.records if "closed:" in r.getMessage()]
    assert "the lift PLC came back from an outage" in line
    assert line.endswith("if VIN1 is still on the lift, stationd reopen VIN1 --user NAME")
