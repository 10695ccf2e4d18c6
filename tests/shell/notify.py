"""A service manager's notification socket for the daemon under test, read all the time as
systemd reads it: the daemon drops what a full queue would block on, so a harness that reads
only when it waits for something would miss what came in between."""

from __future__ import annotations

import socket
import threading
import time
from pathlib import Path


class NotifyManager:
    """Binds ``path`` (a ``NOTIFY_SOCKET``) and keeps every datagram; :meth:`until` waits for
    one containing a text, after the last one an earlier call returned."""

    def __init__(self, path: Path) -> None:
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self._sock.bind(str(path))
        self._sock.settimeout(0.1)
        self._got: list[str] = []
        self._seen = 0
        self._cv = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()

    def _read(self) -> None:
        while not self._closed:
            try:
                msg = self._sock.recv(4096).decode()
            except TimeoutError:
                continue
            except OSError:
                return
            with self._cv:
                self._got.append(msg)
                self._cv.notify_all()

    def until(self, needle: str, timeout: float) -> list[str]:
        """The datagrams up to the first (after the last returned) containing ``needle``."""
        end = time.monotonic() + timeout
        with self._cv:
            while True:
                for k in range(self._seen, len(self._got)):
                    if needle in self._got[k]:
                        out, self._seen = self._got[self._seen:k + 1], k + 1
                        return out
                left = end - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"{needle!r} not received; got "
                                         f"{self._got[self._seen:]}")
                self._cv.wait(left)

    def close(self) -> None:
        self._closed = True
        self._thread.join()
        self._sock.close()
