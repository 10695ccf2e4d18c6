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
