"""systemd's notification protocol, without libsystemd: datagrams to ``NOTIFY_SOCKET``.

``Type=notify`` units learn that the daemon is ready (``READY=1``), what it is doing
(``STATUS=...``, shown by ``systemctl status``), that it is alive (``WATCHDOG=1``, at least
every ``WATCHDOG_USEC`` / 2) and that it is stopping (``STOPPING=1``).  An address starting
with ``@`` is in the abstract namespace.  Outside systemd (no ``NOTIFY_SOCKET``) every call is
a no-op, so the daemon runs the same from a terminal.

Sends never block: a manager that does not read (busy, or a harness that stopped reading)
fills the socket's queue (10 datagrams by default, ``net.unix.max_dgram_qlen``), and a
blocking send then stopped the daemon's event loop: no lift reads, no stop on SIGTERM.
A datagram that would block is dropped and counted; the next status says the state again.
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Mapping


class Notifier:
    """Sends notifications to the service manager, if there is one."""

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        env = os.environ if environ is None else environ
        addr = env.get("NOTIFY_SOCKET", "")
        self._address: str | bytes | None = None
        if addr.startswith("@"):
            self._address = b"\0" + addr[1:].encode()
        elif addr.startswith("/"):
            self._address = addr
        self.watchdog_s = _watchdog_interval(env)
        self._sock: socket.socket | None = None
        self.dropped = 0   # datagrams not sent because the manager's queue was full

    @property
    def enabled(self) -> bool:
        return self._address is not None

    def send(self, **fields: str | int) -> bool:
        """Send ``KEY=value`` lines (keys upper-cased); False when there is no manager or the
        datagram could not be sent, at once (never blocks, never raises: notifications must
        not stop or crash the daemon)."""
        if self._address is None:
            return False
        msg = "\n".join(f"{k.upper()}={v}" for k, v in fields.items()).encode()
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto(msg, socket.MSG_DONTWAIT, self._address)
        except BlockingIOError:
            self.dropped += 1
            return False
        except OSError:
            return False
        return True

    def ready(self, status: str = "") -> bool:
        return self.send(ready=1, **({"status": status} if status else {}))

    def status(self, text: str) -> bool:
        return self.send(status=text.replace("\n", " "))

    def watchdog(self) -> bool:
        return self.send(watchdog=1)

    def reloading(self, status: str = "") -> bool:
        """A reload begins (READY=1 ends it); the monotonic time is what systemd 253+ asks
        for with it, harmless before."""
        usec = time.clock_gettime_ns(time.CLOCK_MONOTONIC) // 1000
        return self.send(reloading=1, monotonic_usec=usec,
                         **({"status": status} if status else {}))

    def extend_timeout(self, seconds: float, status: str = "") -> bool:
        """Ask systemd (236+) for ``seconds`` more before it takes the start, reload or stop
        under way for hung (``EXTEND_TIMEOUT_USEC``): sent again before they run out while
        the work goes on."""
        return self.send(extend_timeout_usec=int(seconds * 1_000_000),
                         **({"status": status} if status else {}))

    def stopping(self, status: str = "") -> bool:
        return self.send(stopping=1, **({"status": status} if status else {}))

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def _watchdog_interval(env: Mapping[str, str]) -> float | None:
    """Seconds between WATCHDOG=1 pings (half of WATCHDOG_USEC), or None when the watchdog is
    off or meant for another process (WATCHDOG_PID names a different pid)."""
    usec = env.get("WATCHDOG_USEC")
    if not usec:
        return None
    pid = env.get("WATCHDOG_PID")
    if pid and pid.isdigit() and int(pid) != os.getpid():
        return None
    try:
        value = int(usec)
    except ValueError:
        return None
    return value / 2e6 if value > 0 else None
