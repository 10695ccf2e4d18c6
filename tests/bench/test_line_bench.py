"""``stationd bench line`` with tiny sizes: it starts its own PostgreSQL, forwards a few
stations' rundowns, stops the server for a backlog and drains it, then the same for one
station alone; the figures are the
benchmark's business (README), not asserted here beyond being there and sane."""

from __future__ import annotations

import json

import pytest

from stationd.cli import main
from stationd.pgserver import PgServer


@pytest.mark.timeout(240)
def test_bench_line_prints_lag_and_drain_with_tiny_sizes(capsys):
    if PgServer().missing:
        pytest.skip(PgServer().missing or "")
    code = main(["bench", "line", "--stations", "2", "--rundowns", "2", "--interval", "0.1",
                 "--backlog", "30", "--station-backlog", "20", "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    res = json.loads(out.strip().splitlines()[-1])
    n, o, d = res["normal"], res["outage"], res["drain"]
    assert n["rundowns"] == 4 and n["caught_up"]
    assert 0 <= n["lag_s"]["p50"] <= n["lag_s"]["p95"] <= n["lag_s"]["max"] < 30
    assert o["rundowns"] == 30 and o["line_db"] == "stopped" and o["forwarders_down"] == 2
    assert d["rundowns"] >= 30 and d["per_s"] > 0 and d["recording_station"] == "BENCH-01"
    assert d["record_ms"]["n"] >= 1 and d["record_ms"]["p50"] > 0
    so, sd = res["station_outage"], res["station_drain"]
    assert (so["stations"], so["rundowns"], so["forwarders_down"]) == (1, 20, 1)
    assert sd["rundowns"] >= 20 and sd["per_s"] > 0


def test_bench_line_refuses_a_line_database_that_is_not_postgresql(capsys):
    code = main(["bench", "line", "--pg", "sqlite:///line.db"])
    _, err = capsys.readouterr()
    assert code == 2 and "PostgreSQL, not sqlite" in err and len(err.splitlines()) == 1
    code = main(["bench", "line", "--stations", "0"])
    _, err = capsys.readouterr()
    assert code == 2 and "--stations 0" in err
