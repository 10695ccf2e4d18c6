"""The fan-out benchmark runs and reports what both clients received (figures: printed)."""

from __future__ import annotations

from stationd.web.bench import fanout_bench


def test_fanout_bench_reports_both_clients_served():
    r = fanout_bench(seconds=0.6, rate_hz=20.0, clients=2)
    print(r)
    assert r["clients"] == 2 and r["published"] >= 3
    assert len(r["snapshots_per_client"]) == 2
    assert all(n >= 1 for n in r["snapshots_per_client"])
    assert r["cpu_pct_with"] >= 0.0 and r["cpu_pct_without"] >= 0.0
