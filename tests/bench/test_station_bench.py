"""``stationd bench station`` runs the daemon on the simulated station and reports what it
measured (the figures themselves are the benchmark's business, not a timed test's)."""

import json
from typing import Any

import pytest

from stationd.cli import main


def check_the_pass_without_screens(summary: dict[str, Any]) -> None:
    """What ``stationd bench station`` reports of its first pass (the daemon alone), with or
    without a comparison after it: latency and its stages, memory, the idle station."""
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
    idle = summary["idle"]           # polled at its period, not spinning (issue 9)
    assert 0 < idle["plc_requests_per_s"] <= 20 and idle["cpu_pct_of_a_core"] >= 0


@pytest.mark.timeout(300)
def test_bench_station_with_two_browsers_reports_latency_and_cpu_with_and_without(
        tmp_path, capsys):
    """``--browsers 2``: the plan with the screens served to two headless Chromium windows
    (``/`` and ``/cameras``) between two passes without; both sides' figures and the deltas
    against the issue's targets, and proof the clients were really served."""
    import shutil

    out = tmp_path / "bench-station.json"
    code = main(["bench", "station", "--cycles", "2", "--seed", "3", "--browsers", "2",
                 "--paired", "--json", "--out", str(out)])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and summary == json.loads(out.read_text())
    check_the_pass_without_screens(summary)
    sc = summary["screens"]
    has_chromium = bool(shutil.which("chromium") or shutil.which("chromium-browser"))
    assert sc["clients"] == ("chromium" if has_chromium else "sse"), sc["why_not_chromium"]
    assert sc["browsers"] == 2 and sc["pages"] == ["/", "/cameras"]
    assert sc["clients_alive_to_the_end"] is True
    assert sc["frames_served"] >= 1 and sc["snapshots_sent"] >= 1
    for side in ("with", "without"):
        lat = sc[side]["latency_ms"]
        assert 0 < lat["p50"] <= lat["p95"]
        assert sc[side]["cpu_s"] > 0 and sc[side]["wall_s"] > 0
    assert len(sc["without"]["passes"]) == 2
    assert sc["delta"]["latency_p95_ms"] == sc["with"]["latency_ms"]["p95"] - \
        sc["without"]["latency_ms"]["p95"]
    assert set(sc["delta"]) == {"latency_p95_ms", "latency_p50_ms", "cpu_pct_of_a_core"}
    lo, hi = sc["delta_p95_interval_ms"]
    assert lo <= hi and len(sc["with"]["passes"]) == 1
    assert sc["targets"] == {"latency_p95_ms": 10.0, "cpu_pct_of_a_core": 5.0}
    # --paired: the first bolt with the browsers running, the second with them held (and
    # resumed before they are closed: they were alive to the end)
    pr = sc["paired"]
    assert pr["running"]["n"] == 1 and pr["held"]["n"] == 1
    assert pr["delta_p95_ms"] == pr["running"]["p95"] - pr["held"]["p95"]


@pytest.mark.timeout(300)
def test_bench_station_stand_in_clients_run_in_their_own_process(tmp_path, capsys):
    """``--clients sse``: the stand-ins for browsers on the panel PCs run in a process of their
    own (their CPU is theirs, not the daemon's) and are really served.  The first pass, the
    daemon alone, reports what a run without ``--browsers`` does (that run is this one's
    first pass: a test of its own ran the same pass again)."""
    out = tmp_path / "bench-station.json"
    code = main(["bench", "station", "--cycles", "2", "--seed", "3", "--browsers", "2",
                 "--clients", "sse", "--json", "--out", str(out)])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and summary == json.loads(out.read_text())
    check_the_pass_without_screens(summary)
    sc = summary["screens"]
    assert sc["clients"] == "sse" and sc["passes"] == 1
    assert sc["frames_served"] >= 1 and sc["snapshots_sent"] >= 1
    assert sc["browser_cpu_pct_of_a_core"] >= 0
    # the daemon's CPU per pass with the screens is of the same order as without (the
    # clients' reading is not in it), whatever the machine's speed
    assert sc["with"]["cpu_s"] < 3 * sc["without"]["cpu_s"]


