"""Open, close and ``with``: the lifecycle the device interfaces share.

:class:`Openable` is the context-manager half, for any device with ``open()`` and ``close()``:
``with device:`` opens it and closes it again (the wrench, whose ``open()`` and ``close()`` are
its own: thread-safe, and a closed wrench is not reopened).  :class:`Device` adds the simple
lifecycle of the lift PLC and the cameras: idempotent ``open()`` / ``close()`` around two
hooks, and a closed device may be opened again.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from types import TracebackType
from typing import Self


class Openable(ABC):
    """A device used as a context manager: ``open()`` on enter, ``close()`` on exit."""

    @abstractmethod
    def open(self) -> None: ...

    @abstractmethod
    def close(self) -> None: ...

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

    @abstractmethod
    def _open(self) -> None:
        """Connect (and start acquisition, for a camera); clean up everything itself if it
        fails."""

    @abstractmethod
    def _close(self) -> None:
        """Release everything; must not raise."""
