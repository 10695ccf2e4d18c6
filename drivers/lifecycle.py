"""Open, reconnect, close and ``with``: the lifecycle every device kind shares.

:class:`Openable` is the context-manager half, for any device with ``open()``, ``reconnect()``
and ``close()``: ``with device:`` opens it and closes it again (the wrench, whose methods are
its own: thread-safe, and a closed wrench is not reopened).  :class:`Device` adds the simple
lifecycle of the lift PLC and the cameras: idempotent ``open()`` / ``close()`` around two
hooks, and a closed device may be opened again.

No device reconnects by itself: a lost link stays down, and every call says so at once, until
``reconnect()`` (one attempt) brings it back.  Who retries, how often and what is reported
meanwhile is one component's business, :class:`drivers.keeper.DeviceKeeper`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from types import TracebackType
from typing import ClassVar, Self, final

from drivers.endpoint import Endpoint, UrlEndpoint


class Openable(ABC):
    """A device used as a context manager: ``open()`` on enter, ``close()`` on exit."""

    #: a twin that exists only in this process (it serves its own simulated PLC or
    #: controller on loopback, or shows the simulated world): what starts a station asks
    #: it whether a simulated world must run beside (``drivers.devices.simulated``)
    simulated: ClassVar[bool] = False

    @final
    @classmethod
    def endpoint(cls, url: str) -> Endpoint | None:
        """What a device of this backend at ``url`` drives (``drivers.endpoint``), asked of
        the class: nothing is built or opened.  None for a simulated twin (it exists only
        in this process), whatever its real parent backend would say of the URL: a
        simulated backend is often a real one talking to its own simulator
        (``sim://wrench`` is the Open Protocol client), so this is not overridden; backends
        override :meth:`_endpoint`.  A UrlError when the backend refuses the URL."""
        return None if cls.simulated else cls._endpoint(url)

    @classmethod
    def _endpoint(cls, url: str) -> Endpoint | None:
        """What a real device of this backend at ``url`` drives.  By default the URL's
        text (:class:`UrlEndpoint`): a backend that does not say is still one device per
        URL, never silently shared (None) and never a failure of whoever asks (an abstract
        method would break every device double and a backend added without it at the
        first lock, not at review).  None only for what no other process can take from
        this one: files read by anyone."""
        return UrlEndpoint(url)

    @abstractmethod
    def open(self) -> None: ...

    @abstractmethod
    def close(self) -> None: ...

    @abstractmethod
    def reconnect(self) -> None:
        """Drop the link and connect again, keeping the device object (its settings, and
        the simulator a simulated device runs): one attempt, a DeviceError if it fails."""

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class Device(Openable):
    """``open()`` and ``close()`` are idempotent; backends implement ``_open`` and ``_close``."""

    def __init__(self) -> None:
        self._is_open = False

    @property
    def is_open(self) -> bool:
        return self._is_open

    def open(self) -> None:
        """Connect; a DeviceError (ConnectError, UrlError, ...) if the device cannot be reached
        or used."""
        if not self._is_open:
            self._open()
            self._is_open = True

    def close(self) -> None:
        """Disconnect and stop any background work; safe to call twice."""
        if self._is_open:
            self._is_open = False
            self._close()

    def reconnect(self) -> None:
        """Drop the link and connect again (opens a device that is not open).  By default
        close and open; backends with a link of their own override ``_reconnect``."""
        if not self._is_open:
            self.open()
            return
        self._reconnect()

    def _reconnect(self) -> None:
        self.close()
        self.open()

    @abstractmethod
    def _open(self) -> None:
        """Connect (and start acquisition, for a camera); clean up everything itself if it
        fails."""

    @abstractmethod
    def _close(self) -> None:
        """Release everything; must not raise."""
