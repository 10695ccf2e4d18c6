"""The repository: atomic, idempotent imports, versioned parameters, vehicles and records."""

from __future__ import annotations

import sqlite3
from datetime import UTC, datetime

import pytest
from sqlalchemy import func, select, text
from sqlalchemy.exc import IntegrityError

import db.importer
from db.errors import DataError
from db.models import Bolt, ProcessParameters, TighteningRecord, VehicleModel
from db.repository import DatabaseError, NotFoundError, Repository
from stationd.boltfile import import_bolts, load_bolts
from stationd.errors import ConfigError
from tests.db.conftest import BASE, EXAMPLE, record, url_of

NEW_B1 = BASE.replace("target: 50, min: 45, max: 55", "target: 52, min: 45, max: 55")


def _counts(repo: Repository) -> dict[str, int]:
    with repo.engine.connect() as c:
        return {t: c.execute(text(f"SELECT count(*) FROM {t}")).scalar_one()  # noqa: S608
                for t in ("vehicle_models", "psets", "bolts", "process_parameters", "vehicles",
                          "tightening_records")}


def test_wal_and_foreign_keys_are_on(repo, tmp_path):
    with repo.engine.connect() as c:
        assert c.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
        assert c.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
        assert c.exec_driver_sql("PRAGMA synchronous").scalar() == 2  # FULL
    raw = sqlite3.connect(tmp_path / "station.db")  # WAL is a property of the file itself
    assert raw.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    raw.close()
    with pytest.raises(IntegrityError, match="FOREIGN KEY"), repo.engine.begin() as c:
        c.execute(text("INSERT INTO bolts (model_id, code, name, x_mm, y_mm, z_mm, seq) "
                       "VALUES (999, 'X', 'x', 0, 0, 0, 0)"))


def test_import_reports_and_second_import_changes_nothing(repo, bolts_file):
    first = import_bolts(repo, bolts_file)
    assert first.models_added == ["SEDAN", "WAGON"]
    assert first.psets_added == ["pset 1", "SEDAN/pset 21"]
    assert first.added == ["SEDAN/B1", "SEDAN/B2", "SEDAN/B3", "WAGON/B1"]
    before = _counts(repo)
    second = import_bolts(repo, bolts_file)
    assert not second.has_changes and second.lines() == ["no changes (4 bolts unchanged)"]
    assert _counts(repo) == before
    infos = repo.bolts_for_model("SEDAN")
    assert [b.bolt_id for b in infos] == ["B1", "B2", "B3"]
    assert infos[0].parameters.pset == 1 and infos[0].parameters.torque.target == 50
    assert infos[2].order == 2 and infos[2].batch == "wheel" and infos[0].version == 1
    assert repo.model_for_code(12) == "SEDAN" and repo.model_for_code(13) is None


def test_a_file_with_an_error_changes_nothing(repo, bolts_file, tmp_path):
    import_bolts(repo, bolts_file)
    before, table = _counts(repo), repo.table()
    bad = tmp_path / "bad.yaml"
    bad.write_text(NEW_B1.replace("id: B3", "id: B2"))  # a valid change plus a duplicate
    with pytest.raises(ConfigError, match="duplicate bolt id"):
        import_bolts(repo, bad)
    assert _counts(repo) == before and repo.table() == table


def test_a_failure_halfway_through_rolls_everything_back(repo, bolts_file, tmp_path,
                                                         monkeypatch):
    import_bolts(repo, bolts_file)
    before, table = _counts(repo), repo.table()
    changed = tmp_path / "changed.yaml"
    changed.write_text(NEW_B1.replace("name: three", "name: THREE")
                       .replace("  WAGON:", "  VAN:\n    bolts: []\n  WAGON:"))
    real = db.importer._Importer.sync_bolt
    calls = []

    def failing(self, *args):
        calls.append(args)
        if len(calls) == 3:  # after B1 and B2 were written (flushed) in the transaction
            raise RuntimeError("disk pulled")
        return real(self, *args)

    monkeypatch.setattr(db.importer._Importer, "sync_bolt", failing)
    with pytest.raises(RuntimeError, match="disk pulled"):
        import_bolts(repo, changed)
    assert _counts(repo) == before and repo.table() == table
    monkeypatch.undo()
    report = import_bolts(repo, changed)
    assert report.models_added == ["VAN"]
    assert report.changed == ["SEDAN/B1", "SEDAN/B3", "WAGON/B1"]


