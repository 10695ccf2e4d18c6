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
