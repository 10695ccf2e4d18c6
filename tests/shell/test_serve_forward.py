"""The forwarder beside a station (stationd/shell/serve.py ``forward``): the line database's
link is told to the station's core (its feed), not published by the shell, so the core stays
the one writer of what OPC UA and the screens show.  The line database here is a loopback
port nothing listens on: a real refused connection, no server."""

from __future__ import annotations

import asyncio
import time

from db.repository import Repository
from stationd.bus import EventBus
from stationd.config import StationConfig
from stationd.forward import LineConfig
from stationd.shell.sdnotify import Notifier
from stationd.shell.serve import Screens, forward
from stationd.station.inputs import Event, LineLinkIn
from tests.shell.daemons import free_port


def test_a_line_database_that_refuses_is_told_to_the_core_as_its_link_down(tmp_path):
    db = f"sqlite:///{tmp_path / 'st.db'}"
    Repository.open(db).close()
    url = f"postgresql+psycopg://line@127.0.0.1:{free_port()}/line"
    cfg = StationConfig(database_url=db, line=LineConfig(url, "ST-F"))
    bus = EventBus()
    published: list[object] = []
    bus.subscribe(published.append)
    told: list[Event] = []

    def tell(ev: Event) -> None:    # as Station.tell is: from the forwarder's callback
        told.append(ev)

    async def main() -> None:
        stop = asyncio.Event()
        task = asyncio.create_task(forward(cfg, Notifier({}), Screens(bus), stop, bus, tell))
        end = time.monotonic() + 30
        while not told and time.monotonic() < end:
            await asyncio.sleep(0.02)
        stop.set()
        await task

    asyncio.run(main())
    links = [e for e in told if isinstance(e, LineLinkIn)]
    assert links, "the forwarder told the core nothing in 30 s"
    assert links[0].up is False
    assert "connection" in links[0].reason and str(cfg.line.url.split(":")[-1].split("/")[0]) \
        in links[0].reason     # the forwarder's own words: which port refused
    assert published == []      # the shell published nothing itself: the core tells it
