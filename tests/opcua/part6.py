"""A reader of OPC UA Binary (Part 6 §5.2) driven by the published NodeSet2 files alone: no
asyncua class, no dictionary of the station.  It holds the station's bytes against the
specification's layout, so that no workaround for one client's bug (asyncua's, node-opcua's)
can change what conforming clients read.

Structures follow Part 6 §5.2.7: a StructureWithOptionalFields starts with a UInt32
EncodingMask whose bit *n* is the *n*-th optional field of the whole structure, base type's
fields first (so JoiningTechnology, the 20th optional field of JoiningResultMetaDataType, is
bit 19); a field with ``AllowSubTypes`` is an ExtensionObject (a Variant for an abstract
built-in); an array is an Int32 length and its elements; an enumeration an Int32.
"""

from __future__ import annotations

import re
import struct
import uuid
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

NODESET = "{http://opcfoundation.org/UA/2011/03/UANodeSet.xsd}"
UA = "http://opcfoundation.org/UA/"
#: built-in type ids (Part 6 §5.1.2) by the names this reader decodes
BUILTIN = {1: "Boolean", 2: "SByte", 3: "Byte", 4: "Int16", 5: "UInt16", 6: "Int32",
           7: "UInt32", 8: "Int64", 9: "UInt64", 10: "Float", 11: "Double", 12: "String",
           13: "DateTime", 14: "Guid", 15: "ByteString", 17: "NodeId", 19: "StatusCode",
           20: "QualifiedName", 21: "LocalizedText", 22: "ExtensionObject", 24: "Variant",
           26: "Variant", 27: "Variant", 28: "Variant"}
#: the few ns 0 types the companion models use, by what they are encoded as
NS0 = {290: "Double", 294: "DateTime", 295: "String", 887: "EUInformation", 884: "Range",
       29: "Int32", 12755: "Variant", 31917: "String", 31918: "String"}
_FIXED = {"Boolean": "<?", "SByte": "<b", "Byte": "<B", "Int16": "<h", "UInt16": "<H",
          "Int32": "<i", "UInt32": "<I", "Int64": "<q", "UInt64": "<Q", "Float": "<f",
          "Double": "<d", "StatusCode": "<I"}


@dataclass
class Field:
    name: str
    data_type: tuple[str, str]      # (namespace URI, identifier text)
    optional: bool
    subtyped: bool
    array: bool


@dataclass
class DataType:
    key: tuple[str, str]
    name: str
    base: tuple[str, str] | None
    fields: list[Field] | None        # None: not a structure (an enumeration, a simple type)
    enum: bool
    encoding: tuple[str, str] | None  # Default Binary


