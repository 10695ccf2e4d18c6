"""The migrations create exactly the schema the models describe, and run on open."""

from __future__ import annotations

from typing import Any

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import Column, Integer, MetaData, inspect

from db.engine import make_engine
from db.migrate import alembic_config, current_revision, head_revision, upgrade
from db.models import Base
from db.repository import Repository
from tests.db.conftest import url_of

TABLES = {"vehicle_models", "psets", "bolts", "process_parameters", "vehicles",
          "tightening_records", "tool_enables", "unattributed_results", "commands", "feed", "meta",
          "forward_quarantine", "result_gaps", "curves", "opcua_acknowledged",
          "calibration_checks", "camera_pins", "controller_events", "unreadable_results",
          "vehicle_closings",
          "alembic_version"}


def _diff(engine, metadata: MetaData) -> list[Any]:
    with engine.connect() as conn:
        ctx = MigrationContext.configure(conn, opts={"compare_type": True})
        return list(compare_metadata(ctx, metadata))


def test_migrated_schema_matches_the_models(tmp_path):
    engine = make_engine(url_of(tmp_path / "m.db"))
    upgrade(engine)
    assert set(inspect(engine).get_table_names()) == TABLES
    assert _diff(engine, Base.metadata) == []
    with engine.connect() as conn:
        assert current_revision(conn) == head_revision() == "0023"
    engine.dispose()


def test_the_comparison_would_see_a_difference(tmp_path):
    """Guard against a vacuous pass: an extra column, and an empty database, both differ."""
    engine = make_engine(url_of(tmp_path / "m.db"))
    missing = {d[1].name for d in _diff(engine, Base.metadata) if d[0] == "add_table"}
    assert missing == TABLES - {"alembic_version"}
    upgrade(engine)
    extra = MetaData(naming_convention=Base.metadata.naming_convention)
    for table in Base.metadata.sorted_tables:
        table.to_metadata(extra)
    extra.tables["bolts"].append_column(Column("torque_hint", Integer()))
    diffs = _diff(engine, extra)
    assert [d[0] for d in diffs] == ["add_column"] and diffs[0][3].name == "torque_hint"
    engine.dispose()


def test_open_migrates_once_and_downgrade_upgrade_round_trips(tmp_path):
    url = url_of(tmp_path / "m.db")
    Repository.open(url).close()
    Repository.open(url).close()  # already at head: nothing to do
    engine = make_engine(url)
    with engine.begin() as conn:
        command.downgrade(alembic_config(connection=conn), "base")
    assert set(inspect(engine).get_table_names()) == {"alembic_version"}
    upgrade(engine)
    assert _diff(engine, Base.metadata) == []
    engine.dispose()


def test_offline_sql_can_be_generated(capsys):
    command.upgrade(alembic_config(url="sqlite:///x.db"), "head", sql=True)
    sql = capsys.readouterr().out
    assert "CREATE TABLE tightening_records" in sql and "0001" in sql


def test_the_last_revision_goes_down_with_rows_and_curves_that_refer_to_them(tmp_path):
    """A downgrade of a working database (a rundown and its curve, which refers to it): the
    table rebuild of a batch drop was refused by the curve's foreign key."""
    from sqlalchemy import text

    from stationd.boltfile import import_bolts
    from tests.db.conftest import BASE, record

    url = url_of(tmp_path / "m.db")
    table = tmp_path / "bolts.yaml"
    table.write_text(BASE)
    with Repository.open(url) as repo:
        import_bolts(repo, table)
        repo.start_vehicle("VIN1", "SEDAN")
        rec = record(repo, "VIN1", "B1", tightening_id=1)
    engine = make_engine(url)
    with engine.begin() as conn:
        conn.execute(text("INSERT INTO curves (record_id, tightening_id, trace_type, unit, "
                          "sample_period_s, \"values\", recorded_at) VALUES (:r, 1, 'torque', "
                          "'Nm', 0.01, '[1.0]', '2026-11-29 12:00:00')"), {"r": rec})
        command.downgrade(alembic_config(connection=conn), "0013")
    columns = {c["name"] for c in inspect(engine).get_columns("tightening_records")}
    assert "controller_at" not in columns
    with engine.connect() as conn:
        assert conn.execute(text("SELECT count(*) FROM tightening_records")).scalar() == 1
        assert conn.execute(text("SELECT count(*) FROM curves")).scalar() == 1
    engine.dispose()


