"""The byte links every device protocol runs on: TCP, and serial (a device path, a pty, or any
pyserial URL), with the same error types for the same failures on every backend.

    connect timeout   -> ConnectTimeoutError    refused, no such host/port -> ConnectError
    closed by peer    -> ConnectionLostError    (EIO on a pty, "socket disconnected", EOF)
    garbage           -> ProtocolError          (raised by the protocol on top: framing)

Open Protocol reads and writes bytes through :class:`TcpLink` / :class:`SerialLink`; Modbus
hands the socket or port from :func:`connect_tcp` / :func:`open_serial` to pymodbus's client
(``drivers.modbus_link``).  Errors here carry no device name: the protocol layer adds it and
what it was doing.  Nothing here reconnects: a link is connected, used and closed by one owner,
and connected again by ``reconnect()`` (the station's keeper decides when).
"""

from __future__ import annotations

import errno
import importlib
import math
import os
import select
import socket
import termios
import threading
import time
from abc import ABC, abstractmethod
from typing import Any, Literal

from drivers.errors import ConnectError, ConnectionLostError, ConnectTimeoutError
from drivers.url import OptionError

Kind = Literal["tcp", "serial"]


def pyserial() -> Any:
    """pyserial ships no type hints and has no stubs here; importing it by name keeps the
    untyped surface in this one file (and out of the import when only TCP is used)."""
    return importlib.import_module("serial")


def connect_tcp(host: str, port: int, timeout: float, refused_hint: str) -> socket.socket:
    """A connected TCP socket (no Nagle: requests are small and answered one by one).
    ``refused_hint`` says what to check when the connection is refused."""
    where = f"{host}:{port}"
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except ConnectionRefusedError:
        raise ConnectError(f"connection refused by {where} ({refused_hint})") from None
    except TimeoutError:
        raise ConnectTimeoutError(f"no answer connecting to {where} within {timeout:g} s") \
            from None
    except socket.gaierror as exc:
        raise ConnectError(f"unknown host {host}: {exc.strerror}") from None
    except OSError as exc:
        raise ConnectError(f"cannot connect to {where}: {exc.strerror or exc}") from None
    if sock.getsockname() == sock.getpeername():
        # TCP simultaneous open: a local port in the ephemeral range that nothing listens on
        # can be given to this very socket, which then "connects" to itself and would read
        # its own requests back; it is the refusal it stands for
        sock.close()
        raise ConnectError(f"connection refused by {where} ({refused_hint})")
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock


def bind_words(exc: BaseException) -> str:
    """Why a server could not listen, in words: a port in use said so (asyncio's "[Errno 98]
    error while attempting to bind on address ('127.0.0.1', 8080): address already in use"
    read as a crash, and each server said it its own way)."""
    if isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE:
        return "the port is in use (another program, or another stationd, serves there)"
    if isinstance(exc, OSError) and exc.errno == errno.EACCES:
        return "the port is not allowed (below 1024 needs privileges)"
    text = getattr(exc, "strerror", None) or str(exc)
    return (text.strip().splitlines() or [type(exc).__name__])[0]


#: serial line speeds a port can be set to: 0 or a negative speed is a typo (pyserial takes 0
#: on Linux: B0 hangs the line up, and the device then never answers); above 4 Mbaud no
#: RS-232/RS-485 adapter goes
BAUD = (50, 4_000_000)


#: the speeds serial ports are set to (Linux's termios speeds, Windows' CBR speeds and the
#: few others adapters take): a speed off the list is more often a typo than a device's (a
#: technician's trial: ``baud=96000`` passed ``config check``, and the controller never
#: answered): ``config check`` warns of one (:func:`baud_warning`), the driver takes it
STANDARD_BAUD = (50, 75, 110, 134, 150, 200, 300, 600, 1200, 1800, 2400, 4800, 9600, 14400,
                 19200, 28800, 38400, 56000, 57600, 76800, 115200, 128000, 230400, 250000,
                 256000, 460800, 500000, 576000, 921600, 1000000, 1152000, 1500000, 2000000,
                 2500000, 3000000, 3500000, 4000000)


