"""Every write checks the SQLite file first (stationd/shell/records.py ``_writer``): a command,
a vehicle's opening, a gap or a hold written into a file removed under the daemon would be
answered "accepted" and be gone (an operator trial: ``stationd release`` answered accepted
with the file moved away; only the next result saw it)."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from db.errors import DbError
from stationd.station.actions import LoadVehicle, RecordCommand
from stationd.station.commands import Issuer, Right, SkipBolt
from stationd.station.inputs import VehicleLoaded
from tests.shell.test_records_words import _records


def _skip(bolt: str) -> RecordCommand:
    return RecordCommand(0, SkipBolt("VIN1", bolt, "no access"),
                         Issuer("sam", frozenset(Right), "cli"), time.time())


@pytest.mark.parametrize("how", ["removed", "replaced"])
def test_a_command_into_a_removed_or_replaced_file_is_not_taken(tmp_path: Path, how: str):
    records = _records(tmp_path)
    assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    assert records.record_command(_skip("B1"), "VIN1") is None        # the file there: taken
    moved = tmp_path / "elsewhere.db"
    os.rename(tmp_path / "st.db", moved)
    if how == "replaced":
        (tmp_path / "st.db").write_bytes(b"")
    with pytest.raises(DbError, match=f"was {how}"):
        records.record_command(_skip("B2"), "VIN1")
    with pytest.raises(DbError, match=f"was {how}"):
        records.record_gap(5, 7, "VIN1", "link cut")
    with pytest.raises(DbError, match=f"was {how}"):
        records.load_vehicle(LoadVehicle(12, "VIN2"))
    assert records.repo is not None
    records.repo.close()
    # nothing went into the file moved away after it left (its connection was still open)
    os.replace(moved, tmp_path / "st.db")
    again = _records(tmp_path)
    loaded = again.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(loaded, VehicleLoaded) and set(loaded.skipped) == {"B1"}
    assert again.repo is not None
    again.repo.close()


def test_a_lock_the_database_refused_is_recorded_when_it_is_back(tmp_path: Path):
    """A review: a NOK policy's lock that could not be written was only journaled, and a
    reload raising max_nok then ended it.  It is kept, written first by the database's way
    back (``probe``), and carried to the next station by a reload."""
    from stationd.station.actions import NoteLock

    records = _records(tmp_path)
    assert isinstance(records.load_vehicle(LoadVehicle(12, "VIN1")), VehicleLoaded)
    moved = tmp_path / "elsewhere.db"
    os.rename(tmp_path / "st.db", moved)
    lock = NoteLock("VIN1", "B1", 3, time.time())
    with pytest.raises(DbError, match="was removed"):
        records.note_lock(lock)
    assert records.locks_owed() == [lock]
    os.replace(moved, tmp_path / "st.db")            # the database back
    assert records.repo is not None
    records.probe(records.repo)
    assert records.locks_owed() == []
    loaded = records.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(loaded, VehicleLoaded) and loaded.locked == frozenset({"B1"})
    # a reload's next station takes over what this one still owed
    nxt = _records(tmp_path)
    nxt.carry([], [NoteLock("VIN1", "B2", 3, time.time())])
    assert nxt.repo is not None
    nxt.probe(nxt.repo)
    again = nxt.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(again, VehicleLoaded) and again.locked == frozenset({"B1", "B2"})
    records.repo.close()
    nxt.repo.close()