def test_results_of_no_bolt_stored_before_their_release_count_as_acknowledged(tmp_path):
    """A station upgraded to the release that sends its results of no bolt and those not read
    over OPC UA (0018), and its OK results not taken for a tightening (0019): those stored
    before count as acknowledged (a reviewer: an MES asking for the unacknowledged ones got
    the station's whole history of them at once); its rundowns, and its controller events
    that are no result (a batch increment), stay as they were."""
    from sqlalchemy import text

    from db.kinds import NOT_TAKEN
    from stationd.boltfile import import_bolts
    from tests.db.conftest import BASE, record

    url = url_of(tmp_path / "m.db")
    table = tmp_path / "bolts.yaml"
    table.write_text(BASE)
    engine = make_engine(url)
    with engine.begin() as conn:
        command.upgrade(alembic_config(connection=conn), "0017")
    with Repository.open(url) as repo:       # (opening migrates to the head: below, back)
        import_bolts(repo, table)
        repo.start_vehicle("VIN1", "SEDAN")
        record(repo, "VIN1", "B1", tightening_id=1)
        repo.others.record_unattributed(vin="VIN1", controller_vin=None, tightening_id=2, pset=1,
                                        ok=True, torque_nm=1.0, angle_deg=2.0, result_at=None,
                                        reason="outside a tool enable")
        for what in (NOT_TAKEN, "batch increment"):
            repo.others.record_controller_event(
                result_type=0, what=what, vin="VIN1", bolt="B2", controller_vin=None,
                tightening_id=3, pset=1, ok=True, torque_nm=4.9, angle_deg=2.0,
                result_at=None)
        assert repo.ledger.unacknowledged_count() == 3   # the rundown, those two results
    with engine.begin() as conn:
        conn.execute(text("DELETE FROM opcua_acknowledged"))
        command.downgrade(alembic_config(connection=conn), "0017")
        command.upgrade(alembic_config(connection=conn), "head")
    with Repository.open(url) as repo:
        assert repo.ledger.unacknowledged_count() == 1          # the rundown alone
        assert [e["kind"] for e in repo.ledger.unacknowledged(0)] == ["rundown"]
    engine.dispose()


def test_holds_stored_before_have_no_verdict_after_the_upgrade(tmp_path):
    """A bolt held where no result says it (a link cut's, a lost push's) was stored with
    status 'nok': an MES counting status 'nok' counted each as a NOK tightening (an MES
    integrator's trial).  0020 sets them to NULL (no verdict), leaves the controller's own
    events as they were, keeps the status check, and its downgrade puts 'nok' back."""
    from sqlalchemy import text
    from sqlalchemy.exc import IntegrityError

    from db.kinds import CUT_UNKNOWN, LOST_UNKNOWN

    url = url_of(tmp_path / "m.db")
    engine = make_engine(url)
    with engine.begin() as conn:
        command.upgrade(alembic_config(connection=conn), "0019")
        for what in (CUT_UNKNOWN, LOST_UNKNOWN, "batch increment"):
            conn.execute(text("INSERT INTO controller_events (result_type, what, status, "
                              "recorded_at) VALUES (0, :w, 'nok', '2026-12-01 08:00:00')"),
                         {"w": what})
        command.upgrade(alembic_config(connection=conn), "head")
    with engine.connect() as conn:
        assert dict(conn.execute(text("SELECT what, status FROM controller_events")).all()) \
            == {CUT_UNKNOWN: None, LOST_UNKNOWN: None, "batch increment": "nok"}
    with pytest.raises(IntegrityError), engine.begin() as conn:
        conn.execute(text("INSERT INTO controller_events (result_type, what, status, "
                          "recorded_at) VALUES (0, 'x', 'bad', '2026-12-01 08:00:00')"))
    with engine.begin() as conn:
        command.downgrade(alembic_config(connection=conn), "0019")
    with engine.connect() as conn:
        assert {s for (s,) in conn.execute(text("SELECT status FROM controller_events"))} \
            == {"nok"}
    engine.dispose()


def test_an_upgrade_says_the_schema_it_moved_and_a_newer_database_is_named_so(tmp_path,
                                                                              caplog):
    """A maintenance trial: a new stationd moved a station's database from 0017 to 0020 with
    no line in the journal (the way back, an older stationd, then refused it); and a report
    of a later stationd's database (a later schema) was told to migrate it, which failed.  The
    move is said once; a reopen at the same schema says nothing; a newer schema is named
    as a newer stationd's."""
    import logging

    from sqlalchemy import text

    from db.errors import DatabaseError

    url = url_of(tmp_path / "old.db")
    engine = make_engine(url)
    upgrade(engine, "0017")
    engine.dispose()
    with caplog.at_level(logging.INFO, logger="db"):
        Repository.open(url).close()
        Repository.open(url).close()
    said = [r for r in caplog.records if "migrated" in r.getMessage()]
    assert len(said) == 1 and "schema 0017 migrated to 0023" in said[0].getMessage()
    assert said[0].levelno == logging.WARNING
    engine = make_engine(url)
    with engine.begin() as conn:
        conn.execute(text("UPDATE alembic_version SET version_num = '0099'"))
    engine.dispose()
    with pytest.raises(DatabaseError) as err:
        Repository.open(url, read_only=True)
    assert "schema 0099, this stationd reads 0023: a newer stationd's database" in str(err.value)
    assert "migrates it" not in str(err.value)
