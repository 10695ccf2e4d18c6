"""OPC Binary DataTypeDictionaries (Part 5 §D, Part 3 "OPC Binary") for the companion models'
structures, generated from the very definitions the server encodes with.

Why a server whose structures all carry a DataTypeDefinition publishes the legacy form too:
the working group's conformance client (IJT_Test_Client) and MES code derived from it call
asyncua's ``load_type_definitions()`` (this dictionary) before ``load_data_type_definitions()``,
and the asyncua they pin reads the modern attribute without the ``AllowSubTypes`` flag and the
optional-field switches: without a dictionary no result decodes there (``PROTOCOLS.md``).
The working group's own ``.bsd`` files do not serve: their enums are bound by name (which
breaks asyncua's modern loader afterwards) and they have no switch fields.

What is written, per structure with a Default Binary encoding (abstract ones have none):

- every field of the flattened definition (a subtype's base fields first: the definitions of
  :func:`stationd.opcua.model.load_model` are complete), so EncodingMask bits count across
  the whole structure as Part 6 numbers them (JoiningTechnology = bit 19 in
  JoiningResultMetaDataType);
- an optional member as an ``opc:Bit`` ``XSpecified`` switch, the switches padded to 32 bits,
  the member with ``SwitchField``;
- a subtyped (``AllowSubTypes``) member as ``ua:ExtensionObject`` (``ua:Variant`` for an
  abstract built-in): what :func:`stationd.opcua.model._codec_definition` encodes;
- an array as ``NoOfX`` (``opc:Int32``) and ``X`` with ``LengthField``;
- an enumeration as ``opc:Int32`` (its binary encoding; bound by number, not by name).

Each dictionary holds the structures of one namespace at one depth of the "field's type is a
structure of the models" relation, the shallowest first under ``OPC Binary``: asyncua's legacy
loader executes a dictionary's classes before it registers any of them and writes an optional
member's type unquoted (``Optional[ua.X]``), so a dictionary must not use its own structures as
field types, and must come after the ones whose structures it uses.  Each has its
``NamespaceUri`` and a ``DataTypeDescriptionType`` per structure, referenced by
``HasDescription`` from the structure's Default Binary encoding.  The modern
``DataTypeDefinition`` attributes are unchanged.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any
from xml.sax.saxutils import quoteattr

from asyncua.common.node import Node
from asyncua.server.server import Server

from stationd.opcua.uatypes import ua

OPC_BINARY = 93                  # the OPC Binary type system (ns 0)
DICTIONARY_TYPE = 72             # DataTypeDictionaryType
DESCRIPTION_TYPE = 69            # DataTypeDescriptionType
HAS_DESCRIPTION = 39
HAS_ENCODING = 38
ENUMERATION, STRUCTURE, BASE_DATA_TYPE = 29, 22, 24
UA_URI = "http://opcfoundation.org/UA/"
#: the built-in types by id (Part 6 §5.1.2) as the standard dictionary (Opc.Ua.Types.bsd)
#: names them: the first group in the ``opc`` namespace, the others in ``ua``
BUILTIN = {1: "opc:Boolean", 2: "opc:SByte", 3: "opc:Byte", 4: "opc:Int16", 5: "opc:UInt16",
           6: "opc:Int32", 7: "opc:UInt32", 8: "opc:Int64", 9: "opc:UInt64", 10: "opc:Float",
           11: "opc:Double", 12: "opc:String", 13: "opc:DateTime", 14: "opc:Guid",
           15: "opc:ByteString", 16: "ua:XmlElement", 17: "ua:NodeId",
           18: "ua:ExpandedNodeId", 19: "ua:StatusCode", 20: "ua:QualifiedName",
           21: "ua:LocalizedText", 22: "ua:ExtensionObject", 23: "ua:DataValue",
           24: "ua:Variant", 25: "ua:DiagnosticInfo",
           # abstract numbers (Number, Integer, UInteger) travel as a Variant
           26: "ua:Variant", 27: "ua:Variant", 28: "ua:Variant"}


@dataclass
class Structure:
    """One structure to describe: its DataType, name, the definition the codec encodes and
    its Default Binary encoding node."""

    data_type: Any
    name: str
    sdef: Any
    encoding: Any


@dataclass
class Dictionary:
    """One dictionary: its namespace, depth, structures and the XML text."""

    uri: str
    depth: int
    structures: list[Structure]
    xml: str = ""

    @property
    def name(self) -> str:
        return _dictionary_name(self.uri, self.depth)


def _dictionary_name(uri: str, depth: int) -> str:
    """``Opc.Ua.IJT.Base`` for ``http://opcfoundation.org/UA/IJT/Base/`` (the published
    dictionaries' naming), the depth appended after the first."""
    path = re.sub(r"^[a-z]+://(?:www\.)?opcfoundation\.org/UA/", "", uri).strip("/")
    base = "Opc.Ua." + ".".join(p for p in re.split(r"[/:]+", path) if p) if path != uri \
        else re.sub(r"[^A-Za-z0-9.]+", ".", uri).strip(".")
    return base if depth == 0 else f"{base}.{depth}"


