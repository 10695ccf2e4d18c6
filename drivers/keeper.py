"""One device's life in the daemon: open, use, and on a failure report it, back off and
reconnect, until the task is cancelled.  The single reconnect-with-backoff mechanism of the
station: drivers do not reconnect by themselves (a lost link stays down and every call says
so at once), so what a device does while it is down, how long it waits and what it reports
is decided here, once, for the lift, the wrench and every camera pair.

pymodbus's transport design (one named reconnect task that closing cancels), as an asyncio
task: blocking driver calls run through ``blocking`` (an executor), waits through ``sleep``,
both injectable so the unit tests run on a fake clock.  Waits grow exponentially with jitter
(so devices that fell together do not come back in lockstep) up to a cap, and start again
from the first wait only once the device has *worked* after a reconnect: a device that
accepts a connection and then answers garbage is retried ever more slowly, never hammered.
"""

from __future__ import annotations

import asyncio
import logging
import random
import threading
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any, Generic, TypeVar

from drivers.errors import DeviceError, DeviceTimeoutError, ProtocolError, RefusedError

D = TypeVar("D")
T = TypeVar("T")

log = logging.getLogger(__name__)


class FaultKind(StrEnum):
    """What kind of fault a device has (the screens colour and the journal names it)."""

    TIMEOUT = "timeout"     # it did not answer in time
    GARBAGE = "garbage"     # it said something that is not the protocol, or does not decode
    REFUSED = "refused"     # it answered no
    DOWN = "down"           # refused connection, lost link, no such port, not open
    # the vehicle's data (the station's "vehicle" device): another car than the one loaded,
    # or a vehicle the database refuses (an unknown model, a closed VIN)
    CHANGED = "changed"
    REJECTED = "rejected"
    # it answers, and says it is itself in fault (the lift PLC's fault bit)
    REPORTED = "reported"


def fault_kind(exc: BaseException) -> FaultKind:
    """What kind of fault ``exc`` is, from the driver's error type: timeout, garbage (the
    device said something that is not the protocol, or the data does not decode), refused,
    down (any other device error: refused connection, lost link, no such port)."""
    if isinstance(exc, DeviceTimeoutError):
        return FaultKind.TIMEOUT
    if isinstance(exc, ProtocolError):
        return FaultKind.GARBAGE
    if isinstance(exc, RefusedError):
        return FaultKind.REFUSED
    if isinstance(exc, DeviceError):
        return FaultKind.DOWN
    return FaultKind.GARBAGE


#: Python's own error types that mean a bug in the station's code (a typo, a wrong index, a
#: wrong call): their traceback is what a developer needs to fix it, so it is journaled (once
#: per reason).  Any other error that is not a driver error comes from a library under a
#: driver (OpenCV's ``cv2.error`` for a camera it cannot open, ...): its message is the whole
#: story, the traceback only points into the library, and one on every retry buries the
#: journal, so it is one line (the traceback stays at debug level).
BUG_TYPES: tuple[type[BaseException], ...] = (
    AttributeError, NameError, TypeError, LookupError, AssertionError, ArithmeticError,
    NotImplementedError, RecursionError)


def _journal_crash(logger: logging.Logger, name: str, what: str, exc: BaseException) -> None:
    """Journal an exception from a device that is neither a driver error nor an OSError or
    ValueError (:data:`BUG_TYPES`: with its traceback, else one line)."""
    if isinstance(exc, BUG_TYPES):
        logger.error("%s: %s", name, what, exc_info=exc)
        return
    logger.error("%s: %s: %s: %s", name, what, type(exc).__name__, one_line(exc))
    logger.debug("%s: %s", name, what, exc_info=exc)


def one_line(exc: BaseException) -> str:
    """The first line of an error's message (the type's name if it has none): a fault
    reason is one readable line."""
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


