"""The vehicles' list (``Results.vehicles``): a vehicle reopened for rework and not back at
the station yet says so, not "open, reworked" as the vehicle on the lift (an operator
trial)."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

from stationd.web.results import Results
from tests.web.scenario import VIN, results_db


def test_a_reopened_vehicle_not_back_yet_is_reopened_not_open(tmp_path: Path) -> None:
    repo = results_db(tmp_path)
    try:
        results = Results(repo)
        assert [v["status"] for v in results.vehicles()] == ["open"]     # on the lift
        repo.close_vehicle(VIN)
        assert [v["status"] for v in results.vehicles()] == ["incomplete"]
        repo.reopen_vehicle(VIN, at=datetime.now(UTC), user="sam", source="cli", comment="")
        [v] = results.vehicles()
        assert v["status"] == "reopened" and v["reopened_at"] is not None
        repo.start_vehicle(VIN, "SEDAN", reopen=True)                   # back at the station
        assert [v["status"] for v in results.vehicles()] == ["open"]
    finally:
        repo.close()


def test_the_list_counts_a_vehicle_s_held_bolts_as_its_page_does(tmp_path: Path) -> None:
    """A supervisor's trial: the list had no word of a bolt held for a person (its result
    could not be read), which the vehicle's page says; now each row has its held bolts, read
    only for the vehicles that have a record that may hold one."""
    repo = results_db(tmp_path)
    try:
        repo.start_vehicle("VIN2", "SEDAN")             # no hold: its row says none
        repo.others.record_unreadable(mid=61, revision=7, raw="00230061007 garbled", error="short",
                                      vin=VIN, bolt="B3", controller_vin=None, tightening_id=7,
                                      pset=1, result_at=None)
        assert repo.may_hold([VIN, "VIN2"]) == {VIN}
        results = Results(repo)
        rows = {v["vin"]: v for v in results.vehicles()}
        assert rows[VIN]["held"] == repo.vehicle_report(VIN, held=True).to_json()["held"]
        assert list(rows[VIN]["held"]) == ["B3"] and rows["VIN2"]["held"] == {}
        # released: no longer held, in the list as on the page
        repo.ledger.record_command(at=datetime.now(UTC), user="sue", source="cli",
                                   kind="release", vin=VIN, bolt="B3", comment="")
        assert {v["vin"]: v["held"] for v in results.vehicles()}[VIN] == {}
    finally:
        repo.close()
