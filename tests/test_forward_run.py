"""The forwarder's loop and connection: woken by a recorded result, a record reaches the line
database at once, not at the next poll (the lag under normal load is then the forwarding's own
time); a wake never cuts a backoff short (a line database that is down is not hammered at the
station's rate); line tables that cannot be made are the line database down, never records
refused for good."""

from __future__ import annotations

import asyncio
import time

import pytest

from db.repository import Repository
from stationd import forward
from stationd.boltfile import import_bolts
from stationd.forward import Forwarder, LineConfig
from tests.db.conftest import BASE, record

VIN = "9SDST0010TL000001"


@pytest.fixture
def repo(tmp_path):
    table = tmp_path / "bolts.yaml"
    table.write_text(BASE)
    r = Repository.open(f"sqlite:///{tmp_path / 'st.db'}")
    import_bolts(r, table)
    r.start_vehicle(VIN, "SEDAN")
    yield r
    r.close()


async def _until(pred, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        await asyncio.sleep(0.01)
    return False


def test_a_recorded_result_wakes_the_forwarder(repo, pg_url, monkeypatch):
    monkeypatch.setattr(forward, "POLL_S", 60.0)      # a poll alone would wait a minute
    record(repo, VIN, "B1", tightening_id=1)

    async def main() -> tuple[bool, bool]:
        f = Forwarder(repo, LineConfig(pg_url, "ST-W"))
        stop, wake = asyncio.Event(), asyncio.Event()
        task = asyncio.create_task(f.run(stop, lambda st: None, wake))
        first = await _until(lambda: f.cursor == 1, 20.0)      # the first step at start
        record(repo, VIN, "B2", tightening_id=2)
        wake.set()                                              # as ResultRecorded does
        woken = await _until(lambda: f.cursor == 2, 20.0)
        stop.set()
        await task
        f.line.dispose()
        return first, woken

    assert asyncio.run(main()) == (True, True)


def test_a_wake_does_not_cut_a_backoff_short(repo, pg_url, pg_server, monkeypatch):
    monkeypatch.setattr(forward, "BACKOFF_S", (60.0, 60.0))
    down = pg_url.replace(f":{pg_server.port}/", ":1/")
    record(repo, VIN, "B1", tightening_id=1)

    async def main() -> int:
        f = Forwarder(repo, LineConfig(down, "ST-W"))
        tries = 0
        step = f.step

        def counted() -> int:
            nonlocal tries
            tries += 1
            return step()

        f.step = counted  # type: ignore[method-assign]
        stop, wake = asyncio.Event(), asyncio.Event()
        task = asyncio.create_task(f.run(stop, lambda st: None, wake))
        await _until(lambda: f.up is False, 20.0)
        for _ in range(5):
            wake.set()
            await asyncio.sleep(0.05)
        stop.set()
        await task
        return tries

    assert asyncio.run(main()) == 1


def test_line_tables_that_cannot_be_made_are_the_line_down_not_refused_records(
        repo, pg_url, pg_server):
    """A role without the right to create the line's tables (PostgreSQL 15 on: nobody but
    the owner creates in ``public``): the records wait, none is quarantined."""
    import psycopg

    db = pg_url.rsplit("/", 1)[1]
    with psycopg.connect(f"host=127.0.0.1 port={pg_server.port} user=postgres dbname={db}",
                         autocommit=True) as c:
        c.execute("CREATE ROLE station_ro LOGIN")
        c.execute("REVOKE CREATE ON SCHEMA public FROM PUBLIC")
    record(repo, VIN, "B1", tightening_id=1)
    f = Forwarder(repo, LineConfig(pg_url.replace("postgres@", "station_ro@"), "ST-R"))
    with pytest.raises(forward.LineDown, match="the line tables: permission denied"):
        f.step()
    st = f.status()
    assert (st["up"], st["backlog"], st["quarantined"]) == (False, 1, 0)


def test_a_new_reason_while_down_is_told(repo, monkeypatch):
    """While the line database stays down, a new reason is told (the journal, STATUS=, the
    line asset's ErrorMessage): it was told only on up/down changes, so OPC UA kept saying the
    first reason after the server answered again but refused the role."""
    monkeypatch.setattr(forward, "BACKOFF_S", (0.01, 0.02))
    monkeypatch.setattr(forward, "STATUS_S", 0.01)
    record(repo, VIN, "B1", tightening_id=1)
    reasons = iter(["connection refused", "connection refused", "role st lacks INSERT"])
    said: list[tuple[bool | None, str | None]] = []

    async def main() -> None:
        f = Forwarder(repo, LineConfig("postgresql+psycopg://st@127.0.0.1:1/line", "ST-R"))

        def push(*_: object) -> int:
            raise forward.LineDown(next(reasons, "role st lacks INSERT"))

        monkeypatch.setattr(f.line, "push", push)
        stop = asyncio.Event()
        task = asyncio.create_task(f.run(stop, lambda st: said.append(
            (st["up"], st["last_error"])), None))
        await _until(lambda: len(said) >= 2, 20.0)
        await asyncio.sleep(0.2)           # more tries, the same reason: nothing more told
        stop.set()
        await task
        f.line.dispose()

    asyncio.run(main())
    assert said == [(False, "connection refused"), (False, "role st lacks INSERT")]


def test_an_outage_is_said_again_while_it_lasts_and_its_end_once_caught_up(repo, monkeypatch):
    """The line database down: said as it goes down, then again every DOWN_SAID_S with the
    backlog grown; back up, said once caught up, with how many records waited at most (a
    quality trial: one line as the outage began, then nothing while 52 records waited).  The
    loop's statuses are given (the line database's own behaviour is the system tests')."""
    monkeypatch.setattr(forward, "DOWN_SAID_S", 0.05)
    monkeypatch.setattr(forward, "STATUS_S", 0.01)
    monkeypatch.setattr(forward, "BACKOFF_S", (0.01, 0.01))
    monkeypatch.setattr(forward, "POLL_S", 0.01)
    f = Forwarder(repo, LineConfig("postgresql+psycopg://u@127.0.0.1:1/line", "ST-W"))
    steps = {"n": 0}
    backlog = iter([3, 5, 8, 13, 21] + [21] * 200)
    heard: list[dict] = []

    def step() -> int:
        steps["n"] += 1
        if len(heard) < 3:
            time.sleep(0.02)
            raise forward.LineDown("connection refused")
        return 0

    def status(measure_s=None) -> dict:
        down = len(heard) < 3
        return {"up": not down, "alarm": None, "last_error": "refused" if down else None,
                "backlog": next(backlog) if down else (4 if len(heard) == 3 else 0),
                "url": "line"}

    f.step = step
    f.status = status

    async def main() -> None:
        stop = asyncio.Event()
        task = asyncio.create_task(f.run(stop, heard.append))
        await _until(lambda: any("caught_up" in h for h in heard), 20.0)
        stop.set()
        await task

    asyncio.run(main())
    downs = [h for h in heard if h["up"] is False]
    assert len(downs) >= 2 and downs[-1]["backlog"] > downs[0]["backlog"], heard
    [end] = [h for h in heard if "caught_up" in h]
    assert end["up"] is True and end["caught_up"] == max(h["backlog"] for h in downs)
    f.line.dispose()
