"""The demo's NOK policy and its summary, without running the simulated vehicle: a station file
without a ``nok:`` section runs the demo's policy (its loosen pset programmed on the simulated
controller), one with its own keeps it; the summary counts NOKs, loosenings, locks and
releases, and a parameter send for a locked bolt, or a rundown not recorded, is a FAIL."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest

from stationd.bus import EventBus
from stationd.config import load_station_config
from stationd.demo.station import (
    LOOSEN_PROGRAM,
    SIM_CONFIG,
    _summary,
    demo_policy,
    loosen_programs,
    policy_words,
)
from stationd.sim.devices_cli import psets_of
from stationd.station.events import BoltLocked, BoltReleased, ResultRecorded
from stationd.station.policy import NokPolicy, NokRule
from tests.demo.test_station_services import _one_pair

ROOT = Path(__file__).resolve().parents[2]


def _bus() -> SimpleNamespace:
    """B01: NOK, loosened, NOK, loosened, NOK, locked, released, loosened, OK; B02: OK."""
    bus = EventBus()
    kinds = [("tightening", False), ("loosening", True), ("tightening", False),
             ("loosening", True), ("tightening", False)]
    for k, (kind, ok) in enumerate(kinds):
        bus.publish(ResultRecorded("V", "B01", ok, 20.0, 30.0, k, kind=kind))
    bus.publish(BoltLocked("B01", 3))
    bus.publish(BoltReleased("B01", "supervisor"))
    bus.publish(ResultRecorded("V", "B01", True, 1.0, 1.0, 6, kind="loosening"))
    bus.publish(ResultRecorded("V", "B01", True, 20.0, 30.0, 7))
    bus.publish(ResultRecorded("V", "B02", True, 20.0, 30.0, 8))
    return SimpleNamespace(bus=bus)


REPORT = [{"bolt": "B01", "result": "OK 20.0 Nm", "ok": True, "rundowns": 7,
           "before": ["NOK 20.0 Nm", "loosened (pset 4) OK"]},
          {"bolt": "B02", "result": "OK 20.0 Nm", "ok": True, "rundowns": 1}]


def test_the_summary_counts_the_nok_policy_and_stays_honest():
    s = _summary(_bus(), REPORT, 2, 0)
    assert s["verdict"].startswith("PASS: 2/2 bolts handled")
    assert (s["results"], s["recorded"]) == (8, 8)
    assert s["nok_policy"] == {"nok": 3, "loosenings": 3, "locks": 1, "releases": 1,
                               "locked_sends": 0}
    assert s["operators"] == {"-": 8}     # nobody signed in on this bus: said as such
    locked = _summary(_bus(), REPORT, 2, 0, locked_sends=1)
    assert locked["verdict"] == "FAIL: 1 parameter send for a locked bolt"
    lost = _summary(_bus(), [{**REPORT[0], "rundowns": 8}, REPORT[1]], 2, 0)
    assert "1 result not recorded" in lost["verdict"]
    stuck = _summary(_bus(), [{**REPORT[0], "unfinished": True}, REPORT[1]], 2, 0)
    assert "1 of 2 bolts not handled" in stuck["verdict"]


def test_the_demo_runs_its_policy_only_where_the_station_file_has_none():
    cfg = load_station_config(SIM_CONFIG)
    assert cfg.bolts_path is not None
    psets = psets_of(cfg.bolts_path)
    policy = demo_policy(cfg, psets)
    assert policy is not None
    assert policy.default == NokRule(max_nok=3)
    assert policy.rule("B01", 1).strategy == "repeat"
    assert policy.rule("B02", 2) == policy.rule("B03", 3) == NokRule(3, "loosen", 4)
    assert loosen_programs(policy) == {4: LOOSEN_PROGRAM} and 4 not in psets
    assert policy_words(policy) == ("max_nok 3, repeat; pset 2: loosen with loosen pset 4; "
                                    "pset 3: loosen with loosen pset 4")
    own = replace(cfg, nok=NokPolicy(NokRule(max_nok=2, strategy="skip")))
    assert demo_policy(own, psets) is None


@pytest.mark.timeout(300)
def test_the_demos_lines_read_in_the_order_things_happened_on_one_stream(tmp_path):
    """"B11 locked after 3 NOK ..." came after B11's final OK line: the station's notice on
    stderr, the bolt's line on stdout.  Seed 7's first bolt is a stubborn joint: it locks,
    is released, then tightens OK; every line of it on stdout, in that order."""
    run = subprocess.run(
        [sys.executable, "-m", "stationd", "demo", "--config", str(_one_pair(tmp_path)),
         "--cycles", "1", "--seed", "7", "--no-http", "--no-opcua"],
        capture_output=True, text=True, timeout=240, cwd=tmp_path, check=False,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 0, run.stdout + run.stderr
    lines = run.stdout.splitlines()
    locked = next(i for i, s in enumerate(lines) if " locked after 3 NOK in a row" in s)
    # the station's notice, a journal line: its time stamp first (issue 30, item 5)
    found = re.search(r"(\S+) locked after 3 NOK in a row", lines[locked])
    assert found is not None and re.match(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d", lines[locked])
    bolt = found[1]
    before = lines.index(next(s for s in lines if s.startswith(f"  {bolt} first: ")))
    final = lines.index(next(s for s in lines if s.startswith(f"{bolt}: pset ")))
    assert locked < before < final and "OK" in lines[final]
    assert lines.index(next(s for s in lines if "in view of no pair" in s)) < locked
    assert "locked after" not in run.stderr and "in view of no pair" not in run.stderr
