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
(MachineryComponentIdentificationType: Manufacturer and SerialNumber, mandatory for an asset,
empty where the station does not know them; the controller's identity from its MID 0002 in
``Model``) and ``Health`` (DI FunctionalGroupType) with ``DeviceHealth`` (DI
DeviceHealthEnumeration: NORMAL 0 while the device answers, FAILURE 1 while it is in fault;
the line link OFF_SPEC 3 while its backlog is past a bound), ``ErrorMessage`` (the station's
reason, empty when NORMAL) and ``ErrorTimestamp`` (when it last changed).  The line
database's link down is FAILURE of that asset only: never a fault of the station (its
``State`` stays what the station says).  A device first heard of in an event (a pair added
by a reload) gets its asset then.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from asyncua.common.node import Node
from asyncua.server.server import Server

from stationd.opcua.model import DI_URI, IJT_URI, MACHINERY_URI
from stationd.opcua.uatypes import ua

NORMAL, FAILURE, OFF_SPEC = 0, 1, 3          # DI DeviceHealthEnumeration
DEVICE_HEALTH_ENUM = 6244                    # in DI
FUNCTIONAL_GROUP_TYPE = 1005                 # in DI
COMPONENT_IDENTIFICATION_TYPE = 1005         # MachineryComponentIdentificationType
HAS_INTERFACE = 17603
LINE_LINK, STATION_DATABASE = "line", "database"

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
    model: Node


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
        why, since ``at`` (epoch seconds)."""
        async with self._lock:
            asset = self._assets.get(device) or await self._add(device)
            await asset.health.write_value(ua.Variant(health, ua.VariantType.Int32))
            await asset.message.write_value(ua.Variant(
                ua.LocalizedText("" if health == NORMAL else reason or "fault", "en"),
                ua.VariantType.LocalizedText))
            await asset.stamp.write_value(ua.Variant(datetime.fromtimestamp(at, UTC),
                                                     ua.VariantType.DateTime))

    async def identified(self, device: str, identity: str) -> None:
        """What the device said it is (the controller's MID 0002), in its ``Model``."""
        async with self._lock:
            asset = self._assets.get(device) or await self._add(device)
            await asset.model.write_value(ua.Variant(ua.LocalizedText(identity[:200], "en"),
                                                     ua.VariantType.LocalizedText))

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
        model = await _variable(ident, f"{base}.Identification.Model", idx,
                                ua.QualifiedName("Model", di),
                                ua.Variant(ua.LocalizedText("", "en"),
                                           ua.VariantType.LocalizedText))
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
                                ua.Variant(datetime.now(UTC), ua.VariantType.DateTime),
                                ua.NodeId(ua.ObjectIds.UtcTime))
        asset = _Asset(dh, msg, stamp, model)
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


async def _variable(parent: Node, nodeid: str, idx: int, name: Any, value: Any,
                    datatype: Any = None) -> Node:
    """A read-only variable under ``parent``, or the one its type made there (the
    identification's mandatory ones)."""
    try:
        node = await parent.get_child([name.to_string()])
    except ua.UaError:
        return await parent.add_variable(ua.NodeId(nodeid, idx), name, value,
                                         datatype=datatype)
    await node.write_value(value)
    return node


__all__ = ["FAILURE", "LINE_LINK", "NORMAL", "OFF_SPEC", "STATION_DATABASE", "DeviceAssets"]
