"""Typed device errors: every failure a person must act on, with the device's own code.

The daemon turns any :class:`DeviceError` into a fault state with ``str(error)`` as the reason
and reconnects with backoff; commands print it as one line and exit non-zero.
"""

from __future__ import annotations


class DriverError(Exception):
    """Base of every error of the device layer (``drivers`` imports nothing from ``stationd``;
    the station prints these as one line, or turns them into a fault)."""


class DeviceError(DriverError):
    """A device failed; ``device`` names it (its URL), ``code`` is the device's own error code."""

    def __init__(self, message: str, *, device: str | None = None,
                 code: int | str | None = None) -> None:
        self.device = device
        self.code = code
        self.reason = message    # without the device: a wrapper that names it again says it
        prefix = f"{device}: " if device else ""
        super().__init__(prefix + message)


class UrlError(DeviceError):
    """A device URL that cannot be used: unknown scheme, bad option, missing port."""


class ConnectError(DeviceError):
    """The device could not be reached (refused, unreachable, no such port)."""


class DeviceTimeoutError(DeviceError):
    """The device did not answer in time."""


class ConnectTimeoutError(ConnectError, DeviceTimeoutError):
    """Connecting got no answer in time.  One type on every backend (Open Protocol, Modbus
    TCP, ...): it is both a failed connect and a timeout, so a handler of either sees it."""


class ConnectionLostError(DeviceError):
    """The link dropped (peer closed, cable pulled, EIO on a pty)."""


class ProtocolError(DeviceError):
    """The device sent something that is not the protocol: garbage, a bad frame, a bad length."""


class RefusedError(DeviceError):
    """The device answered with a refusal (Open Protocol MID 0004, a Modbus exception)."""
