"""Lift PLC over Modbus TCP or RTU, through the shared Modbus link (``drivers.modbus_link``,
the only module that uses pymodbus's client API).

    modbus-tcp://HOST[:PORT]?unit=1&timeout=1.0
    modbus-rtu:///dev/ttyUSB0?baud=19200&parity=E&stopbits=1&unit=1&timeout=1.0

A link that fails (timeout, peer gone, garbled answer) is closed and stays down: reads fail at
once with a ConnectionLostError that carries the reason, until ``reconnect()`` (the station's
keeper, :mod:`drivers.keeper`, retries it with backoff).  A Modbus exception leaves the link
up.
"""

from __future__ import annotations

import logging
import threading
import time

from drivers.endpoint import Endpoint
from drivers.errors import (
    ConnectError,
    ConnectionLostError,
    DeviceTimeoutError,
    ProtocolError,
    UrlError,
)
from drivers.lift.base import Lift, RegisterMap
from drivers.link import baud_rate
from drivers.modbus_link import (
    EXCEPTION_NAMES,
    RTU_FORM,
    TCP_FORM,
    LinkSpec,
    ModbusLink,
    Wording,
    modbus_endpoint,
    parse_modbus_url,
)

__all__ = ["EXCEPTION_HINTS", "EXCEPTION_NAMES", "RTU_FORM", "TCP_FORM", "LinkSpec",
           "ModbusLift", "parse_modbus_url"]

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT = 1.0

EXCEPTION_HINTS = {
    1: "the PLC does not serve this register table (registers.table?)",
    2: "the register map names registers the PLC does not have (0-based wire addresses?)",
    4: "a PLC fault, or a unit id it does not serve: pymodbus-based servers answer 4 to an "
       "unknown unit (unit=?)",
    10: "the gateway has no route to this unit (unit=?)",
    11: "no device answers at this unit behind the gateway (unit=?)",
}
#: the lift's words in link errors
WORDING = Wording(refused="PLC off, or not its Modbus port?",
                  unknown_exception="unknown exception", hints=EXCEPTION_HINTS)


class ModbusLift(Lift):
    """A lift PLC on Modbus TCP or RTU.  The timeout comes from the URL, else the keyword
    argument, else 1 s per poll.  A failed link is closed and stays down (reads say so at
    once, with the reason) until ``reconnect()``."""

    def __init__(self, url: str, register_map: RegisterMap | None = None, *,
                 timeout: float | None = None) -> None:
        super().__init__(url, register_map)
        self.spec, opts = parse_modbus_url(url)
        if self.spec.kind == "rtu":
            try:
                baud_rate(self.spec.baud)
            except ValueError as exc:
                raise UrlError(f"option baud={self.spec.baud} is not valid: {exc}",
                               device=url) from None
        self.timeout = opts["timeout"] or timeout or DEFAULT_TIMEOUT
        self._io = threading.Lock()  # one request on the wire at a time; guards the link
        self._link: ModbusLink | None = None
        self._down = "not connected"   # why the link is down

    @classmethod
    def _endpoint(cls, url: str) -> Endpoint:
        """One unit of a Modbus TCP host and port (502 by default), or a whole RTU line."""
        return modbus_endpoint(url)

    def identity(self) -> str:
        return self.spec.describe()

    def _connect(self) -> ModbusLink:
        link = ModbusLink(self.spec, self.url, WORDING)
        link.connect(self.timeout)
        return link

    def _open(self) -> None:
        link = self._connect()
        with self._io:
            self._link = link

    def _close(self) -> None:
        with self._io:
            link, self._link = self._link, None
        if link is not None:
            link.close()

    def _reconnect(self) -> None:
        """Close the link and connect again (one attempt)."""
        with self._io:
            link, self._link = self._link, None
            if link is not None:
                link.close()
            try:
                self._link = self._connect()
            except ConnectError as exc:
                self._down = str(exc).removeprefix(f"{self.url}: ")
                raise

    def _read_registers(self, spans: list[tuple[int, int]],
                        timeout: float | None) -> dict[int, int]:
        deadline = time.monotonic() + (timeout or self.timeout)
        out: dict[int, int] = {}
        with self._io:
            link = self._link
            if link is None:
                raise ConnectionLostError(f"link down ({self._down})", device=self.url)
            for start, count in spans:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeoutError(f"no complete answer within {timeout or self.timeout}"
                                             " s", device=self.url)
                try:
                    values = self._read_span(link, start, count, remaining)
                except (DeviceTimeoutError, ConnectionLostError, ProtocolError) as exc:
                    # a late answer must never be read as the next one's: drop the link
                    link.close()
                    self._link = None
                    self._down = str(exc).removeprefix(f"{self.url}: ")
                    raise
                out.update(zip(range(start, start + count), values, strict=True))
        return out

    def _read_span(self, link: ModbusLink, start: int, count: int, timeout: float
                   ) -> list[int]:
        table = self.register_map.table
        what = f"{table} registers {start}-{start + count - 1} of unit {self.spec.unit}"
        values = link.read(table, start, count, timeout, f"reading {what}",
                           no_answer=f"no answer within {timeout:.2f} s to a read of {what}")
        if len(values) != count:
            raise ProtocolError(f"asked for {count} registers ({what}), got {len(values)}",
                                device=self.url)
        return values
