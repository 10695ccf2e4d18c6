"""The joining-system companion model (OPC 40450-1 "IJT Base" 1.01 and what it needs) loaded into
asyncua 2.1.0, and the few workarounds that make asyncua load and encode it as published.

The vendored NodeSet2 files (``nodesets/``, Apache-2.0, from the working group's repository
umati/UA-for-Industrial-Joining-Technologies) load in the order of their RequiredModel: DI, IA,
AMB, Machinery, Machinery Result, IJT Base.  What asyncua 2.1.0 gets wrong, and what is done
here (``../shared/design/PROTOCOLS.md`` numbers them):

1. A default value holding an ExtensionObject nested in a field (7 placeholders in Machinery
   Result and IJT Base) fails the import (``KeyError: 'TypeId'``): those values are dropped
   from the text before the import (the files on disk stay as published).
2. A subtype's DataTypeDefinition lacks its base type's fields (JoiningResultMetaDataType has
   no ResultId): the base fields are prepended, as Part 3 says the attribute must hold, and
   written back, so every client reads complete definitions.
3. ``AllowSubTypes`` fields (ResultDataType.ResultMetaData, JoiningProcessDataType.
   JoiningProcessMetaData, SignalDataType.SignalValue) are dropped by the parser: the
   definition written back says StructureWithSubtypedValues with those fields flagged, as the
   standard has it; the Python classes asyncua encodes with type those fields
   ExtensionObject (Variant for an abstract built-in), which is the standard's binary
   encoding of a subtyped field.  :func:`load_client_types` does the same for an asyncua
   client (a stock asyncua client decodes a result only with it).

Items 4-7 (methods, where events are fired, the abstract event type, security) are in
:mod:`stationd.opcua.server`.  Also here: a structure whose ``<Definition>`` has no field of its
own gets no DataTypeDefinition at all from the import (Machinery Result's
ResultTransferOptionsDataType, DI's FetchResultDataType: node-opcua could not register them),
and one whose encodings name it only from their side no DefaultEncodingId: both are completed
(:func:`_complete`).
"""

from __future__ import annotations

import logging
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from asyncua.client.client import Client
from asyncua.common.node import Node
from asyncua.common.structures104 import make_structure
from asyncua.server.address_space import AddressSpace, AttributeValue, NodeData
from asyncua.server.server import Server

from stationd.opcua import dictionary
from stationd.opcua.uatypes import ua

NODESETS = Path(__file__).with_name("nodesets")
#: load order (each file's RequiredModel before it)
MODELS = ("DI", "IA", "AMB", "Machinery", "MachineryResult", "IJTBase")
IJT_URI = "http://opcfoundation.org/UA/IJT/Base/"
MACHINERY_URI = "http://opcfoundation.org/UA/Machinery/"
RESULT_URI = "http://opcfoundation.org/UA/Machinery/Result/"
DI_URI = "http://opcfoundation.org/UA/DI/"
#: the namespaces whose structures are fixed (the companion models')
MODEL_URIS = ("http://opcfoundation.org/UA/DI/", "http://opcfoundation.org/UA/IA/",
              "http://opcfoundation.org/UA/AMB/", MACHINERY_URI, RESULT_URI, IJT_URI)

_UANODESET = "{http://opcfoundation.org/UA/2011/03/UANodeSet.xsd}"
# a <Value> whose <Body> holds another <TypeId>: an ExtensionObject nested in a field
_NESTED_DEFAULT = re.compile(
    r"<Value>(?:(?!</Value>).)*?<Body[^>]*>(?:(?!</Body>).)*<TypeId(?:(?!</Value>).)*</Value>",
    re.S)
# abstract built-in types a subtyped field may hold: encoded as a Variant
_ABSTRACT_BUILTINS = {24, 26, 27, 28}   # BaseDataType, Number, Integer, UInteger


def nodeset_text(model: str) -> tuple[str, int]:
    """The NodeSet2 text of ``model`` as asyncua can import it, and how many default values
    were dropped (workaround 1)."""
    text = (NODESETS / f"{model}.NodeSet2.xml").read_text(encoding="utf-8-sig")
    return _NESTED_DEFAULT.subn("", text)


