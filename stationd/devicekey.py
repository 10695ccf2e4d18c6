"""Which physical device a device URL names, as the key of its lock, and where those locks live.

Two daemons with different databases but one lift or one controller would both poll the PLC
and both send parameters to one tool: each device endpoint a daemon drives is locked for the
daemon's life (``stationd.lock.StationLocks``).  Two URLs that reach one device must give one
key, so the key is the endpoint, not the text: ``modbus-tcp://PLC:502?unit=1&timeout=2`` and
``modbus-tcp://plc?unit=1`` are one lift.

- TCP: the host (lower case; an IP literal in its canonical form; ``localhost`` as
  127.0.0.1) and the port with the protocol's default (Open Protocol 4545, Modbus 502); a
  Modbus TCP endpoint is one unit of it (a gateway serves several devices, one per unit id).
  A host name is resolved to its address (:func:`_resolve`), so ``tcp://plc.local:502`` and
  ``tcp://192.168.0.10:502`` are one lift: a station file written with the name and another
  with the address would both drive it.  The look-up is bounded (:data:`RESOLVE_TIMEOUT_S`:
  a name server that does not answer must not hold the daemon's start or a reload), and a
  name that does not resolve in time keeps the name as its key (those two files are then
  not told apart, as before the look-up).
- Serial ports (Modbus RTU, Open Protocol over RS-232): the device path with its links
  resolved (``/dev/serial/by-id/...`` is the ``/dev/ttyUSB0`` it points at); the whole line,
  whatever the unit (two processes on one serial line garble each other's frames).
- Cameras: an Aravis device id as written (case kept), an OpenCV camera index as its
  ``/dev/videoN``, an OpenCV device path resolved.
- No lock: ``sim://`` and ``sim+modbus://`` (each daemon simulates its own), ``file://``
  replays and OpenCV video files (read by any number of processes).

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
from urllib.parse import quote, unquote, urlsplit

from drivers.errors import UrlError
from drivers.url import parse_url

#: the shared folder of device locks when it can be written (Debian's /run/lock is 1777;
#: systemd/stationd.service lets the service write it)
RUN_LOCK_DIR = Path("/run/lock/stationd")
#: default ports of the TCP protocols a station speaks
DEFAULT_PORTS = {"openprotocol": 4545, "modbus-tcp": 502}
#: schemes that drive no device of their own (simulated, or files read by anyone)
UNLOCKED = {"sim", "sim+modbus", "file"}
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


def device_key(url: str) -> str | None:
    """The endpoint ``url`` drives, as a lock key (module docstring); None for a device no
    other process can share (simulated ones, files).  A URL that does not parse is its own
    key (the configuration refuses it before any lock is taken)."""
    try:
        parsed = parse_url(url)
    except UrlError:
        return f"url {url}"
    scheme = parsed.scheme
    if scheme in UNLOCKED:
        return None
    if scheme in ("modbus-rtu", "openprotocol+serial"):
        return f"serial {os.path.realpath(unquote(parsed.path))}"
    if scheme in DEFAULT_PORTS:
        where = f"tcp {_host(parsed.host or '')}:{parsed.port or DEFAULT_PORTS[scheme]}"
        if scheme == "modbus-tcp":
            unit = parsed.options.get("unit", "1").strip()
            where += f" unit {int(unit) if unit.isdigit() else unit}"
        return where
    if scheme == "aravis":
        return f"aravis {unquote(urlsplit(url).netloc)}"
    if scheme == "opencv":
        if parsed.host and parsed.host.isdigit():
            return f"video {os.path.realpath(f'/dev/video{int(parsed.host)}')}"
        path = unquote(parsed.path)
        return f"video {os.path.realpath(path)}" if path.startswith("/dev/") else None
    return f"url {url}"


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
