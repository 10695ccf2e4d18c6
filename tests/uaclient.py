"""asyncua's client as the tests use it: a request timeout for a loaded machine.

Why: asyncua's default request timeout is 4 s; with two test workers, a daemon and other work
on two cores, the first walk of a server's data type definitions (``load_client_types``) took
longer, asyncua closed the connection and the test failed with "client is disconnected",
though the server answered.  A request that really gets no answer still fails (in 30 s)."""

from __future__ import annotations

from typing import Any, Self

from asyncua.client.client import Client as _AsyncuaClient

#: seconds a request may wait for its answer
REQUEST_TIMEOUT_S = 30.0


class Client(_AsyncuaClient):
    """:class:`asyncua.Client` with :data:`REQUEST_TIMEOUT_S` unless told otherwise."""

    def __init__(self, url: str, timeout: float = REQUEST_TIMEOUT_S, **kwargs: Any) -> None:
        super().__init__(url, timeout=timeout, **kwargs)

    async def __aenter__(self) -> Self:
        await super().__aenter__()
        return self
