"""A Modbus TCP or RTU link, and Modbus URLs: the only module that uses pymodbus's client API.

pymodbus is pinned (3.16.*) because its API changes in minor releases; everything the drivers
ask of its client is in :class:`ModbusLink` below (its server: ``modbus_server.py``), so an
upgrade is checked here and in the tests, nowhere else.  The lift PLC (``drivers.lift.modbus``)
and the register-driven wrench (``drivers.wrench.modbus``) both talk through it.

    modbus-tcp://HOST[:PORT]?unit=1&timeout=1.0
    modbus-rtu:///dev/ttyUSB0?baud=19200&parity=E&stopbits=1&unit=1&timeout=1.0

The socket or serial port is opened by ``drivers.link`` (the link layer Open Protocol uses
too, so a failure is the same error on every protocol), not by pymodbus, and handed to its
synchronous client: pymodbus's ``connect()`` logs the reason and returns False, and the
station must tell "refused" from "no such port" from "permission denied".  Every failure is
a typed DeviceError; what a device says in its own words (what a refused connection means,
hints for Modbus exceptions) is its :class:`Wording`.  Reconnecting is the station keeper's
business.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from drivers.endpoint import SerialEndpoint, TcpEndpoint
from drivers.errors import (
    ConnectionLostError,
    DeviceError,
    DeviceTimeoutError,
    ProtocolError,
    RefusedError,
)
from drivers.link import baud_rate, connect_tcp, open_serial
from drivers.url import OptionError, parse_url

# pymodbus journals its own view of a failure (hex frame dumps, "Invalid Modbus protocol id",
# "Repeating...") in lines that name no device; every failure reaches the station as one of
# our errors, with the device and its reason.  Its lines are kept for a crash only.
logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

#: Modbus TCP's registered port, where a ``modbus-tcp://`` URL without one connects
DEFAULT_PORT = 502
TCP_FORM = "modbus-tcp://HOST[:PORT]?unit=1&timeout=1.0"
RTU_FORM = "modbus-rtu:///dev/ttyUSB0?baud=19200&parity=E&unit=1"

EXCEPTION_NAMES = {
    1: "illegal function", 2: "illegal data address", 3: "illegal data value",
    4: "server device failure", 5: "acknowledge", 6: "server device busy",
    8: "memory parity error", 10: "gateway path unavailable",
    11: "gateway target device failed to respond",
}


@dataclass(frozen=True)
class LinkSpec:
    """Where the device is: TCP host and port, or serial port and line settings."""

    kind: str  # "tcp" | "rtu"
    target: str  # host name or serial port path
    port: int = DEFAULT_PORT
    unit: int = 1
    baud: int = 19200
    parity: str = "E"
    stopbits: int = 1

    def describe(self) -> str:
        if self.kind == "tcp":
            return f"Modbus TCP {self.target}:{self.port} unit {self.unit}"
        return (f"Modbus RTU {self.target} {self.baud} 8{self.parity}{self.stopbits} "
                f"unit {self.unit}")


@dataclass(frozen=True)
class Wording:
    """What a device's link errors say in its own words."""

    refused: str  # after "connection refused by HOST:PORT", in parentheses: what to check
    unknown_exception: str = "unknown"  # the name of a Modbus exception code not listed
    hints: Mapping[int, str] = field(default_factory=dict)  # exception code -> what to check


def _choice(*allowed: str) -> Callable[[str], str]:
    def conv(text: str) -> str:
        if text.upper() not in allowed:   # the accepted ones said (a technician's trial)
            raise OptionError(f"one of {', '.join(allowed)}")
        return text.upper()
    return conv


def _positive(text: str) -> float:
    value = float(text)
    if not 0 < value < 3600:
        raise ValueError(text)
    return value


def _unit(text: str) -> int:
    value = int(text)
    if not 0 <= value <= 247:
        raise OptionError("a Modbus unit id is 0-247")
    return value