def baud_rate(text: str | int) -> int:
    """A serial speed in baud (URL option converter); OptionError saying the range."""
    value = int(text)
    if not BAUD[0] <= value <= BAUD[1]:
        raise OptionError(f"a serial speed is {BAUD[0]}-{BAUD[1]} baud (e.g. 9600, 19200, "
                          "115200)")
    return value


def baud_warning(value: int) -> str | None:
    """Words for a speed off :data:`STANDARD_BAUD` naming the standard ones meant: those a
    digit's typo away (96000: 9600), else the nearest (a factor, not digits: 128500:
    128000); None for a standard speed."""
    if value in STANDARD_BAUD:
        return None
    # a digit changed: only a speed near it (96000 is not 56000); one added or left out:
    # whatever it makes (96000: 9600); at most two said, the closest first
    typed = sorted((b for b in STANDARD_BAUD if _one_edit(str(value), str(b)) and (
        len(str(b)) != len(str(value)) or abs(math.log(value / b)) < math.log(1.5))),
        key=lambda b: abs(math.log(value / b)))
    nearest = min(STANDARD_BAUD, key=lambda b: abs(math.log(value / b)))
    meant = [*typed, *([nearest] if nearest not in typed else [])][:2]
    return (f"baud={value} is not a standard serial speed: "
            f"{' or '.join(str(b) for b in meant)}? (right if the device's manual says "
            f"{value})")


def _one_edit(a: str, b: str) -> bool:
    """Whether ``a`` becomes ``b`` by one digit changed, added or left out."""
    if abs(len(a) - len(b)) > 1 or a == b:
        return False
    if len(a) == len(b):
        return sum(x != y for x, y in zip(a, b, strict=True)) == 1
    short, long = (a, b) if len(a) < len(b) else (b, a)
    return any(long[:i] + long[i + 1:] == short for i in range(len(long)))


def open_serial(port: str, *, baudrate: int, parity: str = "N", stopbits: int = 1,
                timeout: float, write_timeout: float, exclusive: bool = True,
                inter_byte_timeout: float | None = None) -> Any:
    """An open pyserial port (8 data bits), every setting applied at once so that a refused
    one fails here, not on first use; ConnectError saying why in a person's words."""
    serial = pyserial()
    ser = serial.serial_for_url(port, do_not_open=True, baudrate=baudrate, bytesize=8,
                                parity=parity, stopbits=stopbits, timeout=timeout,
                                write_timeout=write_timeout, exclusive=exclusive,
                                inter_byte_timeout=inter_byte_timeout)
    try:
        ser.open()
        ser.reset_input_buffer()
    except (serial.SerialException, OSError, ValueError, termios.error) as exc:
        ser.close()
        raise ConnectError(serial_reason(port, f"{baudrate} 8{parity}{stopbits}", exc)) \
            from None
    return ser


def _errnos(exc: BaseException) -> set[int]:
    """The error numbers of ``exc`` and the exceptions it was raised from or during."""
    out: set[int] = set()
    seen: BaseException | None = exc
    while seen is not None and len(out) < 8:
        for v in (getattr(seen, "errno", None), *(seen.args[:1] if seen.args else ())):
            if isinstance(v, int):
                out.add(v)
        seen = seen.__cause__ or seen.__context__
    return out


def serial_reason(port: str, settings: str, exc: BaseException) -> str:
    """Why ``port`` did not open, in a person's words."""
    code = getattr(exc, "errno", None)
    if code == errno.ENOENT:
        return f"no such serial port {port}"
    if code == errno.EACCES:
        return f"permission denied on {port} (is the user in group dialout?)"
    if code == errno.EBUSY or "lock" in str(exc):
        return f"{port} is in use by another program"
    if errno.ENOTTY in _errnos(exc):   # pyserial wraps it: "Could not configure port"
        return f"{port} is not a serial port (a terminal device: /dev/ttyUSB0, /dev/ttyS0, ...)"
    if isinstance(exc, termios.error | ValueError):
        pty = "; a pty may refuse parity bits: use parity=N" if "/pts/" in port else ""
        return f"{port} refuses {settings} ({exc}){pty}"
    return f"cannot open serial port {port}: {exc}"


