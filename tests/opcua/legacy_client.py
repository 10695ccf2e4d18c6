"""A client in its own process that builds its classes the way the working group's conformance
client does, then reads results by id and prints what it decoded as JSON (one line).

Why its own process: asyncua registers the classes it generates in its global ``ua`` module,
where the server under test keeps its own; a client in the test's process would change what
the server encodes with.

    python -m tests.opcua.legacy_client URL MODE RESULT_ID...

MODE: ``legacy`` (``load_type_definitions()`` alone: the OPC Binary dictionaries),
``conformance`` (the legacy loader, then ``load_data_type_definitions()``, the working
group's order), ``stock`` (``load_data_type_definitions()`` alone) or ``helper``
(:func:`stationd.opcua.model.load_client_types`); ``raw`` loads no types and prints each
result's ExtensionObject as it came (its TypeId and body bytes in hex) with the server's
namespace array.  ``+optional`` after a mode applies :func:`resolvable_optional` first.
Only asyncua is imported (the helper mode excepted): any interpreter with any asyncua runs
it, the conformance client's too.
"""

from __future__ import annotations

import asyncio
import json
import math
import sys
from typing import Any

from asyncua import ua
from asyncua.client.client import Client
from asyncua.ua.uaerrors import UaError

RESULT_URI = "http://opcfoundation.org/UA/Machinery/Result/"


def resolvable_optional() -> None:
    """The client-side fix for asyncua 2.x's legacy loader (2.1.0 and newer): it executes
    the classes it generates under its own module's ``from __future__ import annotations``,
    so an optional member's type stays the text ``Optional[ua.X]``, resolved later in the
    namespace of ``builtins`` (the classes' ``__module__``), where ``Optional`` is not:
    every structure with an optional member fails (NameError) whatever the dictionary."""
    import builtins
    import typing

    builtins.Optional = typing.Optional  # type: ignore[attr-defined]


def _text(value: Any) -> Any:
    return value.Text if isinstance(value, ua.LocalizedText) else value


def summary(result: Any) -> dict[str, Any]:
    """What an MES needs of a result, as plain JSON."""
    meta = result.ResultMetaData
    content = result.ResultContent[0]
    content = content.Value if isinstance(content, ua.Variant) else content
    trace = getattr(content, "Trace", None)
    return {
        "type": type(meta).__name__, "result_id": meta.ResultId,
        "seq": meta.SequenceNumber, "evaluation": int(meta.ResultEvaluation),
        "technology": _text(meta.JoiningTechnology), "assembly": meta.AssemblyType,
        "name": meta.Name, "simulated": meta.IsSimulated,
        # made while the link to the controller was down (absent: the default, false)
        "offline": bool(getattr(meta, "IsGeneratedOffline", None)),
        "entities": sorted([e.EntityType, e.EntityId] for e in meta.AssociatedEntities),
        "values": [[v.Name, None if math.isnan(v.MeasuredValue) else v.MeasuredValue,
                    v.LowLimit, v.High, v.EngineeringUnits.UnitId]
                   for v in content.OverallResultValues],
        "trace": [] if trace is None else
        [[c.Name, len(c.Values)] for s in trace.StepTraces for c in s.StepTraceContent],
    }


async def main(url: str, mode: str, ids: list[str]) -> None:
    mode, _, fix = mode.partition("+")
    if fix == "optional":
        resolvable_optional()
    async with Client(url, timeout=30) as client:   # 4 s by default: short on a loaded machine
        if mode in ("legacy", "conformance"):
            await client.load_type_definitions()
        if mode in ("conformance", "stock"):
            await client.load_data_type_definitions()
        if mode == "helper":   # the station's helper (needs the station's package)
            from stationd.opcua.model import load_client_types

            await load_client_types(client)
        mr = (await client.get_namespace_array()).index(RESULT_URI)
        rm = None
        for node in await client.nodes.objects.get_children():
            for child in await node.get_children():
                try:
                    rm = await child.get_child([f"{mr}:ResultManagement"])
                except UaError:
                    continue
        assert rm is not None, "no ResultManagement"
        out: list[dict[str, Any]] = []
        if mode == "raw":   # no types loaded: the result's bytes as they came
            for rid in ids:
                _, result, _ = await rm.call_method(f"{mr}:GetResultById", rid, ua.Int32(0))
                out.append({"type_id": result.TypeId.to_string(), "body": result.Body.hex()})
            print(json.dumps({"namespaces": await client.get_namespace_array(),
                              "results": out}))
            return
        for rid in ids:
            try:
                _, result, error = await rm.call_method(f"{mr}:GetResultById", rid,
                                                        ua.Int32(0))
                out.append({"error": error, **summary(result)})
            except Exception as exc:   # what this stack cannot decode is the finding
                out.append({"failed": f"{type(exc).__name__}: {exc}"[:300]})
        print(json.dumps(out))


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1], sys.argv[2], sys.argv[3:]))