def parse_modbus_url(text: str) -> tuple[LinkSpec, dict[str, float | None]]:
    """The link and the timing options (None where the URL does not say) of a Modbus URL."""
    url = parse_url(text)
    timing = {"timeout": (_positive, None)}
    if url.scheme == "modbus-tcp":
        opts = url.typed_options({"unit": (_unit, 1), **timing}, TCP_FORM)
        if not url.host or url.path not in ("", "/"):
            raise url.error(f"expected a host and optional port, e.g. {TCP_FORM}")
        spec = LinkSpec("tcp", url.host, url.port or DEFAULT_PORT, opts.pop("unit"))
    elif url.scheme == "modbus-rtu":
        opts = url.typed_options({"unit": (_unit, 1), "baud": (baud_rate, 19200),
                                  "parity": (_choice("N", "E", "O"), "E"),
                                  "stopbits": (_choice("1", "2"), "1"), **timing}, RTU_FORM)
        if url.host or not url.path.startswith("/"):
            raise url.error(f"expected a serial port path, e.g. {RTU_FORM}")
        spec = LinkSpec("rtu", url.path, 0, opts.pop("unit"), opts.pop("baud"),
                        opts.pop("parity"), int(opts.pop("stopbits")))
    else:
        raise url.error(f"not a Modbus URL; expected {TCP_FORM} or {RTU_FORM}")
    return spec, opts


def modbus_endpoint(text: str) -> TcpEndpoint | SerialEndpoint:
    """What the Modbus URL ``text`` drives, read as the link is (UrlError when it is not
    one): over TCP, the host and port with one unit of it (a gateway serves several
    devices, one per unit id); over RTU, the whole serial line, whatever the unit (the
    lift and a controller on one line are one device to lock)."""
    spec, _ = parse_modbus_url(text)
    if spec.kind == "tcp":
        return TcpEndpoint(spec.target, spec.port, spec.unit)
    return SerialEndpoint(spec.target)


#: how much of a garbage answer a message shows
SAMPLE_BYTES = 32


class _Heard:
    """Mixed into pymodbus's clients: counts the bytes received.  Its framer drops what it
    cannot parse and then reports "No response", so only the count tells a peer that answered
    garbage (ProtocolError, as on every other protocol) from a silent one (a timeout)."""

    heard = 0
    sample = b""   # the first bytes heard since :meth:`listen` (what garbage looked like)

    def listen(self) -> int:
        """Start a request: the count so far (what it heard is then ``heard`` minus it)."""
        self.sample = b""
        return self.heard

    def recv(self, size: int | None) -> bytes:
        data: bytes = super().recv(size)  # type: ignore[misc]  # the client's, after us
        self.heard += len(data)
        if len(self.sample) < SAMPLE_BYTES:
            self.sample += data[:SAMPLE_BYTES - len(self.sample)]
        return data


class _HeardTcp(_Heard, ModbusTcpClient):
    pass


class _HeardSerial(_Heard, ModbusSerialClient):
    pass