def subtyped_fields(model: str) -> dict[tuple[str, str], set[str]]:
    """The ``AllowSubTypes`` fields of ``model``'s structures: (namespace URI, NodeId text
    without its namespace) -> field names."""
    root = ET.parse(NODESETS / f"{model}.NodeSet2.xml").getroot()  # noqa: S314 - vendored file
    uris = [u.text or "" for u in root.iter(f"{_UANODESET}Uri")]
    out: dict[tuple[str, str], set[str]] = {}
    for dt in root.iter(f"{_UANODESET}UADataType"):
        names = {f.get("Name", "") for f in dt.iter(f"{_UANODESET}Field")
                 if f.get("AllowSubTypes") == "true"}
        if names:
            out[_split(uris, dt.get("NodeId", ""))] = names
    return out


def _split(uris: list[str], nodeid: str) -> tuple[str, str]:
    m = re.fullmatch(r"ns=(\d+);(.*)", nodeid)
    return (uris[int(m.group(1)) - 1], m.group(2)) if m else ("http://opcfoundation.org/UA/",
                                                               nodeid)


async def load_model(server: Server) -> list[_Struct]:
    """Import the companion models into ``server`` and fix their structures (1-3); returns
    them (complete definitions, parents first) for :func:`publish_dictionaries`.

    The import is most of a server's start (seconds): the first server of a process imports,
    and what the import added to its address space is kept (:class:`_Imported`); a later
    server of the same process, in the same state before it, takes a copy of that instead."""
    aspace = server.iserver.aspace
    namespaces = list(await server.get_namespace_array())   # (the server's own list)
    if _IMPORTED and await _IMPORTED[0].copy_into(server, namespaces):
        return _IMPORTED[0].types
    before = {nid: len(data.references) for nid, data in aspace._nodes.items()}
    types = await _import(server)
    if not _IMPORTED:
        _IMPORTED.append(_Imported.of(aspace, before, namespaces,
                                      list(await server.get_namespace_array()), types))
    return types


async def _import(server: Server) -> list[_Struct]:
    subtyped: dict[tuple[str, str], set[str]] = {}
    # the published files have references asyncua cannot place (warned about by the hundred)
    quiet = logging.getLogger("asyncua.common.xmlimporter")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        for model in MODELS:
            text, _ = nodeset_text(model)
            await server.import_xml(xmlstring=text)
            subtyped.update(subtyped_fields(model))
    finally:
        quiet.setLevel(level)
    uris = await server.get_namespace_array()
    flagged = {ua.NodeId.from_string(f"ns={uris.index(u)};{i}"): names
               for (u, i), names in subtyped.items()}
    types = await _structures(server, uris)
    for t in types:
        t.sdef = _spec_definition(t.sdef, flagged.get(t.data_type, set()))
        await server.get_node(t.data_type).write_attribute(
            ua.AttributeIds.DataTypeDefinition, ua.DataValue(ua.Variant(t.sdef)))
    _generate(types)
    return types


@dataclass(frozen=True)
class _Imported:
    """What importing the companion models did to a fresh server's address space: the nodes
    it made, the references it added to nodes that were there, the namespaces it registered
    (the only attribute of an existing node it changes: the namespace array), and the fixed
    structures.  Its Python classes are the process's already (:func:`_generate`).

    A copy has attribute holders, reference lists and arrays of its own (asyncua hands out
    a value's own list, which read-modify-write code then changes in place) and shares the
    rest, which a server replaces and never changes, so one server's nodes, references and
    values never reach another's.  asyncua 2.1.0 keeps the nodes in ``AddressSpace._nodes``;
    a test builds one server each way and compares every node."""

    before: tuple[str, ...]          # the namespace array the import started from
    after: tuple[str, ...]           # ... and ended with
    added: dict[ua.NodeId, NodeData]
    grown: dict[ua.NodeId, list[ua.ReferenceDescription]]
    types: list[_Struct]

    @classmethod
    def of(cls, aspace: AddressSpace, before: dict[ua.NodeId, int], ns_before: list[str],
           ns_after: list[str], types: list[_Struct]) -> _Imported:
        nodes = aspace._nodes
        return cls(tuple(ns_before), tuple(ns_after),
                   {nid: _copy(d) for nid, d in nodes.items() if nid not in before},
                   {nid: list(d.references[before[nid]:]) for nid, d in nodes.items()
                    if nid in before and len(d.references) > before[nid]}, types)

    async def copy_into(self, server: Server, namespaces: list[str]) -> bool:
        """Give ``server`` what the import gave; False (nothing done) unless it is where the
        import started: as many namespaces, none of the models', none of the nodes."""
        aspace = server.iserver.aspace
        if len(namespaces) != len(self.before) or \
                set(namespaces) & set(self.after[len(self.before):]) or \
                any(nid in aspace for nid in self.added):
            return False
        for uri in self.after[len(self.before):]:
            await server.register_namespace(uri)
        for nid, data in self.added.items():
            aspace[nid] = _copy(data)
        for nid, refs in self.grown.items():
            aspace[nid].references.extend(refs)
        return True


