"""Link-level acknowledgement on a live session (MID 9997/9998): what is sent is numbered,
waited for and resent; what is received is acknowledged and a repeat is told from a new
message.

Why apart from the channel: the rules (``link.py``) are pure; this is their state on one
link (a counter per direction, the one numbered message outstanding), on or off per session
(the controller's 0002 says whether it does it, or the URL's ``link_ack``).  It writes and
reads through the channel (:class:`Wire`), which fails the link when the resends run out.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Protocol

from drivers.errors import ConnectionLostError, DeviceError, DeviceTimeoutError
from drivers.wrench.openprotocol import link as op_link
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.message import Message


class Wire(Protocol):
    """What link-level acknowledgement needs of the channel it numbers messages on."""

    epoch: int      # guarded by the wrench's condition

    def write(self, msg: Message, epoch: int | None = None) -> None: ...

    def read_once(self) -> None: ...

    def reading_here(self) -> bool: ...

    def fail(self, err: DeviceError, epoch: int | None = None,
             closing: bool = False) -> None: ...


@dataclass
class LinkWait:
    """The one sequenced message awaiting its link-level acknowledgement (9997/9998)."""

    seq: int
    done: threading.Event = field(default_factory=threading.Event)
    error_code: int | None = None           # a 9998's code
    lost: DeviceError | None = None         # the link went down meanwhile


class LinkLevel:
    """Link-level acknowledgement of one wrench's sessions, through ``wire``.  ``on`` and
    the counters are guarded by ``cond`` (the wrench's); the receiving counter is the
    reading thread's only."""

    def __init__(self, wire: Wire, *, device: str, cond: threading.Condition,
                 stop: threading.Event, timeout: float, log: logging.Logger) -> None:
        self._wire = wire
        self._log = log
        self.device = device
        self.timeout = timeout
        self._cond = cond
        self._stop = stop
        self._tx_lock = threading.Lock()        # one sequenced message outstanding
        self.on = False                         # link-level acknowledgement this session
        self._tx_seq = 0
        self._wait: LinkWait | None = None
        self._rx = op_link.RxSequence()

    def reset(self) -> None:
        """A new session (0001/0002 reset the link level): off until its 0002 says, both
        directions counting from 1 again."""
        with self._cond:
            self.on, self._tx_seq = False, 0
        self._rx.reset()

    # -- sending -----------------------------------------------------------------------------
    def send(self, msg: Message, epoch: int | None = None, block: bool = True,
             timeout: float | None = None) -> bool:
        """Send ``msg``; with link-level acknowledgement on, numbered and returning only
        once the controller acknowledged it (MID 9997), waiting ``timeout`` (the response
        timeout by default) for each try.  ``block=False``: False, nothing sent, if another
        sequenced message is outstanding."""
        with self._cond:
            linking = self.on
        if not linking or not op_link.is_sequenced(msg.mid):
            self._wire.write(msg, epoch)
            return True
        if not self._tx_lock.acquire(blocking=block):
            return False
        try:
            self._send_sequenced(msg, epoch, timeout or self.timeout)
        finally:
            self._tx_lock.release()
        return True

    def _send_sequenced(self, msg: Message, epoch: int | None, timeout: float) -> None:
        """Number ``msg``, send it, and resend it (same number) until MID 9997 came, up to
        ``op_link.RESENDS`` times; then the link is lost (called holding ``_tx_lock``)."""
        with self._cond:   # a number is never spent on a link that is gone: the new
            if epoch is not None and epoch != self._wire.epoch:   # session counts from 1
                raise ConnectionLostError("the link was reset before sending")
            self._tx_seq = seq = op_link.next_seq(self._tx_seq)
        numbered = dataclasses.replace(msg, sequence=seq)
        why = ""
        for attempt in range(1 + op_link.RESENDS):
            if attempt:
                self._log.warning("%s: MID %04d sequence %d: %s; resending (%d of %d)",
                                  self.device, msg.mid, seq, why, attempt, op_link.RESENDS)
            wait = LinkWait(seq)
            with self._cond:
                self._wait = wait
            try:
                self._wire.write(numbered, epoch)
                self._await(wait, timeout)
            finally:
                with self._cond:
                    if self._wait is wait:
                        self._wait = None
            if wait.lost is not None:
                raise wait.lost
            if wait.done.is_set() and wait.error_code is None:
                return
            why = (op_link.link_error_text(wait.error_code) if wait.error_code is not None
                   else f"no link-level acknowledgement within {timeout:g} s")
        err = DeviceTimeoutError(f"MID {msg.mid:04d} sequence {seq}: {why} after "
                                 f"{op_link.RESENDS} resends; the link is taken as lost")
        if epoch is not None:
            self._wire.fail(err, epoch)
        raise err

    def _await(self, wait: LinkWait, timeout: float) -> None:
        """Wait up to ``timeout`` for the answer to ``wait``: read it ourselves if this
        thread holds the reading side, else the supervisor reads it."""
        if not self._wire.reading_here():
            wait.done.wait(timeout)
            return
        deadline = time.monotonic() + timeout
        while not wait.done.is_set() and time.monotonic() < deadline:
            if self._stop.is_set():
                raise ConnectionLostError("closing")
            self._wire.read_once()

    # -- receiving (the reading thread) ------------------------------------------------------
    def answer(self, msg: Message) -> None:
        """A 9997/9998 from the controller: it answers the outstanding sequenced message."""
        with self._cond:
            wait = self._wait
            if wait is not None and op_link.answers(msg.sequence, wait.seq):
                if msg.mid == op.MID_LINK_ERROR:
                    wait.error_code = op_link.link_error_code(msg)
                wait.done.set()
                return
        self._log.warning("%s: MID %04d expecting sequence %s next, which answers no "
                          "outstanding message, ignored", self.device, msg.mid, msg.sequence)

    def received(self, msg: Message) -> bool:
        """Acknowledge ``msg`` at link level if it is numbered (before anything else: the
        controller waits for it); False for a repeat (our 9997 was lost), to acknowledge
        again and not process twice."""
        with self._cond:
            linking = self.on
        if linking and op_link.is_sequenced(msg.mid):
            self._wire.write(op_link.link_ack(msg))
            if not self._rx.is_new(msg.sequence):
                self._log.warning("%s: MID %04d repeated (sequence %s): acknowledged again, "
                                  "not processed twice", self.device, msg.mid, msg.sequence)
                return False
        return True

    def lost(self, err: DeviceError) -> None:
        """The link went down: the numbered message outstanding fails (``cond`` held)."""
        if self._wait is not None:
            self._wait.lost = err
            self._wait.done.set()