def test_export_import_round_trip(repo, tmp_path):
    import_bolts(repo, EXAMPLE)
    out = tmp_path / "exported.yaml"
    out.write_text(repo.export_bolts())
    assert load_bolts(out) == load_bolts(EXAMPLE)
    assert not import_bolts(repo, out).has_changes
    other = Repository.open(url_of(tmp_path / "other.db"))  # and into a fresh database
    import_bolts(other, out)
    assert other.export_bolts() == repo.export_bolts()
    other.close()


def test_changed_parameters_of_a_bolt_with_records_become_a_new_version(repo, bolts_file):
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    old = repo.bolts_for_model("SEDAN")[0]
    first = record(repo, "VIN1", "B1")
    bolts_file.write_text(NEW_B1.replace("target: 25, min: 23", "target: 26, min: 23"))
    report = import_bolts(repo, bolts_file)
    assert report.psets_changed == ["pset 1"]
    # B1 has a record; B2 none, but its model is in use (VIN1 at the station: a running
    # station may send v1 as it loaded it): never overwritten either
    assert report.new_versions == ["SEDAN/B1 v2 (v1: 1 record)",
                                   "SEDAN/B2 v2 (v1: its model in use)"]
    assert sorted(report.changed) == ["SEDAN/B1", "SEDAN/B2", "WAGON/B1"]
    new = {b.bolt_id: b for b in repo.bolts_for_model("SEDAN")}
    assert new["B1"].version == 2 and new["B1"].parameters.torque.target == 52
    assert new["B1"].parameters_id != old.parameters_id
    assert new["B2"].version == 2 and new["B2"].parameters.torque.target == 26
    wagon = repo.bolts_for_model("WAGON")[0]   # a model no vehicle used: changed in place
    assert wagon.version == 1 and wagon.parameters.torque.target == 52
    with repo.engine.connect() as c:  # the old version is kept, unchanged, and still referenced
        v1 = c.execute(select(ProcessParameters).where(
            ProcessParameters.id == old.parameters_id)).one()
        assert (v1.version, v1.torque_target) == (1, 50)
        rec = c.execute(select(TighteningRecord).where(TighteningRecord.id == first)).one()
        assert rec.parameters_id == old.parameters_id
        assert rec.params_sent["torque"]["target"] == 50 and rec.params_sent["pset"] == 1
    second = record(repo, "VIN1", "B1")
    report_ = repo.vehicle_report("VIN1")
    assert report_.bolts[0].version == 2 and report_.bolts[0].attempts == 2
    with repo.engine.connect() as c:
        rec = c.execute(select(TighteningRecord).where(TighteningRecord.id == second)).one()
        assert rec.parameters_id == new["B1"].parameters_id
    assert not import_bolts(repo, bolts_file).has_changes


def test_removed_bolts_are_retired_when_referenced_else_deleted(repo, bolts_file):
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    record(repo, "VIN1", "B2", ok=False)
    bolts_file.write_text(BASE.replace(
        "      - id: B2\n        name: two\n        position: [100, 0, 0]\n"
        "        torque: {target: 25, min: 23, max: 27}\n"
        "        angle: {target: 30, min: 10, max: 50}\n", "")
        .replace("  WAGON:\n    bolts:\n      - id: B1\n        name: one\n"
                 "        position: [0, 0, 0]\n        pset: 1\n", ""))
    report = import_bolts(repo, bolts_file)
    assert report.removed == ["WAGON/B1", "SEDAN/B2"] and report.models_removed == ["WAGON"]
    assert [b.bolt_id for b in repo.bolts_for_model("SEDAN")] == ["B1", "B3"]
    assert repo.models() == ["SEDAN"]
    with pytest.raises(NotFoundError, match="WAGON"):
        repo.bolts_for_model("WAGON")
    with repo.engine.connect() as c:
        assert c.scalar(select(func.count()).select_from(VehicleModel)) == 1  # WAGON deleted
        kept = c.execute(select(Bolt).where(Bolt.code == "B2")).one()
        assert kept.removed_at is not None
    rep = repo.vehicle_report("VIN1")  # the NOK of the retired bolt is still reported
    assert [(b.bolt_id, b.status, b.retired) for b in rep.bolts] == [
        ("B1", "missing", False), ("B2", "nok", True), ("B3", "missing", False)]
    bolts_file.write_text(BASE)
    again = import_bolts(repo, bolts_file)
    assert again.added == ["SEDAN/B2", "WAGON/B1"] and again.models_added == ["WAGON"]
    assert not import_bolts(repo, bolts_file).has_changes


