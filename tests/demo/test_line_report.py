"""The demo's read-back of the line: it checks the line database against every station's
records at the end (what arrived against what each recorded), not a flag from the first
station's wait.  A line database that was away while the first station forwarded and came
back before the end: "every record arrived" (it printed "not every record had arrived").
Real forwarders on SQLite station databases to a real PostgreSQL, through a proxy that cuts
the link."""

from __future__ import annotations

import asyncio
import io
import time
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import pytest
from sqlalchemy import make_url

from db.repository import Repository
from stationd.bench.cutproxy import CutProxy
from stationd.bus import EventBus
from stationd.config import StationConfig, load_station_config
from stationd.demo.services import StationServices, line_config, line_report
from stationd.demo.station import SIM_CONFIG


def _station(tmp: Path, k: int, url: str) -> StationConfig:
    return replace(load_station_config(SIM_CONFIG), opcua=None,
                   database_url=f"sqlite:///{tmp}/station{k}.db",
                   line=line_config(url, f"DEMO-{k}"))


def _record(cfg: StationConfig, n: int) -> None:
    """``n`` records in the station's database (commands: each a feed entry, as a
    rundown is)."""
    repo = Repository.open(cfg.database_url)
    try:
        for i in range(n):
            repo.ledger.record_command(at=datetime.now(UTC), user="sue", source="test",
                                       kind="skip", vin="V1", bolt=f"B{i:02d}", comment="")
    finally:
        repo.close()


@pytest.mark.timeout(120)
def test_an_outage_during_the_first_station_is_checked_again_at_the_end(tmp_path, pg_url):
    u = make_url(pg_url)
    proxy = CutProxy((u.host or "127.0.0.1", u.port or 5432))
    via = u.set(host="127.0.0.1", port=proxy.port).render_as_string(hide_password=False)
    first, second = _station(tmp_path, 1, via), _station(tmp_path, 2, via)
    text = io.StringIO()

    async def scenario() -> tuple[bool, dict]:
        one = StationServices(first, EventBus())
        await one.start()
        proxy.cut()                                    # the line database away
        _record(first, 3)
        drained = await one.drain(timeout=1.0)         # the first station's wait: in vain
        # its forwarder backs off (1, 2, 4 s...): after its third failed try the next one is
        # seconds away when the line comes back, longer than the second station takes; the
        # read-back must wait for that try (a wait of a fixed time lost it on a busy machine)
        end = time.monotonic() + 60
        while one.tries() < 3 and time.monotonic() < end:
            await asyncio.sleep(0.05)
        assert one.tries() >= 3 and one.down()
        proxy.restore()                                # back, before the demo ends
        two = StationServices(second, EventBus())
        await two.start()
        _record(second, 2)
        try:
            return drained, await line_report(pg_url, [one, two], text, None, False)
        finally:
            await one.stop()
            await two.stop()

    try:
        drained, doc = asyncio.run(scenario())
    finally:
        proxy.close()
    assert drained is False and proxy.cuts + proxy.refused >= 1
    assert doc["missing"] == 0 and doc["all_forwarded"] is True
    assert doc["arrival"] == {
        "DEMO-1": {"records": 3, "arrived": 3, "missing": 0, "missing_rundowns": 0},
        "DEMO-2": {"records": 2, "arrived": 2, "missing": 0, "missing_rundowns": 0}}
    head = text.getvalue().splitlines()[0]
    assert head.endswith("every record arrived (DEMO-1 3 of 3, DEMO-2 2 of 2 records)")
    assert "not every" not in text.getvalue().lower()


@pytest.mark.timeout(120)
def test_records_that_never_reached_the_line_are_counted_per_station(tmp_path, pg_url):
    """The link is down from the start to the end: the read-back (straight to the database)
    finds none of the first station's records, and says how many and where they stay."""
    u = make_url(pg_url)
    proxy = CutProxy((u.host or "127.0.0.1", u.port or 5432))
    proxy.cut()
    via = u.set(host="127.0.0.1", port=proxy.port).render_as_string(hide_password=False)
    cfg = _station(tmp_path, 1, via)
    text = io.StringIO()

    async def scenario() -> dict:
        one = StationServices(cfg, EventBus())
        await one.start()
        _record(cfg, 4)
        try:
            return await line_report(pg_url, [one], text, None, True)
        finally:
            await one.stop()

    try:
        doc = asyncio.run(scenario())
    finally:
        proxy.close()
    assert doc["missing"] == 4 and doc["all_forwarded"] is False
    assert doc["arrival"]["DEMO-1"] == {"records": 4, "arrived": 0, "missing": 4,
                                        "missing_rundowns": 0}
    said = text.getvalue()
    assert "NOT every record arrived (DEMO-1 0 of 4 records): 4 records" in said
    assert f"the line database at 127.0.0.1:{proxy.port} does not answer" in said
    assert "they stay in the demo's station database, kept when the demo ends" in said


def test_the_end_names_no_command_for_a_throw_away_line_database():
    """Issue 30: after --stations N without --hold and --line-db, the demo suggested
    `stationd line results` for the throw-away line database, already gone; and "9 OK, 3
    NOK" did not say these were results."""
    from stationd.demo.services import read_back_words

    doc = {"stations": {"DEMO-1": {"rundowns": 4, "ok": 2, "nok": 1, "loosenings": 1,
                                   "bolts": ["B01", "B02"]}}}
    gone = read_back_words(doc, None, throwaway=True)
    assert gone[0] == ("  DEMO-1: 4 rundowns: 2 OK results, 1 NOK result, "
                       "1 loosening; bolts OK: B01, B02")
    assert "stationd line results with" not in gone[-1]
    assert "throw-away" in gone[-1] and "--line-db URL" in gone[-1] and "--hold" in gone[-1]
    kept = read_back_words(doc, None, throwaway=False)
    assert kept[-1].startswith("  every row: stationd line results with a station file")
    held = read_back_words(doc, "http://127.0.0.1:8080/line", throwaway=True)
    assert held[-1].startswith("  every row: http://127.0.0.1:8080/line (until Ctrl-C")