def test_passes_with_the_screens_are_pooled_per_pass():
    """``--passes K``: latencies pooled, times per pass (mean), counts added; the deltas
    compare a pass with a pass."""
    from stationd.bench.station import _pooled, _screens_summary

    def run(lat, cpu, wall, **kw):
        return {"latency": lat, "cpu_s": cpu, "wall_s": wall, "clients": "sse",
                "pages": ["/", "/cameras"], "why_not_chromium": "",
                "by_bolt": [(f"B{k}", x) for k, x in enumerate(lat)], **kw}
    served = _pooled([run([10.0, 20.0], 4.0, 10.0, frames_served=3, browser_cpu_s=1.0),
                      run([30.0, 40.0], 6.0, 10.0, frames_served=5, browser_cpu_s=3.0)])
    assert served["latency"] == [10.0, 20.0, 30.0, 40.0]
    assert served["by_bolt"] == [("B0", 10.0), ("B1", 20.0), ("B0", 30.0), ("B1", 40.0)]
    assert (served["cpu_s"], served["wall_s"], served["frames_served"]) == (5.0, 10.0, 8)
    assert served["browser_cpu_s"] == 2.0
    sc = _screens_summary([run([10.0], 4.0, 10.0), run([12.0], 4.0, 10.0)], served, 2)
    assert abs(sc["delta"]["cpu_pct_of_a_core"] - 10.0) < 1e-9      # (5 - 4) s in 10 s
    assert abs(sc["browser_cpu_pct_of_a_core"] - 20.0) < 1e-9       # 2 s in 10 s


def test_tree_cpu_counts_a_process_and_its_children():
    import subprocess
    import sys

    from stationd.web.bench import tree_cpu_s

    busy = "import time\nt = time.process_time()\nwhile time.process_time() - t < 0.3: pass\n"
    parent = subprocess.Popen([sys.executable, "-c",  # a child that runs a busy grandchild
                               "import subprocess, sys, time\n"
                               f"subprocess.run([sys.executable, '-c', {busy!r}])\n"
                               "time.sleep(5)\n"])
    try:
        import time
        deadline = time.monotonic() + 20
        while tree_cpu_s([parent.pid]) < 0.3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert tree_cpu_s([parent.pid]) >= 0.3      # the grandchild's, reaped by the child
        assert tree_cpu_s([]) == 0.0
    finally:
        parent.kill()
        parent.wait()


def test_the_p95_difference_interval_finds_a_shift_and_not_an_absent_one():
    """The interval printed beside the screens' p95 cost, bolts resampled whole: it holds 0
    for two samples of one distribution and excludes it for a 30 ms shift, even with two
    slow placements that set the p95 (the same on both sides, they do not widen it); the
    same latencies give the same interval (seeded); no bolt on both sides, no interval."""
    import math

    import numpy as np

    from stationd.bench.station import p95_delta_interval

    rng = np.random.default_rng(11)
    mean = {f"B{k:02d}": 40.0 + (60.0 if k < 2 else 0.0) for k in range(20)}

    def passes(n: int, shift: float = 0.0) -> list[tuple[str, float]]:
        return [(b, m + shift + float(rng.normal(0, 5))) for _ in range(n)
                for b, m in mean.items()]
    without = passes(4)
    same = passes(3)
    lo, hi = p95_delta_interval(same, without)
    assert lo < 0 < hi and hi - lo < 25, (lo, hi)
    shifted = [(b, x + 30) for b, x in same]
    lo2, hi2 = p95_delta_interval(shifted, without)
    assert 0 < lo2 < 30 < hi2 < 60
    assert p95_delta_interval(shifted, without) == [lo2, hi2]
    assert all(math.isnan(x) for x in p95_delta_interval([], without))
    assert all(math.isnan(x) for x in p95_delta_interval([("X", 1.0)], without))


def test_paired_latencies_are_split_by_the_bolt_they_belong_to():
    """``_split_held``: each latency goes with the state of the bolt it was measured at (a
    bolt may give none, or two when a selection was made again)."""
    from stationd.bench.station import _split_held

    lat = [10.0, 11.0, 12.0, 13.0, 14.0]      # any item: the bench splits (bolt, ms)
    # bolt 0 running (latencies 0, 1), bolt 1 held (2), bolt 2 running (none), bolt 3 held
    held_from = [(0, False), (2, True), (3, False), (3, True)]
    assert _split_held(lat, held_from) == ([10.0, 11.0], [12.0, 13.0, 14.0])
    assert _split_held([], held_from) == ([], [])