class Model:
    """The data types of NodeSet2 ``files`` (a namespace's URI with each NodeId)."""

    def __init__(self, files: list[Path]) -> None:
        self.types: dict[tuple[str, str], DataType] = {}
        self.by_encoding: dict[tuple[str, str], DataType] = {}
        for path in files:
            self._read(path)
        for t in self.types.values():
            if t.encoding is not None:
                self.by_encoding[t.encoding] = t

    def _read(self, path: Path) -> None:
        root = ET.parse(path).getroot()  # noqa: S314 - the vendored, published files
        uris = [UA] + [u.text or "" for u in root.iter(f"{NODESET}Uri")]
        aliases = {a.get("Alias", ""): a.text or "" for a in root.iter(f"{NODESET}Alias")}

        def key(text: str) -> tuple[str, str]:
            text = aliases.get(text, text)
            m = re.fullmatch(r"ns=(\d+);(.*)", text)
            return (uris[int(m.group(1))], m.group(2)) if m else (UA, text)

        binary: dict[tuple[str, str], tuple[str, str]] = {}   # DataType -> Default Binary
        for obj in root.iter(f"{NODESET}UAObject"):
            if obj.get("BrowseName", "").split(":")[-1] != "Default Binary":
                continue
            for ref in obj.iter(f"{NODESET}Reference"):
                if ref.get("ReferenceType") in ("HasEncoding", "i=38") and \
                        ref.get("IsForward") == "false":
                    binary[key(ref.text or "")] = key(obj.get("NodeId", ""))
        for dt in root.iter(f"{NODESET}UADataType"):
            base = None
            for ref in dt.iter(f"{NODESET}Reference"):
                kind = ref.get("ReferenceType", "")
                if kind in ("i=45", "HasSubtype") and ref.get("IsForward") == "false":
                    base = key(ref.text or "")
            defn = dt.find(f"{NODESET}Definition")
            fields = None
            enum = False
            if defn is not None:
                raw = defn.findall(f"{NODESET}Field")
                enum = any(f.get("Value") is not None for f in raw)
                if not enum:
                    fields = [Field(f.get("Name", ""), key(f.get("DataType", "i=24")),
                                    f.get("IsOptional") == "true",
                                    f.get("AllowSubTypes") == "true",
                                    int(f.get("ValueRank", "-1")) >= 0)
                              for f in raw]
            me = key(dt.get("NodeId", ""))
            self.types[me] = DataType(me, dt.get("BrowseName", "").split(":")[-1], base,
                                      fields, enum, binary.get(me))

    def fields(self, t: DataType) -> list[Field]:
        """Every field of structure ``t``, its base types' first (Part 3: a subtype's
        DataTypeDefinition holds them all; the NodeSet files list only its own)."""
        own = list(t.fields or [])
        if t.base is not None and t.base in self.types and self.types[t.base].fields:
            names = {f.name for f in own}
            return [f for f in self.fields(self.types[t.base]) if f.name not in names] + own
        return own

    def is_enum(self, key: tuple[str, str]) -> bool:
        t = self.types.get(key)
        while t is not None:
            if t.enum:
                return True
            t = self.types.get(t.base) if t.base else None
        return False

    def simple(self, key: tuple[str, str]) -> str | None:
        """A non-structure's built-in encoding (walking up to ns 0)."""
        seen = key
        while seen[0] != UA:
            t = self.types.get(seen)
            if t is None or t.base is None:
                return None
            if t.fields is not None:
                return None
            seen = t.base
        n = int(seen[1][2:])
        return BUILTIN.get(n) or NS0.get(n)


