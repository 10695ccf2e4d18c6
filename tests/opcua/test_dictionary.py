"""The OPC Binary dictionaries (:mod:`stationd.opcua.dictionary`) and the station's bytes.

Why both: the working group's conformance client, and MES code built like it, decode results
through asyncua's legacy loader (the dictionaries); every other client through the modern
definitions.  A dictionary that pleased one loader by describing something other than what
the server sends would break the rest, so the bytes themselves are read here by a Part 6
reader that knows only the published NodeSet2 files (:mod:`tests.opcua.part6`), and the
dictionaries' switch bits are held against the same files' optional fields.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from db.curves import store_curve
from db.repository import Repository
from stationd.opcua.model import MODELS, NODESETS
from stationd.opcua.results import DISASSEMBLED
from stationd.opcua.uatypes import ua
from tests.db.conftest import record
from tests.opcua.part6 import Model, Reader, optional_bits
from tests.opcua.test_server import VIN, config, repo, serving, stopping

__all__ = ["repo"]   # the fixture, shared with test_server

ROOT = Path(__file__).resolve().parents[2]
OPC = "{http://opcfoundation.org/BinarySchema/}"
N = 40
TORQUE = [round(0.5 * i, 3) for i in range(N)]
ANGLE = [round(2.0 * i, 3) for i in range(N)]
NM, DEG = 0x4E55, 0x4444          # UNECE "NU", "DD"


def shapes(repo: Repository) -> list[dict[str, Any]]:
    """One rundown of every shape a result takes (OK with an operator and curves, NOK with a
    bolt's own limits, a loosening, a pset with torque limits only, no values at all), and
    what each must decode to."""
    record(repo, VIN, "B1", ok=True, operator="olga", tightening_id=101)
    store_curve(repo, tightening_id=101, trace_type=2, unit="Nm", values=TORQUE,
                sample_period_s=0.002)
    store_curve(repo, tightening_id=101, trace_type=1, unit="deg", values=ANGLE,
                sample_period_s=0.002)
    record(repo, VIN, "B2", ok=False, torque_nm=30.0, angle_deg=35.0)
    record(repo, VIN, "B2", ok=True, kind="loosening", torque_nm=20.0, angle_deg=303.0)
    # fetched after a link cut: made while the link was down
    record(repo, VIN, "B3", ok=True, torque_nm=120.0, angle_deg=40.0, offline=True)
    record(repo, VIN, "B1", ok=False, torque_nm=None, angle_deg=None)
    joint = [[20, VIN]]
    return [
        {"bolt": "B1", "evaluation": 1, "assembly": 1, "trace": [["Time", N], ["Angle", N],
                                                                 ["Torque", N]],
         "entities": sorted([*joint, [23, "B1"], [-1, "olga"]]),
         "values": [["Torque", 50.0, 45.0, 55.0, NM], ["Angle", 35.0, 15.0, 60.0, DEG]]},
        {"bolt": "B2", "evaluation": 2, "assembly": 1, "trace": [],
         "entities": sorted([*joint, [23, "B2"]]),
         "values": [["Torque", 30.0, 23.0, 27.0, NM], ["Angle", 35.0, 10.0, 50.0, DEG]]},
        {"bolt": "B2", "evaluation": 1, "assembly": DISASSEMBLED, "trace": [],
         "entities": sorted([*joint, [23, "B2"]]),
         # a loosening: the controller's program judged it, none of the bolt's window
         "values": [["Torque", 20.0, None, None, NM], ["Angle", 303.0, None, None, DEG]]},
        {"bolt": "B3", "evaluation": 1, "assembly": 1, "trace": [], "offline": True,
         "entities": sorted([*joint, [23, "B3"]]),
         "values": [["Torque", 120.0, 110.0, 130.0, NM], ["Angle", 40.0, None, None, DEG]]},
        {"bolt": "B1", "evaluation": 2, "assembly": 1, "trace": [],
         "entities": sorted([*joint, [23, "B1"]]),
         "values": [["Torque", None, 45.0, 55.0, NM], ["Angle", None, 15.0, 60.0, DEG]]},
    ]


async def _client(url: str, mode: str, ids: list[str], python: str = sys.executable) -> Any:
    proc = await asyncio.create_subprocess_exec(
        python, str(ROOT / "tests" / "opcua" / "legacy_client.py"), url, mode, *ids,
        cwd=ROOT, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    try:
        out, err = await asyncio.wait_for(proc.communicate(), 120)
    finally:
        if proc.returncode is None:   # timed out: not left running
            proc.kill()
            await proc.wait()
    assert proc.returncode == 0, err.decode()[-3000:]
    return json.loads(out.decode().strip().splitlines()[-1])


#: an interpreter with the asyncua the working group's conformance client pins (35a77c6b),
#: e.g. that client's venv (its set-up: README.md, "The working group's conformance
#: client"); its stock legacy loader is tried too when this is set
PINNED_PYTHON = os.environ.get("IJT_ASYNCUA_PYTHON")


def _serve_and_read(repo: Repository, clients: dict[str, tuple[str, str]]) -> \
        tuple[dict[str, Any], list[str], list[str]]:
    """The server on ``repo``, a client per entry (label -> interpreter, mode); what each
    read, the result ids and the dictionaries' XML as served."""
    async def scenario() -> tuple[dict[str, Any], list[str], list[str]]:
        srv, stop, task = await serving(config(), repo, simulated=True)
        try:
            db_id = await asyncio.get_running_loop().run_in_executor(None, repo.ledger.db_id)
            ids = [f"{db_id}:{e['seq']}" for e in repo.ledger.since(0)
                   if e["kind"] == "rundown"]
            await asyncio.sleep(0.2)   # the server's first read of the feed
            got = {label: await _client(srv.url, mode, ids, python)
                   for label, (python, mode) in clients.items()}
            assert srv.server is not None
            xml = [(await n.read_value()).decode()
                   for n in await srv.server.nodes.opc_binary.get_children()
                   if (await n.read_browse_name()).Name != "Opc.Ua"]
            return got, ids, xml
        finally:
            await stopping(srv, stop, task)
    return asyncio.run(scenario())


@pytest.mark.system   # clients in their own processes
def test_every_result_shape_round_trips_through_the_legacy_loader_and_part_6(repo):
    want = shapes(repo)
    # (the station's asyncua in the working group's order would decode with the modern
    # loader's classes, which replace the legacy ones there: stock 2.1.0 cannot, see
    # test_stacks)
    clients = {"legacy": (sys.executable, "legacy+optional"),
               "raw": (sys.executable, "raw")}
    if PINNED_PYTHON:
        clients |= {"pinned legacy": (PINNED_PYTHON, "legacy"),
                    "pinned conformance": (PINNED_PYTHON, "conformance")}
    got, ids, dictionaries = _serve_and_read(repo, clients)

    # asyncua's legacy loader alone, and in the working group's order (legacy, then modern):
    # the station's asyncua with the client-side fix its legacy loader needs, and the
    # conformance client's asyncua as it is
    for mode in set(clients) - {"raw"}:
        assert len(got[mode]) == len(want), mode
        for rid, w, g in zip(ids, want, got[mode], strict=True):
            assert "failed" not in g, (mode, g)
            assert g["error"] == 0
            assert g["type"] == "JoiningResultMetaDataType", (mode, g)
            assert g["result_id"] == rid and g["seq"] == int(rid.rsplit(":", 1)[1])
            assert g["technology"] == "Tightening"
            assert g["simulated"] is True
            for key in ("evaluation", "assembly", "entities", "values", "trace"):
                assert g[key] == w[key], (mode, rid, key, g[key])
            assert g["offline"] is w.get("offline", False), (mode, rid)

    # the same bytes read by the specification's layout alone
    model = Model([NODESETS / f"{m}.NodeSet2.xml" for m in MODELS])
    raw = got["raw"]
    bit = optional_bits(model, "JoiningResultMetaDataType").index("JoiningTechnology")
    assert bit == 19
    for rid, w, r in zip(ids, want, raw["results"], strict=True):
        reader = Reader(model, bytes.fromhex(r["body"]), raw["namespaces"])
        top = model.by_encoding[_key(r["type_id"], raw["namespaces"])]
        assert top.name == "ResultDataType"
        result = reader.structure(top)
        assert reader.pos == len(reader.data)
        meta = result["ResultMetaData"]
        assert meta["_type"] == "JoiningResultMetaDataType"
        assert meta["_mask"] & (1 << bit)
        assert meta["JoiningTechnology"]["Text"] == "Tightening"
        assert meta["ResultId"] == rid and meta["AssemblyType"] == w["assembly"]
        assert meta["ResultEvaluation"] == w["evaluation"]
        # IsGeneratedOffline set (true) only on the one made during a link cut
        assert meta.get("IsGeneratedOffline") is (True if w.get("offline") else None), rid
        assert sorted([e["EntityType"], e["EntityId"]]
                      for e in meta["AssociatedEntities"]) == w["entities"]
        # the controller's tightening id, where the rundown has one (the first: 101)
        assert [kv["Key"] for kv in meta.get("ExtendedMetaData") or []] == (
            ["TighteningId"] if w["trace"] else [])
        values = result["ResultContent"][0]["OverallResultValues"]
        assert [[v["Name"], None if math.isnan(v["MeasuredValue"]) else v["MeasuredValue"],
                 v.get("LowLimit"), v.get("High"), v["EngineeringUnits"]["UnitId"]]
                for v in values] == w["values"]

    # each dictionary's switch bits are the specification's optional fields, in its order
    described: set[str] = set()
    for text in dictionaries:
        root = ET.fromstring(text)  # noqa: S314 - the server under test's own output
        own = {t.get("Name") for t in root.iter(f"{OPC}StructuredType")}
        for st in root.iter(f"{OPC}StructuredType"):
            name = st.get("Name", "")
            fields = st.findall(f"{OPC}Field")
            bits = [f.get("Name", "")[:-len("Specified")] for f in fields
                    if f.get("TypeName") == "opc:Bit" and f.get("Name", "").endswith(
                        "Specified")]
            assert bits == optional_bits(model, name), name
            padding = sum(int(f.get("Length", "1")) for f in fields
                          if f.get("TypeName") == "opc:Bit")
            assert padding in (0, 32), name
            for f in fields:   # a dictionary uses none of its own structures as a field
                assert f.get("TypeName", "").split(":")[-1] not in own or \
                    f.get("TypeName", "").startswith(("opc:", "ua:")), (name, f.attrib)
            described.add(name)
    assert {"ResultDataType", "JoiningResultMetaDataType", "JoiningResultDataType",
            "ResultValueDataType", "EntityDataType", "JoiningTraceDataType",
            "StepTraceDataType", "TraceContentDataType", "StepResultDataType",
            "ResultMetaDataType", "ProcessingTimesDataType"} <= described


def _key(text: str, namespaces: list[str]) -> tuple[str, str]:
    nodeid = ua.NodeId.from_string(text)
    ident = f"i={nodeid.Identifier}" if isinstance(nodeid.Identifier, int) \
        else f"s={nodeid.Identifier}"
    return (namespaces[nodeid.NamespaceIndex], ident)


def test_every_dictionary_is_described_and_reachable_from_its_encodings(repo):
    """Part 5: a dictionary names its namespace; each structure's Default Binary encoding
    points at its description (HasDescription), which names the dictionary's type."""
    async def scenario() -> None:
        srv, stop, task = await serving(config(), repo)
        try:
            assert srv.server is not None
            server = srv.server
            uris = await server.get_namespace_array()
            seen = 0
            for d in await server.nodes.opc_binary.get_children():
                if (await d.read_browse_name()).Name == "Opc.Ua":
                    continue
                assert (await d.read_type_definition()) == ua.NodeId(72)
                root = ET.fromstring((await d.read_value()).decode())  # noqa: S314
                uri = (await (await d.get_child(["0:NamespaceUri"])).read_value())
                assert root.get("TargetNamespace") == uri and uri in uris
                names = {t.get("Name") for t in root.iter(f"{OPC}StructuredType")}
                for desc in await d.get_children(refs=ua.ObjectIds.HasComponent):
                    assert (await desc.read_type_definition()) == ua.NodeId(69)
                    assert await desc.read_value() in names
                    encoding = await desc.get_references(
                        refs=ua.ObjectIds.HasDescription, direction=ua.BrowseDirection.Inverse)
                    assert [e.BrowseName.Name for e in encoding] == ["Default Binary"]
                    seen += 1
            assert seen >= 30
        finally:
            await stopping(srv, stop, task)

    asyncio.run(scenario())
