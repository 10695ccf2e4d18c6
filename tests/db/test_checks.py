"""Calibration checks in the database: migration 0009 creates what the model describes, a check
is stored with each reference's offset and joins the results feed (so the line gets it), and a
bad value is refused."""

from __future__ import annotations

from datetime import UTC, datetime

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import inspect

from db.checks import checks, record_check
from db.engine import make_engine
from db.errors import DataError
from db.ledger import CHECK
from db.migrate import upgrade
from db.models import Base
from db.repository import Repository
from tests.db.conftest import url_of

AT = datetime(2026, 11, 27, 8, 0, tzinfo=UTC)
REFS = {"R1": {"offset_mm": 3.4, "measured_mm": [1.0, 2.0, 3.0], "why": None, "note": None},
        "R2": {"offset_mm": None, "measured_mm": None, "why": "ambiguous", "note": "2 markers"}}


def test_the_migration_creates_the_table_the_model_describes(tmp_path):
    engine = make_engine(url_of(tmp_path / "m.db"))
    upgrade(engine)
    assert "calibration_checks" in inspect(engine).get_table_names()
    with engine.connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn, opts={"compare_type": True}),
                                Base.metadata)
    assert [d for d in diff if "calibration_checks" in str(d)] == []
    engine.dispose()


def test_a_check_is_stored_with_its_references_and_joins_the_feed(tmp_path):
    repo = Repository.open(url_of(tmp_path / "s.db"))
    try:
        before = repo.ledger.last_seq()
        cid = record_check(repo, at=AT, pair="pair2", verdict="moved", reference="R1",
                           offset_mm=3.4, tolerance_mm=2.0, reason=None, references=REFS)
        record_check(repo, at=AT, pair="pair1", verdict="ok", reference="R3", offset_mm=0.1,
                     tolerance_mm=2.0, reason=None, references={})
        (got, *_) = checks(repo, "pair2")
        assert got["id"] == cid and got["verdict"] == "moved" and got["offset_mm"] == 3.4
        assert got["references"]["R2"]["why"] == "ambiguous"
        assert got["at"] == AT
        assert [c["pair"] for c in checks(repo)] == ["pair1", "pair2"]   # newest first
        feed = repo.ledger.since(before)
        assert [e["kind"] for e in feed] == [CHECK, CHECK]
        rec = feed[0]["record"]
        assert rec["pair"] == "pair2" and rec["reference"] == "R1"
        assert rec["references"]["R1"]["offset_mm"] == pytest.approx(3.4)
    finally:
        repo.close()


@pytest.mark.parametrize(("kw", "message"), [
    ({"verdict": "bent"}, "verdict"),
    ({"at": datetime(2026, 11, 27)}, "timezone"),
    ({"offset_mm": float("nan")}, "finite"),
])
def test_bad_values_are_refused(tmp_path, kw, message):
    repo = Repository.open(url_of(tmp_path / "s.db"))
    try:
        args = {"at": AT, "pair": "pair1", "verdict": "ok", "reference": None,
                "offset_mm": 0.1, "tolerance_mm": 2.0, "reason": None, "references": {}}
        with pytest.raises(DataError, match=message):
            record_check(repo, **{**args, **kw})
        assert checks(repo) == []
    finally:
        repo.close()
