"""The station's devices in the joining-system model, each with its health: an asset of the
JoiningSystem (OPC 40450-1 1.01: ``AssetManagement/Assets``), updated from the station's
events (``DeviceHealth``, and ``LineLinkChanged`` for the link to the line database).

Why assets and not variables of our own: the IJT Base model has the place
(``IJoiningSystemAssetType``: an asset's ``Health`` with DI's ``DeviceHealth``, its
``ErrorMessage`` and ``ErrorTimestamp``), so an MES that knows the companion model finds them
where it looks for any joining system's.  Where each device goes (the asset folder of
``JoiningSystemType`` and the interface the asset declares):

- ``wrench`` (the controller): Controllers, IControllerType;
- ``lift`` (its PLC): Accessories, IAccessoryType;
- each camera pair (its name): Sensors, ISensorType;
- ``database`` (the station's own) and ``line`` (the link to the line database):
  SoftwareComponents, ISoftwareType.

The JoiningSystem is instantiated with its optional children, AssetManagement/Assets and its
folders among them.  Each asset (browse name: the device's name as the station's screens and
journal use it, in the server's namespace) holds ``Identification``
(MachineryComponentIdentificationType) and ``Health`` (DI FunctionalGroupType).  The
identification is what the device said it is (``DeviceIdentified``: the controller's MID
0002, mapped by its driver), in DI's nameplate properties: ``Manufacturer`` and
``SerialNumber`` (mandatory for an asset: empty while the station does not know them),
``Model`` (the device's model, else its one line of words, as before the fields were typed),
``SoftwareRevision``, and IJT's ``Description`` (the system-specific description of the
asset: the device's words, whole).  The type's instantiation makes DI's ones (optional
ones among them, left empty: the station knows no ManufacturerUri or ProductCode); IJT's
Description is made when first known, with the module's NodeIds
(``<asset>.Identification.<name>``).  IJT's ``SupplierCode`` (the user's ERP code for the
supplier) is not the Open Protocol supplier code and is left out.

``Health`` holds ``DeviceHealth`` (DI DeviceHealthEnumeration: NORMAL 0 while the device
answers, FAILURE 1 while it is in fault; the line link OFF_SPEC 3 while its backlog is past a
bound), ``ErrorMessage`` (the station's
reason, empty when NORMAL) and ``ErrorTimestamp``: when the error occurred (IJT: "the
timestamp when the error occurred in the given asset"), i.e. when the device went to that
health (the same health said again with other words keeps it), and OPC UA's null DateTime
while there is none (:data:`NO_ERROR`, DateTime.MinValue, 0 on the wire: Part 6 5.1.2).  Why
null and not the time of the last change: a client that reads ErrorTimestamp without
DeviceHealth took a device that came back, or never failed (stamped at the server's start),
for one with an error.  Why MinValue and not a Null Variant: the variable stays of its type
(UtcTime) for the clients that check it.  The line database's link down is FAILURE of
that asset only: never a fault of the station (its ``State`` stays what the station says).
A device first heard of in an event (a pair added by a reload) gets its asset then.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

from asyncua.common.node import Node
from asyncua.server.server import Server

from drivers.identity import DeviceIdentity
from stationd.opcua.model import DI_URI, IJT_URI, MACHINERY_URI
from stationd.opcua.uatypes import ua

NORMAL, FAILURE, OFF_SPEC = 0, 1, 3          # DI DeviceHealthEnumeration
DEVICE_HEALTH_ENUM = 6244                    # in DI
FUNCTIONAL_GROUP_TYPE = 1005                 # in DI
COMPONENT_IDENTIFICATION_TYPE = 1005         # MachineryComponentIdentificationType
HAS_INTERFACE = 17603
LINE_LINK, STATION_DATABASE = "line", "database"
#: ErrorTimestamp with no error: DateTime.MinValue, OPC UA's null DateTime (encoded as 0)
NO_ERROR = datetime(1601, 1, 1, tzinfo=UTC)

#: device name -> (asset folder, interface in IJT Base); a camera pair: :data:`PAIR`
KNOWN = {"wrench": ("Controllers", 1003), "lift": ("Accessories", 1015),
         STATION_DATABASE: ("SoftwareComponents", 1019),
         LINE_LINK: ("SoftwareComponents", 1019)}
PAIR = ("Sensors", 1011)
DESCRIPTIONS = {"wrench": "the tightening controller", "lift": "the lift's PLC",
                STATION_DATABASE: "the station's own database",
                LINE_LINK: "the link to the line database (store-and-forward)"}


@dataclass
class _Asset:
    health: Node
    message: Node
    stamp: Node
    ident: Node
    nodeid: str                                  # its Identification's NodeId (a string)
    plate: dict[str, Node] = field(default_factory=dict)   # property -> node, once made
    error: int = NORMAL                          # the health its ErrorTimestamp is of


class DeviceAssets:
    """The assets of one JoiningSystem: :meth:`build` once, then :meth:`report` per event
    (in the server's loop; reports are applied one at a time, in order)."""

    def __init__(self) -> None:
        self._server: Server | None = None
        self._js: Node | None = None
        self._idx = 0
        self._prefix = ""
        self._uris: list[str] = []
        self._assets: dict[str, _Asset] = {}
        self._lock = asyncio.Lock()

    @property
    def devices(self) -> tuple[str, ...]:
        return tuple(self._assets)

    async def build(self, server: Server, js: Node, idx: int, prefix: str,
                    devices: tuple[str, ...]) -> None:
        self._server, self._js, self._idx, self._prefix = server, js, idx, prefix
        self._uris = await server.get_namespace_array()
        for d in devices:
            await self._add(d)

    async def report(self, device: str, health: int, reason: str, at: float) -> None:
        """``device``'s ``health`` (:data:`NORMAL`, :data:`FAILURE`, :data:`OFF_SPEC`) and
        why, since ``at`` (epoch seconds): its ErrorTimestamp ``at`` when it goes to a health
        that is an error, null when it is NORMAL (see the module's docstring)."""
        async with self._lock:
            asset = self._assets.get(device) or await self._add(device)
            await asset.health.write_value(ua.Variant(health, ua.VariantType.Int32))
            await asset.message.write_value(ua.Variant(
                ua.LocalizedText("" if health == NORMAL else reason or "fault", "en"),
                ua.VariantType.LocalizedText))
            if health != asset.error:
                stamp = NO_ERROR if health == NORMAL else datetime.fromtimestamp(at, UTC)
                await asset.stamp.write_value(ua.Variant(stamp, ua.VariantType.DateTime))
                asset.error = health

    async def identified(self, device: str, identity: DeviceIdentity) -> None:
        """What the device said it is (the controller's MID 0002), in its Identification's
        nameplate properties (see the module's docstring); a field no longer said is
        emptied, never left from an earlier device."""
        async with self._lock:
            asset = self._assets.get(device) or await self._add(device)
            for name, value in _nameplate(identity):
                node = asset.plate.get(name)
                if node is None and value is None:
                    continue                     # optional, never said: not made
                spec = PLATE[name]
                v = _plate_value(spec.localized, value or "")
                if node is None:
                    node = asset.plate[name] = await _property(
                        asset.ident, f"{asset.nodeid}.{name}", self._idx,
                        ua.QualifiedName(name, self._uris.index(spec.uri)), v)
                else:
                    await node.write_value(v)

    async def _add(self, device: str) -> _Asset:
        assert self._server is not None and self._js is not None  # noqa: S101 - built first
        uris, idx = self._uris, self._idx
        ijt, di, mach = (uris.index(u) for u in (IJT_URI, DI_URI, MACHINERY_URI))
        folder_name, interface = KNOWN.get(device, PAIR)
        folder = await self._folder(folder_name, ijt)
        base = f"{self._prefix}.Assets.{device}"
        node = await folder.add_object(ua.NodeId(base, idx), ua.QualifiedName(device, idx))
        await node.write_attribute(ua.AttributeIds.Description, ua.DataValue(ua.Variant(
            ua.LocalizedText(DESCRIPTIONS.get(device, f"camera pair {device}"), "en"))))
        await node.add_reference(ua.NodeId(interface, ijt), ua.NodeId(HAS_INTERFACE),
                                 forward=True, bidirectional=False)
        ident = await node.add_object(ua.NodeId(f"{base}.Identification", idx),
                                      ua.QualifiedName("Identification", di),
                                      objecttype=ua.NodeId(COMPONENT_IDENTIFICATION_TYPE,
                                                           mach))
        plate: dict[str, Node] = {}
        for name, spec in PLATE.items():   # the mandatory ones, and Model as before
            if spec.always:
                plate[name] = await _property(
                    ident, f"{base}.Identification.{name}", idx,
                    ua.QualifiedName(name, uris.index(spec.uri)),
                    _plate_value(spec.localized, ""))
        health = await node.add_object(ua.NodeId(f"{base}.Health", idx),
                                       ua.QualifiedName("Health", ijt),
                                       objecttype=ua.NodeId(FUNCTIONAL_GROUP_TYPE, di))
        dh = await _variable(health, f"{base}.Health.DeviceHealth", idx,
                             ua.QualifiedName("DeviceHealth", di),
                             ua.Variant(NORMAL, ua.VariantType.Int32),
                             ua.NodeId(DEVICE_HEALTH_ENUM, di))
        msg = await _variable(health, f"{base}.Health.ErrorMessage", idx,
                              ua.QualifiedName("ErrorMessage", ijt),
                              ua.Variant(ua.LocalizedText("", "en"),
                                         ua.VariantType.LocalizedText))
        stamp = await _variable(health, f"{base}.Health.ErrorTimestamp", idx,
                                ua.QualifiedName("ErrorTimestamp", ijt),
                                ua.Variant(NO_ERROR, ua.VariantType.DateTime),
                                ua.NodeId(ua.ObjectIds.UtcTime))
        asset = _Asset(dh, msg, stamp, ident, f"{base}.Identification", plate)
        self._assets[device] = asset
        return asset

    async def _folder(self, name: str, ijt: int) -> Node:
        """The asset folder ``name`` under AssetManagement/Assets, made where missing (the
        JoiningSystem is instantiated with its mandatory children only, and AssetManagement
        is optional: it is made with the first asset)."""
        assert self._js is not None  # noqa: S101 - built first
        di = self._uris.index(DI_URI)
        node, nid = self._js, self._prefix
        for part, objecttype in (("AssetManagement", ua.NodeId(FUNCTIONAL_GROUP_TYPE, di)),
                                 ("Assets", ua.NodeId(ua.ObjectIds.FolderType)),
                                 (name, ua.NodeId(ua.ObjectIds.FolderType))):
            nid = f"{nid}.{part}"
            try:
                node = await node.get_child([f"{ijt}:{part}"])
            except ua.UaError:
                node = await node.add_object(ua.NodeId(nid, self._idx),
                                             ua.QualifiedName(part, ijt), objecttype=objecttype)
        return node


@dataclass(frozen=True)
class _Plate:
    """A nameplate property: its model's URI, whether LocalizedText (else String), and
    whether every asset has it from the start (mandatory, or served before: Model)."""

    uri: str
    localized: bool
    always: bool = False


#: Identification's properties the station writes, in DI's (and IJT's) names
PLATE = {"Manufacturer": _Plate(DI_URI, True, True), "SerialNumber": _Plate(DI_URI, False, True),
         "Model": _Plate(DI_URI, True, True), "SoftwareRevision": _Plate(DI_URI, False),
         "Description": _Plate(IJT_URI, True)}


def _nameplate(identity: DeviceIdentity) -> list[tuple[str, str | None]]:
    """``identity`` as PLATE's properties (None: not said).  Model falls back to the
    words: a device that gives no model is still named there, as before the fields."""
    return [("Manufacturer", identity.manufacturer), ("SerialNumber", identity.serial_number),
            ("Model", identity.model or identity.words or None),
            ("SoftwareRevision", identity.software_revision),
            ("Description", identity.words or None)]


def _plate_value(localized: bool, text: str) -> ua.Variant:
    text = text[:200]    # a controller's odd field does not make a page of a property
    if localized:
        return ua.Variant(ua.LocalizedText(text, "en"), ua.VariantType.LocalizedText)
    return ua.Variant(text, ua.VariantType.String)


async def _property(parent: Node, nodeid: str, idx: int, name: Any, value: Any) -> Node:
    """A property (HasProperty, PropertyType, as the nameplate interfaces declare them)
    under ``parent``, or the one its type made there (the identification's mandatory
    ones), written with ``value``."""
    try:
        node = await parent.get_child([name.to_string()])
    except ua.UaError:
        return await parent.add_property(ua.NodeId(nodeid, idx), name, value)
    await node.write_value(value)
    return node


async def _variable(parent: Node, nodeid: str, idx: int, name: Any, value: Any,
                    datatype: Any = None) -> Node:
    """A read-only variable under ``parent``, or the one its type made there (the health's
    DeviceHealth)."""
    try:
        node = await parent.get_child([name.to_string()])
    except ua.UaError:
        return await parent.add_variable(ua.NodeId(nodeid, idx), name, value,
                                         datatype=datatype)
    await node.write_value(value)
    return node


__all__ = ["FAILURE", "LINE_LINK", "NORMAL", "NO_ERROR", "OFF_SPEC", "STATION_DATABASE",
           "DeviceAssets"]