def _copy(data: NodeData) -> NodeData:
    """A node of its own (:class:`_Imported` says what is shared); no callbacks (an
    imported node, or a standard one as filled, has none)."""
    out = NodeData(data.nodeid)
    attributes = out.attributes
    for attr, held in data.attributes.items():
        dv = held.value
        if dv is not None and dv.Value is not None and isinstance(dv.Value.Value, list):
            dv = replace(dv, Value=replace(dv.Value, Value=list(dv.Value.Value)))
        attributes[attr] = AttributeValue(dv)   # type: ignore[arg-type]  # (None as held)
    out.references = list(data.references)
    return out


_IMPORTED: list[_Imported] = []   # this process's first import (at most one)
#: this process's first standard address space, as asyncua filled it (at most one)
_STANDARD: list[dict[ua.NodeId, NodeData]] = []


async def init_server(server: Server) -> None:
    """``server.init()``, with the standard address space (Part 5's 6,000 nodes) of a
    process's later servers copied from its first: asyncua fills each one from generated
    code, about 3 s of a server's start; a copy takes a tenth of that.  The copy is taken
    as the fill left it, before asyncua's own fixes and writes, which each server then makes
    to its own nodes (:func:`_copy`: no node, reference list or array shared)."""
    iserver = server.iserver
    fill = iserver.load_standard_address_space

    async def standard(shelf_file: Path | None = None) -> None:
        if shelf_file is not None or not _STANDARD:
            await fill(shelf_file)
            if shelf_file is None and not _STANDARD:
                _STANDARD.append({nid: _copy(d) for nid, d in iserver.aspace._nodes.items()})
            return
        for nid, data in _STANDARD[0].items():
            iserver.aspace[nid] = _copy(data)

    iserver.load_standard_address_space = standard   # type: ignore[method-assign]
    await server.init()


async def publish_dictionaries(server: Server, types: list[_Struct], idx: int) -> \
        list[dictionary.Dictionary]:
    """The OPC Binary dictionaries of ``types`` (:func:`load_model`'s), each structure
    described as the codec encodes it (:func:`_codec_definition`: the classes of
    :func:`_generate` are made from the same definitions), under ``OPC Binary`` with NodeIds
    in namespace ``idx`` (:mod:`stationd.opcua.dictionary` says why and how)."""
    structures = []
    for t in types:
        encoding = await dictionary.default_binary(server, t.data_type)
        if encoding is not None:   # abstract: nothing is ever encoded as it
            structures.append(dictionary.Structure(t.data_type, t.name,
                                                   _codec_definition(t.sdef), encoding))
    dictionaries = await dictionary.build(server, structures)
    await dictionary.publish(server, dictionaries, idx)
    return dictionaries


async def load_client_types(client: Client) -> None:
    """What an asyncua client needs to decode this server's results: the definitions loaded,
    then the companion models' classes made again with subtyped fields as ExtensionObject or
    Variant (workaround 3; the server's definitions are complete, so 2 is not needed)."""
    await client.load_data_type_definitions()
    _generate(await _structures(client, await client.get_namespace_array()))


@dataclass
class _Struct:
    data_type: ua.NodeId
    name: str
    sdef: ua.StructureDefinition


async def _structures(endpoint: Server | Client, uris: list[str]) -> list[_Struct]:
    """Every structure of the companion models, parents first, with its base type's fields
    in front of its own (workaround 2)."""
    wanted = {uris.index(u) for u in MODEL_URIS if u in uris}
    out: list[_Struct] = []

    async def walk(node: Node, inherited: list[ua.StructureField]) -> None:
        for child in await node.get_children(refs=ua.ObjectIds.HasSubtype,
                                             nodeclassmask=ua.NodeClass.DataType):
            fields = inherited
            sdef = await _definition(child)
            if child.nodeid.NamespaceIndex in wanted:
                sdef = await _complete(child, node, sdef)
            if sdef is not None:
                own = {f.Name for f in sdef.Fields}
                sdef.Fields = [f for f in inherited if f.Name not in own] + list(sdef.Fields)
                fields = list(sdef.Fields)
                if child.nodeid.NamespaceIndex in wanted:
                    name = (await child.read_browse_name()).Name
                    out.append(_Struct(child.nodeid, name, sdef))
            await walk(child, fields)

    await walk(endpoint.get_node(ua.ObjectIds.Structure), [])
    return out


