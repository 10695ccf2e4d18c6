"""The station's schema, migrations and repository on a real PostgreSQL server (psycopg 3),
as on SQLite: the line database and a station that keeps its records on a server."""

from __future__ import annotations

from datetime import UTC, datetime

from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext

from db.engine import make_engine
from db.migrate import current_revision, head_revision
from db.models import Base
from db.repository import Repository
from stationd.boltfile import import_bolts
from tests.db.conftest import record


def test_the_migrations_make_the_models_schema_on_postgresql(pg_url):
    Repository.open(pg_url).close()
    engine = make_engine(pg_url)
    with engine.connect() as conn:
        ctx = MigrationContext.configure(conn, opts={"compare_type": True})
        assert list(compare_metadata(ctx, Base.metadata)) == []
        assert current_revision(conn) == head_revision()
    engine.dispose()


def test_a_vehicle_its_records_commands_and_feed_on_postgresql(pg_url, bolts_file):
    with Repository.open(pg_url) as repo:
        import_bolts(repo, bolts_file)
        repo.start_vehicle("VINPG1", "SEDAN")
        at = datetime(2026, 11, 27, 8, 0, tzinfo=UTC)
        enable = repo.enables.note("VINPG1", "B1", 1, None, {"point_mm": [0, 0, 0]}, at)
        record(repo, "VINPG1", "B1", tightening_id=11, enable_id=enable)
        assert repo.enables.owed() is None
        assert record(repo, "VINPG1", "B1", tightening_id=11) is not None   # resent: once
        repo.ledger.record_command(at=at, user="sam", source="cli", kind="skip", vin="VINPG1",
                                   bolt="B2", comment="no access")
        assert repo.others.record_unattributed(vin="VINPG1", controller_vin=None, tightening_id=12,
                                               pset=1, ok=False, torque_nm=1.0, angle_deg=2.0,
                                               result_at=None, reason="outside any tightening")
        report = repo.close_vehicle("VINPG1")
        # (B2 is skipped, not missing, when its skip's time is after the vehicle's start)
        assert report.ok == ["B1"] and sorted(report.untightened) == ["B2", "B3"]
        feed = repo.ledger.since(0)
        assert [e["kind"] for e in feed] == ["rundown", "command", "unattributed", "closing"]
        assert feed[-1]["record"]["not_ok"] == {"missing": ["B2", "B3"]}
        assert [e["seq"] for e in feed] == sorted(e["seq"] for e in feed)
        assert repo.ledger.skipped("VINPG1", None) == {"B2": ("sam", "no access")}
        assert len(repo.ledger.db_id()) == 36
