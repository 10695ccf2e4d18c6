"""``stationd bench soak`` runs the daemon through a (here very short) shift with an outage
and reports what a shift must show (the long runs with load are the benchmark's business)."""

import json

import pytest

import stationd.bench.soak as soak
from stationd.cli import main


@pytest.mark.timeout(300)
def test_bench_soak_reports_tightened_wrong_exits_and_lost(capsys, monkeypatch):
    monkeypatch.setattr(soak, "FAULT_RATE", 1.0)          # an outage before every bolt
    monkeypatch.setattr(soak, "FAULTS", ("controller", "lift"))
    code = main(["bench", "soak", "--bolts", "2", "--per-vehicle", "2", "--faults", "--seed",
                 "4", "--json"])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0
    assert summary["wrong_bolt_sends"] == 0 and summary["exits"] == 0
    assert summary["results_lost"] == 0
    assert summary["tightened"] == 2 and sum(summary["faults_injected"].values()) == 2


def test_bench_soak_refuses_bad_numbers_in_one_line(capsys):
    assert main(["bench", "soak", "--bolts", "0"]) == 2
    assert main(["bench", "soak", "--load", "-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("must" in line for line in err)


@pytest.mark.timeout(300)
def test_bench_soak_survives_reloads_good_bad_and_with_the_lift_down(capsys, monkeypatch):
    """A reload before every bolt: the station reopens on a valid file, keeps running on a bolt
    table with a duplicate id (refused, counted), and runs in fault on a lift URL where nothing
    answers until the next reload; every bolt still tightened, nothing lost."""
    monkeypatch.setattr(soak, "FAULT_RATE", 1.0)
    monkeypatch.setattr(soak, "FAULTS", ("reload with a bad bolt table", "reload",
                                         "reload with the lift down"))
    code = main(["bench", "soak", "--bolts", "3", "--per-vehicle", "3", "--faults", "--seed",
                 "2", "--json"])
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0, summary
    assert summary["wrong_bolt_sends"] == 0 and summary["exits"] == 0
    assert summary["results_lost"] == 0 and summary["tightened"] == 3
    assert summary["faults_injected"] == {k: 1 for k in soak.FAULTS}   # one of each, dealt
    assert summary["reloads_refused"] == 1
    assert summary["device_faults"].get("lift", 0) >= 1     # the new station's lift, down
