"""Links for Open Protocol: bytes in, bytes out, nothing about messages (pymodbus's transport).

A link is connected, used and closed by one owner (the client serialises access); it can be
connected again after a close, which is how the client reconnects.  Every failure is a
:class:`DeviceError` without the device name: the client adds the name and what it was doing.
Both a controller that closes the TCP connection and a serial device that disappears (EIO on a
pty, "socket disconnected" from pyserial) are a :class:`ConnectionLostError`.
"""

from __future__ import annotations

import importlib
import select
import socket
from abc import ABC, abstractmethod
from typing import Any, Literal

from drivers.errors import (
    ConnectError,
    ConnectionLostError,
    ConnectTimeoutError,
)

Kind = Literal["tcp", "serial"]


def _pyserial() -> Any:
    """pyserial ships no type hints and has no stubs here; importing it by name keeps the
    untyped surface in this one file (and out of the import when only TCP is used)."""
    return importlib.import_module("serial")


class Link(ABC):
    """A byte stream to the controller; ``kind`` selects the framing the client uses."""

    kind: Kind
    where: str

    @abstractmethod
    def connect(self, timeout: float) -> None:
        """Open the link (closing any previous one); ConnectError or DeviceTimeoutError."""

    @abstractmethod
    def send(self, data: bytes) -> None:
        """Write all of ``data`` or raise ConnectionLostError (the link is then unusable)."""

    @abstractmethod
    def recv(self, timeout: float) -> bytes:
        """Bytes available within ``timeout`` (b"" if none); ConnectionLostError if gone."""

    @abstractmethod
    def close(self) -> None:
        """Release the link; safe to call at any time, any number of times."""


class TcpLink(Link):
    """Open Protocol over TCP: the controller is the server (port 4545 by default)."""

    kind: Kind = "tcp"

    def __init__(self, host: str, port: int) -> None:
        self.host = host
        self.port = port
        self.where = f"{host}:{port}"
        self._sock: socket.socket | None = None

    def connect(self, timeout: float) -> None:
        self.close()
        try:
            sock = socket.create_connection((self.host, self.port), timeout=timeout)
        except ConnectionRefusedError:
            raise ConnectError(f"connection refused by {self.where} (controller off, or Open "
                               "Protocol not enabled on this port?)") from None
        except TimeoutError:
            raise ConnectTimeoutError(f"no answer connecting to {self.where} within "
                                      f"{timeout:g} s") from None
        except OSError as e:
            raise ConnectError(f"cannot connect to {self.where}: {e.strerror or e}") from None
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.settimeout(timeout)          # bounds sendall when the controller stops reading
        self._sock = sock

    def send(self, data: bytes) -> None:
        sock = self._sock
        if sock is None:
            raise ConnectionLostError(f"not connected to {self.where}")
        try:
            sock.sendall(data)
        except TimeoutError:
            raise ConnectionLostError(f"sending to {self.where} timed out (controller not "
                                      "reading)") from None
        except OSError as e:
            raise ConnectionLostError(f"sending to {self.where} failed: {e.strerror or e}") \
                from None

    def recv(self, timeout: float) -> bytes:
        sock = self._sock
        if sock is None:
            raise ConnectionLostError(f"not connected to {self.where}")
        try:
            ready, _, _ = select.select([sock], [], [], timeout)
            if not ready:
                return b""
            data = sock.recv(65536)
        except (OSError, ValueError) as e:   # ValueError: the socket was closed under us
            raise ConnectionLostError(f"reading from {self.where} failed: {e}") from None
        if not data:
            raise ConnectionLostError(f"{self.where} closed the connection")
        return data

    def close(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()


class SerialLink(Link):
    """Open Protocol over RS-232 through pyserial's ``serial_for_url`` (a device path, a pty,
    or any pyserial URL such as ``socket://`` or ``loop://``)."""

    kind: Kind = "serial"

    def __init__(self, port: str, baudrate: int = 9600) -> None:
        self.port = port
        self.baudrate = baudrate
        self.where = port
        self._ser: Any = None
        self._timeout: float | None = None

    def connect(self, timeout: float) -> None:
        self.close()
        serial = _pyserial()
        try:
            ser = serial.serial_for_url(self.port, baudrate=self.baudrate, timeout=0.05,
                                        write_timeout=timeout)
            ser.reset_input_buffer()
        except (serial.SerialException, OSError, ValueError) as e:
            raise ConnectError(f"cannot open serial port {self.port}: {e}") from None
        self._ser = ser
        self._timeout = 0.05

    def send(self, data: bytes) -> None:
        ser = self._ser
        if ser is None:
            raise ConnectionLostError(f"serial port {self.port} is not open")
        serial = _pyserial()
        try:
            ser.write(data)
        except serial.SerialTimeoutException:
            raise ConnectionLostError(f"writing to {self.port} timed out") from None
        except (serial.SerialException, OSError) as e:
            raise ConnectionLostError(f"serial device {self.port} is gone: {e}") from None

    def recv(self, timeout: float) -> bytes:
        ser = self._ser
        if ser is None:
            raise ConnectionLostError(f"serial port {self.port} is not open")
        serial = _pyserial()
        try:
            if self._timeout != timeout:    # pyserial reconfigures the port on every change
                ser.timeout = timeout
                self._timeout = timeout
            data: bytes = ser.read(1)
            if data:
                waiting = ser.in_waiting
                if waiting:
                    data += ser.read(waiting)
        except (serial.SerialException, OSError, TypeError) as e:
            # TypeError: pyserial's posix read after a concurrent close (fd is None)
            raise ConnectionLostError(f"serial device {self.port} is gone: {e}") from None
        return data

    def close(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # noqa: S110 - a port that vanished may fail to close; it is gone
                pass
