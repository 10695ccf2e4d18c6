"""Lift PLC over Modbus TCP or RTU: the only module that uses pymodbus's client API.

pymodbus is pinned (3.16.*) because its API changes in minor releases; everything it is asked
for is in :class:`_Link` below, so an upgrade is checked here and in the tests, nowhere else.

    modbus-tcp://HOST[:PORT]?unit=1&timeout=1.0&backoff=0.1&backoff_max=5
    modbus-rtu:///dev/ttyUSB0?baud=19200&parity=E&stopbits=1&unit=1&timeout=1.0

The socket or serial port is opened here, not by pymodbus, and handed to its synchronous
client: pymodbus's ``connect()`` logs the reason and returns False, and the station must tell
"refused" from "no such port" from "permission denied".  A link that fails (timeout, peer gone,
garbled answer) is dropped and one named thread reconnects with exponential backoff until
``close()`` stops it; reads meanwhile wait for the link within their own timeout, then fail with
a ConnectionLostError that carries the last reason.  A Modbus exception leaves the link up.
"""

from __future__ import annotations

import errno
import importlib
import logging
import socket
import termios
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from drivers.errors import (
    ConnectError,
    ConnectionLostError,
    DeviceError,
    DeviceTimeoutError,
    ProtocolError,
    RefusedError,
)
from drivers.lift.base import Lift, RegisterMap
from drivers.url import parse_url

log = logging.getLogger(__name__)
# pyserial ships no type hints (and the project has no stub package): typed as Any on purpose.
serial: Any = importlib.import_module("serial")

TCP_FORM = "modbus-tcp://HOST[:PORT]?unit=1&timeout=1.0"
RTU_FORM = "modbus-rtu:///dev/ttyUSB0?baud=19200&parity=E&unit=1"
DEFAULT_TIMEOUT = 1.0
DEFAULT_BACKOFF = (0.1, 5.0)  # first and largest delay between reconnect attempts, seconds

EXCEPTION_NAMES = {
    1: "illegal function", 2: "illegal data address", 3: "illegal data value",
    4: "server device failure", 5: "acknowledge", 6: "server device busy",
    8: "memory parity error", 10: "gateway path unavailable",
    11: "gateway target device failed to respond",
}
EXCEPTION_HINTS = {
    1: "the PLC does not serve this register table (registers.table?)",
    2: "the register map names registers the PLC does not have (0-based wire addresses?)",
    4: "a PLC fault, or a unit id it does not serve: pymodbus-based servers answer 4 to an "
       "unknown unit (unit=?)",
    10: "the gateway has no route to this unit (unit=?)",
    11: "no device answers at this unit behind the gateway (unit=?)",
}


@dataclass(frozen=True)
class LinkSpec:
    """Where the PLC is: TCP host and port, or serial port and line settings."""

    kind: str  # "tcp" | "rtu"
    target: str  # host name or serial port path
    port: int = 502
    unit: int = 1
    baud: int = 19200
    parity: str = "E"
    stopbits: int = 1

    def describe(self) -> str:
        if self.kind == "tcp":
            return f"Modbus TCP {self.target}:{self.port} unit {self.unit}"
        return (f"Modbus RTU {self.target} {self.baud} 8{self.parity}{self.stopbits} "
                f"unit {self.unit}")


def _choice(*allowed: str) -> Callable[[str], str]:
    def conv(text: str) -> str:
        if text.upper() not in allowed:
            raise ValueError(text)
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
        raise ValueError(text)
    return value


def parse_modbus_url(text: str) -> tuple[LinkSpec, dict[str, float | None]]:
    """The link and the timing options (None where the URL does not say) of a Modbus URL."""
    url = parse_url(text)
    timing = {"timeout": (_positive, None), "backoff": (_positive, None),
              "backoff_max": (_positive, None)}
    if url.scheme == "modbus-tcp":
        opts = url.typed_options({"unit": (_unit, 1), **timing}, TCP_FORM)
        if not url.host or url.path not in ("", "/"):
            raise url.error(f"expected a host and optional port, e.g. {TCP_FORM}")
        spec = LinkSpec("tcp", url.host, url.port or 502, opts.pop("unit"))
    elif url.scheme == "modbus-rtu":
        opts = url.typed_options({"unit": (_unit, 1), "baud": (int, 19200),
                                  "parity": (_choice("N", "E", "O"), "E"),
                                  "stopbits": (_choice("1", "2"), "1"), **timing}, RTU_FORM)
        if url.host or not url.path.startswith("/"):
            raise url.error(f"expected a serial port path, e.g. {RTU_FORM}")
        spec = LinkSpec("rtu", url.path, 0, opts.pop("unit"), opts.pop("baud"),
                        opts.pop("parity"), int(opts.pop("stopbits")))
    else:
        raise url.error(f"not a Modbus URL; expected {TCP_FORM} or {RTU_FORM}")
    return spec, opts