def test_a_bolt_whose_tool_was_enabled_and_never_used_is_retired_or_versioned(repo,
                                                                              bolts_file):
    """The tool enabled for B2 (the trail points at its parameters), the operator left
    before tightening: removing B2 from the table retires it, retuning it makes a new
    version (an engineer's trial: the delete broke the trail's foreign key, the import was
    refused by the database and the reloaded station stayed in fault)."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    b1, b2 = repo.bolts_for_model("SEDAN")[:2]
    for b in (b1, b2):
        repo.enables.note("VIN1", b.bolt_id, 1, b.parameters_id, {}, datetime.now(UTC))
    bolts_file.write_text(BASE.replace(
        "      - id: B2\n        name: two\n        position: [100, 0, 0]\n"
        "        torque: {target: 25, min: 23, max: 27}\n"
        "        angle: {target: 30, min: 10, max: 50}\n", "")
        .replace("target: 50, min: 45", "target: 52, min: 45"))
    report = import_bolts(repo, bolts_file)
    assert report.removed == ["SEDAN/B2"]
    assert report.new_versions == ["SEDAN/B1 v2 (v1: 1 tool enable)"]
    with repo.engine.connect() as c:
        kept = c.execute(select(Bolt).where(Bolt.code == "B2")).one()
        assert kept.removed_at is not None
        v1 = c.execute(select(ProcessParameters).where(
            ProcessParameters.id == b1.parameters_id)).one()
        assert v1.torque_target == 50                     # the enable's, unchanged
    assert [b.bolt_id for b in repo.bolts_for_model("SEDAN")] == ["B1", "B3"]


def test_vehicle_cycle_and_close_summary(repo, bolts_file):
    import_bolts(repo, bolts_file)
    info = repo.start_vehicle("WVW1234567890", "SEDAN")
    assert info.ended_at is None and info.started_at.tzinfo is not None
    assert repo.start_vehicle("WVW1234567890", "SEDAN") == info  # resumed after a restart
    with pytest.raises(DataError, match="already known as model SEDAN"):
        repo.start_vehicle("WVW1234567890", "WAGON")
    with pytest.raises(NotFoundError, match="model 'TRUCK'"):
        repo.start_vehicle("V2", "TRUCK")
    with pytest.raises(DataError, match="VIN"):
        repo.start_vehicle("has space", "SEDAN")
    when = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)
    record(repo, "WVW1234567890", "B1", ok=False, tightening_id=7, result_at=when,
           images=["cam1/0001.png"], params_sent={"pset": 1})
    record(repo, "WVW1234567890", "B1", ok=True, tightening_id=8)
    record(repo, "WVW1234567890", "B2", ok=True)
    record(repo, "WVW1234567890", "B2", ok=False)  # a double hit: the last result decides
    with pytest.raises(NotFoundError, match="bolt 'B9'"):
        record(repo, "WVW1234567890", "B9")
    with pytest.raises(DataError, match="parameter version"):
        record(repo, "WVW1234567890", "B3", parameters_id=repo.bolts_for_model("SEDAN")[0]
               .parameters_id)
    summary = repo.close_vehicle("WVW1234567890")
    assert summary.missing == ["B3"] and summary.nok == ["B2"] and summary.ok == ["B1"]
    assert not summary.complete and summary.vehicle.ended_at is not None
    # the bolts ending NOK (B2) and the NOK results (B1's first and B2's last): both, named
    assert summary.summary().endswith(": bolts: 1 OK, 1 ending NOK (B2), 0 skipped, "
                                      "1 missing (B3); rundowns: 4 tightenings, 2 NOK "
                                      "results")
    assert (summary.to_json()["tightenings"], summary.to_json()["nok_results"]) == (4, 2)
    assert repo.close_vehicle("WVW1234567890").vehicle.ended_at == summary.vehicle.ended_at
    with pytest.raises(DataError, match="is closed"):
        record(repo, "WVW1234567890", "B3")
    with pytest.raises(DataError, match="reopen"):
        repo.start_vehicle("WVW1234567890", "SEDAN")
    assert not summary.vehicle.rework and summary.to_json()["reopened_at"] is None
    reopened = repo.start_vehicle("WVW1234567890", "SEDAN", reopen=True)
    assert reopened.rework and reopened.ended_at is None
    # resumed (a daemon reloaded mid-rework): still a rework, as the database says
    assert repo.start_vehicle("WVW1234567890", "SEDAN").reopened_at == reopened.reopened_at
    record(repo, "WVW1234567890", "B2")
    record(repo, "WVW1234567890", "B3")
    final = repo.close_vehicle("WVW1234567890")
    assert final.complete and final.to_json()["complete"] is True
    assert final.vehicle.rework and final.to_json()["reopened_at"] is not None
    assert "closed, reworked" in final.summary()
    b1 = final.to_json()["bolts"][0]
    assert b1["attempts"] == 2 and b1["tightening_id"] == 8 and b1["status"] == "ok"
    with repo.engine.connect() as c:
        first = c.execute(select(TighteningRecord).order_by(TighteningRecord.id)).first()
        assert first is not None and first.images == ["cam1/0001.png"]
        assert first.result_at == when and first.status == "nok"
    with pytest.raises(NotFoundError, match=r"'NOPE' is not in the database$"):
        repo.vehicle_report("NOPE")
    # a VIN typed in another case is another VIN, and the error says which was meant
    with pytest.raises(NotFoundError, match=r"'wvw1234567890' is not in the database "
                                            r"\(did you mean WVW1234567890\?\)$"):
        repo.vehicle_report("wvw1234567890")


def test_a_vehicle_reopened_and_not_back_is_said_waiting_not_open(repo, bolts_file):
    """Reopened by a supervisor while another vehicle is on the lift: its report said "open,
    reworked" as if it were at the station (a newcomer's trial); it waits for its rework
    until it is loaded again, then it is open, and closed again after."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("WVW1234567890", "SEDAN")
    repo.close_vehicle("WVW1234567890")
    repo.start_vehicle("OTHER000000000001", "SEDAN")      # the next one on the lift
    at = datetime(2026, 1, 2, 3, 4, 5, tzinfo=UTC)
    repo.reopen_vehicle("WVW1234567890", at=at, user="sam", source="cli", comment="")
    report = repo.vehicle_report("WVW1234567890")
    assert report.vehicle.waiting and report.to_json()["waiting"] is True
    assert "(SEDAN, reopened for rework at 2026-01-02 03:04:05 UTC, not back at the " \
           "station yet)" in report.summary()
    assert not repo.vehicle_report("OTHER000000000001").vehicle.waiting
    repo.start_vehicle("WVW1234567890", "SEDAN")        # back at the station
    report = repo.vehicle_report("WVW1234567890")
    assert not report.vehicle.waiting and "(SEDAN, open, reworked)" in report.summary()
    repo.close_vehicle("WVW1234567890")
    assert "(SEDAN, closed, reworked)" in repo.vehicle_report("WVW1234567890").summary()


