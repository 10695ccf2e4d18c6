"""The screens' listening socket, with a limit on the connections it keeps, and who knocks at
it with a wrong token.

Why not aiohttp's own site: aiohttp reads a request's head with no time limit and keeps any
number of connections, so anyone who reached the port, without the token, could open a
thousand connections that never finish a request: the daemon ran out of file descriptors (the
screens, OPC UA and the devices share them), ``/healthz`` stopped answering and asyncio logged
a traceback for every refused accept (135,000 in 80 s in a security review).  Here each
connection must be let in by its first request (a head read, the token and the address
accepted: the server's middleware says so) within :data:`FIRST_REQUEST_S`, a refused request
ends its connection, and at most :data:`MOST_CONNECTIONS` are kept, :data:`MOST_PER_ADDRESS`
from one address off this machine; one over is closed at once.  aiohttp's protocol is wrapped,
not changed: its churn stays out of this file.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import Any

from stationd.configread import is_local
from stationd.logsetup import Sparing

#: connections kept at once (two screens per station, a few browsers, the CLI: far fewer),
#: and from one address off this machine (one client cannot take them all)
MOST_CONNECTIONS = 128
MOST_PER_ADDRESS = 16
#: seconds a new connection has to be let in by a request (its token and address accepted)
FIRST_REQUEST_S = 10.0
#: at most one warning of refused connections per this many seconds
WARN_EVERY_S = 60.0

log = logging.getLogger("stationd.web")


class Connections:
    """Counts the open connections and closes those that send no request in time.

    ``factory``: aiohttp's protocol factory (``AppRunner.server``).  :meth:`served` is called
    for every request let in (the server's middleware, after its token and address checks):
    from then on aiohttp's keep-alive timeout governs the connection."""

    def __init__(self, factory: Callable[[], Any], *, most: int = MOST_CONNECTIONS,
                 first_request_s: float = FIRST_REQUEST_S) -> None:
        self._factory = factory
        self.most, self.first_request_s = most, first_request_s
        self.most_per_address = MOST_PER_ADDRESS
        self.open: set[asyncio.Transport] = set()
        self._address: dict[asyncio.Transport, str] = {}
        self._per_address: dict[str, int] = {}
        self._waiting: dict[asyncio.Transport, asyncio.TimerHandle] = {}
        self.refused = 0              # connections closed as over the limit, since the start
        self._told = Sparing(log, every_s=WARN_EVERY_S)

    def __call__(self) -> asyncio.Protocol:
        return _Counted(self._factory(), self)

    def served(self, transport: asyncio.Transport | None) -> None:
        """A request was let in on ``transport``: it is no longer on probation."""
        timer = self._waiting.pop(transport, None) if transport is not None else None
        if timer is not None:
            timer.cancel()

    def _made(self, transport: asyncio.Transport) -> bool:
        peer = transport.get_extra_info("peername")
        address = str(peer[0]) if isinstance(peer, tuple) and peer else "?"
        mine = self._per_address.get(address, 0)
        if len(self.open) >= self.most or (mine >= self.most_per_address
                                           and not is_local(address)):
            self.refused += 1
            self._told.tell("refused", f"screens: connection(s) refused, {len(self.open)} open "
                            f"(at most {self.most}, {self.most_per_address} from one address); "
                            "another program or client keeps connections to the screens' port")
            transport.abort()
            return False
        self.open.add(transport)
        self._address[transport] = address
        self._per_address[address] = mine + 1
        loop = asyncio.get_running_loop()
        self._waiting[transport] = loop.call_later(self.first_request_s, _close, transport)
        return True

    def _lost(self, transport: asyncio.Transport) -> None:
        self.open.discard(transport)
        address = self._address.pop(transport, None)
        if address is not None:
            left = self._per_address.get(address, 1) - 1
            if left > 0:
                self._per_address[address] = left
            else:
                self._per_address.pop(address, None)
        timer = self._waiting.pop(transport, None)
        if timer is not None:
            timer.cancel()


def _close(transport: asyncio.Transport) -> None:
    """No whole request head in time: the connection is closed (nothing was answered)."""
    if not transport.is_closing():
        transport.abort()


class _Counted(asyncio.Protocol):
    """aiohttp's protocol for one connection, counted by :class:`Connections`."""

    def __init__(self, inner: Any, limits: Connections) -> None:
        self._inner, self._limits = inner, limits
        self._transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)  # noqa: S101 - a TCP server's
        if self._limits._made(transport):
            self._transport = transport
            self._inner.connection_made(transport)

    def connection_lost(self, exc: Exception | None) -> None:
        if self._transport is not None:
            self._limits._lost(self._transport)
            self._inner.connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        self._inner.data_received(data)

    def eof_received(self) -> bool | None:
        return bool(self._inner.eof_received())

    def pause_writing(self) -> None:
        self._inner.pause_writing()

    def resume_writing(self) -> None:
        self._inner.resume_writing()


class WrongTokens:
    """Requests refused for a wrong or missing token, told in the journal: the first, then at
    most one line a minute with the count and the addresses (a guessing client was silent:
    300 guesses, no line).  A request without any token is a browser not signed in yet: only
    counted when a wrong one came too."""

    def __init__(self) -> None:
        self._told_at = -WARN_EVERY_S
        self._wrong: dict[str, int] = {}
        self._later: asyncio.TimerHandle | None = None

    def tell(self, remote: str, given: bool) -> None:
        if not given:
            return
        if remote not in self._wrong and len(self._wrong) >= 1000:
            remote = "other addresses"           # bounded
        self._wrong[remote] = self._wrong.get(remote, 0) + 1
        now = time.monotonic()
        if now - self._told_at >= WARN_EVERY_S:
            self._flush()
        elif self._later is None:   # the rest of a burst told when the minute is over
            self._later = asyncio.get_running_loop().call_later(
                self._told_at + WARN_EVERY_S - now, self._flush)

    def _flush(self) -> None:
        self._later = None
        if not self._wrong:
            return
        who = ", ".join(f"{n} from {r}" for r, n in sorted(self._wrong.items()))
        log.warning("screens: requests with a wrong token refused: %s", who)
        self._told_at = time.monotonic()
        self._wrong.clear()

    def close(self) -> None:
        """The server stops: what is left untold is told now."""
        if self._later is not None:
            self._later.cancel()
        self._flush()
