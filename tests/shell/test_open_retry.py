"""A database that does not open at start-up is retried with the keeper's backoff (first
wait 1 s, jittered shorter), READY=1 is sent once with the reason, and the daemon goes on
once it opens: never an exit."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace
from typing import Any

from db.errors import DbError
from stationd.bus import EventBus
from stationd.shell import serve
from stationd.shell.daemon import Station
from stationd.shell.sdnotify import Notifier
from stationd.shell.serve import Opened, _open
from stationd.station.core import StationCore
from stationd.station.events import DeviceHealth, StateChanged


class Recording(Notifier):
    def __init__(self) -> None:
        super().__init__({})
        self.sent: list[dict[str, Any]] = []

    def send(self, **fields: str | int) -> bool:
        self.sent.append(fields)
        return True


class FlakyStation:
    """Fails to open twice (the database is on a disk not mounted yet), then opens.  Its
    core is a real one, and what the serve loop saw reaches it as the daemon's does (the
    daemon's own method): the core decides the fault, its events go to the bus."""

    heard_before_run = Station.heard_before_run

    def __init__(self) -> None:
        self.attempts = 0
        self.bus = EventBus()      # where the daemon tells its screens meanwhile
        self.core = StationCore()
        self.effects = SimpleNamespace(publish=self.bus.publish)

    def open(self) -> None:
        self.attempts += 1
        if self.attempts <= 2:
            raise DbError("unable to open database file /var/lib/stationd/s.db")


def test_a_database_that_does_not_open_is_retried_then_the_daemon_goes_on(monkeypatch):
    # the keeper's backoff as the daemon runs it, from a first wait of 50 ms, not 1 s: the
    # two retries took 3 s of waiting, and no assertion is about their length
    monkeypatch.setattr(serve, "OPEN_RETRY_S", (0.05, 30.0))
    station, notifier = FlakyStation(), Recording()

    async def main() -> Opened:
        return await asyncio.wait_for(_open(station, notifier, asyncio.Event()), 30)

    assert asyncio.run(main()) is Opened.OPEN
    assert station.attempts == 3
    ready = [f for f in notifier.sent if f.get("ready") == 1]
    assert len(ready) == 1 and "fault: database: unable to open" in str(ready[0]["status"])
    # the screens heard it (the station's loop is not running yet): faulty, then back
    health = [(e.ok, e.reason) for e in station.bus.of(DeviceHealth)]
    assert health[0][0] is False and "unable to open" in health[0][1] and health[-1] == (True, "")
    assert any(e.state == "fault" for e in station.bus.of(StateChanged))
    # the core heard both: no fault left, and its loop's Started still comes once
    assert station.core.status().faults == {}
    assert station.core.status().state == "waiting for vehicle"


def test_stopping_while_the_database_is_down_ends_the_wait():
    class Down(FlakyStation):
        def open(self) -> None:
            raise DbError("no database")

    stop = asyncio.Event()

    async def main() -> Opened:
        asyncio.get_running_loop().call_later(0.2, stop.set)
        return await asyncio.wait_for(_open(Down(), Recording(), stop), 10)  # type: ignore[arg-type]

    assert asyncio.run(main()) is Opened.STOPPED


def test_a_reload_while_the_database_is_down_ends_the_wait(monkeypatch):
    """An engineer who fixed the database's path sent SIGHUP and waited for the next retry
    (up to 30 s), which was of the old path: the reload ends the wait at once, for the
    files to be read again.  Here every retry waits 600 s: only the reload ends it."""
    class Down(FlakyStation):
        def open(self) -> None:
            self.attempts += 1
            raise DbError("no database")

    monkeypatch.setattr(serve, "OPEN_RETRY_S", (600.0, 600.0))
    stop, reload, down = asyncio.Event(), asyncio.Event(), Down()

    async def main() -> Opened:
        asyncio.get_running_loop().call_later(0.2, reload.set)
        return await asyncio.wait_for(_open(down, Recording(), stop, reload), 120)

    assert asyncio.run(main()) is Opened.RELOAD and down.attempts == 1


def test_a_database_down_at_start_is_said_once_per_reason_not_at_every_retry(monkeypatch,
                                                                                caplog):
    """A commissioning trial: the database file left root's by a ``db import`` run as root
    before the service's first start.  Each retry (every 30 s at most) wrote the same ERROR
    line to the journal, hours of them (``journalctl -p warning`` full of one line), while
    a device that stays down is said once per change of its reason.  The first of each
    reason is said, the retries between are not."""
    import logging

    same = "attempt to write a readonly database"

    class Down(FlakyStation):
        def open(self) -> None:
            self.attempts += 1
            if self.attempts <= 4:
                raise DbError(same)
            if self.attempts == 5:
                raise DbError("unable to open database file")

    monkeypatch.setattr(serve, "OPEN_RETRY_S", (0.01, 0.02))
    station = Down()

    async def main() -> Opened:
        return await asyncio.wait_for(_open(station, Recording(), asyncio.Event()), 30)

    with caplog.at_level(logging.DEBUG, logger="stationd"):
        assert asyncio.run(main()) is Opened.OPEN
    assert station.attempts == 6
    said = [r.getMessage() for r in caplog.records
            if r.name == "stationd" and r.levelno >= logging.WARNING]
    assert len(said) == 2, said
    assert same in said[0] and "unable to open" in said[1]
