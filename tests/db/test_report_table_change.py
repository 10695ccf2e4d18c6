"""A vehicle that left the station keeps the report it left with when the engineer changes
the model's bolt table afterwards (a new model year: bolts added, bolts removed).  A process
engineer's and a shift supervisor's trial: a vehicle that left with B2 never tightened read
complete (``db report`` exit 0, the vehicles list "complete") once B2 was taken out of the
table for the next model year; a vehicle that left with every bolt OK read incomplete, a
bolt it never had "missing", once a bolt was added."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

from db.repository import Repository
from stationd.boltfile import import_bolts
from tests.db.conftest import BASE, record

B2 = ("      - id: B2\n        name: two\n        position: [100, 0, 0]\n"
      "        torque: {target: 25, min: 23, max: 27}\n"
      "        angle: {target: 30, min: 10, max: 50}\n")
B4 = ("      - id: B4\n        name: four\n        position: [300, 0, 0]\n"
      "        pset: 1\n")


def test_a_vehicle_that_left_with_a_bolt_missing_stays_incomplete_when_it_is_removed(
        repo: Repository, bolts_file: Path) -> None:
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    record(repo, "VIN1", "B1")
    record(repo, "VIN1", "B3")
    left = repo.close_vehicle("VIN1")
    assert left.missing == ["B2"] and not left.complete
    bolts_file.write_text(BASE.replace(B2, ""))      # the next model year has no B2
    assert import_bolts(repo, bolts_file).removed == ["SEDAN/B2"]
    report = repo.vehicle_report("VIN1")
    assert report.missing == ["B2"], [(b.bolt_id, b.status) for b in report.bolts]
    assert not report.complete


def test_a_vehicle_that_left_complete_stays_complete_when_a_bolt_is_added(
        repo: Repository, bolts_file: Path) -> None:
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    for bolt in ("B1", "B2", "B3"):
        record(repo, "VIN1", bolt)
    assert repo.close_vehicle("VIN1").complete
    bolts_file.write_text(BASE.replace("  WAGON:", B4 + "  WAGON:"))   # B4 for new vehicles
    assert import_bolts(repo, bolts_file).added == ["SEDAN/B4"]
    report = repo.vehicle_report("VIN1")
    assert report.complete, [(b.bolt_id, b.status) for b in report.bolts]
    assert "B4" not in [b.bolt_id for b in report.bolts]


def test_a_vehicle_whose_model_was_renamed_under_it_does_not_leave_complete(
        repo: Repository, bolts_file: Path) -> None:
    """A reload renames the model for the next model year (SEDAN -> SEDAN-MY27, the same
    code) while a SEDAN is on the lift with one bolt of three tightened: the station cannot
    open it again ("already known as model SEDAN"), the lift goes down, and it was closed
    "bolts: 1 OK, 0 ending NOK, 0 skipped, 0 missing" at INFO: complete, ``db report`` exit
    0, the vehicles list "complete" (a process engineer's trial, 49 of 50 bolts never
    tightened)."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN2", "SEDAN")
    record(repo, "VIN2", "B1")
    bolts_file.write_text(BASE.replace("  SEDAN:\n", "  SEDAN-MY27:\n"))
    assert "SEDAN" in import_bolts(repo, bolts_file).models_removed
    left = repo.close_vehicle("VIN2")
    assert not left.complete and left.missing == ["B2", "B3"], left.counts()