def test_a_result_taken_before_the_close_is_recorded_after_it(repo, bolts_file):
    """The database away while a bolt was tightened and the vehicle then closed (the result
    kept in memory meanwhile): stored later, the result is its vehicle's, taken while open.
    A result taken after the close, or of unknown time, is still refused."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("WVW1234567890", "SEDAN")
    taken = datetime.now(UTC)
    summary = repo.close_vehicle("WVW1234567890")
    assert summary.missing == ["B1", "B2", "B3"]
    record(repo, "WVW1234567890", "B1", ok=True, tightening_id=8, result_at=taken)
    assert repo.vehicle_report("WVW1234567890").ok == ["B1"]
    assert repo.vehicle_report("WVW1234567890").vehicle.ended_at == summary.vehicle.ended_at
    # a result owed to a tool enabled before the close, taken after it (fetched after a
    # restart): the vehicle's too
    record(repo, "WVW1234567890", "B3", ok=True, tightening_id=9, sent_at=taken,
           result_at=datetime.now(UTC))
    assert repo.vehicle_report("WVW1234567890").ok == ["B1", "B3"]
    for late in (datetime.now(UTC), None):
        with pytest.raises(DataError, match="is closed"):
            record(repo, "WVW1234567890", "B2", result_at=late, sent_at=late)


def test_open_errors_are_one_line_station_errors(tmp_path):
    with pytest.raises(DatabaseError, match="cannot open"):
        Repository.open(url_of(tmp_path / "no" / "such" / "dir.db"))
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"this is not a database" * 100)
    with pytest.raises(DatabaseError, match="file is not a database"):
        Repository.open(url_of(junk))
    with pytest.raises(DataError, match="database URL"):
        Repository.open("not a url")


def test_any_url_works_in_memory():
    with Repository.open("sqlite://") as r:
        import_bolts(r, EXAMPLE)
        assert len(r.bolts_for_model("SEDAN-A")) == 6


def test_lift_codes_can_move_between_models_in_one_import(repo, bolts_file):
    bolts_file.write_text(BASE.replace("  WAGON:\n", "  WAGON:\n    code: 13\n"))
    import_bolts(repo, bolts_file)
    bolts_file.write_text(BASE.replace("code: 12", "code: 13")
                          .replace("  WAGON:\n", "  WAGON:\n    code: 12\n"))
    report = import_bolts(repo, bolts_file)
    assert report.models_changed == ["SEDAN", "WAGON"] and not report.changed
    assert (repo.model_for_code(12), repo.model_for_code(13)) == ("WAGON", "SEDAN")


def test_a_result_sent_again_is_recorded_once(repo, bolts_file):
    """A station killed after storing a result but before acknowledging it gets the result
    again from the controller: the same tightening id is one record, not two."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VINDUP", "SEDAN")
    first = record(repo, "VINDUP", "B1", tightening_id=77)
    assert record(repo, "VINDUP", "B1", tightening_id=77) == first
    assert record(repo, "VINDUP", "B1", tightening_id=78) != first  # a new tightening
    assert _counts(repo)["tightening_records"] == 2


