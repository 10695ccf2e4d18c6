"""The supervisor thread: one per wrench, it owns the link's reading side while the link is
up, and between reads sends what the reading thread may only owe (0062s, data 0005s),
starts a renewal owed, and keeps the link alive (MID 9999).  When the link fails it closes
it and waits: ``reconnect()`` brings it back (one attempt at a time; the station's keeper
retries with backoff).

Why one thread does all of it: the link's reading side is the one place where answers are
seen, so whatever else runs there must never wait for an answer; the sends it makes are
those that never block (``block=False`` at link level) or need no answer.
"""

from __future__ import annotations

import threading
import time

from drivers.errors import DeviceError, DeviceTimeoutError
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.channel import POLL, Channel
from drivers.wrench.openprotocol.dataacks import DataAcks
from drivers.wrench.openprotocol.message import Message
from drivers.wrench.openprotocol.renewal import Renewal
from drivers.wrench.openprotocol.resultfeed import ResultFeed


class KeepAlive:
    """MID 9999 after ``interval`` seconds without traffic either way; the link is lost when
    its mirror does not come within ``timeout``.  The supervisor's only.

    Either way: the controller drops a client it has not heard from for 15 s, and a
    controller that hangs with its socket open answers nothing while the station keeps
    asking (an integrator's trial: 18 unanswered MID 0064 in 45 s, each taken as a refusal,
    no keep-alive ever sent for the traffic, the wrench said "ok" throughout)."""

    def __init__(self, channel: Channel, *, interval: float) -> None:
        self._channel = channel
        self._interval = interval
        self._sent: float | None = None
        channel.route(op.MID_KEEPALIVE, self.mirrored)

    def reset(self) -> None:
        """A new session: no keep-alive outstanding."""
        self._sent = None

    def mirrored(self, msg: Message) -> None:
        """The controller mirrored the keep-alive."""
        self._sent = None

    def tick(self) -> None:
        now = time.monotonic()
        timeout = self._channel.timeout
        if self._sent is not None:
            if now - self._sent > timeout:
                raise DeviceTimeoutError(f"keep-alive (MID 9999) not mirrored within "
                                         f"{timeout:g} s")
        elif now - min(self._channel.last_sent, self._channel.last_heard) >= self._interval:
            self._sent = now
            self._channel.send(Message(op.MID_KEEPALIVE))


class Supervisor:
    """The loop of one wrench's supervisor thread (:meth:`run`) until ``stop`` is set."""

    def __init__(self, channel: Channel, stop: threading.Event, *, feed: ResultFeed,
                 acks: DataAcks, renewal: Renewal, keepalive: KeepAlive) -> None:
        self._channel = channel
        self._stop = stop
        self._feed = feed
        self._acks = acks
        self._renewal = renewal
        self._keepalive = keepalive

    def run(self) -> None:
        """Read while the link is up; when it is down, close it and wait for
        ``reconnect()`` (which holds the reading side while it starts a session)."""
        channel = self._channel
        while not self._stop.is_set():
            with channel.reading():
                with channel.cond:
                    up = channel.connected
                if up:
                    try:
                        self._turn()
                    except DeviceError as e:
                        channel.fail(e)
                    continue
                with channel.write_lock:
                    channel.link.close()
            self._stop.wait(POLL)

    def _turn(self) -> None:
        """One read, then what is owed: the 0062s first (a result's before any data's),
        a renewal, the keep-alive."""
        self._channel.read_once()
        if self._feed.flush():
            self._acks.flush()
        self._renewal.tick()
        self._keepalive.tick()
