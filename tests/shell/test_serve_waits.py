"""What the daemon waits for at its start and stop, kept within systemd's timeouts
(``stationd.shell.serve``): OPC UA's start gives way to a stop (its companion models load for
tens of seconds on a busy machine, and a daemon stopped meanwhile waited for them, beyond the
unit's TimeoutStopSec), and a long open of the database asks for more time (an IT
administrator's trial)."""

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


def test_a_long_database_open_asks_systemd_for_more_time_until_it_ends():
    """A schema upgrade of a large database runs before READY=1: systemd is asked for more
    time (EXTEND_TIMEOUT_USEC) and told how long it has taken, for as long as it runs (an IT
    administrator's trial: 38 s without a word against TimeoutStartSec=60s)."""
    from stationd.shell.serve import _extending

    sent: list[dict[str, object]] = []

    class Notifier:
        def extend_timeout(self, seconds: float, status: str = "") -> bool:
            sent.append({"seconds": seconds, "status": status})
            return True

    async def main() -> None:
        loop = asyncio.get_running_loop()
        opening: asyncio.Future[None] = loop.create_future()

        def told() -> None:          # the open ends once systemd was asked twice
            if len(sent) >= 2:
                opening.set_result(None)
            else:
                loop.call_later(0.01, told)

        told()
        await _extending(opening, Notifier(), every=0.01)  # type: ignore[arg-type]

    asyncio.run(main())
    assert len(sent) >= 2 and all(s["seconds"] == 0.02 for s in sent)
    assert "opening the database" in str(sent[0]["status"])
    assert "schema upgrade" in str(sent[0]["status"])