class Reader:
    """Decodes bytes by :class:`Model` (``model``); structures become dicts with a
    ``_type`` (their name) and ``_mask`` (the EncodingMask, when they have one)."""

    def __init__(self, model: Model, data: bytes, namespaces: list[str] | None = None) -> None:
        self.model, self.data, self.pos = model, data, 0
        self.namespaces = namespaces or [UA]   # the server's namespace array

    def take(self, n: int) -> bytes:
        if self.pos + n > len(self.data):
            raise ValueError(f"{n} bytes wanted at {self.pos}, {len(self.data)} in all")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def fixed(self, kind: str) -> Any:
        fmt = _FIXED[kind]
        return struct.unpack(fmt, self.take(struct.calcsize(fmt)))[0]

    def builtin(self, kind: str) -> Any:
        if kind in _FIXED:
            return self.fixed(kind)
        if kind in ("String", "ByteString"):
            n = self.fixed("Int32")
            if n < 0:
                return None
            raw = self.take(n)
            return raw.decode("utf-8") if kind == "String" else raw
        if kind == "DateTime":
            ticks = self.fixed("Int64")
            return None if ticks == 0 else \
                datetime(1601, 1, 1, tzinfo=UTC) + timedelta(microseconds=ticks // 10)
        if kind == "Guid":
            return uuid.UUID(bytes_le=self.take(16))
        if kind == "LocalizedText":
            mask = self.fixed("Byte")
            locale = self.builtin("String") if mask & 1 else None
            text = self.builtin("String") if mask & 2 else None
            return {"Locale": locale, "Text": text}
        if kind == "QualifiedName":
            return (self.fixed("UInt16"), self.builtin("String"))
        if kind == "NodeId":
            return self.node_id()
        if kind == "ExtensionObject":
            return self.extension_object()
        if kind == "Variant":
            return self.variant()
        if kind == "EUInformation":
            return {"_type": "EUInformation", "NamespaceUri": self.builtin("String"),
                    "UnitId": self.fixed("Int32"),
                    "DisplayName": self.builtin("LocalizedText"),
                    "Description": self.builtin("LocalizedText")}
        if kind == "Range":
            return {"_type": "Range", "Low": self.fixed("Double"), "High": self.fixed("Double")}
        raise ValueError(f"no reader for {kind}")

    def node_id(self) -> tuple[int, Any]:
        form = self.fixed("Byte")
        if form == 0:
            return (0, self.fixed("Byte"))
        if form == 1:
            return (self.fixed("Byte"), self.fixed("UInt16"))
        if form == 2:
            return (self.fixed("UInt16"), self.fixed("UInt32"))
        if form == 3:
            return (self.fixed("UInt16"), self.builtin("String"))
        raise ValueError(f"NodeId encoding {form}")

    def extension_object(self) -> Any:
        type_id = self.node_id()
        body = self.fixed("Byte")
        if body == 0:
            return None
        length = self.fixed("Int32")
        end = self.pos + length
        t = self.model_type(type_id)
        if t is None:
            self.pos = end
            return {"_type": f"unknown {type_id}"}
        out = self.structure(t)
        if self.pos != end:
            raise ValueError(f"{t.name}: {self.pos - end:+d} bytes against its length")
        return out

    def model_type(self, type_id: tuple[int, Any]) -> DataType | None:
        ns, ident = type_id
        uri = self.namespaces[ns] if ns < len(self.namespaces) else ""
        return self.model.by_encoding.get((uri, f"i={ident}" if isinstance(ident, int)
                                           else f"s={ident}"))

    def variant(self) -> Any:
        mask = self.fixed("Byte")
        kind = BUILTIN[mask & 0x3F]
        if mask & 0x80:
            n = self.fixed("Int32")
            values = [self.builtin(kind) for _ in range(max(n, 0))]
            if mask & 0x40:
                dims = self.fixed("Int32")
                for _ in range(dims):
                    self.fixed("Int32")
            return values
        return self.builtin(kind)

    def value(self, f: Field) -> Any:
        if f.subtyped:
            simple = self.model.simple(f.data_type)
            kind = "Variant" if simple == "Variant" else "ExtensionObject"
            return self.builtin(kind)
        t = self.model.types.get(f.data_type)
        if self.model.is_enum(f.data_type):
            return self.fixed("Int32")
        if t is not None and t.fields is not None:
            return self.structure(t)
        simple = self.model.simple(f.data_type)
        if simple is None:
            raise ValueError(f"field {f.name}: type {f.data_type} unknown")
        return self.builtin(simple)

    def structure(self, t: DataType) -> dict[str, Any]:
        fields = self.model.fields(t)
        out: dict[str, Any] = {"_type": t.name}
        optional = [f for f in fields if f.optional and not f.subtyped]
        mask = self.fixed("UInt32") if optional else 0
        if optional:
            out["_mask"] = mask
            if mask >> len(optional):
                raise ValueError(f"{t.name}: EncodingMask {mask:#x} sets bits beyond its "
                                 f"{len(optional)} optional fields")
        bits = {f.name: i for i, f in enumerate(optional)}
        for f in fields:
            if f.name in bits and not mask & (1 << bits[f.name]):
                continue
            if f.array:
                n = self.fixed("Int32")
                out[f.name] = None if n < 0 else [self.value(f) for _ in range(n)]
            else:
                out[f.name] = self.value(f)
        return out


def optional_bits(model: Model, name: str) -> list[str]:
    """The optional fields of structure ``name`` in EncodingMask bit order."""
    t = next(t for t in model.types.values() if t.name == name and t.fields is not None)
    return [f.name for f in model.fields(t) if f.optional and not f.subtyped]


__all__ = ["Model", "Reader", "optional_bits"]
