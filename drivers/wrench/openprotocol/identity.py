"""Who the controller says it is: MID 0002 (communication start acknowledge), revisions 1-7.

Why typed: the station logs it at every session start and shows it on the devices panel, so
that "which controller, which software, does it acknowledge at link level" is answered by
the controller itself and not by the station's configuration.  ``sequence_number_support``
(revision 6: the specification R2.8.0's table 16 brings parameters 12-16 together; an
integrator asking for revision 5 or lower never learns it) is also what switches link-level
acknowledgement on, as integrators' libraries decide it (node-open-protocol: on when the
0002 it asked for at revision 6 says 1).

Each revision appends parameters (2-digit tag, fixed width) to the previous one; they are
read by tag, and a 0002 that does not read (an odd controller) still starts the session:
what was read is kept and the rest is in ``unread``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from drivers.identity import DeviceIdentity

#: tag -> (field, width); the revision that brought each one is in the comments.
IDENTITY_PARAMS: dict[int, tuple[str, int]] = {
    1: ("cell_id", 4), 2: ("channel_id", 2), 3: ("controller_name", 25),        # rev 1
    4: ("supplier_code", 3),                                                     # rev 2
    5: ("open_protocol_version", 19), 6: ("controller_software_version", 19),    # rev 3
    7: ("tool_software_version", 19),
    8: ("rbu_type", 24), 9: ("controller_serial", 10),                           # rev 4
    10: ("system_type", 3), 11: ("system_subtype", 3),                           # rev 5
    12: ("sequence_number_support", 1), 13: ("linking_handling_support", 1),     # rev 6
    14: ("station_id", 10), 15: ("station_name", 25), 16: ("client_id", 1),      # rev 6 too
}
_INTS = {"cell_id", "channel_id", "system_type", "system_subtype", "client_id"}
_FLAGS = {"sequence_number_support", "linking_handling_support"}


@dataclass(frozen=True)
class ControllerIdentity:
    """MID 0002 as received; a field the revision does not carry is None."""

    revision: int = 1
    cell_id: int | None = None
    channel_id: int | None = None
    controller_name: str = ""
    supplier_code: str | None = None
    open_protocol_version: str | None = None
    controller_software_version: str | None = None
    tool_software_version: str | None = None
    rbu_type: str | None = None
    controller_serial: str | None = None
    system_type: int | None = None
    system_subtype: int | None = None
    sequence_number_support: bool | None = None   # link-level acknowledgement (9997/9998)
    linking_handling_support: bool | None = None  # multi-part messages
    station_id: str | None = None
    station_name: str | None = None
    client_id: int | None = None
    unread: str = ""                              # what did not read as parameters

    def describe(self) -> str:
        """One line for logs and the devices panel: name, cell, channel, then what the
        revision adds (supplier, versions, serial, link-level acknowledgement)."""
        if self.cell_id is None and self.channel_id is None and not self.controller_name:
            return self.unread.strip() or f"controller (MID 0002 revision {self.revision})"
        head = (f"{self.controller_name or 'controller'} (cell {self.cell_id or 0:04d}, "
                f"channel {self.channel_id or 0:02d})")
        extra = [f"{label} {value}" for label, value in (
            ("supplier", self.supplier_code), ("Open Protocol", self.open_protocol_version),
            ("software", self.controller_software_version),
            ("tool software", self.tool_software_version), ("RBU", self.rbu_type),
            ("serial", self.controller_serial)) if value]
        if self.sequence_number_support is not None:
            extra.append("link-level ack " + ("yes" if self.sequence_number_support else "no"))
        return f"{head}: {', '.join(extra)}" if extra else head

    def device_identity(self) -> DeviceIdentity:
        """The nameplate fields an MES reads (DI's names), from what this 0002 carries;
        ``words`` is :meth:`describe`.

        MID 0002 has no manufacturer, model or product code field: what comes nearest is
        taken, and a revision that does not carry it leaves the field None.

        - manufacturer: the supplier code (parameter 04, three letters, e.g. ``ACT`` for
          Atlas Copco Tools), the only word of who made the controller.  IJT Base has a
          ``SupplierCode`` of its own on an asset's Identification, but defined as the
          SAP or ERP supplier code *of the user*, another thing: the station leaves it
          empty rather than give the protocol's code for the ERP's;
        - model: the controller's name (parameter 03: what the controller calls itself),
          with the RBU type (parameter 08, the controller's function level) after it when
          the revision gives it;
        - serial_number: the controller's serial number (parameter 09);
        - software_revision: the controller's software version (parameter 06); the tool's
          software and the Open Protocol version stay in the words."""
        model = self.controller_name or None
        if self.rbu_type:
            model = f"{model or 'controller'} (RBU {self.rbu_type})"
        return DeviceIdentity(self.describe(), manufacturer=self.supplier_code, model=model,
                              serial_number=self.controller_serial,
                              software_revision=self.controller_software_version)


def parse_identity(revision: int, data: bytes) -> ControllerIdentity:
    """MID 0002's data (any revision) -> ControllerIdentity; never raises."""
    text = data.decode("ascii", "replace")
    values: dict[str, Any] = {}
    pos = 0
    while pos + 2 <= len(text):
        tag = text[pos:pos + 2]
        spec = IDENTITY_PARAMS.get(int(tag)) if tag.isdigit() else None
        if spec is None or spec[0] in values or pos + 2 + spec[1] > len(text):
            break
        name, width = spec
        raw = text[pos + 2:pos + 2 + width]
        value: Any = raw.rstrip()
        if name in _INTS:
            value = int(raw) if raw.isdigit() else None
        elif name in _FLAGS:
            value = {"0": False, "1": True}.get(raw)
        values[name] = value
        pos += 2 + width
    return ControllerIdentity(revision=revision, unread=text[pos:], **values)
