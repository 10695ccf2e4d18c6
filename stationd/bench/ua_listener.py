"""An MES in a process of its own for ``stationd bench station --opcua``: subscribed at the
station's Server object to its result events, it prints one JSON line per event with the
moment it arrived (``time.monotonic()``: one clock for every process of the machine) so the
benchmark can tell each event's delay after its result was stored.

Why a process: a client in the daemon's own event loop would take its cores' time from the
station being measured; a plant's MES runs elsewhere.

    python -m stationd.bench.ua_listener opc.tcp://127.0.0.1:4840 [PUBLISHING_MS]
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from typing import Any

from asyncua.client.client import Client

from stationd.opcua.model import IJT_URI, load_client_types
from stationd.opcua.uatypes import ua

RESULT_READY_EVENT_TYPE = 1007   # in IJT Base
ENTITY_JOINT = 23


class _Printer:
    def event_notification(self, event: Any) -> None:
        t = time.monotonic()
        meta = event.Result.ResultMetaData
        bolt = next((e.EntityId for e in meta.AssociatedEntities
                     if e.EntityType == ENTITY_JOINT), None)
        sys.stdout.write(json.dumps({"t": t, "seq": meta.SequenceNumber, "bolt": bolt}) + "\n")
        sys.stdout.flush()


#: seconds a request may wait for its answer (asyncua's 4 s default closed the connection on a
#: loaded machine during the first walk of the data type definitions)
REQUEST_TIMEOUT_S = 30.0


async def listen(url: str, publishing_ms: float) -> None:
    async with Client(url, timeout=REQUEST_TIMEOUT_S) as client:
        await load_client_types(client)
        uris = await client.get_namespace_array()
        etype = client.get_node(ua.NodeId(RESULT_READY_EVENT_TYPE, uris.index(IJT_URI)))
        sub = await client.create_subscription(publishing_ms, _Printer())
        await sub.subscribe_events(client.nodes.server, etype)
        sys.stdout.write(json.dumps({"ready": True}) + "\n")
        sys.stdout.flush()
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, sys.stdin.read)   # until the benchmark closes it


if __name__ == "__main__":
    asyncio.run(listen(sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else 10.0))