@dataclass
class Backoff:
    """Waits between attempts: ``first_s``, doubling up to ``max_s``, each shortened by up
    to ``jitter`` of itself at random (never longer than the nominal wait, so never above
    the cap).  ``rng`` is seeded by the caller (by the device's name in the daemon): the
    waits are reproducible, and different devices get different jitter."""

    first_s: float = 0.5
    max_s: float = 5.0
    jitter: float = 0.25
    rng: random.Random = field(default_factory=lambda: random.Random(0))  # noqa: S311
    failures: int = 0

    def __post_init__(self) -> None:
        if not 0 < self.first_s <= self.max_s:
            raise ValueError(f"backoff needs 0 < first ({self.first_s} s) <= max "
                             f"({self.max_s} s)")
        if not 0 <= self.jitter < 1:
            raise ValueError(f"jitter must be in [0, 1), not {self.jitter}")

    def nominal(self) -> float:
        """The wait before the next attempt, without jitter."""
        return min(self.max_s, self.first_s * 2.0 ** min(self.failures, 60))

    def next(self) -> float:
        """The wait before the next attempt; each call counts one failure more."""
        wait = self.nominal() * (1.0 - self.jitter * self.rng.random())
        self.failures += 1
        return wait

    def reset(self) -> None:
        """The device worked: the next failure waits ``first_s`` again."""
        self.failures = 0


class KeeperClosedError(DeviceError):
    """The keeper was closed while an attempt was under way; the device it made is closed."""


async def _to_thread(fn: Callable[[], T]) -> T:
    return await asyncio.to_thread(fn)