def test_a_resent_copy_is_only_the_same_tightening_by_the_controller_s_time(repo, bolts_file):
    """A controller reset or replaced (a simulated one built anew at a reload) numbers its
    tightenings from 1 again, and its torque and angle can coincide with an earlier result's:
    with another controller timestamp it is another tightening, stored as a new record (it
    was returned as the stored one, silently lost).  A true resend (same id, values and
    time) is stored once and said to be a copy."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VINDUP", "SEDAN")
    at = datetime(2026, 12, 1, 8, 0, 0, tzinfo=UTC)
    kw = {"position_mm": (1.0, 2.0, 3.0), "match_distance_mm": 1.5, "tilt_deg": 2.0,
          "torque_nm": 30.0, "angle_deg": 35.0, "tightening_id": 7}
    first = repo.record_tightening_once("VINDUP", "B1", ok=False, controller_at=at, **kw)
    assert not first.again
    copy = repo.record_tightening_once("VINDUP", "B1", ok=False, controller_at=at, **kw)
    assert (copy.id, copy.again) == (first.id, True)                  # sent again: once
    later = at.replace(minute=5)
    other = repo.record_tightening_once("VINDUP", "B1", ok=False, controller_at=later, **kw)
    assert not other.again and other.id != first.id                  # ids started again
    # a time not known on either side (a controller without a clock): the values decide
    assert repo.record_tightening_once("VINDUP", "B1", ok=False, **kw).again
    with repo.engine.connect() as c:
        rows = c.execute(select(TighteningRecord.id, TighteningRecord.controller_at)
                         .order_by(TighteningRecord.id)).all()
    assert [(i, t.replace(tzinfo=UTC)) for i, t in rows] == [(first.id, at), (other.id, later)]
    # the same rule where a result no bolt owns is stored, and for a controller event
    un = {"vin": "VINDUP", "controller_vin": None, "pset": 1, "ok": False, "torque_nm": 30.0,
          "angle_deg": 35.0, "reason": "outside any tightening"}
    assert repo.others.record_unattributed(tightening_id=7, result_at=at, **un) is None  # recorded
    assert repo.others.record_unattributed(tightening_id=7, result_at=at.replace(minute=9), **un)
    ev = {"result_type": 3, "what": "batch increment", "vin": "VINDUP", "bolt": None,
          "controller_vin": None, "tightening_id": 8, "pset": 1, "ok": True, "torque_nm": 0.0,
          "angle_deg": 0.0}
    assert repo.others.record_controller_event(result_at=at, **ev)
    assert repo.others.record_controller_event(result_at=at, **ev) is None       # sent again
    assert repo.others.record_controller_event(result_at=later, **ev)            # another one


def test_the_owed_enable_is_the_latest_unsettled_one_and_its_record_settles_it(repo,
                                                                               bolts_file):
    """What a station owes the next (a reload, a restart): the latest tool enable until a
    record settles it; an older one is superseded by a newer enable."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    assert repo.enables.owed() is None
    at = datetime(2026, 11, 27, 8, 0, tzinfo=UTC)
    pid = repo.bolts_for_model("SEDAN")[1].parameters_id
    first = repo.enables.note("VIN1", "B1", 1, None, {"point_mm": [0, 0, 0]}, at)
    second = repo.enables.note("VIN1", "B2", 21, pid, {"point_mm": [1, 2, 3]}, at)
    owed = repo.enables.owed()
    assert owed is not None and owed.id == second != first
    assert (owed.bolt, owed.pset, owed.parameters_id, owed.off_at) == ("B2", 21, pid, None)
    repo.enables.tool_off(second, at.replace(second=5))
    repo.enables.tool_off(second, at.replace(second=9))       # the first time counts
    owed = repo.enables.owed()
    assert owed is not None and owed.off_at == at.replace(second=5)
    record(repo, "VIN1", "B2", tightening_id=70060, parameters_id=pid, enable_id=second)
    assert repo.enables.owed() is None


