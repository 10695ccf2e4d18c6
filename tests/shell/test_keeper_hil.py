"""The keeper over a real Modbus TCP link on loopback: a "PLC" that accepts every connection
and hangs up at the first request (a gateway whose PLC is off) is a fault with a readable
reason, and is retried ever more slowly (the backoff only resets once the device has
worked), never hammered; the daemon keeps running.  Counted at the peer's accept()."""

from __future__ import annotations

import asyncio
import socket
import threading
from dataclasses import replace

import pytest

from stationd.config import load_station_config
from stationd.demo.station import SIM_CONFIG
from stationd.shell.daemon import Station
from stationd.sim.devices_cli import psets_of
from stationd.station.events import State
from stationd.words import state_words

WATCH_S = 6.0


class HangUp:
    """Accepts, reads one request, closes; counts the connections."""

    def __init__(self) -> None:
        self.server = socket.socket()
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(8)
        self.server.settimeout(0.1)
        self.port = self.server.getsockname()[1]
        self.accepted = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="hang-up-peer")
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.server.accept()
            except TimeoutError:
                continue
            self.accepted += 1
            with conn:
                conn.settimeout(1.0)
                try:
                    conn.recv(256)
                except OSError:
                    pass

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self.server.close()


@pytest.mark.timeout(120)
def test_a_plc_that_hangs_up_is_a_fault_retried_ever_more_slowly(tmp_path):
    peer = HangUp()
    cfg = load_station_config(SIM_CONFIG)
    cfg = replace(cfg, database_url=f"sqlite:///{tmp_path}/s.db",
                  lift=replace(cfg.lift, url=f"modbus-tcp://127.0.0.1:{peer.port}?timeout=0.5"))
    st = Station(cfg, device_kw={"wrench": {"psets": psets_of(cfg.bolts_path)}})
    seen: dict[str, object] = {}

    async def main() -> None:
        stop = asyncio.Event()
        task = asyncio.create_task(st.run(stop))
        await asyncio.sleep(WATCH_S)
        seen.update(state=st.core.state, reason=state_words(st.core.reason), done=task.done())
        stop.set()
        await task

    try:
        st.open()              # connecting works: the lift opens, its first read fails
        asyncio.run(main())
    finally:
        st.close()
        peer.close()
    assert seen["done"] is False                         # never an exit
    assert seen["state"] is State.FAULT
    assert str(seen["reason"]).startswith("lift: ")
    assert "link lost reading holding registers" in str(seen["reason"])
    # waits 0.5, 1, 2, 4 s (jittered shorter): a handful of connections in 6 s, where a
    # backoff reset by every successful connect would give one every 0.5 s
    assert 2 <= peer.accepted <= 7, peer.accepted
