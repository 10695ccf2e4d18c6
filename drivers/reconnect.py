"""The link to a device that may go away: the current connection and the one named thread that
reconnects with exponential backoff until the device is back or ``stop()`` is called.

pymodbus's transport design (one reconnect task that ``close()`` cancels), used by the lift's
Modbus backend and the Aravis camera, and kept out of both so each is only about its device.
Callers wait for the link within their own timeout and otherwise get a ConnectionLostError
saying how long it has been down, why, and when the next attempt is.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Generic, TypeVar

from drivers.errors import ConnectionLostError, DeviceError

L = TypeVar("L")
JOIN_TIMEOUT = 30.0  # an attempt may sit in SDK timeouts (GigE: 2.5 s per register access)


class LinkKeeper(Generic[L]):
    """Holds the current link of one device.  ``connect(refresh)`` makes a new link (raising
    a DeviceError when it cannot); ``dispose(link, lost)`` releases one and must not raise.

    The thread is called ``name``, and ``stop()`` waits ``join_timeout`` seconds for it.  The
    device's own words: ``noun`` ("the camera is closed"), ``attempts`` (how the status line
    counts them), and its logger ``log``."""

    def __init__(self, device: str, connect: Callable[[bool], L],
                 dispose: Callable[[L, bool], None], *, backoff: float, backoff_max: float,
                 name: str, noun: str, attempts: str = "failed attempt(s)",
                 join_timeout: float = JOIN_TIMEOUT, log: logging.Logger | None = None) -> None:
        self.device = device
        self._connect = connect
        self._dispose = dispose
        self.backoff = backoff
        self.backoff_max = max(backoff, backoff_max)
        self.name = name
        self._noun = noun
        self._attempts_word = attempts
        self._join_timeout = join_timeout
        self._log = log or logging.getLogger(__name__)
        self._lock = threading.Lock()
        self._up = threading.Event()
        self._stop = threading.Event()
        self._link: L | None = None
        self._thread: threading.Thread | None = None
        self._last_error = ""  # the message only: an exception would pin the failed link
        self._down_since = 0.0
        self._attempts = 0
        self._next_try = 0.0

    def start(self, link: L) -> None:
        """Install the first link (made by the caller, so open() reports its own errors)."""
        self._stop.clear()
        with self._lock:
            self._link = link
            self._up.set()

    def current(self) -> L | None:
        with self._lock:
            return self._link

    def status(self) -> str:
        """One line: up, or down since when, why, and the reconnect progress."""
        with self._lock:
            if self._link is not None:
                return "connected"
            if self._stop.is_set():
                return "closed"
            reason = self._last_error or "not connected"
            down = time.monotonic() - self._down_since
            nxt = max(0.0, self._next_try - time.monotonic())
            attempts = self._attempts
        return (f"link down for {down:.1f} s ({reason}); reconnecting: {attempts} "
                f"{self._attempts_word}, next in {nxt:.1f} s")

    def wait(self, deadline: float) -> L:
        """The link, waiting for a reconnect until ``deadline`` (monotonic)."""
        if not self._stop.is_set():
            self._up.wait(max(0.0, deadline - time.monotonic()))
        with self._lock:
            if self._link is not None:
                return self._link
            if self._stop.is_set():
                raise DeviceError(f"the {self._noun} is closed", device=self.device)
        raise ConnectionLostError(self.status(), device=self.device)

    def lost(self, link: L, exc: DeviceError) -> None:
        """``link`` failed with ``exc``: retire it and start the reconnect thread (which
        disposes of the old link first, so the caller does not sit in SDK timeouts).  While
        ``stop()`` runs, the caller disposes of it here: nobody else would."""
        with self._lock:
            if self._link is not link:
                return
            self._link = None
            self._up.clear()
            self._last_error = str(exc).removeprefix(f"{self.device}: ")
            self._down_since = time.monotonic()
            self._attempts = 0
            self._next_try = time.monotonic()
            if not self._stop.is_set() and self._thread is None:
                self._log.warning("%s; reconnecting", exc)
                self._thread = threading.Thread(target=self._run, args=(link,), daemon=True,
                                                name=self.name)
                self._thread.start()
                return
        self._dispose(link, True)

    def stop(self) -> L | None:
        """Stop the reconnect thread (waiting for it) and hand back the current link, which
        the caller closes."""
        self._stop.set()
        with self._lock:
            thread = self._thread
        if thread is not None:
            thread.join(self._join_timeout)
            if thread.is_alive():
                self._log.error("%s: reconnect thread did not stop within %.0f s", self.device,
                                self._join_timeout)
        with self._lock:
            link, self._link = self._link, None
            self._up.clear()
        return link

    def _run(self, old: L) -> None:
        """Dispose of the failed link, then try at once, after backoff, 2 x backoff, ... up to
        backoff_max.  The new link is installed in the same locked step that retires the
        thread, so a link that fails at once finds no thread running and starts a new one."""
        self._dispose(old, True)
        delay = self.backoff
        link: L | None = None
        try:
            while not self._stop.is_set():
                try:
                    link = self._connect(True)
                    break
                except Exception as exc:  # a bug must not end the thread: keep trying
                    if not isinstance(exc, DeviceError):
                        self._log.exception("%s: reconnect attempt crashed", self.device)
                        exc = DeviceError(f"reconnect attempt crashed: {exc!r}",
                                          device=self.device)
                    with self._lock:
                        self._last_error = str(exc).removeprefix(f"{self.device}: ")
                        self._attempts += 1
                        self._next_try = time.monotonic() + delay
                    self._log.debug("%s: reconnect attempt failed: %s", self.device, exc)
                    del exc  # its traceback holds the failed attempt's objects
                    if self._stop.wait(delay):
                        break
                    delay = min(2 * delay, self.backoff_max)
        finally:
            with self._lock:
                self._thread = None
                if link is not None and not self._stop.is_set():
                    self._link, link = link, None
                    self._up.set()
                    self._log.info("%s: reconnected after %d failed attempt(s)", self.device,
                                   self._attempts)
            if link is not None:
                self._dispose(link, False)