def test_an_unattributed_result_is_stored_once_and_not_when_already_recorded(repo,
                                                                              bolts_file):
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    kw = {"vin": "VIN1", "controller_vin": None, "pset": 1, "ok": False,
          "result_at": None, "reason": "result 7 (pset 1) outside any tightening"}
    assert repo.others.record_unattributed(tightening_id=7, torque_nm=12.5, angle_deg=30.0, **kw)
    assert repo.others.record_unattributed(tightening_id=7, torque_nm=12.5, angle_deg=30.0,
                                           **kw) is None                     # a resent copy
    assert repo.others.record_unattributed(tightening_id=7, torque_nm=13.0, angle_deg=30.0, **kw)
    record(repo, "VIN1", "B1", tightening_id=8, torque_nm=50.0, angle_deg=40.0)
    assert repo.others.record_unattributed(tightening_id=8, torque_nm=50.0, angle_deg=40.0,
                                           **kw) is None                     # stored to its bolt
    rows = repo.others.unattributed("VIN1")
    assert [(r["tightening_id"], r["torque_nm"], r["status"]) for r in rows] == \
        [(7, 12.5, "nok"), (7, 13.0, "nok")]
    assert repo.others.unattributed("OTHER") == []


def test_nok_streaks_count_the_noks_in_a_row_since_an_ok_or_a_release(repo, bolts_file):
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    for tid, ok in ((1, False), (2, False), (3, True), (4, False)):
        record(repo, "VIN1", "B1", ok=ok, tightening_id=tid)
    for tid in (5, 6, 7):
        record(repo, "VIN1", "B2", ok=False, tightening_id=tid)
    assert repo.nok_streaks("VIN1") == {"B1": 1, "B2": 3}
    repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli", kind="release",
                               vin="VIN1", bolt="B2", comment="checked")
    assert repo.nok_streaks("VIN1") == {"B1": 1}
    record(repo, "VIN1", "B2", ok=False, tightening_id=8)
    assert repo.nok_streaks("VIN1") == {"B1": 1, "B2": 1}
    # a skip ends the row too (the station takes it only from who may release): the lock
    # does not come back with the vehicle after a restart
    repo.ledger.record_command(at=datetime.now(UTC), user="sam", source="cli", kind="skip",
                               vin="VIN1", bolt="B2", comment="to rework")
    assert repo.nok_streaks("VIN1") == {"B1": 1}