class DeviceKeeper(Generic[D]):
    """Keeps one device: ``open()`` makes and connects it (blocking; raises when it cannot),
    ``reconnect(device)`` brings a lost link back on the same object (a simulated device
    keeps its simulator), ``close(device)`` releases it for good.

    ``on_fault(kind, reason)`` is awaited when the device fails (each loss, and each change
    of reason while attempts keep failing); ``on_back(reconnects)`` when it works again
    (``reconnects`` counts successful reconnects since the first open: a controller that
    reconnected may have forgotten what it was told).  Every exception from the device is a
    fault, never an exit; one that is not a driver error is journaled as well, with its
    traceback when it is a bug (:data:`BUG_TYPES`)."""

    def __init__(self, name: str, *, open: Callable[[], D],
                 reconnect: Callable[[D], None], close: Callable[[D], None],
                 on_fault: Callable[[FaultKind, str], Awaitable[None]],
                 on_back: Callable[[int], Awaitable[None]], backoff: Backoff | None = None,
                 blocking: Callable[[Callable[[], Any]], Awaitable[Any]] = _to_thread,
                 sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
                 logger: logging.Logger | None = None) -> None:
        self.name = name
        self._open, self._reconnect, self._close = open, reconnect, close
        self._on_fault, self._on_back = on_fault, on_back
        self.backoff = backoff or Backoff(rng=random.Random(name))  # noqa: S311 - jitter
        self._blocking, self._sleep = blocking, sleep
        self._log = logger or log
        self._lock = threading.Lock()     # device and closed: set from executor threads
        self._device: D | None = None
        self._closed = False
        self.up = False
        self.reconnects = 0
        self._reported: tuple[FaultKind, str] | None = None   # the fault last reported
        self._told: str | None = None                   # the open failure last logged
        self._lost: BaseException | None = None
        self._wake = asyncio.Event()
        self._waited = True    # True: the next attempt may go at once (nothing failed yet)
        self._worked = False   # the device served a use since it last came up
        self._up_once = False  # it came up at least once: a later success is a reconnect

    @property
    def device(self) -> D | None:
        """The device object once it has been opened (also while its link is down)."""
        with self._lock:
            return self._device

    # -- attempts (executor threads) ------------------------------------------------------------
    def _attempt(self) -> D:
        """One attempt: open the device the first time, reconnect it afterwards."""
        with self._lock:
            if self._closed:
                raise KeeperClosedError("closed", device=self.name)
            device = self._device
        if device is not None:
            self._reconnect(device)
            return device
        device = self._open()
        with self._lock:
            if not self._closed:
                self._device = device
                return device
        self._quiet_close(device)
        raise KeeperClosedError("closed while opening", device=self.name)

    def open_now(self) -> tuple[FaultKind, str] | None:
        """One blocking attempt to open the device (at start-up, before ``run``): None if it
        opened, else the fault (kind, reason), which ``run`` retries after a backoff."""
        try:
            self._attempt()
        except Exception as exc:
            fault = self._failed_attempt(exc)
            self._reported = fault
            return fault
        self._came_up()
        return None

    def _failed_attempt(self, exc: Exception) -> tuple[FaultKind, str]:
        self._waited = False
        fault = (fault_kind(exc), one_line(exc))
        if self._told != fault[1]:    # journaled once per reason, not once per attempt
            self._told = fault[1]
            if not isinstance(exc, DeviceError | OSError | ValueError):
                _journal_crash(self._log, self.name, "an attempt to connect crashed", exc)
            verb = "not opened" if self.device is None else "not reconnected"
            # debug: the owner journals the fault it is told (one line per event)
            self._log.debug("%s %s: %s", self.name, verb, fault[1])
        return fault

    def _came_up(self) -> None:
        if self._up_once:
            self.reconnects += 1
        if self._told is not None:
            self._log.debug("%s %s", self.name, "reconnected" if self._up_once else "opened")
        self.up, self._up_once, self._reported = True, True, None
        self._lost, self._told, self._worked = None, None, False
        self._wake.clear()

    # -- the task -----------------------------------------------------------------------------
    async def run(self, use: Callable[[D], Awaitable[None]] | None = None) -> None:
        """Keep the device until cancelled.  ``use(device)`` does one unit of work (a poll, a
        wait for a result) and raises when the device failed; without ``use`` the device is
        someone else's, who calls :meth:`lost` when it fails."""
        while True:
            if not self.up:
                await self._come_up()
                continue
            device = self.device
            failure = self._lost
            if failure is None and device is not None:
                try:
                    if use is None:
                        await self._wake.wait()
                        continue
                    await use(device)
                    if not self._worked:
                        self._worked = True
                        self.backoff.reset()
                    continue
                except Exception as exc:
                    failure = exc if self._lost is None else self._lost
                    if not isinstance(exc, DeviceError | OSError | ValueError):
                        _journal_crash(self._log, self.name, "using it crashed", exc)
            await self._go_down(failure or DeviceError("lost", device=self.name))

    @property
    def losing(self) -> bool:
        """A failure was reported by :meth:`lost` and the task has not handled it yet."""
        return self._lost is not None

    def lost(self, exc: BaseException) -> None:
        """Someone using the device saw it fail (call on the event loop's thread): the task
        reports the fault and reconnects.  Ignored while the device is already down."""
        if self.up and self._lost is None:
            self._lost = exc
            self._wake.set()

    def worked(self) -> None:
        """Someone using the device (without ``use``) saw it work: a later failure waits
        ``first_s`` again."""
        if self.up and not self._worked:
            self._worked = True
            self.backoff.reset()

    async def _go_down(self, exc: BaseException) -> None:
        self.up, self._lost, self._waited = False, None, False
        fault = (fault_kind(exc), one_line(exc))
        self._log.debug("%s lost: %s", self.name, fault[1])
        self._reported = fault
        await self._on_fault(*fault)

    async def _come_up(self) -> None:
        if not self._waited:
            await self._sleep(self.backoff.next())
            self._waited = True
        try:
            await self._blocking(self._attempt)
        except Exception as exc:
            fault = self._failed_attempt(exc)
            if fault != self._reported:
                self._reported = fault
                await self._on_fault(*fault)
            return
        self._came_up()
        await self._on_back(self.reconnects)

    # -- closing ------------------------------------------------------------------------------
    def close(self) -> None:
        """Close the device for good (blocking; the task should be cancelled first).  An
        attempt still running in a thread closes what it opens."""
        with self._lock:
            self._closed = True
            device, self._device = self._device, None
        self.up = False
        if device is not None:
            self._quiet_close(device)

    def _quiet_close(self, device: D) -> None:
        try:
            self._close(device)
        except Exception as exc:
            self._log.warning("closing %s: %s", self.name, one_line(exc))
