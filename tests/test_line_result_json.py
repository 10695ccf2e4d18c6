"""A line rundown as ``line results --json`` and ``/api/line/results`` give it
(:meth:`stationd.linedb.LineResult.to_json`): each limit named, and the exports' spellings
beside the older ones (a quality trial: bare [target, min, max] arrays, ``ok`` and
``parameters_version`` where the exports say ``status`` and ``parameter_version``)."""

from __future__ import annotations

from datetime import UTC, datetime

from stationd.linedb import LineResult


def test_each_limit_is_named_and_the_exports_spellings_are_there():
    at = datetime(2026, 12, 2, 8, 0, tzinfo=UTC)
    r = LineResult("ST-1", "db1", 7, at, "VIN1", "SEDAN", "B1", False, "tightening", 124.5,
                   12.0, 2, at, "olga", 2, 41, (110.0, 100.0, 120.0), (None, 20.0, 80.0))
    j = r.to_json()
    assert (j["torque_target_nm"], j["torque_min_nm"], j["torque_max_nm"]) == (110.0, 100.0,
                                                                                120.0)
    assert (j["angle_target_deg"], j["angle_min_deg"], j["angle_max_deg"]) == (None, 20.0, 80.0)
    assert j["torque_window_nm"] == [110.0, 100.0, 120.0]        # as documented before
    assert (j["status"], j["ok"]) == ("nok", False)
    assert j["parameter_version"] == j["parameters_version"] == 2
    assert j["at"] == j["received_at"] == "2026-12-02T08:00:00+00:00"