def test_the_journal_line_of_a_closing_vehicle_counts_in_the_reports_words(tmp_path,
                                                                           bolts_file, caplog):
    """Issue 30: a vehicle leaving with 45 bolts untouched was journaled as "closed: missing
    B01, B02, ..., B50, skipped none, NOK none": 45 names, no count, other words than
    ``db report``'s.  Now the line is the report's counts, labelled."""
    import logging

    from stationd.config import StationConfig
    from stationd.shell.records import Records

    records = Records(StationConfig(database_url=url_of(tmp_path / "st.db"),
                                    bolts_path=bolts_file))
    repo = records.open()
    repo.start_vehicle("VIN1", "SEDAN")
    record(repo, "VIN1", "B1", ok=False)
    record(repo, "VIN1", "B1", ok=True)
    record(repo, "VIN1", "B2", ok=False)
    with caplog.at_level(logging.INFO, logger="stationd"):
        records.close_vehicle("VIN1")
    said = [r.getMessage() for r in caplog.records if "closed" in r.getMessage()]
    report = repo.vehicle_report("VIN1")
    assert said == [f"vehicle VIN1 (SEDAN) closed: {report.counts()}"]
    assert report.summary() == f"VIN1 (SEDAN, closed): {report.counts()}"
    assert said[0].startswith("vehicle VIN1 (SEDAN) closed: bolts: 1 OK, 1 ending NOK (B2), "
                              "0 skipped, ")
    assert said[0].endswith("; rundowns: 3 tightenings, 2 NOK results")
    repo.close()


def test_a_vehicle_that_left_unseen_is_closed_when_the_next_one_is_loaded(repo, bolts_file):
    """A station killed while its vehicle was lowered never saw it go: it stayed open for
    good beside the next one (a newcomer's Results list).  The next vehicle loaded closes it;
    the same vehicle back (a restart at height) does not, nor does a vehicle reopened for
    rework and not back yet."""
    import_bolts(repo, bolts_file)
    assert repo.at_station() is None
    repo.start_vehicle("VIN1", "SEDAN")
    assert repo.at_station() == "VIN1"                     # a restart finds it at height
    record(repo, "VIN1", "B1", tightening_id=1)
    assert repo.left_unseen("VIN1") is None              # the same vehicle, resumed
    repo.start_vehicle("VIN1", "SEDAN")
    gone = repo.left_unseen("VIN2")                        # the station down as VIN1 left
    assert gone is not None and gone.vehicle.vin == "VIN1" and gone.vehicle.ended_at
    assert gone.ok == ["B1"]
    assert repo.at_station() is None                       # closed: none left at height
    assert repo.left_unseen("VIN2") is None                # once
    repo.start_vehicle("VIN2", "SEDAN")
    repo.close_vehicle("VIN2")                             # lowered, seen: none at the station
    repo.reopen_vehicle("VIN1", at=datetime.now(UTC), user="sam", source="cli",
                        comment="rework")
    assert repo.left_unseen("VIN3") is None                # VIN1 reopened, not loaded since
    with pytest.raises(DataError, match=r"reopened for rework at .* not back at the station"):
        repo.reopen_vehicle("VIN1", at=datetime.now(UTC), user="sam", source="cli",
                            comment="again")
    repo.start_vehicle("VIN3", "SEDAN")
    assert repo.vehicle_report("VIN1").vehicle.ended_at is None


def test_every_close_of_a_vehicle_is_kept_with_what_it_left_and_joins_the_feed(sedan):
    """An MES integrator's trial: a vehicle that left with bolts not tightened never reached
    the line (no record of it in the feed), and a reopen cleared when it had first left.
    Each close is its own record in the feed, with the bolts' counts and the bolts not OK
    by name; closing again keeps nothing twice; a reworked vehicle closes again, its first
    close kept; one found gone at the next vehicle's start is said so."""
    from db.ledger import CLOSING

    record(sedan, "VIN1", "B1")
    record(sedan, "VIN1", "B2", ok=False)
    sedan.close_vehicle("VIN1")
    sedan.close_vehicle("VIN1")                       # again: the first close stands
    closings = [e for e in sedan.ledger.since(0) if e["kind"] == CLOSING]
    assert len(closings) == 1
    first = closings[0]["record"]
    assert (first["vin"], first["model"], first["how"], first["bolts"], first["ok"],
            first["nok"], first["missing"]) == ("VIN1", "SEDAN", "lowered", 3, 1, 1, 1)
    assert first["not_ok"] == {"nok": ["B2"], "missing": ["B3"]}
    sedan.reopen_vehicle("VIN1", at=datetime.now(UTC), user="sam", source="cli",
                         comment="rework B2, B3")
    sedan.start_vehicle("VIN1", "SEDAN")
    record(sedan, "VIN1", "B2")
    record(sedan, "VIN1", "B3")
    assert sedan.left_unseen("VIN2") is not None     # VIN1 gone unseen as VIN2 came
    sedan.start_vehicle("VIN2", "SEDAN")
    closings = [e["record"] for e in sedan.ledger.since(0) if e["kind"] == CLOSING]
    assert [(c["how"], c["ok"], c["not_ok"]) for c in closings] == [
        ("lowered", 1, {"nok": ["B2"], "missing": ["B3"]}), ("unseen", 3, {})]
    assert closings[0]["closed_at"] < closings[1]["closed_at"]
    # its report keeps when it first left (ended_at is the last close)
    info = sedan.vehicle_report("VIN1").vehicle
    assert info.first_closed_at is not None and info.ended_at is not None
    assert info.first_closed_at.isoformat() == closings[0]["closed_at"]
    assert info.ended_at.isoformat() == closings[1]["closed_at"]
    assert sedan.vehicle_report("VIN1").to_json()["first_closed_at"] == closings[0]["closed_at"]