def test_a_table_imported_by_hand_under_the_running_station_does_not_refuse_its_results(
        repo: Repository, bolts_file: Path, tmp_path: Path) -> None:
    """``db import`` by hand into the running daemon's database (the README: it "lasts until"
    the next reload; the command warns of that and imports) removed bolts the station still
    worked from its table in memory: the next tightening of one was refused by the database
    ("bolt 'B34' is not a bolt of model ..."), the station stayed in a database fault, the
    tool off, until a reload (a process engineer's trial).  The result of a bolt the station
    sent parameters for is stored."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    b2 = repo.bolts_for_model("SEDAN")[1]        # the daemon's table in memory
    assert b2.bolt_id == "B2"
    cut = tmp_path / "cut.yaml"
    cut.write_text(BASE.replace(B2, ""))
    url = repo.engine.url.render_as_string(hide_password=False)
    with Repository.open(url) as by_hand:         # stationd db import cut.yaml --config ...
        assert import_bolts(by_hand, cut).removed == ["SEDAN/B2"]
    enable = repo.enables.note("VIN1", "B2", 2, b2.parameters_id, {}, datetime.now(UTC))
    record(repo, "VIN1", "B2", parameters_id=b2.parameters_id, enable_id=enable)
    assert repo.vehicle_report("VIN1").ok == ["B2"]


def test_a_vehicle_whose_model_was_renamed_under_it_keeps_only_the_bolts_it_started_with(
        repo: Repository, bolts_file: Path) -> None:
    """The model renamed under the vehicle at the station keeps its bolts on it, not the
    bolts an earlier table had taken out before the vehicle was started."""
    import_bolts(repo, bolts_file)                   # last year's table had B2
    repo.start_vehicle("VIN0", "SEDAN")
    repo.close_vehicle("VIN0")
    bolts_file.write_text(BASE.replace(B2, ""))      # this year's has not
    assert import_bolts(repo, bolts_file).removed == ["SEDAN/B2"]
    repo.start_vehicle("VIN3", "SEDAN")
    record(repo, "VIN3", "B1")
    bolts_file.write_text(BASE.replace(B2, "").replace("  SEDAN:\n", "  SEDAN-MY27:\n"))
    import_bolts(repo, bolts_file)
    left = repo.close_vehicle("VIN3")
    assert left.missing == ["B3"], left.counts()
    # and closed, it keeps them when the next table brings B2 back under the old name
    bolts_file.write_text(BASE)
    import_bolts(repo, bolts_file)
    assert repo.vehicle_report("VIN3").missing == ["B3"]
    assert repo.vehicle_report("VIN0").missing == ["B1", "B2", "B3"]


def test_a_vehicle_that_left_with_a_bolt_missing_keeps_it_missing_through_a_rework(
        repo: Repository, bolts_file: Path) -> None:
    """A vehicle that left with B2 never tightened, B2 taken out of the table afterwards: it
    stays missing (above); reopened for rework of another bolt (or by mistake) and closed
    again, it left "complete" (B2 dropped by the table as it is now), the bolt never
    tightened."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    record(repo, "VIN1", "B1")
    record(repo, "VIN1", "B3")
    assert repo.close_vehicle("VIN1").missing == ["B2"]
    bolts_file.write_text(BASE.replace(B2, ""))      # the next model year has no B2
    assert import_bolts(repo, bolts_file).removed == ["SEDAN/B2"]
    repo.reopen_vehicle("VIN1", at=datetime.now(UTC), user="quality", source="test",
                        comment="B3 to check")
    assert repo.vehicle_report("VIN1").missing == ["B2"]      # reopened, waiting
    repo.start_vehicle("VIN1", "SEDAN", reopen=True)
    record(repo, "VIN1", "B3")
    left = repo.close_vehicle("VIN1")
    assert left.missing == ["B2"] and not left.complete, left.counts()
    assert repo.vehicle_report("VIN1").missing == ["B2"]


def test_a_table_imported_by_hand_under_the_running_station_leaves_its_records_limits_true(
        repo: Repository, bolts_file: Path, tmp_path: Path) -> None:
    """``db import`` by hand into the running daemon's database that retunes a bolt the
    station has not enabled yet (B2: torque 23-27 -> 20-30) wrote the new window over its
    parameter version in place (no record, no enable pointed at it).  The station works
    on from the table it loaded (the README: the hand import "lasts until" the next reload)
    and tightens B2 to 23-27 under that version's id: its record then says it was
    tightened with 20-30, the window quality judges it by (the export's limits)."""
    from stationd.web.results import Results

    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    b2 = repo.bolts_for_model("SEDAN")[1]        # the daemon's table in memory
    assert b2.bolt_id == "B2" and b2.parameters.torque.min == 23
    retuned = tmp_path / "retuned.yaml"
    retuned.write_text(BASE.replace("target: 25, min: 23, max: 27",
                                    "target: 25, min: 20, max: 30"))
    url = repo.engine.url.render_as_string(hide_password=False)
    with Repository.open(url) as by_hand:         # stationd db import retuned.yaml ...
        assert import_bolts(by_hand, retuned).changed == ["SEDAN/B2"]
    enable = repo.enables.note("VIN1", "B2", None, b2.parameters_id, {}, datetime.now(UTC))
    record(repo, "VIN1", "B2", parameters_id=b2.parameters_id, enable_id=enable)
    [run] = Results(repo).rundowns("VIN1")
    assert (run["torque_min_nm"], run["torque_max_nm"]) == (23.0, 27.0), run
