"""What the shell stores for a typed reason of the core (stationd/shell/records.py): an
unattributed result's reason, a controller event's name and the station's idle sign-out's
comment are the words of the typed value, written as it stores them, byte for byte the text
the core wrote before (quality reads these columns; a report shows them)."""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path
from typing import Any

from db.kinds import NOT_TAKEN
from stationd.config import StationConfig
from stationd.reasons import Unattributed, UnattributedKind, Unproved, UnprovedKind
from stationd.shell.records import Records
from stationd.station.actions import (
    LoadVehicle,
    RecordCommand,
    StoreControllerEvent,
    StoreUnattributed,
)
from stationd.station.commands import Issuer, SignOut
from stationd.station.inputs import VehicleLoaded
from tests.db.conftest import BASE, url_of
from tests.rundowns import rundown


def _result(tid: int, code: int | None) -> Any:
    return rundown(tid, 3, code=code)


def _records(tmp_path: Path) -> Records:
    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BASE)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts))
    records.open()
    return records


def test_typed_reasons_are_stored_in_the_words_the_core_wrote(tmp_path: Path) -> None:
    records = _records(tmp_path)
    unproved = Unproved(UnprovedKind.VIN, vin="OTHER", sent_vin="VIN1")
    records.store_unattributed(StoreUnattributed(
        _result(41, 1), None, Unattributed(UnattributedKind.FETCHED, 41, 3, unproved)))
    records.store_unattributed(StoreUnattributed(
        _result(42, 2), None, Unattributed(UnattributedKind.OUTSIDE, 42, 3)))
    records.store_controller_event(StoreControllerEvent(_result(43, 3), None, None))
    records.store_controller_event(StoreControllerEvent(_result(44, 9), None, None))
    records.store_controller_event(StoreControllerEvent(_result(45, None), None, "B1",
                                                        NOT_TAKEN))
    why = records.record_command(RecordCommand(
        0, SignOut(user="olga", idle_s=600.0), Issuer("olga", frozenset(), "station (idle)"),
        time.time()), None)
    assert why is None
    assert records.repo is not None
    records.repo.close()
    with sqlite3.connect(tmp_path / "st.db") as con:
        reasons = [r for (r,) in con.execute("SELECT reason FROM unattributed_results "
                                             "ORDER BY id")]
        types = [t for (t,) in con.execute("SELECT result_type FROM unattributed_results "
                                           "ORDER BY id")]
        whats = [w for (w,) in con.execute("SELECT what FROM controller_events ORDER BY id")]
        comments = [c for (c,) in con.execute("SELECT comment FROM commands ORDER BY id")]
    assert reasons == ["result 41 (pset 3) fetched after a reconnect (VIN OTHER, not VIN1)",
                       "result 42 (pset 3) outside any tightening"]
    assert whats == ["batch increment", "result type 9 (unknown)", NOT_TAKEN]
    assert types == [1, 2]      # each its type as the controller sent it (2: a loosening)
    assert comments == ["idle for 600 s"]


def _reloaded_without_b2_b3(records: Records, tmp_path: Path,
                            runs: tuple[tuple[int, str, bool], ...]) -> None:
    """VIN2 at the station with ``runs`` (tightening id, bolt, OK) recorded, then the
    station's records opened again (a reload) on a table without SEDAN's B2 and B3."""
    assert records.repo is not None
    records.repo.start_vehicle("VIN2", "SEDAN")
    for tid, bolt, ok in runs:
        records.repo.record_tightening("VIN2", bolt, ok=ok, torque_nm=50.0, angle_deg=30.0,
                                       tightening_id=tid, position_mm=(0.0, 0.0, 0.0),
                                       match_distance_mm=1.0, tilt_deg=1.0)
    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BASE.split("      - id: B2")[0] + BASE.split("  WAGON:")[1].join(
        ["  WAGON:", ""]))
    records.repo.close()
    records.open()


def test_a_table_that_removes_bolts_and_a_vehicle_leaving_unfinished_are_warnings(
        tmp_path: Path, caplog: Any) -> None:
    """A bolt table cut short that still reads (30 of 50 bolts gone on a SIGHUP) and a
    vehicle leaving with bolts missing were INFO lines: a journal read by priority
    (``journalctl -p warning``) showed neither (an engineer's trial)."""
    records = _records(tmp_path)
    assert records.repo is not None
    records.repo.start_vehicle("VIN1", "SEDAN")
    caplog.set_level("INFO", logger="stationd.shell.records")
    records.close_vehicle("VIN1")
    # VIN2 at the station, B1 and B2 tightened OK
    _reloaded_without_b2_b3(records, tmp_path, ((7, "B1", True), (8, "B2", True)))
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert any(m.startswith("vehicle VIN1 (SEDAN) closed: ") and "3 missing" in m
               for m in warned), warned
    # the vehicle at the station too (a new user's trial read "on new vehicles" only)
    assert any("2 bolts removed (SEDAN/B2, SEDAN/B3): no longer tightened, on the vehicle "
               "at the station too" in m for m in warned), warned
    # opened again (a reload): its bolts now, and of them the done ones (B2's OK no more:
    # the trial read "49 bolts, 5 done" beside the status's 4/49)
    caplog.set_level("INFO", logger="stationd")
    loaded = records.load_vehicle(LoadVehicle(12, "VIN2"))
    assert isinstance(loaded, VehicleLoaded) and set(loaded.bolts) == {"B1"}
    said = [r.getMessage() for r in caplog.records if "VIN2 (SEDAN) opened" in r.getMessage()]
    assert said == ["vehicle VIN2 (SEDAN) opened: 1 bolts, 1 done"], said
    records.repo.close()