def test_a_vehicle_that_leaves_with_a_bolt_held_says_so_in_its_closing(sedan):
    """A bolt held for a person (its last result not known: here a lost push after its OK
    rundown, as LostRules._gap_again stores one after the pushed result is recorded) is
    not OK whatever its status says (VehicleReport.held); the station's own close line
    counts it (Repository._with_held).  The closing that goes to the line and an MES
    (line_vehicle_closings) must say it too: without it the vehicle reads complete, every
    bolt OK, while the station holds B1 for a person."""
    from db.kinds import LOST_UNKNOWN
    from db.ledger import CLOSING

    record(sedan, "VIN1", "B1")
    record(sedan, "VIN1", "B2")
    record(sedan, "VIN1", "B3")
    sedan.others.record_controller_event(result_type=1, what=LOST_UNKNOWN, vin="VIN1", bolt="B1",
                                         controller_vin=None, tightening_id=None, pset=1, ok=None,
                                         torque_nm=None, angle_deg=None, result_at=None,
                                         note="a lost push may be its second rundown")
    report = sedan.close_vehicle("VIN1")
    assert [b for b, _ in report.held] == ["B1"]          # the station's close line says it
    [closing] = [e["record"] for e in sedan.ledger.since(0) if e["kind"] == CLOSING]
    named = [b for bolts in closing["not_ok"].values() for b in bolts]
    assert "B1" in named, f"the closing says nothing of B1's hold: {closing}"


def test_an_export_s_result_ids_are_read_by_an_index_not_a_scan_of_the_whole_feed(repo):
    """``Ledger.result_ids`` (each row's ``db_id:seq`` in a results export) looks the
    feed up by kind and record id: without an index on them every vehicle's export read
    the whole feed (a year of rundowns, curves and commands), once per vehicle of ``db
    export --results``."""
    from sqlalchemy import event

    from db.ledger import RUNDOWN

    seen: list[tuple[str, object]] = []

    def note(conn, cursor, statement, parameters, context, executemany):
        if "FROM feed" in statement:
            seen.append((statement, parameters))

    event.listen(repo.engine, "before_cursor_execute", note)
    try:
        repo.ledger.result_ids([(RUNDOWN, 1), (RUNDOWN, 2)])
    finally:
        event.remove(repo.engine, "before_cursor_execute", note)
    [(statement, parameters)] = seen
    with repo.engine.connect() as c:
        plan = [row[-1] for row in c.exec_driver_sql("EXPLAIN QUERY PLAN " + statement,
                                                      parameters)]
    assert not any(step.startswith("SCAN feed") for step in plan), plan


def test_a_vehicle_s_commands_are_read_by_an_index_not_a_scan_of_every_command(repo):
    """Each vehicle's report reads its commands by VIN (skips, releases, loosen commands):
    without an index every report of an export or a shift's hand-over read every command
    the station ever took."""
    with repo.engine.connect() as c:
        plan = [row[-1] for row in c.exec_driver_sql(
            "EXPLAIN QUERY PLAN SELECT * FROM commands WHERE vin = ?", ("VIN1",))]
    assert not any(step.startswith("SCAN commands") for step in plan), plan
