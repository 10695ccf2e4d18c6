"""A demo station's OPC UA port taken by another program after the demo found it free: served
on the next free port, and said (it ran with no endpoint, under a PASS that did not say so)."""

from __future__ import annotations

import asyncio
import socket
from dataclasses import replace
from pathlib import Path

from stationd.bus import EventBus
from stationd.config import load_station_config
from stationd.demo.services import StationServices, demo_opcua
from stationd.demo.station import SIM_CONFIG


def test_a_port_taken_after_it_was_found_free_moves_to_the_next_free_one(tmp_path: Path
                                                                        ) -> None:
    with socket.socket() as other:        # another program listening on the chosen port
        other.bind(("127.0.0.1", 0))
        other.listen()
        taken = other.getsockname()[1]
        endpoint = f"opc.tcp://127.0.0.1:{taken}"
        cfg = replace(load_station_config(SIM_CONFIG), opcua=demo_opcua(endpoint, "DEMO-2"),
                      database_url=f"sqlite:///{tmp_path / 's.db'}", line=None)

        async def main(movable: bool) -> tuple[str | None, str | None, str | None]:
            services = StationServices(cfg, EventBus(), movable=movable)
            await services.start()
            try:
                url = services.opcua.url if services.opcua is not None else None
                assert services.endpoint == url
                return url, services.moved, services.problem
            finally:
                await services.stop()

        url, moved, problem = asyncio.run(main(True))
        # a port asked for (--opcua HOST:PORT) is never moved: an MES is told that one
        pinned = asyncio.run(main(False))
    assert problem is None and url is not None and url != endpoint
    assert url.startswith("opc.tcp://127.0.0.1:") and int(url.rsplit(":", 1)[1]) > taken
    assert moved == f"{endpoint} was taken after it was found free: the next free port"
    assert pinned[0] is None and pinned[1] is None
    assert pinned[2] is not None and pinned[2].startswith(f"not served on {endpoint}: EADDRINUSE")
