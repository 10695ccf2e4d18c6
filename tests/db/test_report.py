"""A vehicle's report line (db/report.py): the journal's closing line and ``db report``'s
first line name at most ten missing bolts and count the rest (the report lists every bolt
below it; 45 names made the line about 700 characters long)."""

from __future__ import annotations

from datetime import UTC, datetime

from db.kinds import MISSING, OK
from db.report import MISSING_NAMED, BoltResult, VehicleInfo, VehicleReport

AT = datetime(2026, 11, 29, 12, 0, tzinfo=UTC)


def _report(n_ok: int, n_missing: int) -> VehicleReport:
    bolts = [BoltResult(f"B{k:02d}", f"bolt {k}", OK if k <= n_ok else MISSING,
                        1 if k <= n_ok else 0) for k in range(1, n_ok + n_missing + 1)]
    return VehicleReport(VehicleInfo("VIN1", "SEDAN", AT, AT), tuple(bolts), n_ok, 0)


def test_at_most_ten_missing_bolts_are_named_and_the_rest_counted():
    line = _report(5, 45).counts()
    assert "45 missing (B06, B07, B08, B09, B10, B11, B12, B13, B14, B15 and 35 more)" in line
    assert "B16" not in line
    assert len(_report(5, 45).missing) == 45     # the list itself is whole (JSON, exports)


def test_ten_missing_bolts_or_fewer_are_all_named():
    line = _report(40, MISSING_NAMED).counts()
    assert f"{MISSING_NAMED} missing (B41, " in line and "B50)" in line and "more" not in line
    assert "1 missing (B50)" in _report(49, 1).counts()
