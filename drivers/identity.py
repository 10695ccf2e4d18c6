"""What a device says it is, typed: its one line of words and the nameplate fields it gave.

Why typed and not only words: the station serves its devices as assets of the joining
system over OPC UA, whose ``Identification`` (OPC 10000-100 DI's IVendorNameplateType, as
Machinery's MachineryComponentIdentificationType carries it) has a place for each of these;
an MES reads the controller's manufacturer and serial number there, not in a sentence.  The
words stay what they were (the journal, the devices panel and the station's status show
them): a backend that knows no field gives its words alone.

A field is None where the device did not say it (never an empty string: "not said" and
"said empty" read the same to an MES, and None keeps the backends from inventing one).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DeviceIdentity:
    """A device's identity as its driver read it.

    ``words``: the one line the station logs and shows (unchanged by the fields);
    ``manufacturer``, ``model``, ``serial_number``, ``software_revision``: as DI's
    nameplate names them (Manufacturer, Model, SerialNumber, SoftwareRevision), each None
    where the device did not say it.  Which of the device's own fields goes where is the
    backend's to document (Open Protocol: :meth:`drivers.wrench.openprotocol.identity.
    ControllerIdentity.device_identity`)."""

    words: str
    manufacturer: str | None = None
    model: str | None = None
    serial_number: str | None = None
    software_revision: str | None = None

    def __post_init__(self) -> None:
        # an empty field (a controller padding it with spaces) is a field not said
        for name in ("manufacturer", "model", "serial_number", "software_revision"):
            value = getattr(self, name)
            if value is not None and not value.strip():
                object.__setattr__(self, name, None)


__all__ = ["DeviceIdentity"]
