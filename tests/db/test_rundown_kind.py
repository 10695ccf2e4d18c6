"""Every rundown says tightening or loosening: in the database (migrated old records are
tightenings), the vehicle report (a bolt loosened last is not done), the NOK rows the policy
counts, the feed, the exports and the quality figures; the station's records write the kind
the core decided and what was sent for a loosening."""

from __future__ import annotations

import time
from datetime import UTC, datetime

import pytest
from sqlalchemy import create_engine

from db.errors import DataError
from db.kinds import LOOSENED, LOOSENING, NOK, OK, TIGHTENING, TO_LOOSEN
from db.repository import Repository
from stationd.station.actions import Record
from stationd.web.results import Results, rundowns_csv
from tests.db.conftest import b1_selected, old_record, record, url_of
from tests.rundowns import rundown


def _status(repo: Repository, bolt: str) -> tuple[str, str | None]:
    b = {b.bolt_id: b for b in repo.vehicle_report("VIN1").bolts}[bolt]
    return b.status, b.kind


def test_a_bolt_loosened_last_is_not_done_and_its_tightening_ends_that(sedan):
    record(sedan, "VIN1", "B1", ok=False, tightening_id=1)
    assert _status(sedan, "B1") == (NOK, TIGHTENING)
    record(sedan, "VIN1", "B1", ok=True, tightening_id=2, kind=LOOSENING)
    assert _status(sedan, "B1") == (LOOSENED, LOOSENING)
    for tid, b in ((10, "B2"), (11, "B3")):
        record(sedan, "VIN1", b, tightening_id=tid)
    report = sedan.vehicle_report("VIN1")
    assert not report.complete and report.loosen == ["B1"] and report.nok == []
    # a loosening is no tightening: 3 tightenings, the first NOK
    assert report.summary().endswith(", 1 to tighten again (B1); rundowns: 3 tightenings, "
                                     "1 NOK result, 1 loosening")
    assert report.to_json()["bolts"][0]["kind"] == LOOSENING
    record(sedan, "VIN1", "B1", ok=True, tightening_id=3)
    assert _status(sedan, "B1") == (OK, TIGHTENING) and sedan.vehicle_report("VIN1").complete
    record(sedan, "VIN1", "B1", ok=False, tightening_id=4, kind=LOOSENING)
    assert _status(sedan, "B1") == (NOK, LOOSENING)   # a joint that did not come loose


def test_a_loosen_command_after_the_last_rundown_reopens_the_bolt(sedan):
    record(sedan, "VIN1", "B1", tightening_id=1)
    sedan.ledger.record_command(at=datetime.now(UTC), user="lea",
                                source="cli", kind="loosen", vin="VIN1", bolt="B1",
                                comment="rework")
    assert _status(sedan, "B1") == (TO_LOOSEN, TIGHTENING)
    assert not sedan.vehicle_report("VIN1").complete
    record(sedan, "VIN1", "B1", tightening_id=2, kind=LOOSENING)
    assert _status(sedan, "B1")[0] == LOOSENED


def test_the_nok_row_counts_nok_loosenings_and_not_ok_ones(sedan):
    record(sedan, "VIN1", "B1", ok=False, tightening_id=1)
    record(sedan, "VIN1", "B1", ok=True, tightening_id=2, kind=LOOSENING)
    record(sedan, "VIN1", "B1", ok=False, tightening_id=3)
    assert sedan.nok_streaks("VIN1") == {"B1": 2}
    record(sedan, "VIN1", "B1", ok=False, tightening_id=4, kind=LOOSENING)
    assert sedan.nok_streaks("VIN1") == {"B1": 3}
    record(sedan, "VIN1", "B1", ok=True, tightening_id=5)
    assert sedan.nok_streaks("VIN1") == {}


def test_the_feed_the_exports_and_the_quality_figures_carry_the_kind(sedan):
    record(sedan, "VIN1", "B1", ok=True, tightening_id=1, torque_nm=50.0)
    record(sedan, "VIN1", "B1", ok=True, tightening_id=2, kind=LOOSENING, torque_nm=80.0,
           params_sent={"pset": 90, "torque": None, "angle": None, "loosen": True})
    record(sedan, "VIN1", "B1", ok=True, tightening_id=3, torque_nm=51.0)
    feed = sedan.ledger.since(0)
    assert [e["record"]["rundown"] for e in feed if e["kind"] == "rundown"] == [
        TIGHTENING, LOOSENING, TIGHTENING]
    # a loosening ran its loosen pset, judged by the controller's program: not the bolt's
    # tightening window (in the feed, and so in the line's tables, and in the export)
    first, loosening = (e["record"]["parameters"] for e in feed[:2])
    assert first["torque"] is not None and first["pset"] != 90
    assert loosening == {"version": first["version"], "pset": 90, "torque": None,
                         "angle": None}
    runs = Results(sedan).export("VIN1")
    assert [r["rundown"] for r in runs if r["bolt"] == "B1"] == [TIGHTENING, LOOSENING,
                                                                 TIGHTENING]
    assert runs[0]["torque_min_nm"] is not None and runs[2]["torque_min_nm"] is not None
    assert [runs[1][k] for k in ("pset", "torque_min_nm", "torque_max_nm", "angle_min_deg",
                                 "angle_max_deg")] == [90, None, None, None, None]
    csv = rundowns_csv(runs).splitlines()
    assert csv[0].startswith("vin,model,bolt,attempt,rundown,status,")
    assert csv[2].split(",")[4] == LOOSENING
    spc = sedan.spc("SEDAN")
    [b1] = [g for g in spc["bolts"] if g["bolt"] == "B1"]
    assert b1["torque"]["n"] == 2 and b1["torque"]["mean"] == pytest.approx(50.5)


def test_a_kind_that_is_not_a_rundown_is_refused(sedan):
    with pytest.raises(DataError, match="kind 'reverse'"):
        record(sedan, "VIN1", "B1", tightening_id=1, kind="reverse")


def test_records_before_the_migration_are_tightenings(tmp_path):
    url = url_of(tmp_path / "old.db")
    engine = create_engine(url)
    old_record(engine, "0007")
    engine.dispose()
    with Repository.open(url) as repo:
        [b1] = repo.vehicle_report("OLD").bolts
        assert (b1.status, b1.kind) == (OK, TIGHTENING)


def test_the_station_records_the_kind_and_the_loosen_pset_it_sent(tmp_path, bolts_file):
    _, records, repo, sel = b1_selected(tmp_path, bolts_file, 90, loosen=True)
    result = rundown(7, 90, torque_nm=40.0, angle_deg=-720.0)
    records.write(records.unsaved_result(
        Record("VIN1", "B1", result, sel, kind=LOOSENING, t=time.time()), None))
    [entry] = [e["record"] for e in repo.ledger.since(0) if e["kind"] == "rundown"]
    assert entry["rundown"] == LOOSENING
    assert entry["params_sent"] == {"pset": 90, "torque": None, "angle": None, "loosen": True}
    assert _status(repo, "B1") == (LOOSENED, LOOSENING)
    repo.close()
