"""The channel to one controller: the link, one message on the wire at a time, the one
command in flight and its answer, the link's epoch, and what is read handed to its subject.

Why, "acknowledged or reported failed": a command returns only on its answer.  A MID 0004 is
a RefusedError with the controller's code; any other failure (timeout, lost link, garbage)
raises and also resets the link: the controller's state is then unknown, and a late answer
must never be taken as the answer to the next command.  Sends carry the link's epoch, bumped
by every reset, so a command can never leak onto a reconnected link before its session
started.

Reading: whoever holds the reading side (:meth:`Channel.reading`: the supervisor thread, or
the session start, which reads its own answers) reads.  A message is acknowledged at link
level (``linklevel.py``), put together from its parts (``parts.py``), and handed to the
subject that asked for its MID (:meth:`Channel.route`: results, curves, the keep-alive) or
else to the command in flight that it answers.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TypeVar

from drivers.errors import (
    ConnectionLostError,
    DeviceError,
    DeviceTimeoutError,
    ProtocolError,
    RefusedError,
)
from drivers.link import Link
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.linklevel import LinkLevel
from drivers.wrench.openprotocol.message import Message, SerialFramer, TcpFramer
from drivers.wrench.openprotocol.parts import BrokenParts, PartAssembler

T = TypeVar("T")
Handler = Callable[[Message], None]

POLL = 0.05            # the reader's granularity: bounds reaction to close() and resets
RESET = "; the link is reset and reconnects"


@dataclass
class Pending:
    """The one command in flight and what may answer it."""

    mid: int
    expect: frozenset[int]
    done: threading.Event = field(default_factory=threading.Event)
    reply: Message | None = None
    error: DeviceError | None = None

    def matches(self, msg: Message) -> bool:
        if msg.mid not in self.expect:
            return False
        if msg.mid in (op.MID_ERROR, op.MID_ACCEPTED):      # both carry the MID they answer
            return msg.data[:4] == f"{self.mid:04d}".encode()
        return True


class Channel:
    """One wrench's link and what runs on it.  ``cond`` is the wrench's: it guards
    ``connected``, ``epoch``, ``stopping`` and the command in flight here, and every
    subject's own state.  The wrench's bookkeeping comes in as three functions: ``down``
    (the error a caller sees while the link is down), ``surface`` (an error named with what
    was being done) and ``went_down`` (the link was reset: the reason when it was up, and
    whether the wrench is closing; called with ``cond`` held).  ``log`` is the driver's one
    logger, its facade's, which every part writes to: a site's logging configuration (and
    the tests) name ``drivers.wrench.openprotocol.client`` whichever part speaks."""

    def __init__(self, link: Link, *, device: str, cond: threading.Condition,
                 stop: threading.Event, timeout: float,
                 down: Callable[[str], ConnectionLostError],
                 surface: Callable[[DeviceError, str, str], DeviceError],
                 went_down: Callable[[str | None, bool], None], log: logging.Logger) -> None:
        self.link = link
        self.log = log
        self.device = device
        self.timeout = timeout
        self.cond = cond
        self._stop = stop
        self._down, self._surface, self._went_down = down, surface, went_down
        self.framer: TcpFramer | SerialFramer = TcpFramer()
        self.write_lock = threading.Lock()      # one message on the wire at a time
        self.request_lock = threading.Lock()    # one command in flight
        self._reader = threading.Lock()         # the link's reading side: supervisor or session
        self._reader_owner: threading.Thread | None = None
        self.links = LinkLevel(self, device=device, cond=cond, stop=stop, timeout=timeout,
                               log=log)
        self.connected = False
        self.epoch = 0
        # the communication stop is being sent (closing): subscribed data that arrives after
        # it (curves in flight) is no longer acknowledged, nor a subscription renewed
        self.stopping = False
        self._pending: Pending | None = None
        self._parts = PartAssembler()           # the reading thread's only
        self.last_sent = 0.0
        # when the controller last sent anything: a controller that stops answering while
        # the station keeps asking (each unanswered ask taken as refused) is asked to mirror
        # a keep-alive as soon as it has been silent for the keep-alive's interval
        self.last_heard = 0.0
        self._routes: dict[int, Handler] = {}
        self._on_broken: Callable[[BrokenParts], None] = lambda broken: None

    def route(self, mid: int, handler: Handler) -> None:
        """Hand every whole MID ``mid`` read to ``handler`` (on the reading thread, which it
        must never make wait for the link: that thread reads the answers)."""
        self._routes[mid] = handler

    def on_broken(self, handler: Callable[[BrokenParts], None]) -> None:
        """Tell ``handler`` of each message in parts given up (after it is logged)."""
        self._on_broken = handler

    # -- a session on the link -------------------------------------------------------------
    def begin(self, connect_timeout: float) -> None:
        """Connect for a new session: framing for the link's kind, nothing sent yet, the
        link level off and counting from 1, no message half put together."""
        self.link.connect(connect_timeout)
        self.framer = SerialFramer() if self.link.kind == "serial" else TcpFramer()
        self.last_sent = self.last_heard = time.monotonic()
        self.links.reset()
        self._parts.reset()

    @contextmanager
    def reading(self) -> Iterator[None]:
        """Hold the link's reading side; a sequenced send from this thread then reads its
        own link-level acknowledgement instead of waiting for the supervisor."""
        with self._reader:
            self._reader_owner = threading.current_thread()
            try:
                yield
            finally:
                self._reader_owner = None

    def reading_here(self) -> bool:
        """Whether this thread holds the reading side."""
        return self._reader_owner is threading.current_thread()

    def current_epoch(self, what: str) -> int:
        """The link's epoch, or the "link down" error for ``what``."""
        with self.cond:
            if not self.connected:
                raise self._down(what)
            return self.epoch

    def fail(self, err: DeviceError, epoch: int | None = None, closing: bool = False) -> None:
        """Mark the link down (the supervisor then closes it, ``reconnect()`` brings it
        back) and fail the command in flight and the numbered message outstanding; nothing
        when ``epoch`` is a link already gone."""
        with self.cond:
            if epoch is not None and epoch != self.epoch:
                return
            was_up = self.connected
            if was_up and not closing:   # logged before anyone can see the link down
                self.log.warning("%s: link lost: %s", self.device, err)
            self.connected = False
            self.epoch += 1
            self._went_down(str(err) if was_up else None, closing)
            if self._pending is not None:
                self._pending.error = err
                self._pending.done.set()
                self._pending = None
            self.links.lost(err)
            self.cond.notify_all()

    # -- sending and commands --------------------------------------------------------------
    def write(self, msg: Message, epoch: int | None = None) -> None:
        """Put one message on the wire (nothing waited for)."""
        data = op.frame_serial(msg) if self.link.kind == "serial" else op.frame_tcp(msg)
        with self.write_lock:
            if epoch is not None:
                with self.cond:
                    if epoch != self.epoch:
                        raise ConnectionLostError("the link was reset before sending")
            self.link.send(data)
            self.last_sent = time.monotonic()

    def send(self, msg: Message, epoch: int | None = None, block: bool = True,
             timeout: float | None = None) -> bool:
        """Send ``msg``, at link level when that is on (:meth:`LinkLevel.send`)."""
        return self.links.send(msg, epoch, block, timeout)

    def transact(self, msg: Message, expect: set[int], timeout: float,
                 epoch: int | None = None) -> Message:
        """Send ``msg`` and return its answer.  With ``epoch`` (a caller's thread) the
        supervisor reads the answer; without (open, reconnect) this thread reads."""
        slot = Pending(msg.mid, frozenset(expect))
        with self.cond:
            if epoch is not None and epoch != self.epoch:
                raise ConnectionLostError("the link was reset; nothing was sent")
            self._pending = slot
        try:
            self.send(msg, epoch, timeout=timeout)
            if epoch is not None:
                slot.done.wait(timeout)
            else:
                deadline = time.monotonic() + timeout
                while not slot.done.is_set() and time.monotonic() < deadline:
                    if self._stop.is_set():
                        raise ConnectionLostError("closing")
                    self.read_once()
        finally:
            with self.cond:
                if self._pending is slot:
                    self._pending = None
        if slot.error is not None:
            raise slot.error
        if slot.reply is None:
            noise = getattr(self.framer, "noise", 0)
            hint = f" ({noise} bytes of line noise received)" if noise else ""
            raise DeviceTimeoutError(f"no answer to MID {msg.mid:04d} within {timeout:g} s"
                                     + hint)
        if slot.reply.mid == op.MID_ERROR:
            _, code = op.refusal(slot.reply)
            raise RefusedError(f"refused by the controller: {op.refusal_text(code)}", code=code)
        return slot.reply

    def ask(self, msg: Message, expect: set[int], timeout: float, epoch: int) -> Message:
        """:meth:`transact` of a request a controller may ignore (MID 0064, the VIN): no
        answer at all is its refusal, the link kept (its keep-alive says whether it is
        alive: sent once the controller has been silent for its interval, however much the
        station asks: the supervisor's ``KeepAlive``).  Taken for a dead link, a trial's
        peers had the link reset at every reconnect, for ever.  A late answer is taken for
        nothing else: each names the MID it answers."""
        try:
            return self.transact(msg, expect, timeout, epoch)
        except DeviceTimeoutError as e:
            raise RefusedError(f"{e}: taken as refused (the link kept: its keep-alive tells "
                               "whether it is alive)") from None

    def request(self, what: str, exchange: Callable[[int], T], note: str = RESET,
                passes: tuple[type[DeviceError], ...] = (),
                when_down: Callable[[], T] | None = None) -> T:
        """``exchange(epoch)`` as the one command in flight on the current link, its errors
        named ``what``: a refusal raised as it is, ``passes`` untouched, and any other
        failure resets the link (the controller's state is unknown) and is raised with
        ``note``.  A link already down raises the "link down" error, or returns
        ``when_down()`` when given."""
        with self.request_lock:
            try:
                epoch = self.current_epoch(what)
            except ConnectionLostError:
                if when_down is None:
                    raise
                return when_down()
            try:
                return exchange(epoch)
            except RefusedError as e:
                raise self._surface(e, what, "") from None
            except passes:
                raise
            except DeviceError as e:
                self.fail(e, epoch)
                raise self._surface(e, what, note) from None

    def command(self, msg: Message, what: str, timeout: float) -> None:
        """Send ``msg`` and return on its MID 0005 (a 0004 raises RefusedError)."""
        self.request(what, lambda epoch: self.transact(msg, {op.MID_ACCEPTED, op.MID_ERROR},
                                                       timeout, epoch),
                     "; not acknowledged, treat it as not done (the link is reset and "
                     "reconnects)")

    # -- reading (the thread holding the reading side) -------------------------------------
    def read_once(self) -> None:
        """Read for up to POLL seconds and dispatch every complete message."""
        try:
            data = self.link.recv(POLL)
        except ConnectionLostError as e:
            if self.framer.pending:
                raise ConnectionLostError(f"{e} in the middle of a message ("
                                          f"{self.framer.pending} bytes of it received)") \
                    from None
            raise
        if data:
            self.last_heard = time.monotonic()
        for item in self.framer.feed(data) if data else ():
            if isinstance(item, ProtocolError):
                raise item
            self._dispatch(item)

    def _dispatch(self, msg: Message) -> None:
        if msg.mid in (op.MID_LINK_ACK, op.MID_LINK_ERROR):
            self.links.answer(msg)
            return
        if not self.links.received(msg):
            return
        for item in self._parts.feed(msg):      # a message in parts: once it is whole
            if isinstance(item, BrokenParts):
                self.log.warning("%s: MID %04d in parts given up: %s", self.device,
                                 item.mid, item.reason)
                self._on_broken(item)
            else:
                self._deliver(item)

    def _deliver(self, msg: Message) -> None:
        """One whole message (its link-level work done): to its subject, or as the answer
        to the command in flight."""
        handler = self._routes.get(msg.mid)
        if handler is not None:
            handler(msg)
            return
        with self.cond:
            slot = self._pending
            if slot is not None and slot.matches(msg):
                slot.reply, self._pending = msg, None
                slot.done.set()
                return
        self.log.warning("%s: unexpected MID %04d ignored (data %r)", self.device, msg.mid,
                         msg.data[:40])
