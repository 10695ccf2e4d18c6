"""Which physical device a device URL names, as the key of its lock, and where those locks live.

Two daemons with different databases but one lift or one controller would both poll the PLC
and both send parameters to one tool: each device endpoint a daemon drives is locked for the
daemon's life (``stationd.lock.StationLocks``).  Two URLs that reach one device must give one
key, so the key is the endpoint, not the text: ``modbus-tcp://PLC:502?unit=1&timeout=2`` and
``modbus-tcp://plc?unit=1`` are one lift.

What a URL reaches is its backend's to say, not its scheme's name
(``drivers.lifecycle.Openable.endpoint``: the protocol's default port, that a Modbus TCP
endpoint is one unit of it, that a serial line is one device whatever the unit, that an
OpenCV camera index is a ``/dev/videoN``, that a simulated twin or a file drives nothing
another process can share).  What is this machine's is kept here:

- TCP: the host (lower case; an IP literal in its canonical form; ``localhost`` as
  127.0.0.1) and the backend's port, with the unit when the backend names one.  A host name
  is resolved to its address (:func:`_resolve`), so ``tcp://plc.local:502`` and
  ``tcp://192.168.0.10:502`` are one lift: a station file written with the name and another
  with the address would both drive it.  The look-up is bounded (:data:`RESOLVE_TIMEOUT_S`:
  a name server that does not answer must not hold the daemon's start or a reload), and a
  name that does not resolve in time keeps the name as its key (those two files are then
  not told apart, as before the look-up).
- Serial ports and video devices: the path with its links resolved
  (``/dev/serial/by-id/...`` is the ``/dev/ttyUSB0`` it points at).
- Aravis cameras: the device id as the backend reads it.
- A URL naming no backend, or one its backend refuses, is its own key: ``url {url}`` (the
  configuration refuses it before any lock is taken).

The locks live in one folder every daemon on the machine shares (:func:`lock_dir`).
"""

from __future__ import annotations

import ipaddress
import os
import socket
import tempfile
import threading
import time
from pathlib import Path
from urllib.parse import quote

from drivers.devices import Kind, backend_class
from drivers.endpoint import (
    AravisEndpoint,
    Endpoint,
    SerialEndpoint,
    TcpEndpoint,
    UrlEndpoint,
    VideoEndpoint,
)
from drivers.errors import UrlError

#: the shared folder of device locks when it can be written (Debian's /run/lock is 1777;
#: systemd/stationd.service lets the service write it)
RUN_LOCK_DIR = Path("/run/lock/stationd")
#: the longest a host name's look-up may take (a name server that does not answer)
RESOLVE_TIMEOUT_S = 1.0
#: how long a look-up's answer is reused: a daemon's start names each device several times,
#: and a reload hours later looks the name up anew (an address given by DHCP may change)
RESOLVE_TTL_S = 30.0
_resolved: dict[str, tuple[float, str | None]] = {}   # name -> (when, its address or None)


def lock_dir() -> Path:
    """The folder of the machine's device locks: :data:`RUN_LOCK_DIR` when it (or /run/lock,
    to create it in) can be written, else ``stationd-locks`` in the system's temp folder.
    Every daemon on the machine must choose the same one: a daemon run by hand as root and
    the service (which may write /run/lock: systemd/stationd.service) both choose /run/lock;
    the temp folder is the fallback of a machine without /run/lock (not shared with a
    service that has PrivateTmp=yes)."""
    for folder in (RUN_LOCK_DIR, RUN_LOCK_DIR.parent):
        if folder.is_dir():
            if os.access(folder, os.W_OK | os.X_OK):
                return RUN_LOCK_DIR
            break
    return Path(tempfile.gettempdir()) / "stationd-locks"


def device_key(url: str, kind: Kind | None = None) -> str | None:
    """The endpoint ``url`` drives as a device of ``kind``, as a lock key (module
    docstring); None for a device no other process can share (simulated ones, files).  The
    backend says what it drives (:meth:`drivers.lifecycle.Openable.endpoint`); a URL naming
    no backend of ``kind``, or one its backend refuses, is its own key.

    ``kind`` None (a caller holding a URL alone): the first kind with a backend for the
    URL's scheme answers.  The schemes several kinds share (``sim``, ``modbus-tcp``,
    ``modbus-rtu``) are one transport in each and name one endpoint in each (the lift and
    the controller on one Modbus unit are one device: ``deviceconfig.one_device_each``);
    tests/drivers/test_endpoints.py holds them to it."""
    kinds = list(Kind) if kind is None else [kind]
    for each in kinds:
        try:
            backend = backend_class(each, url)
        except UrlError:
            continue
        try:
            return endpoint_key(backend.endpoint(url))
        except UrlError:
            break
    return f"url {url}"


def endpoint_key(endpoint: Endpoint | None) -> str | None:
    """The key text of ``endpoint`` as this machine sees it: host names resolved, device
    links followed (one key per device whatever the text reaching it)."""
    match endpoint:
        case None:
            return None
        case TcpEndpoint(host, port, unit):
            where = f"tcp {_host(host)}:{port}"
            return where if unit is None else f"{where} unit {unit}"
        case SerialEndpoint(path):
            return f"serial {os.path.realpath(path)}"
        case VideoEndpoint(path):
            return f"video {os.path.realpath(path)}"
        case AravisEndpoint(device_id):
            return f"aravis {device_id}"
        case UrlEndpoint(text):
            return f"url {text}"


def _host(host: str) -> str:
    """A host as one text per address: IP literals canonical, names resolved to their
    address (lower case when they do not resolve in time)."""
    host = host.lower()
    if host == "localhost":
        return "127.0.0.1"
    address = _literal(host)
    if address is not None:
        return address
    return _resolve(host) or host


def _literal(host: str) -> str | None:
    """An IP literal in its canonical form (an IPv4-mapped IPv6 address as the IPv4 one,
    IPv6 in brackets); None for a name."""
    try:
        address = ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        return None
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        return str(address.ipv4_mapped)
    return f"[{address}]" if address.version == 6 else str(address)


def _resolve(name: str) -> str | None:
    """The address ``name`` resolves to, canonical; None when it does not resolve within
    :data:`RESOLVE_TIMEOUT_S`.  ``getaddrinfo`` has no timeout of its own, so it runs in a
    daemon thread that is left behind when it takes longer (it ends with the resolver's own
    timeout).  A name with several addresses is keyed by the lowest, IPv4 first: one key
    whatever order the name server gives them in."""
    now = time.monotonic()
    cached = _resolved.get(name)
    if cached is not None and now - cached[0] < RESOLVE_TTL_S:
        return cached[1]
    found: list[str] = []

    def look_up() -> None:
        try:
            infos = socket.getaddrinfo(name, None, type=socket.SOCK_STREAM)
        except (OSError, UnicodeError):
            return
        found.extend(a for a in (_literal(str(info[4][0])) for info in infos) if a)

    worker = threading.Thread(target=look_up, name=f"resolve {name}", daemon=True)
    worker.start()
    worker.join(RESOLVE_TIMEOUT_S)
    if worker.is_alive():
        return None     # not cached: the next start or reload tries again
    address = min(found, key=lambda a: (a.startswith("["), a)) if found else None
    _resolved[name] = (now, address)
    return address


def key_file(key: str) -> str:
    """The lock file's name for ``key``: the key itself, percent-encoded (one name per key,
    readable in ``ls``)."""
    return f"{quote(key, safe='')}.lock"