class Link(ABC):
    """A byte stream to a device; ``kind`` selects the framing the protocol uses."""

    kind: Kind
    where: str

    @abstractmethod
    def connect(self, timeout: float) -> None:
        """Open the link (closing any previous one); ConnectError or ConnectTimeoutError."""

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
    """A TCP client link; ``refused_hint`` says what to check when the device refuses."""

    kind: Kind = "tcp"

    def __init__(self, host: str, port: int, refused_hint: str = "device off, or not its "
                 "port?") -> None:
        self.host = host
        self.port = port
        self.where = f"{host}:{port}"
        self.refused_hint = refused_hint
        self._sock: socket.socket | None = None

    def connect(self, timeout: float) -> None:
        self.close()
        sock = connect_tcp(self.host, self.port, timeout, self.refused_hint)
        sock.settimeout(timeout)          # bounds sendall when the device stops reading
        self._sock = sock

    def send(self, data: bytes) -> None:
        sock = self._sock
        if sock is None:
            raise ConnectionLostError(f"not connected to {self.where}")
        try:
            sock.sendall(data)
        except TimeoutError:
            raise ConnectionLostError(f"sending to {self.where} timed out (device not "
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


def write_all(fd: int, data: bytes, timeout: float) -> bool:
    """Write ``data`` to the non-blocking ``fd`` (pyserial opens ports so); False once the
    port has taken no byte for ``timeout`` s.  Not pyserial's ``write``: pyserial 3.5 reads the
    clock after ``os.write`` and raises a write timeout for bytes already sent when its
    thread was stalled that long (a loaded host), so a command that reached the device would
    be taken as not sent.  Here only a port that takes nothing times out."""
    view = memoryview(data)
    deadline = time.monotonic() + timeout
    while view:
        try:
            taken = os.write(fd, view)
        except BlockingIOError:
            taken = 0
        if taken:
            view = view[taken:]
            deadline = time.monotonic() + timeout
        elif not select.select([], [fd], [], max(0.0, deadline - time.monotonic()))[1]:
            return False    # (after a stall past the deadline, a last look without waiting)
    return True


class SerialLink(Link):
    """A serial link through pyserial's ``serial_for_url`` (a device path, a pty, or any
    pyserial URL such as ``socket://`` or ``loop://``), 8N1 unless told."""

    kind: Kind = "serial"

    def __init__(self, port: str, baudrate: int = 9600, parity: str = "N",
                 stopbits: int = 1) -> None:
        self.port = port
        self.baudrate = baudrate
        self.parity, self.stopbits = parity, stopbits
        self.where = port
        self._ser: Any = None
        self._timeout: float | None = None
        self._write_timeout = 1.0
        # a send and a close take turns: a write holds the port's file number for up to its
        # timeout, and a number closed under it could be a newly opened file's by then
        self._writing = threading.Lock()

    def connect(self, timeout: float) -> None:
        self.close()
        self._ser = open_serial(self.port, baudrate=self.baudrate, parity=self.parity,
                                stopbits=self.stopbits, timeout=0.05, write_timeout=timeout,
                                exclusive=False)
        self._timeout = 0.05
        self._write_timeout = timeout

    def send(self, data: bytes) -> None:
        serial = pyserial()
        timed_out = ConnectionLostError(f"writing to {self.port} timed out (the port took "
                                        f"nothing within {self._write_timeout:g} s)")
        with self._writing:
            ser = self._ser
            if ser is None:
                raise ConnectionLostError(f"serial port {self.port} is not open")
            posix = getattr(serial, "serialposix", None)
            try:
                if posix is None or not isinstance(ser, posix.Serial):
                    ser.write(data)     # a pyserial URL (socket://, loop://): its own write
                elif not write_all(ser.fd, data, self._write_timeout):
                    raise timed_out
            except serial.SerialTimeoutException:
                raise timed_out from None
            except (serial.SerialException, OSError) as e:
                raise ConnectionLostError(f"serial device {self.port} is gone: {e}") from None

    def recv(self, timeout: float) -> bytes:
        ser = self._ser
        if ser is None:
            raise ConnectionLostError(f"serial port {self.port} is not open")
        serial = pyserial()
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
        with self._writing:
            ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # noqa: S110 - a port that vanished may fail to close; it is gone
                pass
