"""What the shell loads with a vehicle (a restart, a reload), against a real SQLite database:
the bolts whose last rundown is a NOK loosening (its loosen pset goes again)."""

from __future__ import annotations

from pathlib import Path

from stationd.station.actions import LoadVehicle
from stationd.station.inputs import VehicleLoaded
from tests.db.conftest import record
from tests.shell.test_records_copies import _records


def test_a_nok_loosening_is_loaded_as_one(tmp_path: Path) -> None:
    records = _records(tmp_path)
    assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    assert records.repo is not None
    record(records.repo, "VIN1", "B1", ok=True, tightening_id=1)
    record(records.repo, "VIN1", "B1", ok=False, kind="loosening", tightening_id=2)
    record(records.repo, "VIN1", "B2", ok=False, tightening_id=3)    # a NOK tightening
    records.repo.close()
    again = _records(tmp_path)
    loaded = again.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(loaded, VehicleLoaded)
    assert loaded.status == {"B1": "nok", "B2": "nok"}
    assert loaded.loosen_nok == frozenset({"B1"})
