"""Tightening curves as they come (MID 0008 for MID 0900): subscribed at every session start
once asked for, queued apart from the results, each acknowledged.

Why optional and never in the way: a controller that refuses the subscription (MID 0004
"unknown MID", "subscription on specific data not supported", ...) leaves curves off
(``on``, ``reason``) and nothing else changes; one that does not answer is not asked again
(it would hang every reconnect).  A curve is read on the same link as the results but queued
apart, bounded (the oldest goes): nobody reading curves never holds a result back.  Curves
are binary, so they are asked for over TCP only.  Each MID 0900 is acknowledged with MID
0005 naming it unless its header's no-ack flag is set (``dataacks.py``); a curve longer than
one message comes in parts, put together before it is read (the channel does it) and
acknowledged once, after its last part.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from drivers.counting import counted
from drivers.errors import DeviceError, DeviceTimeoutError, ProtocolError, RefusedError
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.channel import Channel
from drivers.wrench.openprotocol.curve import (
    CURVE_REFUSALS,
    MID_DATA_SUBSCRIBE,
    MID_TRACE,
    Curve,
    parse_curve_data,
    subscribe_data,
)
from drivers.wrench.openprotocol.dataacks import DataAcks
from drivers.wrench.openprotocol.message import Message


@dataclass
class CurveFetch:
    """The curves of one earlier tightening being asked for (``replay.py``)."""

    tightening_id: int
    wanted: int
    curves: list[Curve] = field(default_factory=list)
    done: threading.Event = field(default_factory=threading.Event)


class CurveFeed:
    """The curves of one wrench's sessions, guarded by the channel's ``cond``: ``wanted``
    (asked for, so subscribed at every session start), ``on`` (subscribed this session),
    ``reason`` (why not), the queue (at most ``queue_size``), and ``fetch``, the curves of
    an earlier tightening being collected instead of queued."""

    def __init__(self, channel: Channel, acks: DataAcks, *, wanted: bool,
                 queue_size: int) -> None:
        self._channel = channel
        self._acks = acks
        self._log = channel.log
        self.device = channel.device
        self.wanted = wanted
        self.on = False
        self.reason: str | None = "not asked for" if not wanted else None
        self._queue: deque[Curve] = deque()
        self._queue_size = queue_size
        self._dropped = 0
        self.fetch: CurveFetch | None = None
        channel.route(MID_TRACE, self.received)

    def reset(self) -> None:
        """A new session is not subscribed until it asks."""
        with self._channel.cond:
            self.on = False

    def want(self) -> None:
        """Curves asked for: at every session start from now on."""
        with self._channel.cond:
            self.wanted, self.reason = True, None

    def subscribe(self, epoch: int | None, timeout: float | None = None) -> bool:
        """MID 0008 for the angle and torque traces on this session: whether curves are on.
        A refusal that says the controller gives none turns them off, for good; no answer
        too, and the timeout is raised: the link is then in an unknown state."""
        channel = self._channel
        if channel.link.kind == "serial":
            self.off("curves are binary messages: asked for over TCP only")
            return False
        try:
            channel.transact(Message(MID_DATA_SUBSCRIBE, data=subscribe_data()),
                             {op.MID_ACCEPTED, op.MID_ERROR}, timeout or channel.timeout,
                             epoch)
        except RefusedError as e:
            if e.code in CURVE_REFUSALS:
                self.off(f"the controller gives none (MID 0008 refused: "
                         f"{op.refusal_text(e.code or 0)})")
                return False
            if e.code != 71:                    # 71: subscription already exists
                raise
        except DeviceTimeoutError as e:
            self.off(f"no answer to the curves' subscription (MID 0008): {e}")
            raise
        with channel.cond:
            new = self.reason is not None or not self.on
            self.on, self.reason = True, None
        if new:
            self._log.info("%s: tightening curves subscribed (MID 0008 for MID 0900: angle "
                           "and torque traces)", self.device)
        return True

    def off(self, why: str) -> None:
        """Curves off, on this session and later ones, because ``why`` (said once)."""
        with self._channel.cond:
            was = self.reason
            self.wanted = self.on = False
            self.reason = why
        if was != why:
            self._log.info("%s: no tightening curves: %s", self.device, why)

    def received(self, msg: Message) -> None:
        """A MID 0900 (the reading thread): to the fetch that asked for it, else queued
        (bounded: the oldest goes); its acknowledgement owed either way."""
        try:
            curve: Curve | None = parse_curve_data(msg.data)
        except ProtocolError as e:
            self._log.warning("%s: unreadable tightening curve, acknowledged anyway: %s",
                              self.device, e)
            curve = None
        with self._channel.cond:
            fetch = self.fetch
            if curve is not None and fetch is not None \
                    and curve.tightening_id == fetch.tightening_id:
                fetch.curves.append(curve)           # asked for: handed to fetch_curve
                if len(fetch.curves) >= fetch.wanted:
                    fetch.done.set()
            elif curve is not None:
                if len(self._queue) >= self._queue_size:
                    self._queue.popleft()
                    self._dropped += 1
                    self._log.warning("%s: %s dropped: nobody reads them",
                                      self.device, counted(self._dropped, "curve"))
                self._queue.append(curve)
            if not msg.no_ack:
                self._acks.owe(MID_TRACE)
            self._channel.cond.notify_all()

    def next(self, timeout: float, closing: Callable[[], bool]) -> Curve | None:
        """The oldest curve queued, waiting up to ``timeout`` seconds for one (None then);
        DeviceError once ``closing()`` says the wrench is closing."""
        deadline = time.monotonic() + timeout
        cond = self._channel.cond
        with cond:
            while not self._queue:
                if closing():
                    raise DeviceError("closed", device=self.device)
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                cond.wait(remaining)
            return self._queue.popleft()
