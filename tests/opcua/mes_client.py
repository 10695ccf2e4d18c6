"""A client in its own process, as an MES would run one: connect, load the types (with the
workaround asyncua needs), call GetLatestResult, print the result as JSON."""

from __future__ import annotations

import asyncio
import json
import sys

from asyncua.client.client import Client

from stationd.opcua.model import RESULT_URI, load_client_types
from stationd.opcua.uatypes import ua


async def main(url: str, station: str) -> None:
    async with Client(url, timeout=30) as client:   # 4 s by default: short on a loaded machine
        await load_client_types(client)
        uris = await client.get_namespace_array()
        mr = uris.index(RESULT_URI)
        js = await client.nodes.objects.get_child(
            [f"{uris.index('http://opcfoundation.org/UA/Machinery/')}:Machines",
             f"{uris.index('urn:stationd:opcua')}:{station}"])
        rm = await js.get_child([f"{mr}:ResultManagement"])
        _, result, error = await rm.call_method(f"{mr}:GetLatestResult", ua.Int32(0))
        meta = result.ResultMetaData
        content = result.ResultContent[0].Value
        values = content.OverallResultValues
        steps = content.Trace.StepTraces if content.Trace is not None else []
        print(json.dumps({"error": error, "type": type(meta).__name__,
                          "result_id": meta.ResultId, "seq": meta.SequenceNumber,
                          "evaluation": int(meta.ResultEvaluation),
                          "entities": [[e.EntityType, e.EntityId]
                                       for e in meta.AssociatedEntities],
                          "values": [[v.Name, v.MeasuredValue, v.LowLimit, v.High]
                                     for v in values],
                          "trace": [[c.Name, c.PhysicalQuantity, list(c.Values)]
                                    for step in steps for c in step.StepTraceContent]}))


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1], sys.argv[2]))
