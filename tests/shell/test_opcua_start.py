"""The OPC UA server's start gives way to a stop (``stationd.shell.serve._started``): its
companion models load for tens of seconds on a busy machine, and a daemon stopped meanwhile
waited for them, beyond the unit's TimeoutStopSec (an IT administrator's trial)."""

from __future__ import annotations

import asyncio

import pytest

from stationd.shell.serve import _started


class Server:
    """A server whose start ends when ``ready`` is set (never, unless a test sets it), or
    raises ``fails``."""

    def __init__(self, fails: Exception | None = None) -> None:
        self.ready, self.fails, self.cancelled = asyncio.Event(), fails, False

    async def start(self) -> None:
        if self.fails is not None:
            raise self.fails
        try:
            await self.ready.wait()
        except asyncio.CancelledError:
            self.cancelled = True
            raise


def test_a_stop_during_the_start_cancels_it():
    async def main() -> tuple[bool, bool]:
        server, stop = Server(), asyncio.Event()
        asyncio.get_running_loop().call_soon(stop.set)
        return await _started(server, stop), server.cancelled

    assert asyncio.run(main()) == (False, True)


def test_a_start_that_ends_first_is_started_and_its_failure_raised():
    async def main(server: Server) -> bool:
        server.ready.set()
        return await _started(server, asyncio.Event())

    assert asyncio.run(main(Server()))
    with pytest.raises(OSError, match="in use"):
        asyncio.run(main(Server(OSError("address in use"))))
