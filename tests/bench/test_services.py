"""``stationd bench station --opcua --line``: the events' delays are matched to the results
they carry (the k-th event naming a bolt with the k-th result stored for it), and options
that would mix two comparisons are refused in one line."""

from __future__ import annotations

import pytest

from stationd.bench.services import delays_ms
from stationd.cli import main


def test_each_event_is_timed_from_the_result_it_carries():
    stored = [("B01", 10.0), ("B02", 11.0), ("B01", 12.0)]
    received = [{"bolt": "B01", "t": 10.02, "seq": 1}, {"bolt": "B02", "t": 11.05, "seq": 2},
                {"bolt": "B01", "t": 12.01, "seq": 3}, {"bolt": "B09", "t": 13.0, "seq": 4}]
    assert delays_ms(stored, received) == pytest.approx([20.0, 50.0, 10.0], abs=1e-6)


@pytest.mark.parametrize("argv", [["bench", "station", "--browsers", "1", "--opcua"],
                                  ["bench", "station", "--paired", "--line"]])
def test_two_comparisons_at_once_are_refused(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and ("one comparison at a time" in err or "--browsers" in err)


@pytest.mark.timeout(300)
def test_bench_station_with_opcua_and_the_line_times_every_event(tmp_path, capsys):
    import json

    from stationd.pgserver import PgServer

    if PgServer().missing:
        pytest.skip(PgServer().missing)
    out = tmp_path / "bench.json"
    code = main(["bench", "station", "--cycles", "2", "--seed", "3", "--opcua", "--line",
                 "--json", "--out", str(out)])
    assert code == 0
    s = json.loads(capsys.readouterr().out.strip().splitlines()[-1])["services"]
    assert s["stored"] == s["events"] == 2 == s["opcua_event_delay_ms"]["n"]
    assert 0.0 < s["opcua_event_delay_ms"]["p95"] < 5000.0
    assert s["line_drained"] is True
    assert s["with"]["n"] == 2 and s["without"]["n"] == 4