class _Types:
    """What a field's DataType is in a dictionary (``opc:Int32``, ``ua:EUInformation``,
    ``n1:EntityDataType``), found by walking its supertypes in the server."""

    def __init__(self, server: Server, ours: dict[Any, Structure]) -> None:
        self.server, self.ours = server, ours
        self._cache: dict[Any, tuple[str, str]] = {}

    async def kind(self, dt: Any) -> tuple[str, str]:
        """(``builtin``, name) | (``enum``, opc:Int32) | (``ours``, "") | (``ua``, name)."""
        if dt in self._cache:
            return self._cache[dt]
        out: tuple[str, str]
        if dt in self.ours:
            out = ("ours", "")
        elif dt.NamespaceIndex == 0 and isinstance(dt.Identifier, int) and \
                dt.Identifier in BUILTIN:
            out = ("builtin", BUILTIN[dt.Identifier])
        else:
            chain = await self._supertypes(dt)
            if ua.NodeId(ENUMERATION) in chain:
                out = ("enum", "opc:Int32")
            elif ua.NodeId(STRUCTURE) in chain:
                if dt.NamespaceIndex != 0:
                    raise ValueError(f"field type {dt} is a structure outside the described "
                                     "models")
                name = (await self.server.get_node(dt).read_browse_name()).Name
                out = ("ua", f"ua:{name}")
            else:
                builtin = next((n for n in chain if n.NamespaceIndex == 0 and
                                n.Identifier in BUILTIN), None)
                if builtin is None:
                    raise ValueError(f"field type {dt} has no built-in supertype")
                out = ("builtin", BUILTIN[builtin.Identifier])
        self._cache[dt] = out
        return out

    async def _supertypes(self, dt: Any) -> list[Any]:
        chain = []
        node: Node | None = self.server.get_node(dt)
        while node is not None:
            chain.append(node.nodeid)
            parents = await node.get_references(refs=ua.ObjectIds.HasSubtype,
                                                direction=ua.BrowseDirection.Inverse)
            node = self.server.get_node(parents[0].NodeId) if parents else None
        return chain


async def build(server: Server, structures: Iterable[Structure]) -> list[Dictionary]:
    """The dictionaries of ``structures`` (any namespaces), in the order a client must load
    them (see the module's docstring)."""
    uris = await server.get_namespace_array()
    ours = {s.data_type: s for s in structures}
    types = _Types(server, ours)
    depth: dict[Any, int] = {}

    def depth_of(s: Structure, trail: frozenset[Any]) -> int:
        if s.data_type not in depth:
            deps = [ours[f.DataType] for f in s.sdef.Fields if f.DataType in ours
                    and f.DataType not in trail]
            depth[s.data_type] = 1 + max(
                (depth_of(d, trail | {s.data_type}) for d in deps), default=-1)
        return depth[s.data_type]

    groups: dict[tuple[int, int], Dictionary] = {}
    for s in ours.values():
        ns = s.data_type.NamespaceIndex
        key = (depth_of(s, frozenset()), ns)
        groups.setdefault(key, Dictionary(uris[ns], key[0], [])).structures.append(s)
    out = [groups[k] for k in sorted(groups)]
    for d in out:
        d.xml = await _xml(d, types, uris)
    return out


async def _xml(d: Dictionary, types: _Types, uris: list[str]) -> str:
    prefixes: dict[str, str] = {d.uri: "tns"}

    def prefix(uri: str) -> str:
        if uri not in prefixes:
            prefixes[uri] = f"n{len(prefixes)}"
        return prefixes[uri]

    body: list[str] = []
    for s in sorted(d.structures, key=lambda s: s.name):
        body += [f"  <opc:StructuredType Name={quoteattr(s.name)} "
                 'BaseType="ua:ExtensionObject">']
        if s.sdef.StructureType == ua.StructureType.Union:
            raise ValueError(f"{s.name}: unions are not described")   # the models have none
        optional = [f for f in s.sdef.Fields if f.IsOptional]
        for f in optional:
            body.append(f'    <opc:Field Name={quoteattr(f.Name + "Specified")} '
                        'TypeName="opc:Bit"/>')
        if optional and len(optional) % 32:
            body.append(f'    <opc:Field Name="Reserved1" TypeName="opc:Bit" '
                        f'Length="{32 - len(optional) % 32}"/>')
        for f in s.sdef.Fields:
            kind, name = await types.kind(f.DataType)
            if kind == "ours":
                target = types.ours[f.DataType]
                name = f"{prefix(uris[target.data_type.NamespaceIndex])}:{target.name}"
            switch = f' SwitchField={quoteattr(f.Name + "Specified")}' if f.IsOptional else ""
            if f.ValueRank >= 1 or f.ValueRank == 0:
                body.append(f'    <opc:Field Name={quoteattr("NoOf" + f.Name)} '
                            f'TypeName="opc:Int32"{switch}/>')
                body.append(f'    <opc:Field Name={quoteattr(f.Name)} TypeName="{name}" '
                            f'LengthField={quoteattr("NoOf" + f.Name)}{switch}/>')
            else:
                body.append(f'    <opc:Field Name={quoteattr(f.Name)} TypeName="{name}"'
                            f'{switch}/>')
        body.append("  </opc:StructuredType>")
    head = ['<?xml version="1.0" encoding="utf-8"?>',
            '<opc:TypeDictionary xmlns:opc="http://opcfoundation.org/BinarySchema/" '
            'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
            f'xmlns:ua="{UA_URI}" '
            + " ".join(f"xmlns:{p}={quoteattr(u)}" for u, p in prefixes.items())
            + f' DefaultByteOrder="LittleEndian" TargetNamespace={quoteattr(d.uri)}>',
            f'  <opc:Import Namespace="{UA_URI}" Location="Opc.Ua.BinarySchema.bsd"/>']
    head += [f"  <opc:Import Namespace={quoteattr(u)}/>" for u in prefixes if u != d.uri]
    return "\n".join([*head, *body, "</opc:TypeDictionary>", ""])