def test_a_removed_bolt_the_vehicle_at_the_station_ends_nok_or_holds_is_said(
        tmp_path: Path, caplog: Any) -> None:
    """A bolt locked after its NOKs removed from the table by a reload: the lock left the
    screen without a word while the vehicle's report still counted the bolt ending NOK (an
    engineer's trial).  Said, each such bolt, with what stays; one removed done is not."""
    records = _records(tmp_path)
    assert records.repo is not None
    caplog.set_level("INFO", logger="stationd.shell.records")
    _reloaded_without_b2_b3(records, tmp_path,
                            ((7, "B1", True), (8, "B2", True), (9, "B3", False)))
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert [m for m in warned if "not done" in m] == [
        "vehicle VIN2 at the station: removed from the table while not done: B3 ending NOK; "
        "the vehicle's report keeps each one's records and counts it, the station no more "
        "(put a bolt back to work it, or skip it with a reason before removing it)"], warned
    assert "B3" in records.repo.vehicle_report("VIN2").nok
    records.repo.close()


def test_a_reload_that_changes_or_adds_bolts_of_the_vehicle_at_the_station_says_so(
        tmp_path: Path, caplog: Any) -> None:
    """A reload mid-vehicle whose table changes a bolt not done yet (B2's torque window) and
    adds one (B4): the vehicle at the station goes on under the new table, its B2 tightened
    to the new window and B4 one more bolt to do ("opened: 4 bolts" where it had 3).  The
    journal said only "1 added, 1 changed" (a process engineer's trial), where a removal
    names the vehicle at the station.  Said, naming the vehicle and the bolts; a change of a
    bolt done already (B1, kept at its version) is not one the vehicle meets."""
    records = _records(tmp_path)
    assert records.repo is not None
    records.repo.start_vehicle("VIN2", "SEDAN")
    records.repo.record_tightening("VIN2", "B1", ok=True, torque_nm=50.0, angle_deg=30.0,
                                   tightening_id=7, position_mm=(0.0, 0.0, 0.0),
                                   match_distance_mm=1.0, tilt_deg=1.0)
    (tmp_path / "bolts.yaml").write_text(
        BASE.replace("target: 25, min: 23, max: 27", "target: 25, min: 24, max: 27")
        .replace("  WAGON:", "      - id: B4\n        name: four\n        position: "
                 "[300, 0, 0]\n        pset: 1\n  WAGON:"))
    records.repo.close()
    caplog.set_level("INFO", logger="stationd")
    records.open()
    said = [r.getMessage() for r in caplog.records if "VIN2" in r.getMessage()]
    assert any("B2" in m and "B4" in m for m in said), [r.getMessage()
                                                        for r in caplog.records]
    assert not any("B1" in m for m in said), said
    assert records.repo is not None
    records.repo.close()


def test_a_reload_that_changes_only_a_models_code_does_not_read_as_no_change(
        tmp_path: Path, caplog: Any) -> None:
    """A table whose model codes were swapped for the next model year (SEDAN's code 12 now
    another model's) changes which model the lift's code loads, but the journal's line read
    "0 added, 0 changed, 4 unchanged, 0 removed" (a process engineer's trial: the reload
    looked like a no-op; ``db import`` of the same file says "models changed: SEDAN")."""
    records = _records(tmp_path)
    assert records.repo is not None
    records.repo.close()
    (tmp_path / "bolts.yaml").write_text(BASE.replace("    code: 12\n", "    code: 13\n"))
    caplog.set_level("INFO", logger="stationd")
    records.open()
    said = [r.getMessage() for r in caplog.records if "bolt table" in r.getMessage()]
    assert any("SEDAN" in m for m in said), said
    assert records.repo is not None
    records.repo.close()


def test_a_reload_that_changes_bolts_of_the_vehicle_at_the_station_says_so_for_a_model_with_a_slash(
        tmp_path: Path, caplog: Any) -> None:
    """A model's name may hold a "/" (the bolt table's name rule: "SEDAN/MY27"): the
    import names its bolts "SEDAN/MY27/B2", which read as model "SEDAN", bolt "MY27/B2",
    and the vehicle at the station went on under the changed table without a word."""
    bolts = tmp_path / "bolts.yaml"
    table = BASE.replace("  SEDAN:\n", "  SEDAN/MY27:\n")
    bolts.write_text(table)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts))
    records.open()
    assert records.repo is not None
    records.repo.start_vehicle("VIN2", "SEDAN/MY27")
    bolts.write_text(table.replace("target: 25, min: 23, max: 27", "target: 25, min: 24, max: 27"))
    records.repo.close()
    caplog.set_level("INFO", logger="stationd")
    records.open()
    said = [r.getMessage() for r in caplog.records if "VIN2" in r.getMessage()]
    assert any("B2 changed" in m for m in said), [r.getMessage() for r in caplog.records]
    assert records.repo is not None
    records.repo.close()
