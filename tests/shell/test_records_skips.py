"""A skip read back from the command ledger (stationd/shell/records.py ``load_vehicle``): the
vehicle loaded again after a restart or a reload brings each bolt a person skipped as the
core decided it, a person's command typed (who, their comment), and it is said as it was
before the restart (a daemon test waits for "B08 skipped: sam's command" after a reload)."""

from __future__ import annotations

import time
from pathlib import Path

from stationd.config import StationConfig
from stationd.reasons import Skip, SkipKind
from stationd.shell.records import Records
from stationd.station.actions import LoadVehicle, NoteLock, RecordCommand
from stationd.station.commands import Issuer, ReleaseBolt, Right, SkipBolt
from stationd.station.inputs import VehicleLoaded
from stationd.words import skip_words
from tests.db.conftest import BASE, url_of


def test_a_skip_comes_back_from_the_ledger_typed_and_said_as_before(tmp_path: Path) -> None:
    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BASE)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts))
    records.open()
    first = records.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(first, VehicleLoaded) and first.skipped == {}
    for bolt, user, comment in (("B1", "olga", "no access"), ("B2", "sam", "")):
        why = records.record_command(RecordCommand(
            0, SkipBolt("VIN1", bolt, comment), Issuer(user, frozenset(Right), "cli"),
            time.time()), "VIN1")
        assert why is None
    again = records.load_vehicle(LoadVehicle(12, "VIN1"))   # as after a restart
    assert isinstance(again, VehicleLoaded)
    assert again.skipped["B1"] == Skip(SkipKind.COMMAND, user="olga", comment="no access")
    assert {b: skip_words(s) for b, s in again.skipped.items()} == {
        "B1": "olga's command (no access)", "B2": "sam's command"}
    assert records.repo is not None
    records.repo.close()


def test_a_lock_comes_back_from_the_ledger_until_a_release_ends_it(tmp_path: Path) -> None:
    """The NOK policy's lock is recorded (by the station) and read back with the vehicle, so
    that a reload raising ``max_nok`` keeps it; a release or a skip ends it."""
    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BASE)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts))
    records.open()
    first = records.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(first, VehicleLoaded) and first.locked == frozenset()
    records.note_lock(NoteLock("VIN1", "B1", 3, time.time()))
    records.note_lock(NoteLock("VIN1", "B2", 3, time.time()))
    again = records.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(again, VehicleLoaded) and again.locked == frozenset({"B1", "B2"})
    assert records.record_command(RecordCommand(
        0, ReleaseBolt("VIN1", "B1", "checked"), Issuer("sam", frozenset(Right), "cli"),
        time.time()), "VIN1") is None
    after = records.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(after, VehicleLoaded) and after.locked == frozenset({"B2"})
    assert records.repo is not None
    lock = [c for c in records.repo.ledger.commands("VIN1") if c.kind == "lock"]
    assert [(c.bolt, c.user, c.comment) for c in lock] == [
        ("B1", "station", "3 NOK in a row"), ("B2", "station", "3 NOK in a row")]
    records.repo.close()


def test_a_reopen_of_a_vin_typed_in_lower_case_says_the_one_meant(tmp_path: Path) -> None:
    """An operator trial: "9sdst..." answered "not in the database", no word of the VIN in
    capitals the database has (a skip's bolt in another case says "did you mean")."""
    from stationd.station.commands import ReopenVehicle
    from stationd.words import reason_words

    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BASE)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts))
    records.open()
    records.load_vehicle(LoadVehicle(12, "VINX1"))
    records.close_vehicle("VINX1")
    who = Issuer("sam", frozenset(Right), "cli")
    why = records.record_command(RecordCommand(0, ReopenVehicle("vinx1", ""), who,
                                               time.time()), None)
    assert why is not None and reason_words(why) == \
        "vehicle vinx1 is not in the database (did you mean VINX1?)"
    why = records.record_command(RecordCommand(0, ReopenVehicle("NOPE1", ""), who,
                                               time.time()), None)
    assert why is not None and reason_words(why) == "vehicle NOPE1 is not in the database"
    assert records.repo is not None
    records.repo.close()


def test_a_refused_command_is_kept_as_a_refusal_that_changes_nothing(tmp_path: Path) -> None:
    """A quality trial: an OK of 5 Nm entered for a 22-28 Nm bolt was refused, and only the
    journal knew; it is a ``refused`` command now, with what it was and why, and it ends
    no lock (a refused release is no release)."""
    from stationd.reasons import Reason, Why
    from stationd.station.actions import RecordRefusal
    from stationd.station.commands import EnterOutcome

    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BASE)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts))
    records.open()
    records.load_vehicle(LoadVehicle(12, "VIN1"))
    records.note_lock(NoteLock("VIN1", "B1", 3, time.time()))
    sam = Issuer("sam", frozenset(Right), "cli 127.0.0.1")
    records.record_refusal(RecordRefusal(
        EnterOutcome("VIN1", "B2", True, 5.0, 2.0, "looked"), sam,
        Reason(Why.ENTERED_OUTSIDE, bolt="B2", note="torque 5 Nm outside 45-55 Nm"),
        time.time()))
    records.record_refusal(RecordRefusal(
        ReleaseBolt("VIN1", "B1", "fine"), Issuer("olga", frozenset(), "screen"),
        Reason(Why.NO_RIGHT, right="release"), time.time()))
    assert records.repo is not None
    refused = [c for c in records.repo.ledger.commands("VIN1") if c.kind == "refused"]
    assert [(c.user, c.source, c.bolt) for c in refused] == [
        ("sam", "cli 127.0.0.1", "B2"), ("olga", "screen", "B1")]
    assert refused[0].comment.startswith("enter-outcome B2 of VIN1: ")
    assert "'looked'" in refused[0].comment and ": refused: " in refused[0].comment
    assert "5 Nm outside 45-55 Nm" in refused[0].comment
    assert refused[1].comment.endswith("refused: your role does not have the right to "
                                       "release")
    again = records.load_vehicle(LoadVehicle(12, "VIN1"))
    assert isinstance(again, VehicleLoaded) and again.locked == frozenset({"B1"})
    records.repo.close()


def test_the_records_say_whether_the_database_knows_a_vin_and_the_one_meant(
        tmp_path: Path) -> None:
    """What a command naming a VIN is fed with (a supervisor's trial: a mistyped VIN was
    told to be reopened): known, unknown with the VIN meant in another case, or not
    known at all with the database not open."""
    bolts = tmp_path / "bolts.yaml"
    bolts.write_text(BASE)
    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts))
    assert records.knows_vehicle("VINX1") == (None, None)      # not open: cannot say
    records.open()
    records.load_vehicle(LoadVehicle(12, "VINX1"))
    assert records.knows_vehicle("VINX1") == (True, None)
    assert records.knows_vehicle("vinx1") == (False, "VINX1")
    assert records.knows_vehicle("NOPE1") == (False, None)
    assert records.repo is not None
    records.repo.close()