class _Link:
    """One open connection wrapped in a pymodbus synchronous client (no retries: the caller
    polls again)."""

    def __init__(self, spec: LinkSpec, device: str) -> None:
        self.spec = spec
        self.device = device
        self._client: ModbusTcpClient | ModbusSerialClient | None = None
        self._conn: Any = None  # the socket or serial port, ours to close

    def _error(self, cls: type[DeviceError], message: str, code: int | None = None
               ) -> DeviceError:
        return cls(message, device=self.device, code=code)

    def connect(self, timeout: float) -> None:
        """Open the socket or port; ConnectError with the reason if it cannot be opened."""
        s = self.spec
        if s.kind == "tcp":
            where = f"{s.target}:{s.port}"
            try:
                sock = socket.create_connection((s.target, s.port), timeout=timeout)
            except ConnectionRefusedError:
                raise self._error(ConnectError, f"connection refused by {where} (PLC off, or "
                                                "not its Modbus port?)") from None
            except TimeoutError:
                raise self._error(ConnectError, f"no answer from {where} within "
                                                f"{timeout:.2f} s") from None
            except socket.gaierror as exc:
                raise self._error(ConnectError, f"unknown host {s.target}: {exc.strerror}"
                                  ) from None
            except OSError as exc:
                raise self._error(ConnectError, f"cannot connect to {where}: {exc.strerror or exc}"
                                  ) from None
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            tcp = ModbusTcpClient(s.target, port=s.port, timeout=timeout, retries=0)
            tcp.socket = sock  # connect() then sees an open socket and keeps it
            self._client, self._conn = tcp, sock
            return
        rtu = ModbusSerialClient(s.target, framer=FramerType.RTU, baudrate=s.baud, bytesize=8,
                                 parity=s.parity, stopbits=s.stopbits, timeout=timeout,
                                 retries=0)
        port = serial.serial_for_url(s.target, do_not_open=True, baudrate=s.baud, bytesize=8,
                                     parity=s.parity, stopbits=s.stopbits, timeout=timeout,
                                     write_timeout=timeout, exclusive=True,
                                     inter_byte_timeout=rtu.inter_byte_timeout or None)
        try:
            port.open()  # all settings at once: a refused one fails here, not on first use
        except (serial.SerialException, OSError, ValueError, termios.error) as exc:
            port.close()
            raise self._error(ConnectError, _serial_reason(s, exc)) from None
        rtu.socket = port
        self._client, self._conn = rtu, port

    def read(self, table: str, address: int, count: int, timeout: float) -> list[int]:
        """Registers ``address`` .. ``address + count - 1``; typed errors for every failure."""
        client = self._client
        if client is None:
            raise self._error(ConnectionLostError, "not connected")
        # pymodbus 3.16 has no per-request timeout: the client and its transaction manager
        # each keep a copy of the connect parameters, and both time a read.
        client.comm_params.timeout_connect = timeout
        client.transaction.comm_params.timeout_connect = timeout
        what = (f"{table} registers {address}-{address + count - 1} of unit {self.spec.unit}")
        fn = client.read_holding_registers if table == "holding" else client.read_input_registers
        try:
            rr = fn(address, count=count, device_id=self.spec.unit)
        except ConnectionException as exc:
            raise self._error(ConnectionLostError, f"link lost reading {what}: "
                                                   f"{exc.string}") from None
        except ModbusIOException as exc:
            if "No response" in exc.string:
                raise self._error(DeviceTimeoutError, f"no answer within {timeout:.2f} s to a "
                                                      f"read of {what}") from None
            raise self._error(ProtocolError, f"bad answer reading {what}: {exc.string}") from None
        except ModbusException as exc:
            raise self._error(ProtocolError, f"bad answer reading {what}: {exc.string}") from None
        except OSError as exc:
            raise self._error(ConnectionLostError, f"link lost reading {what}: {exc}") from None
        if rr.isError():
            code = int(getattr(rr, "exception_code", 0))
            name = EXCEPTION_NAMES.get(code, "unknown exception")
            hint = EXCEPTION_HINTS.get(code)
            raise self._error(RefusedError, f"Modbus exception {code} ({name}) reading {what}"
                                            + (f": {hint}" if hint else ""), code)
        if len(rr.registers) != count:
            raise self._error(ProtocolError, f"asked for {count} registers ({what}), got "
                                             f"{len(rr.registers)}")
        return list(rr.registers)

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
        self._client = self._conn = None


def _serial_reason(spec: LinkSpec, exc: BaseException) -> str:
    code = getattr(exc, "errno", None)
    if code == errno.ENOENT:
        return f"no such serial port {spec.target}"
    if code == errno.EACCES:
        return f"permission denied on {spec.target} (is the user in group dialout?)"
    if code == errno.EBUSY or "lock" in str(exc):
        return f"{spec.target} is in use by another program"
    if isinstance(exc, termios.error | ValueError):
        pty = "; a pty may refuse parity bits: use parity=N" if "/pts/" in spec.target else ""
        return f"{spec.target} refuses {spec.baud} 8{spec.parity}{spec.stopbits} ({exc}){pty}"
    return f"cannot open {spec.target}: {exc}"


