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


def test_a_vehicle_of_an_unknown_model_code_is_refused_naming_it_and_the_codes(
        tmp_path: Path) -> None:
    """"unknown vehicle model code 99" named neither the vehicle on the lift nor the codes
    there are (a line engineer's trial)."""
    from stationd.station.inputs import VehicleRejected

    records = _records(tmp_path)
    refused = records.load_vehicle(LoadVehicle(99, "WVWZZZ1JZXW000001"))
    assert isinstance(refused, VehicleRejected)
    assert refused.reason.startswith("unknown vehicle model code 99 for WVWZZZ1JZXW000001 "
                                     "(the bolt tables' codes: ")
    assert " 12" in refused.reason          # the table's model and its code


def test_a_vehicle_that_left_unseen_with_bolts_not_ok_is_a_warning(tmp_path: Path,
                                                                   caplog) -> None:
    """The station was down as VIN1 left with a bolt tightened and the rest missing: closed
    as VIN2 loads, said at WARNING, as any close with a bolt not OK (an IT administrator's
    trial: "45 missing" at INFO, a journal read by priority missed it)."""
    import logging

    records = _records(tmp_path)
    assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    assert records.repo is not None
    record(records.repo, "VIN1", "B1", ok=True, tightening_id=1)
    with caplog.at_level(logging.INFO):
        assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN2")), VehicleLoaded)
    [line] = [r for r in caplog.records if "did not see it go" in r.getMessage()]
    assert line.levelno == logging.WARNING and "missing" in line.getMessage()
