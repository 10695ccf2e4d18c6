"""Tightening curves in the database: migration 0007 creates what the model describes, a curve
is stored with its rundown (found by the controller's tightening id), read back by record or
by tightening id, and a curve that came before its rundown still finds it."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import inspect, update
from sqlalchemy.orm import Session

from db.curves import curves_for, link_curves, store_curve
from db.engine import make_engine
from db.errors import DataError
from db.migrate import current_revision, head_revision, upgrade
from db.models import Base, TighteningCurve
from stationd.boltfile import import_bolts
from tests.db.conftest import record, url_of

TORQUE = [0.5, 10.0, 25.0, 49.5]
ANGLE = [0.0, 10.0, 20.0, 35.0]


def test_the_migration_creates_the_curves_table_the_model_describes(tmp_path):
    engine = make_engine(url_of(tmp_path / "m.db"))
    upgrade(engine)
    assert "curves" in inspect(engine).get_table_names()
    with engine.connect() as conn:
        assert current_revision(conn) == head_revision() == "0023"
        ctx = MigrationContext.configure(conn, opts={"compare_type": True})
        assert list(compare_metadata(ctx, Base.metadata)) == []
    engine.dispose()


def store_pair(repo, tid: int, **kw) -> tuple[int, int]:
    a = store_curve(repo, tightening_id=tid, trace_type=1, unit="deg", values=ANGLE,
                    sample_period_s=0.002, **kw)
    t = store_curve(repo, tightening_id=tid, trace_type=2, unit="Nm", values=TORQUE,
                    sample_period_s=0.002, **kw)
    return a, t


def test_a_curve_is_stored_with_the_rundown_of_its_tightening_id(repo, bolts_file):
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    rec = record(repo, "VIN1", "B1", tightening_id=41)
    other = record(repo, "VIN1", "B2", tightening_id=42)
    at = datetime(2026, 11, 27, 8, 0, tzinfo=UTC)
    store_pair(repo, 41, result_at=at)
    curves = curves_for(repo, record_id=rec)
    assert [(c["name"], c["unit"], c["record_id"]) for c in curves] == [
        ("angle", "deg", rec), ("torque", "Nm", rec)]
    assert curves[1]["values"] == TORQUE and curves[1]["sample_period_s"] == 0.002
    assert curves[1]["result_at"] == at.isoformat()
    assert curves_for(repo, record_id=other) == []
    assert [c["name"] for c in curves_for(repo, tightening_id=41)] == ["angle", "torque"]
    assert curves_for(repo, record_id=9999) == []


def test_a_curve_stored_before_its_rundown_is_found_by_tightening_id(repo, bolts_file):
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    store_pair(repo, 7)                        # no rundown with id 7 yet
    with Session(repo.engine) as s:
        assert s.query(TighteningCurve).filter(TighteningCurve.record_id.is_(None)).count() == 2
    rec = record(repo, "VIN1", "B1", tightening_id=7)
    assert [c["name"] for c in curves_for(repo, record_id=rec)] == ["angle", "torque"]
    assert [c["record_id"] for c in curves_for(repo, record_id=rec)] == [None, None]
    assert link_curves(repo, 7, rec) == 2 and link_curves(repo, 7, rec) == 0
    assert [c["record_id"] for c in curves_for(repo, record_id=rec)] == [rec, rec]


def test_an_old_curve_with_a_reused_id_is_not_taken(repo, bolts_file):
    """A controller's ids start again after a reset: a curve stored long before a rundown
    with the same id is not its curve."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    ids = store_pair(repo, 3)
    with Session(repo.engine) as s, s.begin():
        s.execute(update(TighteningCurve).where(TighteningCurve.id.in_(ids))
                  .values(recorded_at=datetime.now(UTC) - timedelta(days=2)))
    rec = record(repo, "VIN1", "B1", tightening_id=3)
    assert curves_for(repo, record_id=rec) == []


def test_bad_curves_are_refused(repo, bolts_file):
    with pytest.raises(DataError, match="finite"):
        store_curve(repo, tightening_id=1, trace_type=2, unit="Nm", values=[1.0, float("nan")])
    with pytest.raises(DataError, match="sample times"):
        store_curve(repo, tightening_id=1, trace_type=2, unit="Nm", values=[1.0, 2.0],
                    times_s=[0.0])
    with pytest.raises(DataError, match="timezone"):
        store_curve(repo, tightening_id=1, trace_type=2, unit="Nm", values=[1.0],
                    result_at=datetime(2026, 1, 1))            # naive: refused
    with pytest.raises(DataError, match="no rundown record 5"):
        store_curve(repo, tightening_id=1, trace_type=2, unit="Nm", values=[1.0], record_id=5)
    with pytest.raises(ValueError, match="record_id or tightening_id"):
        curves_for(repo)


def test_each_curve_is_a_feed_entry_with_its_samples_and_its_rundown(repo, bolts_file):
    """The results feed (what the forwarder takes to the line database) carries each curve
    whole, in order after its rundown; one stored before its rundown has the tightening id
    as its only link."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    early = store_curve(repo, tightening_id=43, trace_type=2, unit="Nm", values=TORQUE,
                        sample_period_s=0.002)
    rec = record(repo, "VIN1", "B1", tightening_id=41)
    angle, torque = store_pair(repo, 41)
    feed = repo.ledger.since(0)
    assert [(e["kind"], e["record"]["id"]) for e in feed] == [
        ("curve", early), ("rundown", rec), ("curve", angle), ("curve", torque)]
    first, _, a, t = (e["record"] for e in feed)
    assert (t["tightening_id"], t["record_id"], t["vin"], t["bolt"]) == (41, rec, "VIN1", "B1")
    assert (a["trace_type"], a["unit"], a["values"]) == (1, "deg", ANGLE)
    assert t["values"] == TORQUE and t["sample_period_s"] == 0.002 and t["times_s"] is None
    assert (first["tightening_id"], first["record_id"], first["vin"]) == (43, None, None)
