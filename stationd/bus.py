"""The station's event bus: every event the core publishes, fanned out to the screens, OPC
UA, the forwarder and the journal, with a bounded history.

Why not in the core's package: it is the shell's plumbing (threads, an asyncio loop's
queues), and the core is pure; the core's events (:mod:`stationd.station.events`) are what
travels on it."""

from __future__ import annotations

import asyncio
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator

from stationd.station.events import StationEvent


class EventBus:
    """Fan-out of published events: a bounded history (a shift-long run neither grows nor
    floods) plus subscribers.  Synchronous callbacks run in the publisher's thread (keep them
    short); asyncio subscribers get a bounded queue each, and a slow one loses its oldest
    events rather than slowing the station."""

    def __init__(self, history: int = 100_000) -> None:
        self.history: deque[StationEvent] = deque(maxlen=history)
        self._callbacks: list[Callable[[StationEvent], None]] = []
        self._queues: list[tuple[asyncio.AbstractEventLoop, asyncio.Queue[StationEvent]]] = []
        # a subscriber that replays the history takes it and joins in one step, so that no
        # event is between the two (missed) or in both (an older state said after a newer)
        self._joining = threading.RLock()

    def publish(self, event: StationEvent) -> None:
        with self._joining:
            self.history.append(event)
            for cb in list(self._callbacks):
                cb(event)
        for loop, q in list(self._queues):
            loop.call_soon_threadsafe(_put_dropping_oldest, q, event)

    def subscribe(self, callback: Callable[[StationEvent], None],
                  replay: Callable[[list[StationEvent]], Iterable[StationEvent]] | None = None
                  ) -> Callable[[], None]:
        """Call ``callback`` with every event from now on; returns the unsubscribe function.
        ``replay``: first with the events it picks from the history (what is true now, for a
        reader that starts while the station runs), then with every event after them.  A
        callback runs under the bus's lock: it must never wait for a thread that publishes."""
        with self._joining:
            for event in (() if replay is None else replay(list(self.history))):
                callback(event)
            self._callbacks.append(callback)
        return lambda: self._callbacks.remove(callback)

    def queue(self, maxsize: int = 1000) -> asyncio.Queue[StationEvent]:
        """An asyncio queue (of the running loop) fed with every event from now on."""
        q: asyncio.Queue[StationEvent] = asyncio.Queue(maxsize)
        self._queues.append((asyncio.get_running_loop(), q))
        return q

    def unqueue(self, q: asyncio.Queue[StationEvent]) -> None:
        self._queues = [(lp, x) for lp, x in self._queues if x is not q]

    def of(self, *kinds: type[StationEvent]) -> Iterator[StationEvent]:
        """The history's events of the given types, oldest first."""
        return (e for e in list(self.history) if isinstance(e, kinds))

    def count(self, *kinds: type[StationEvent]) -> int:
        return sum(1 for _ in self.of(*kinds))


def _put_dropping_oldest(q: asyncio.Queue[StationEvent], event: StationEvent) -> None:
    if q.full():
        q.get_nowait()
    q.put_nowait(event)
