"""Every rundown with its user: the operator signed in at the station when its tool was
enabled.  In the database (a database of the last revision upgraded: its records have none),
the station's records (also after a restart, from the enable it owed), the feed, ``db report``
and the CSV/JSON exports; a rundown with nobody signed in stays without one, shown as such."""

from __future__ import annotations

import csv
import io
import json
import time
from datetime import UTC, datetime, timedelta

from sqlalchemy import create_engine, inspect

from db.repository import Repository
from stationd.cli import main
from stationd.config import StationConfig
from stationd.shell.records import Records
from stationd.station.actions import Record
from stationd.web.results import Results, rundowns_csv
from tests.db.conftest import b1_selected, old_record, record, url_of
from tests.rundowns import rundown


def test_a_database_of_the_last_revision_upgrades_and_its_records_have_no_operator(tmp_path):
    url = url_of(tmp_path / "old.db")
    engine = create_engine(url)
    old_record(engine, "0010")
    assert "operator" not in {c["name"] for c in inspect(engine).get_columns(
        "tightening_records")}
    engine.dispose()
    with Repository.open(url) as repo:     # opening migrates to the head
        record(repo, "OLD", "B1", tightening_id=9, operator="olga")
        assert [r["operator"] for r in Results(repo).rundowns("OLD")] == [None, "olga"]


def test_the_feed_report_and_exports_carry_the_operator_or_none(sedan, tmp_path, capsys):
    record(sedan, "VIN1", "B1", ok=False, tightening_id=1, operator="olga")
    record(sedan, "VIN1", "B1", tightening_id=2, operator="pia")
    record(sedan, "VIN1", "B2", tightening_id=3)                       # nobody signed in
    feed = [e["record"] for e in sedan.ledger.since(0) if e["kind"] == "rundown"]
    assert [r["operator"] for r in feed] == ["olga", "pia", None]
    runs = Results(sedan).rundowns("VIN1")
    assert [r["operator"] for r in runs] == ["olga", "pia", None]
    rows = list(csv.DictReader(io.StringIO(rundowns_csv(runs))))
    assert [r["operator"] for r in rows] == ["olga", "pia", ""]
    page = Results(sedan).vehicle("VIN1")
    assert [r["operator"] for r in page["bolts"][0]["rundowns"]] == ["olga", "pia"]
    url = str(sedan.engine.url)
    sedan.close()
    assert main(["db", "report", "VIN1", "--db", url]) != 0    # incomplete: B3 missing
    out = capsys.readouterr().out
    assert "2 attempts, by pia" in out and "1. tightening NOK" in out and "by olga" in out
    assert "1 attempt, by -" in out                          # nobody: shown as such
    main(["db", "report", "VIN1", "--db", url, "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert [r["operator"] for r in doc["rundowns"]] == ["olga", "pia", None]
    out_csv = tmp_path / "results.csv"
    assert main(["db", "export", "--results", "--db", url, "--out", str(out_csv)]) == 0
    rows = list(csv.DictReader(out_csv.open()))
    assert [r["operator"] for r in rows if r["status"] not in ("missing", "pending")] == [
        "olga", "pia", ""]


def test_the_station_records_the_selections_operator_also_for_an_owed_enable(tmp_path,
                                                                              bolts_file):
    cfg, records, repo, sel = b1_selected(tmp_path, bolts_file, 1, operator="olga",
                                          torque_window=(45.0, 55.0))
    records.note_enable(sel)            # the station stops with the tool on
    repo.close()
    again = Records(cfg)
    repo = again.open()
    owed = again.owed(late_result_s=60.0)
    assert owed is not None and owed.selection.operator == "olga"
    # its torque window too: an OK without a type outside it is not taken for B1 after the
    # restart either (a reviewer)
    assert owed.selection.torque_window == (45.0, 55.0)
    result = rundown(7, 1, torque_nm=50.0, angle_deg=30.0)
    again.write(again.unsaved_result(
        Record("VIN1", "B1", result, owed.selection, t=time.time()), None))
    assert [r["operator"] for r in Results(repo).rundowns("VIN1")] == ["olga"]
    repo.close()


def test_the_signed_in_operator_is_read_back_from_the_commands(tmp_path, bolts_file):
    cfg = StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts_file)
    records = Records(cfg)
    repo = records.open()
    assert records.operator() is None
    at = datetime(2026, 11, 27, 6, 0, tzinfo=UTC)
    for i, (kind, user) in enumerate((("sign-in", "olga"), ("skip", "sam"),
                                      ("sign-out", "olga"), ("sign-in", "pia"))):
        repo.ledger.record_command(at=at + timedelta(minutes=i), user=user, source="cli",
                                   kind=kind, vin=None, bolt=None, comment="")
        if i == 2:
            assert records.operator() is None
    who = records.operator()
    assert who is not None and who[0] == "pia" and who[1] == at + timedelta(minutes=3)
    repo.close()
