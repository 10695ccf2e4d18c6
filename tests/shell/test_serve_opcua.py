"""The OPC UA server beside a station (stationd/shell/serve.py ``opcua``): it runs on an event
loop of its own, in a thread of its own, so that loading its companion models (seconds, tens
on a busy machine) never stops the daemon's loop, which runs the station and pings systemd's
watchdog; the station's events still reach its nodes across the two loops."""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

from db.repository import Repository
from stationd.bus import EventBus
from stationd.config import StationConfig
from stationd.deviceconfig import WrenchConfig
from stationd.opcua.server import NAMESPACE, OpcUaServer
from stationd.opcua.uatypes import ua
from stationd.shell import serve
from stationd.station.events import Because, State, StateChanged, StateReason
from tests.opcua.test_server import config
from tests.uaclient import Client


def test_the_server_runs_on_a_loop_of_its_own_and_hears_the_station(tmp_path, monkeypatch):
    db = f"sqlite:///{tmp_path / 'st.db'}"
    Repository.open(db).close()
    cfg = StationConfig(database_url=db, opcua=config())
    bus = EventBus()
    started: dict[str, Any] = {}
    real_start = OpcUaServer.start

    async def start(self: OpcUaServer) -> None:
        started["thread"] = threading.current_thread()
        started["loop"] = asyncio.get_running_loop()
        started["simulated"] = self.simulated
        await real_start(self)

    monkeypatch.setattr(OpcUaServer, "start", start)

    async def main() -> tuple[Any, asyncio.AbstractEventLoop, Any]:
        stop = asyncio.Event()
        task = asyncio.create_task(serve.opcua(cfg, bus, stop))
        assert cfg.opcua is not None
        end = time.monotonic() + 120
        value = None
        while time.monotonic() < end:
            try:
                async with Client(cfg.opcua.endpoint) as client:
                    idx = (await client.get_namespace_array()).index(NAMESPACE)
                    node = client.get_node(ua.NodeId("JoiningSystem.ST-07.State", idx))
                    # the station's loop (this one) publishes; the server's writes the node
                    bus.publish(StateChanged(State.TRACKING, StateReason(Because.TRACKING)))
                    while time.monotonic() < end:
                        value = await node.read_value()
                        if value == "tracking":
                            break
                        await asyncio.sleep(0.05)
                    break
            except (TimeoutError, OSError, ua.UaError):
                await asyncio.sleep(0.2)    # not listening yet
        stop.set()
        await task
        return value, asyncio.get_running_loop(), threading.current_thread()

    value, daemon_loop, daemon_thread = asyncio.run(main())
    assert value == "tracking"
    assert started["thread"] is not daemon_thread and started["thread"].name == "opcua"
    assert started["loop"] is not daemon_loop
    assert not started["thread"].is_alive()     # stopped with the station, not left behind
    assert started["simulated"] is True         # sim://wrench: its results say IsSimulated


def test_results_are_simulated_when_the_controller_is():
    assert serve.results_simulated(StationConfig()) is True      # sim://wrench
    real = StationConfig(wrench=WrenchConfig("openprotocol://10.0.0.9:4545"))
    assert serve.results_simulated(real) is False
