"""The multi-station demo's words (issue 30, item 7): the NOK policy's counts say whose they
are and cover every station; each station's journal lines carry its id; the /line link is
printed only while the page is served (with --hold), not as the demo exits; each run's vehicle
has its own VIN (the run's id in the serial part), so a line database tells two runs apart.

Why: the NOK line counted the first station only without saying so, a notice of station 2
came without ``DEMO-2``, the /line link was printed when it was already dead, and every run
used make_vin(1): four demos against one line database read as one car."""

from __future__ import annotations

import logging
import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from stationd.config import load_station_config
from stationd.shell.daemon import Station
from stationd.sim.vin import is_valid, make_vin
from stationd.station.events import Notice, Said
from tests.demo.test_station_services import ROOT, _one_pair


def _counted_re(word: str) -> str:
    """A count of ``word`` as a regular expression, in proper English only: "1 NOK result",
    "0 NOK results", "3 NOK results" (neither "1 NOK results" nor "3 NOK result(s)")."""
    return rf"(?<!\d)(?:1 {word}|(?:0|[2-9]|[1-9]\d+) {word}s)"


def _demo(tmp: Path, pg_url: str) -> str:
    run = subprocess.run(
        [sys.executable, "-m", "stationd", "demo", "--config", str(_one_pair(tmp)),
         "--cycles", "1", "--seed", "7", "--no-http", "--no-opcua", "--line-db", pg_url,
         "--stations", "2"], capture_output=True, text=True, timeout=600, cwd=tmp,
        check=False, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 0, run.stdout + run.stderr
    return run.stdout


@pytest.mark.timeout(900)
def test_two_runs_of_a_two_station_line_say_whose_counts_and_have_their_own_vins(
        tmp_path, pg_url):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first, second = _demo(tmp_path / "a", pg_url), _demo(tmp_path / "b", pg_url)
    vins = []
    for out in (first, second):
        found = re.search(r"^vehicle: (\w{17}) \(this run's own VIN: run id (\d{6}) ", out,
                          re.M)
        assert found is not None, out
        vin = found[1]
        assert is_valid(vin) and vin == make_vin(int(found[2]))
        vins.append(vin)
        # the line's read-back names this run's vehicle alone
        assert re.search(rf"^line database: {_counted_re('rundown')} of {vin} from 2 stations", out,
                         re.M), out
        # whose NOK counts: the first station's said so, the second's on its line, the sum
        assert re.search(rf"^NOK policy \(DEMO-1\): {_counted_re('NOK result')}, ", out, re.M), out
        assert re.search(rf"^DEMO-2: .* {_counted_re('result')} recorded; NOK policy: "
                         rf"{_counted_re('NOK result')}", out, re.M), out
        assert re.search(rf"^NOK policy, all 2 stations: {_counted_re('NOK result')}", out,
                         re.M), out
        # the first station's own lines say whose they are too (DEMO-2's always did), and a
        # total over both stations: bolts OK, NOK results, rundowns per operator
        assert re.search(r"^DEMO-1 summary: \d+/\d+ bolts OK", out, re.M), out
        assert re.search(r"^DEMO-1 B\d\d: pset \d+, ", out, re.M), out
        assert not re.search(r"^(summary: |B\d\d: |  B\d\d first: )", out, re.M), out
        assert re.search(r"^DEMO-1 rundowns recorded, by who was signed in at the station: "
                         r"\d+ by user 'operator'$", out, re.M), out
        assert re.search(r"^DEMO-2: .*; rundowns recorded, by who was signed in at the "
                         r"station: \d+ by user 'operator'$", out, re.M), out
        assert re.search(rf"^all 2 stations: \d+/2 bolts OK, {_counted_re('NOK result')}; rundowns "
                         r"recorded, by who was signed in at the station: \d+ by user "
                         r"'operator'$", out, re.M), out
        assert re.search(r"^PASS: all 2 stations, 2/2 bolts handled \(DEMO-1 1/1: .*; "
                         r"DEMO-2 1/1: ", out, re.M), out
        assert "more station(s) PASS" not in out
        # the bolts its vehicle closed with not worked are the first station's, said so
        assert re.search(rf"^DEMO-1 vehicle {vin} closed with \d+ bolts not worked at this "
                         r"station \(the demo works 1 of its bolts here, at most 1 at each "
                         r"other station, then lowers the lift\)", out,
                         re.M), out
        # no /line link as the demo exits (it would be dead): where the rows are instead
        assert not re.search(r"https?://\S+/line", out), out
        assert "the screens' /line page: with --hold, while the demo holds" in out
    assert vins[0] != vins[1]


def test_a_labelled_stations_journal_lines_carry_its_id(caplog, tmp_path):
    """Each station of the demo's line is labelled (Effects.label): its notices, its state
    lines, its commands' lines and its records' (a vehicle's close: a new user's trial read
    one VIN closed twice, with different counts, neither line naming its station) start with
    its id."""
    cfg = replace(load_station_config(ROOT / "config" / "sim" / "station.yaml"),
                  database_url=f"sqlite:///{tmp_path}/st.db")
    station = Station(cfg)
    station.effects.label("DEMO-2")
    repo = station.records.open()
    repo.start_vehicle("SIMVIN0000000001", "SIM-1")
    with caplog.at_level(logging.INFO, logger="stationd"):
        station.effects.publish(Notice(Said.LOCKED, bolt="B12", count=3))
        station.records.close_vehicle("SIMVIN0000000001")
    repo.close()
    said = [r.getMessage() for r in caplog.records]
    assert said[0] == "DEMO-2 B12 locked after 3 NOK in a row: a supervisor releases it"
    assert said[1].startswith("DEMO-2 vehicle SIMVIN0000000001 (SIM-1) closed: "), said
