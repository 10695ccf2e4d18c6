"""``stationd bench soak`` runs the daemon, as ``stationd run`` runs it, through a (here very
short) shift with disturbances, and reports what a shift must show (the long runs with load
are the benchmark's business)."""

import json

import pytest

from stationd.bench.soak import soak_station
from stationd.cli import main
from stationd.sim.soak import Arrive, Depart, Outage, Reload, Visit


@pytest.mark.timeout(300)
def test_bench_soak_reports_tightened_wrong_exits_and_lost(capsys):
    code = main(["bench", "soak", "--bolts", "2", "--per-vehicle", "2", "--seed", "4",
                 "--json"])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0, summary
    assert summary["wrong_sends"] == 0 and summary["exits"] == 0
    assert summary["results_lost"] == 0 and summary["results_made"] == 2
    assert summary["bolts_tightened"] == 2


@pytest.mark.timeout(300)
def test_the_daemon_survives_outages_reloads_and_a_rework_losing_nothing():
    """Every disturbance of a shift once, on the running daemon over the real protocols: the
    controller off before a bolt and mid-tightening, the lift PLC silent, a camera pair
    unplugged, a valid reload (the station reopens), a bolt table with a duplicate id
    (refused: the running station stays), a station whose lift does not answer (a fault of
    the new station until the next reload), and the closed VIN coming back (rework)."""
    plan = [Arrive("SOAKTEST000000001", 1), Outage("wrench", 1.0), Visit("B01"),
            Reload("bad bolt table"), Outage("lift", 1.0), Visit("B02", power_cut=True),
            Reload("valid"), Outage("cameras", 1.0), Reload("lift down"), Visit("B03"),
            Depart(), Arrive("SOAKTEST000000001", 1, rework=True), Visit("B04"), Depart()]
    tally = soak_station(plan, seed=2)
    s = tally.summary()
    assert tally.passed, s
    assert s["bolts_tightened"] == 4 and s["results_recorded"] == 4 and s["reworks"] == 1
    assert s["reloads_refused"] == 1
    assert {"lift", "wrench"} <= set(s["device_faults"])   # seen as faults, then back
    assert s["outages"]["controller mid-tightening"] == 1


def test_bench_soak_refuses_bad_numbers_in_one_line(capsys):
    assert main(["bench", "soak", "--bolts", "0"]) == 2
    assert main(["bench", "soak", "--load", "-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("must" in line for line in err)
