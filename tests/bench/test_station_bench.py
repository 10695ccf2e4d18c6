"""``stationd bench station`` runs the daemon on the simulated station and reports what it
measured (the figures themselves are the benchmark's business, not a timed test's)."""

import json

import pytest

from stationd.cli import main


@pytest.mark.timeout(300)
def test_bench_station_reports_latency_stages_and_memory(tmp_path, capsys):
    out = tmp_path / "bench-station.json"
    code = main(["bench", "station", "--cycles", "2", "--seed", "3", "--json", "--out",
                 str(out)])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and summary == json.loads(out.read_text())
    assert summary["wrong_bolt_sends"] == 0 and summary["not_selected"] == []
    assert summary["selected"] == summary["recorded"] == 2
    assert summary["cameras"] == 8
    lat = summary["latency_ms"]
    assert 0 < lat["p50"] <= lat["p95"] <= lat["max"]
    stages = summary["stages_ms"]
    assert set(stages) == {"localize", "decide", "acknowledge", "grab_slowest_pair",
                           "vision_slowest_pair"}
    assert stages["localize"]["p50"] <= lat["p50"]  # a stage of the whole
    mem = summary["memory_mb"]
    assert mem["peak_rss"] >= mem["rss_after_open"] > 0
    assert 0 < mem["simulated_world_buffers"] < mem["peak_rss"]