async def _definition(node: Node) -> ua.StructureDefinition | None:
    try:
        sdef = await node.read_data_type_definition()
    except ua.UaError:
        return None
    return sdef if isinstance(sdef, ua.StructureDefinition) else None


async def _complete(node: Node, base: Node,
                    sdef: ua.StructureDefinition | None) -> ua.StructureDefinition:
    """A structure's definition with what asyncua's import leaves out: a structure whose
    ``<Definition>`` has no field of its own (Machinery Result's ResultTransferOptionsDataType,
    DI's abstract FetchResultDataType) gets none at all, and one whose encodings name it only
    from their side (DI's TransferResultErrorDataType, ...) no DefaultEncodingId; Part 3 has
    every structure's definition say both (its base type's fields are added by the caller)."""
    if sdef is None:
        sdef = ua.StructureDefinition(BaseDataType=base.nodeid,
                                      StructureType=ua.StructureType.Structure, Fields=[])
    if sdef.DefaultEncodingId.is_null():
        for ref in await node.get_references(refs=ua.ObjectIds.HasEncoding):
            if ref.BrowseName.Name == "Default Binary":
                sdef = replace(sdef, DefaultEncodingId=ref.NodeId)
    return sdef


def _spec_definition(sdef: ua.StructureDefinition, subtyped: set[str]) -> ua.StructureDefinition:
    """The definition as Part 3 has it: every field, subtyped ones flagged."""
    if subtyped:
        fields = [replace(f, IsOptional=f.Name in subtyped) for f in sdef.Fields]
        return replace(sdef, Fields=fields,
                       StructureType=ua.StructureType.StructureWithSubtypedValues)
    if any(f.IsOptional for f in sdef.Fields) and \
            sdef.StructureType == ua.StructureType.Structure:
        return replace(sdef, StructureType=ua.StructureType.StructureWithOptionalFields)
    return sdef


def _codec_definition(sdef: ua.StructureDefinition) -> ua.StructureDefinition:
    """The definition asyncua's codec encodes right: a subtyped field typed ExtensionObject
    (Variant for an abstract built-in), its binary encoding in the standard."""
    if sdef.StructureType != ua.StructureType.StructureWithSubtypedValues:
        return sdef
    fields = []
    for f in sdef.Fields:
        if f.IsOptional:
            builtin = f.DataType.NamespaceIndex == 0 and \
                f.DataType.Identifier in _ABSTRACT_BUILTINS
            f = replace(f, IsOptional=False, DataType=ua.NodeId(
                ua.ObjectIds.BaseDataType if builtin else ua.ObjectIds.Structure))
        fields.append(f)
    return replace(sdef, Fields=fields, StructureType=ua.StructureType.Structure)


def _generate(types: list[_Struct]) -> None:
    """Make the Python classes of ``types`` again, each after the structures its fields use,
    registered under the encoding ids asyncua already knows."""
    encodings = {dt: enc for enc, cls in ua.extension_objects_by_typeid.items()
                 if (dt := getattr(cls, "data_type", None)) is not None}
    by_id = {t.data_type: t for t in types}
    done: set[ua.NodeId] = set()

    def make(t: _Struct, trail: frozenset[ua.NodeId]) -> None:
        if t.data_type in done:
            return
        for f in t.sdef.Fields:
            dep = by_id.get(f.DataType)
            if dep is not None and dep.data_type not in trail:
                make(dep, trail | {t.data_type})
        done.add(t.data_type)
        encoding = encodings.get(t.data_type)
        if encoding is None:
            return   # abstract: no encoding, nothing to make
        env: dict[str, Any] = make_structure(t.data_type, t.name,
                                             _codec_definition(t.sdef), log_error=False)
        if t.name in env:
            old = getattr(ua, t.name, None)
            if getattr(old, "data_type", None) == t.data_type:
                delattr(ua, t.name)   # asyncua keeps a name's first class otherwise
            ua.register_extension_object(t.name, encoding, env[t.name], t.data_type)

    for t in types:
        make(t, frozenset())


__all__ = ["IJT_URI", "MODELS", "RESULT_URI", "init_server", "load_client_types", "load_model",
           "nodeset_text", "publish_dictionaries", "subtyped_fields"]
