"""What a device backend drives: the physical endpoint its URL reaches, as the backend reads it.

Two processes must not drive one lift PLC, one tightening controller or one camera: they would
both poll the PLC, both send parameters to one tool, both trigger one camera.  Which endpoint a
URL reaches is its backend's knowledge (its protocol's default port, whether a Modbus unit is a
device of its own, that a camera index is a ``/dev/videoN``), so each backend answers it
(:meth:`drivers.lifecycle.Openable.endpoint`) and the station only turns the answer into the
key of a lock (``stationd.devicekey``: host names resolved, device links followed).

The values are as the URL writes them, parsed by the backend's own rules: a host is not
resolved here and a path's links are not followed (that is the machine's view, not the
protocol's).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TcpEndpoint:
    """A device on TCP: ``host`` as written, ``port`` with the protocol's default filled in;
    ``unit``: the Modbus unit id when one gateway serves several devices (None: the port
    is one device, as an Open Protocol controller's)."""

    host: str
    port: int
    unit: int | None = None


@dataclass(frozen=True)
class SerialEndpoint:
    """A serial line (``path`` as the driver opens it): the whole line is one device,
    whatever unit on it is addressed (two processes on one line garble each other's
    frames)."""

    path: str


@dataclass(frozen=True)
class AravisEndpoint:
    """A GenICam camera by its Aravis device id, as written (Aravis ids keep their case)."""

    device_id: str


@dataclass(frozen=True)
class VideoEndpoint:
    """A video device: the ``/dev`` path an OpenCV camera index or device path names."""

    path: str


@dataclass(frozen=True)
class UrlEndpoint:
    """A backend that does not say what it drives: the URL's text stands for the device, so
    two processes given the same text are kept apart (it is never taken for a device no one
    else can reach)."""

    text: str


#: what a backend drives; None (never an Endpoint) is a device no other process can share:
#: a simulated twin of this process, files read by anyone
Endpoint = TcpEndpoint | SerialEndpoint | AravisEndpoint | VideoEndpoint | UrlEndpoint

__all__ = ["AravisEndpoint", "Endpoint", "SerialEndpoint", "TcpEndpoint", "UrlEndpoint",
           "VideoEndpoint"]