class ModbusLink:
    """One open connection wrapped in a pymodbus synchronous client (no retries: the caller
    polls again).  Errors name ``device`` ("" leaves that to the caller)."""

    def __init__(self, spec: LinkSpec, device: str, wording: Wording) -> None:
        self.spec = spec
        self.device = device
        self.wording = wording
        self._client: _HeardTcp | _HeardSerial | None = None
        self._conn: Any = None  # the socket or serial port, ours to close

    def _error(self, cls: type[DeviceError], message: str, code: int | None = None
               ) -> DeviceError:
        return cls(message, device=self.device, code=code)

    def connect(self, timeout: float) -> None:
        """Open the socket or port (``drivers.link``: the same errors as every protocol's)
        and hand it to a pymodbus client."""
        s = self.spec
        if s.kind == "tcp":
            try:
                sock = connect_tcp(s.target, s.port, timeout, self.wording.refused)
            except DeviceError as exc:
                raise self._error(type(exc), str(exc)) from None
            tcp = _HeardTcp(s.target, port=s.port, timeout=timeout, retries=0)
            tcp.socket = sock  # connect() then sees an open socket and keeps it
            self._client, self._conn = tcp, sock
            return
        rtu = _HeardSerial(s.target, framer=FramerType.RTU, baudrate=s.baud, bytesize=8,
                                 parity=s.parity, stopbits=s.stopbits, timeout=timeout,
                                 retries=0)
        try:
            port = open_serial(s.target, baudrate=s.baud, parity=s.parity,
                               stopbits=s.stopbits, timeout=timeout, write_timeout=timeout,
                               inter_byte_timeout=rtu.inter_byte_timeout or None)
        except DeviceError as exc:
            raise self._error(type(exc), str(exc)) from None
        rtu.socket = port
        self._client, self._conn = rtu, port

    def call(self, what: str, timeout: float, fn: Callable[[Any], Any], *,
             no_answer: str | None = None) -> Any:
        """One request, ``fn(client)``, answered within ``timeout``; typed errors for every
        failure, saying ``what`` was being done ("reading registers 6-15 of unit 1"), and
        ``no_answer`` instead of the default message for a timeout.  A Modbus exception is a
        RefusedError with its code (the link stays usable)."""
        client = self._client
        if client is None:
            raise self._error(ConnectionLostError, "not connected")
        # pymodbus 3.16 has no per-request timeout: the client and its transaction manager
        # each keep a copy of the connect parameters, and both time a request.
        client.comm_params.timeout_connect = timeout
        client.transaction.comm_params.timeout_connect = timeout
        heard = client.listen()
        try:
            rr = fn(client)
        except ConnectionException as exc:
            if client.heard > heard:   # it answered, then hung up: not a Modbus device
                raise self._garbage(client, what) from None
            # (a Modbus server answers even what it refuses: a technician's trial, the lift's
            # and the controller's ports swapped, read no hint of another device's port; one
            # that answered on this connection before is that device gone: another trial,
            # a PLC switched off, read the hint of another device's port)
            said = ("the device closed the connection (it answered on it before: switched "
                    "off, restarted, or its network dropped)" if heard else
                    "the device closed the connection without an answer (a Modbus server "
                    "answers, even with an exception: another device's port?)") \
                if "closed" in exc.string else exc.string.replace(type(client).__name__,
                                                                  self._protocol())
            raise self._error(ConnectionLostError, f"link lost {what}: {said}") from None
        except ModbusIOException as exc:
            if "No response" in exc.string and client.heard > heard:
                raise self._garbage(client, what) from None
            if "No response" in exc.string:
                raise self._error(DeviceTimeoutError, no_answer or f"no answer within "
                                                                   f"{timeout:g} s {what}"
                                  ) from None
            raise self._error(ProtocolError, f"bad answer {what}: {exc.string}") from None
        except ModbusException as exc:
            raise self._error(ProtocolError, f"bad answer {what}: {exc.string}") from None
        except OSError as exc:
            raise self._error(ConnectionLostError, f"link lost {what}: {exc}") from None
        if rr.isError():
            code = int(getattr(rr, "exception_code", 0))
            name = EXCEPTION_NAMES.get(code, self.wording.unknown_exception)
            hint = self.wording.hints.get(code)
            raise self._error(RefusedError, f"Modbus exception {code} ({name}) {what}"
                                            + (f": {hint}" if hint else ""), code)
        return rr

    def _protocol(self) -> str:
        return "Modbus TCP" if self.spec.kind == "tcp" else "Modbus RTU"

    def _garbage(self, client: _Heard, what: str) -> DeviceError:
        """A peer that answered bytes pymodbus could not frame: another protocol (an HTTP
        server on the port), or a wrong baud rate's noise; what it said, shortened."""
        more = "..." if client.heard > len(client.sample) else ""
        return self._error(ProtocolError, f"garbage {what}: the device answered something "
                                          f"that is not {self._protocol()} "
                                          f"({client.sample!r}{more})")

    def read(self, table: str, start: int, count: int, timeout: float, what: str, *,
             no_answer: str | None = None) -> list[int]:
        """Registers ``start`` .. ``start + count - 1`` of ``table`` (holding | input), as
        many as the device sent (the caller checks the count)."""
        unit = self.spec.unit
        rr = self.call(what, timeout, lambda c: (
            c.read_holding_registers if table == "holding" else c.read_input_registers)(
            start, count=count, device_id=unit), no_answer=no_answer)
        return list(rr.registers)

    def write(self, start: int, values: list[int], timeout: float, what: str) -> None:
        """One request: function 6 for one holding register, 16 for more (atomic on the
        device)."""
        unit = self.spec.unit
        self.call(what, timeout, lambda c: c.write_register(
            start, values[0], device_id=unit) if len(values) == 1 else c.write_registers(
            start, values, device_id=unit))

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
        self._client = self._conn = None
