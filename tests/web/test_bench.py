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


def test_screen_clients_stand_ins_read_the_stream_and_load_the_frames_in_view(live_server):
    """``bench station --clients sse``: one stand-in holds the event stream like the operator
    screen, the other loads the cameras' list and frames like the cameras screen (all once,
    then the first four, those a 1920x1080 window shows)."""
    import time

    import numpy as np

    from stationd.web.bench import ScreenClients

    srv = live_server()
    img = np.random.default_rng(4).integers(0, 255, (400, 600), dtype=np.uint8)
    for p in ("p1", "p2", "p3", "p4"):
        for side in ("left", "right"):
            srv.frames.put(p, side, img)
    clients = ScreenClients(srv.url, 2, force_sse=True)
    try:
        assert clients.start() == "sse" and clients.why_not_chromium == "forced"
        assert clients.pages == ["", "cameras"]
        frame = "/api/cameras/{pair}/{side}/frame.jpg"
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not (
                srv.server.clients == 1 and srv.server.requests["/api/cameras"] >= 3):
            time.sleep(0.05)
        assert srv.server.clients == 1
        lists = srv.server.requests["/api/cameras"]
        assert lists >= 3 and srv.server.requests["/cameras"] == 1
        # every frame at the first refresh, then 4 per refresh (one may be in flight)
        assert 8 + 4 * (lists - 2) <= srv.server.requests[frame] <= 8 + 4 * (lists - 1)
    finally:
        clients.close()


def test_screen_clients_under_sched_idle_run_every_browser_process_so(live_server):
    """``bench station --browser-nice idle``: Chromium and every process it starts run under
    SCHED_IDLE (policy 5 in /proc/PID/sched), as a kiosk unit with
    CPUSchedulingPolicy=idle would run them."""
    import os
    import shutil
    import time

    import pytest

    from stationd.web.bench import ScreenClients, tree_pids

    if shutil.which("chromium") is None:
        pytest.skip("chromium is not installed (.ci/bootstrap installs it as root)")
    srv = live_server()
    clients = ScreenClients(srv.url, 1, nice="idle")
    try:
        assert clients.start() == "chromium"
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and srv.server.clients < 1:
            time.sleep(0.1)
        assert srv.server.clients == 1            # the page is served and streaming
        pids = tree_pids([p.pid for p in clients._procs])
        policies = {}
        for pid in pids:
            try:
                policies[pid] = os.sched_getscheduler(pid)
            except OSError:
                continue                          # a process that has just ended
        assert len(policies) >= 2 and set(policies.values()) == {os.SCHED_IDLE}, policies
    finally:
        clients.close()


def test_browser_nice_takes_a_number_or_idle(capsys):
    import pytest

    from stationd.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["bench", "station", "--browsers", "1", "--browser-nice", "fast"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "'fast': a number or idle" in err
    assert "Traceback" not in err
