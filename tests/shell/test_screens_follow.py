"""The daemon's screens follow the running configuration: a port another program holds at
start is tried again, and the screens come once it is free (newcomer trial: they were never
served for the daemon's life, one journal line said so)."""

from __future__ import annotations

import asyncio
import json
import socket
import urllib.request
from dataclasses import replace
from typing import Any

import pytest

from stationd.bus import EventBus
from stationd.config import load_station_config
from stationd.demo.station import SIM_CONFIG
from stationd.shell import serve
from stationd.web.config import HttpConfig


def test_a_port_in_use_at_start_is_tried_again_until_the_screens_are_served(
        tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(serve, "SCREENS_RETRY_S", 0.2)
    holder = socket.socket()
    holder.bind(("127.0.0.1", 0))
    holder.listen(1)
    port = holder.getsockname()[1]
    cfg = replace(load_station_config(SIM_CONFIG),
                  database_url=f"sqlite:///{tmp_path}/s.db",
                  http=HttpConfig(f"127.0.0.1:{port}"))
    screens = serve.Screens(EventBus())

    async def main() -> None:
        await screens.follow(cfg)
        assert screens.server is None
        frames = screens.frames                  # the station holds this store
        await asyncio.sleep(0.7)                 # a few attempts while the port is held
        assert screens.server is None
        holder.close()
        for _ in range(100):
            if screens.server is not None:
                break
            await asyncio.sleep(0.05)
        assert screens.server is not None and screens.frames is frames
        body = await asyncio.to_thread(
            lambda: urllib.request.urlopen(  # noqa: S310 - the loopback server above
                screens.server.url + "healthz", timeout=5).read())
        assert body.strip() in (b"ok", b"fault")
        await screens.stop()

    try:
        asyncio.run(main())
    finally:
        holder.close()
    failures = [r for r in caplog.records if "screens not served" in r.getMessage()]
    assert len(failures) == 1      # journaled once, not at every attempt
    # in words, not asyncio's "[Errno 98] error while attempting to bind on address ..."
    assert "the port is in use (another program, or another stationd, serves there)" in \
        failures[0].getMessage() and "Errno" not in failures[0].getMessage()
    with pytest.raises(AttributeError):
        _ = screens.server.url     # stopped


def test_screens_served_late_start_from_the_running_cores_snapshot(tmp_path, monkeypatch):
    """The port freed hours into a run: the bus's bounded history no longer holds the fault
    of a camera pair (localizations since pushed it out); the screens, served at last, say
    the station's state as its core has it now, not "starting" with every device ok."""
    from types import SimpleNamespace

    from drivers.keeper import FaultKind
    from stationd.station.events import Localized
    from stationd.station.inputs import DeviceFault
    from tests.station.test_core import _ready

    monkeypatch.setattr(serve, "SCREENS_RETRY_S", 0.2)
    holder = socket.socket()
    holder.bind(("127.0.0.1", 0))
    holder.listen(1)
    port = holder.getsockname()[1]
    cfg = load_station_config(SIM_CONFIG)
    # and a pair not registered into the vehicle frame: said beside its health
    cfg = replace(cfg, database_url=f"sqlite:///{tmp_path}/s.db",
                  http=HttpConfig(f"127.0.0.1:{port}"),
                  pairs={**cfg.pairs, "pair3": replace(cfg.pairs["pair3"], to_vehicle=None)})
    d = _ready()
    d.feed(DeviceFault(d.t, "pair2", FaultKind.DOWN, "pair2: camera unplugged"))
    bus = EventBus(history=20)
    for i in range(30):
        bus.publish(Localized(point_mm=None, tilt_deg=None, reason=None, candidate=None,
                              distance_mm=None, age_ms=30.0, allowed=(), t=float(i)))
    screens = serve.Screens(bus)
    screens.station = SimpleNamespace(core=d.core, submit=None)   # the running station

    async def main() -> dict:
        await screens.follow(cfg)
        holder.close()
        for _ in range(100):
            if screens.server is not None:
                break
            await asyncio.sleep(0.05)
        assert screens.server is not None
        body = await asyncio.to_thread(
            lambda: urllib.request.urlopen(  # noqa: S310 - the loopback server above
                screens.server.url + "api/status", timeout=5).read())
        await screens.stop()
        doc: dict[str, Any] = json.loads(body)
        return doc

    try:
        st = asyncio.run(main())
    finally:
        holder.close()
    assert st["state"] == "fault" and st["unregistered"] == ["pair3"]
    assert st["devices"]["pair2"]["ok"] is False and "unplugged" in st["devices"]["pair2"][
        "reason"]
