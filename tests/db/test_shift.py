"""A shift's window (:mod:`db.shift`): which vehicles and commands belong to it."""

from __future__ import annotations

import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

from db.repository import Repository
from db.shift import shift
from stationd.boltfile import import_bolts
from tests.db.conftest import record


def _now() -> datetime:
    time.sleep(0.01)
    return datetime.now(UTC)


def test_a_shift_holds_the_vehicles_at_the_station_in_it_and_its_commands_alone(
        repo: Repository, bolts_file: Path) -> None:
    import_bolts(repo, bolts_file)
    repo.start_vehicle("BEFORE", "SEDAN")
    repo.close_vehicle("BEFORE")
    repo.start_vehicle("REWORKED", "SEDAN")
    repo.close_vehicle("REWORKED")
    repo.ledger.record_command(at=datetime.now(UTC), user="ann", source="cli", kind="skip",
                               vin="REWORKED", bolt="B2", comment="before the shift")
    since = _now()
    repo.reopen_vehicle("REWORKED", at=datetime.now(UTC), user="sam", source="cli",
                        comment="B2 to do")                  # reworked in the shift
    repo.start_vehicle("IN", "SEDAN")
    record(repo, "IN", "B1")
    repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli",
                               kind="sign-in", vin=None, bolt=None, comment="")
    until = _now()
    repo.ledger.record_command(at=datetime.now(UTC), user="eve", source="cli", kind="skip",
                               vin="IN", bolt="B2", comment="after the shift")
    done = shift(repo, since, until)
    assert [r.vehicle.vin for r in done.vehicles] == ["REWORKED", "IN"]
    # the reopen is the hand-over's; a sign-in and the commands outside the window are not
    assert [(c.kind, c.vin, c.user) for c in done.commands] == [("reopen", "REWORKED", "sam")]
    later = shift(repo, until + timedelta(hours=1), until + timedelta(hours=2))
    assert [r.vehicle.vin for r in later.vehicles] == ["REWORKED", "IN"]   # both still open
    assert later.commands == ()


def test_a_vehicle_that_left_before_a_shift_and_was_reopened_after_it_is_not_its_own(
        repo: Repository, bolts_file: Path) -> None:
    """Yesterday's hand-over, read today: a vehicle that left before that shift and was
    reopened for rework after it was listed in it (reopened, as if at the station then),
    and the shift's exit said something was open (a quality auditor's trial)."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("LEFT", "SEDAN")
    repo.close_vehicle("LEFT")
    since = _now()
    repo.start_vehicle("IN", "SEDAN")
    until = _now()
    _now()
    repo.reopen_vehicle("LEFT", at=datetime.now(UTC), user="sam", source="cli",
                        comment="B2 to do")                  # reworked after the shift
    done = shift(repo, since, until)
    assert [r.vehicle.vin for r in done.vehicles] == ["IN"]


def test_a_vehicle_the_station_reopened_as_a_rework_in_a_shift_is_its_own(
        repo: Repository, bolts_file: Path) -> None:
    """The station's rework rule reopens a closed VIN back at the lift by itself
    (``start_vehicle(reopen=True)``), with no reopen command: a vehicle that left before the
    shift and came back for rework in it, on the lift or gone again, was at the station."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("AGAIN", "SEDAN")
    repo.close_vehicle("AGAIN")
    repo.start_vehicle("GONE", "SEDAN")
    repo.close_vehicle("GONE")
    since = _now()
    repo.start_vehicle("GONE", "SEDAN", reopen=True)     # back at the lift: a rework
    record(repo, "GONE", "B1")
    repo.close_vehicle("GONE")
    repo.start_vehicle("AGAIN", "SEDAN", reopen=True)    # on the lift now
    until = _now()
    done = shift(repo, since, until)
    assert [r.vehicle.vin for r in done.vehicles] == ["AGAIN", "GONE"]
