"""The companion models in a server's address space: imported, or copied from the process's
first import (:class:`stationd.opcua.model._Imported`), node for node the same; and the
standard address space, filled or copied from the process's first (``init_server``)."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest
from asyncua.server.server import Server

from stationd.opcua import model
from stationd.opcua.model import MACHINERY_URI
from stationd.opcua.uatypes import ua

MACHINES_FOLDER = 1001   # Machinery's Machines folder (what the station's JoiningSystem joins)


async def _server(app: str) -> tuple[Server, float]:
    server = Server()
    await model.init_server(server)     # the standard nodes copied (tested below)
    await server.set_application_uri(app)
    loop = asyncio.get_running_loop()
    start = loop.time()
    await model.load_model(server)
    return server, loop.time() - start


def _nodes(server: Server) -> dict[Any, tuple[dict[Any, str], list[str]]]:
    """Every node: its attributes' values and its references, as text."""
    return {nid: ({a: repr(v.value.Value if v.value is not None else None)
                   for a, v in d.attributes.items()}, sorted(map(repr, d.references)))
            for nid, d in server.iserver.aspace._nodes.items()}


def _differing(a: dict[Any, Any], b: dict[Any, Any]) -> set[Any]:
    assert set(a) == set(b)
    return {nid for nid in a if a[nid] != b[nid]}


@pytest.fixture
def first_import(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(model, "_IMPORTED", [])   # this test's servers make the process's first


@pytest.mark.usefixtures("first_import")
def test_a_copied_model_is_the_imported_one_node_for_node_and_apart_from_it():
    async def scenario() -> None:
        imported, _ = await _server("urn:a")
        assert len(model._IMPORTED) == 1
        copied, _ = await _server("urn:b")
        # a server's changes stay its own: a node under a shared folder, a namespace, arrays
        # grown in place
        uris = await copied.get_namespace_array()
        folder = copied.get_node(ua.NodeId(MACHINES_FOLDER, uris.index(MACHINERY_URI)))
        await folder.add_object(ua.NodeId("Mine", 1), ua.QualifiedName("Mine", 1))
        await copied.register_namespace("urn:one-of-them")
        grown = 0
        for nid, data in copied.iserver.aspace._nodes.items():
            held = data.attributes.get(ua.AttributeIds.Value)
            variant = held.value.Value if held is not None and held.value is not None else None
            if nid.NamespaceIndex > 1 and variant is not None and \
                    isinstance(variant.Value, list):
                variant.Value.append("changed in place")
                grown += 1
        assert grown > 0
        fresh, _ = await _server("urn:c")
        f = _nodes(fresh)
        assert ua.NodeId("Mine", 1) not in f
        assert "urn:one-of-them" not in await fresh.get_namespace_array()
        assert "changed in place" not in repr(f)
        # a server not where the import started (indices would differ) imports itself
        other = Server()
        await model.init_server(other)
        await other.set_application_uri("urn:d")
        await other.register_namespace("urn:an-extra-namespace")
        await model.load_model(other)
        assert (await other.get_namespace_array()).index(MACHINERY_URI) == 6
        # a copy differs from the import only where two imports differ (the application's
        # URI, the server's start time), and only in standard nodes
        model._IMPORTED.clear()
        again, _ = await _server("urn:e")
        a, b, c = _nodes(imported), _nodes(fresh), _nodes(again)
        assert _differing(a, b) <= _differing(a, c)
        assert all(nid.NamespaceIndex == 0 for nid in _differing(a, c))

    asyncio.run(scenario())


def test_a_copied_standard_address_space_is_the_filled_one_node_for_node_and_apart_from_it(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(model, "_STANDARD", [])

    async def scenario() -> None:
        filled = Server()
        await filled.init()
        first = Server()
        await model.init_server(first)      # fills, and keeps the fill
        assert len(model._STANDARD) == 1
        copied = Server()
        await model.init_server(copied)     # copies
        # a server's changes stay its own: arrays grown in place, a node added
        grown = 0
        for data in first.iserver.aspace._nodes.values():
            held = data.attributes.get(ua.AttributeIds.Value)
            variant = held.value.Value if held is not None and held.value is not None else None
            if variant is not None and isinstance(variant.Value, list) and variant.Value \
                    and isinstance(variant.Value[0], str):
                variant.Value.append("changed in place")
                grown += 1
        assert grown > 0
        await first.nodes.objects.add_object(ua.NodeId("Mine", 1), ua.QualifiedName("Mine", 1))
        again = Server()
        await model.init_server(again)
        f, c, a = _nodes(filled), _nodes(copied), _nodes(again)
        assert ua.NodeId("Mine", 1) not in c and ua.NodeId("Mine", 1) not in a
        assert "changed in place" not in repr(c) and "changed in place" not in repr(a)
        # a copy differs from a fill only where two fills differ: the server's status and
        # times, which a server writes at its start (3 nodes with asyncua 2.1.0)
        second = Server()
        await second.init()
        assert _differing(f, c) <= _differing(f, _nodes(second))
        assert _differing(f, a) <= _differing(f, _nodes(second))

    asyncio.run(scenario())


def test_every_structure_of_the_models_has_its_definition_with_its_base_fields() -> None:
    """A structure whose NodeSet2 ``<Definition>`` has no field of its own (Machinery Result's
    ResultTransferOptionsDataType adds none to BaseResultTransferOptionsDataType; DI's abstract
    FetchResultDataType has none) still has a StructureDefinition, with its base type's fields
    and its Default Binary encoding: a client that builds its types from the definitions
    (node-opcua: "2 dataType(s) could not be registered") can decode every one of them."""
    async def scenario() -> None:
        server, _ = await _server("urn:definitions")
        uris = await server.get_namespace_array()
        wanted = {uris.index(u) for u in model.MODEL_URIS}
        missing: list[str] = []

        async def walk(node: Any, base: list[str]) -> None:
            for child in await node.get_children(refs=ua.ObjectIds.HasSubtype,
                                                 nodeclassmask=ua.NodeClass.DataType):
                name = (await child.read_browse_name()).Name
                sdef = await child.read_data_type_definition() \
                    if child.nodeid.NamespaceIndex in wanted else None
                fields = base
                if child.nodeid.NamespaceIndex in wanted:
                    if not isinstance(sdef, ua.StructureDefinition):
                        missing.append(name)
                    else:
                        fields = [f.Name for f in sdef.Fields]
                        if fields[:len(base)] != base:
                            missing.append(f"{name}: {fields} lacks {base}")
                        abstract = await child.read_attribute(ua.AttributeIds.IsAbstract)
                        if not abstract.Value.Value and sdef.DefaultEncodingId.is_null():
                            missing.append(f"{name}: no DefaultEncodingId")
                await walk(child, fields)

        await walk(server.get_node(ua.ObjectIds.Structure), [])
        assert missing == [], missing
        result = uris.index(model.RESULT_URI)
        options = await server.get_node(ua.NodeId(3004, result)).read_data_type_definition()
        assert isinstance(options, ua.StructureDefinition)
        assert [f.Name for f in options.Fields] == ["ResultId"]

    asyncio.run(scenario())