async def default_binary(server: Server, data_type: Any) -> Any | None:
    """The Default Binary encoding node of ``data_type`` (None for an abstract one)."""
    for ref in await server.get_node(data_type).get_references(refs=HAS_ENCODING):
        if ref.BrowseName.Name == "Default Binary":
            return ref.NodeId
    return None


async def publish(server: Server, dictionaries: list[Dictionary], idx: int) -> list[Node]:
    """Add ``dictionaries`` under ``OPC Binary`` (NodeIds in namespace ``idx``), each with its
    NamespaceUri and its descriptions; returns the dictionary nodes."""
    uris = await server.get_namespace_array()
    nodes = []
    for d in dictionaries:
        ns = uris.index(d.uri)
        dict_id = await _add_variable(
            server, ua.NodeId(OPC_BINARY), ua.NodeId(f"Dictionary.{d.name}", idx),
            ua.QualifiedName(d.name, ns), DICTIONARY_TYPE,
            ua.Variant(d.xml.encode(), ua.VariantType.ByteString), ua.ObjectIds.ByteString)
        await _add_variable(
            server, dict_id, ua.NodeId(f"Dictionary.{d.name}.NamespaceUri", idx),
            ua.QualifiedName("NamespaceUri", 0), ua.ObjectIds.PropertyType,
            ua.Variant(d.uri, ua.VariantType.String), ua.ObjectIds.String, property_=True)
        for s in sorted(d.structures, key=lambda s: s.name):
            desc = await _add_variable(
                server, dict_id, ua.NodeId(f"Dictionary.{d.name}.{s.name}", idx),
                ua.QualifiedName(s.name, ns), DESCRIPTION_TYPE,
                ua.Variant(s.name, ua.VariantType.String), ua.ObjectIds.String)
            await server.get_node(s.encoding).add_reference(
                desc, HAS_DESCRIPTION, forward=True, bidirectional=True)
        nodes.append(server.get_node(dict_id))
    return nodes


async def _add_variable(server: Server, parent: Any, nodeid: Any, qname: Any,
                        type_definition: int, value: Any, data_type: int, *,
                        property_: bool = False) -> Any:
    """A read-only variable of ``type_definition`` (asyncua's helpers make every variable a
    BaseDataVariableType)."""
    item = ua.AddNodesItem()
    item.RequestedNewNodeId = nodeid
    item.BrowseName = qname
    item.NodeClass = ua.NodeClass.Variable
    item.ParentNodeId = parent
    item.ReferenceTypeId = ua.NodeId(ua.ObjectIds.HasProperty if property_ else
                                     ua.ObjectIds.HasComponent)
    item.TypeDefinition = ua.NodeId(type_definition)
    attrs = ua.VariableAttributes()
    attrs.DisplayName = ua.LocalizedText(qname.Name)
    attrs.Description = ua.LocalizedText(qname.Name)
    attrs.DataType = ua.NodeId(data_type)
    attrs.Value = value
    attrs.ValueRank = ua.ValueRank.Scalar
    attrs.ArrayDimensions = None
    attrs.WriteMask = attrs.UserWriteMask = 0
    attrs.Historizing = False
    attrs.AccessLevel = attrs.UserAccessLevel = ua.AccessLevel.CurrentRead.mask
    item.NodeAttributes = attrs
    result = (await server.iserver.isession.add_nodes([item]))[0]
    result.StatusCode.check()
    return result.AddedNodeId


__all__ = ["Dictionary", "Structure", "build", "default_binary", "publish"]
