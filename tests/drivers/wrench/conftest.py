"""Fixtures for the wrench drivers: a simulated controller, fast client settings, a scripted
raw peer for faults the simulator does not model (the check that nothing leaks is
``tests/drivers/conftest.py``'s)."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from drivers.errors import DeviceError
from drivers.wrench import open_wrench
from drivers.wrench.openprotocol.client import OpenProtocolWrench
from drivers.wrench.sim.controller import SimController

# short timeouts keep every file well under 10 s
FAST = {"timeout": 0.5, "connect_timeout": 0.5}


@pytest.fixture
def sim() -> Iterator[SimController]:
    with SimController(seed=1, nok_rate=0.0) as controller:
        yield controller


def url_for(sim: SimController, transport: str, tmp_path) -> str:
    """Serve ``sim`` on ``transport`` and give the URL a station would configure."""
    if transport == "tcp":
        return f"openprotocol://127.0.0.1:{sim.listen_tcp()}"
    return f"openprotocol+serial://{sim.open_pty(str(tmp_path / 'ttyWRENCH'))}?baud=9600"


def connect(sim: SimController, transport: str, tmp_path, **kw) -> OpenProtocolWrench:
    wrench = open_wrench(url_for(sim, transport, tmp_path), **{**FAST, **kw})
    assert isinstance(wrench, OpenProtocolWrench)
    return wrench


#: how long a test waits for what a peer thread does before it fails, s: generous, so a busy
#: machine only makes a test slower, never failed (a wait ends as soon as it holds)
WAIT_S = 30.0


def reconnect_within(w: Any, timeout: float = WAIT_S) -> bool:
    """What the station's keeper (``drivers.keeper``) does, without its backoff: call
    ``reconnect()`` until it works.  False if it never did within ``timeout``."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            w.reconnect()
            return True
        except DeviceError:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)


def wait_until(cond: Callable[[], bool], timeout: float = WAIT_S) -> bool:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def op(mid: int, data: bytes = b"", rev: str = "001") -> bytes:
    """A message written out by hand from the specification (header + data + NUL)."""
    return f"{20 + len(data):04d}{mid:04d}{rev}         ".encode() + data + b"\x00"


def read_message(conn: socket.socket) -> bytes:
    """One TCP message (with its NUL) read by hand: 4 length digits, the rest, NUL."""
    buf = b""
    while len(buf) < 4 or len(buf) < int(buf[:4]) + 1:
        chunk = conn.recv(4 - len(buf) if len(buf) < 4 else int(buf[:4]) + 1 - len(buf))
        if not chunk:
            raise ConnectionError("peer closed")
        buf += chunk
    return buf


class ScriptedPeer:
    """A hand-written controller on loopback that runs ``script(conn)`` for one client."""

    def __init__(self, script: Callable[[socket.socket], None]) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.error: BaseException | None = None
        self._script = script
        self._thread = threading.Thread(target=self._serve, name="scripted-peer")
        self._thread.start()

    def _serve(self) -> None:
        self.listener.settimeout(5.0)
        try:
            conn, _ = self.listener.accept()
            with conn:
                conn.settimeout(5.0)
                self._script(conn)
        except (OSError, ConnectionError) as e:
            self.error = e

    def close(self) -> None:
        self._thread.join(timeout=10)
        self.listener.close()


@pytest.fixture
def peer() -> Iterator[Callable[[Callable[[socket.socket], None]], ScriptedPeer]]:
    peers: list[ScriptedPeer] = []

    def make(script: Callable[[socket.socket], None]) -> ScriptedPeer:
        peers.append(ScriptedPeer(script))
        return peers[-1]
    yield make
    for p in peers:
        p.close()