class ModbusLift(Lift):
    """A lift PLC on Modbus TCP or RTU.  Timing comes from the URL, else the keyword
    arguments, else the defaults (1 s per poll, reconnect after 0.1 s doubling to 5 s)."""

    def __init__(self, url: str, register_map: RegisterMap | None = None, *,
                 timeout: float | None = None, backoff: float | None = None,
                 backoff_max: float | None = None) -> None:
        super().__init__(url, register_map)
        self.spec, opts = parse_modbus_url(url)
        self.timeout = opts["timeout"] or timeout or DEFAULT_TIMEOUT
        self.backoff = opts["backoff"] or backoff or DEFAULT_BACKOFF[0]
        self.backoff_max = max(self.backoff, opts["backoff_max"] or backoff_max
                               or DEFAULT_BACKOFF[1])
        self._lock = threading.Lock()  # guards the link and the reconnect bookkeeping
        self._io = threading.Lock()  # one request on the wire at a time
        self._link: _Link | None = None
        self._up = threading.Event()
        self._stop = threading.Event()
        self._reconnector: threading.Thread | None = None
        self._last_error: DeviceError | None = None
        self._down_since = 0.0
        self._attempts = 0
        self._next_try = 0.0

    def identity(self) -> str:
        return self.spec.describe()

    def _open(self) -> None:
        link = _Link(self.spec, self.url)
        link.connect(self.timeout)
        self._stop.clear()
        with self._lock:
            self._link = link
            self._up.set()

    def _close(self) -> None:
        self._stop.set()
        with self._lock:
            thread = self._reconnector
        if thread is not None:
            thread.join(self.timeout + 1.0)
        with self._lock:
            if self._link is not None:
                self._link.close()
            self._link = None
            self._up.clear()

    def _read_registers(self, spans: list[tuple[int, int]],
                        timeout: float | None) -> dict[int, int]:
        deadline = time.monotonic() + (timeout or self.timeout)
        out: dict[int, int] = {}
        with self._io:
            for start, count in spans:
                link = self._wait_link(deadline)
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeoutError(f"no complete answer within {timeout or self.timeout}"
                                             " s", device=self.url)
                try:
                    values = link.read(self.register_map.table, start, count, remaining)
                except (DeviceTimeoutError, ConnectionLostError, ProtocolError) as exc:
                    self._lost(link, exc)
                    raise
                out.update(zip(range(start, start + count), values, strict=True))
        return out

    def _wait_link(self, deadline: float) -> _Link:
        self._up.wait(max(0.0, deadline - time.monotonic()))
        with self._lock:
            if self._link is not None:
                return self._link
            if not self.is_open:
                raise DeviceError("the lift is closed", device=self.url)
            reason = self._last_error
            down = time.monotonic() - self._down_since
            nxt = max(0.0, self._next_try - time.monotonic())
            attempts = self._attempts
        msg = str(reason).removeprefix(f"{self.url}: ") if reason else "not connected"
        raise ConnectionLostError(f"link down for {down:.1f} s ({msg}); reconnecting: "
                                  f"{attempts} attempt(s), next in {nxt:.1f} s", device=self.url)

    def _lost(self, link: _Link, exc: DeviceError) -> None:
        """Drop a failed link (a late answer would be taken for the next one) and start the
        reconnect thread."""
        with self._lock:
            if self._link is not link:
                return
            link.close()
            self._link = None
            self._up.clear()
            self._last_error = exc
            self._down_since = time.monotonic()
            self._attempts = 0
            if self._stop.is_set() or self._reconnector is not None:
                return
            log.warning("%s; reconnecting", exc)
            self._reconnector = threading.Thread(target=self._reconnect, daemon=True,
                                                 name=f"lift-reconnect {self.url}")
            self._reconnector.start()

    def _reconnect(self) -> None:
        """The reconnect task: try at once, then after backoff, 2 x backoff, ... up to
        backoff_max, until connected or ``close()`` sets the stop event.  The new link is
        installed in the same locked step that retires the task, so a link that fails at once
        still finds no task running and starts a new one."""
        delay = self.backoff
        link: _Link | None = None
        try:
            while not self._stop.is_set():
                candidate = _Link(self.spec, self.url)
                try:
                    candidate.connect(self.timeout)
                except DeviceError as exc:
                    with self._lock:
                        self._last_error = exc
                        self._attempts += 1
                        self._next_try = time.monotonic() + delay
                    if self._stop.wait(delay):
                        break
                    delay = min(2 * delay, self.backoff_max)
                    continue
                link = candidate
                break
        finally:
            with self._lock:
                self._reconnector = None
                if link is not None and not self._stop.is_set():
                    self._link, link = link, None
                    self._up.set()
                    log.info("%s: reconnected after %d failed attempt(s)", self.url,
                             self._attempts)
            if link is not None:
                link.close()
