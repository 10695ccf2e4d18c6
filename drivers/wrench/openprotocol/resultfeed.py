"""Results pushed by the controller (MID 0061): queued for the station, read or not, and
acknowledged (MID 0062) only once the station has them, on the link they came on.

Why acknowledged so late: the 0062 tells the controller it may forget the result; a result
lost before the station stored it (the process killed) must be one the controller still
holds.  And why on the same link: 0062 names no result, so on a new session it would
acknowledge whatever that session sent, not this one.

A result is read by its own header's revision (``reading.py``): one laid out as a lower
revision is read so, said once, and its subscription is owed a renewal at that revision
(``renewal.py`` does it; never from here, the reading thread, which has to read the
renewal's answers).  One that reads at no revision is queued as an ``UnreadableResult`` with
its raw text and acknowledged like a result once the station has stored it.  So is one laid
out as a revision without a result type (below 3) under a header whose revision has one:
and the subscription is renewed there only after two such results in a row, the controller's
habit, not a byte lost on the line (a session renewed below 3 reads no result's type).
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable

from drivers.wrench.base import Received, UnreadableResult
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.channel import Channel
from drivers.wrench.openprotocol.message import Message
from drivers.wrench.openprotocol.reading import (
    UntypedInARow,
    layout_words,
    receive,
    untyped_below,
)

#: MID 0060/0061 and 0064/0065 revisions asked for, highest first: all that ``result.py``
#: reads
RESULT_REVISIONS = (7, 6, 5, 4, 3, 2, 1)
NO_ACK = -1            # the acknowledgement token of a fetched result: no 0062 to send


class ResultFeed:
    """The results pushed on one wrench's sessions.  Everything but what was said once is
    per session and guarded by the channel's ``cond``: ``subscribed``, the MID 0060
    revision agreed; ``renew_at``, a renewal owed; ``last_pushed``, the newest tightening id
    pushed on this link; ``caught_up``, those the renewal's catch-up fetched (a push of one
    of them is acknowledged at once, not handed out twice).  ``queue`` is the wrench's
    (a result and its acknowledgement token, ``cond`` held)."""

    def __init__(self, channel: Channel, queue: Callable[[Received, int], None]) -> None:
        self._channel = channel
        self._cond: threading.Condition = channel.cond
        self._queue = queue
        self._log = channel.log
        self.device = channel.device
        self.subscribed: int | None = None
        # results read at a lower revision than their header's: the highest revision results
        # are subscribed at from then on in this session; every new session asks for the
        # highest again (the controller on the other end may be another one, or updated: a
        # revision below 3 carries no result type, and a batch increment then reads as a
        # tightening)
        self.cap = RESULT_REVISIONS[0]
        self.renew_at: int | None = None
        self.last_pushed: int | None = None
        self.caught_up: set[int] = set()
        self._owed = 0                          # 0062s for those pushes, sent by the supervisor
        self._lowered_said: set[tuple[int, int, int]] = set()   # (MID, header, read at)
        # pushed results laid out as a revision without a type, in a row
        self._untyped = UntypedInARow()
        channel.route(op.MID_RESULT, self.received)

    def reset(self) -> None:
        """A new session: nothing pushed or owed yet, the highest revision again."""
        with self._cond:
            self.renew_at, self.last_pushed, self._owed = None, None, 0
            self._untyped.reset()
            self.caught_up.clear()
            self.cap = RESULT_REVISIONS[0]
            # until the 0060 is answered, what it asks for: a result the controller pushes
            # again during the negotiation is judged against that, not against the last
            # session's revision (lowered to 2 there, it let an untyped one close a bolt)
            self.subscribed = RESULT_REVISIONS[0]

    def received(self, msg: Message) -> None:
        """A MID 0061 (the reading thread): queued, read or not, its acknowledgement token
        the link's epoch; one read at a lower revision than the one subscribed owes a
        renewal at that revision."""
        item = receive(msg)
        with self._cond:
            item = untyped_below(msg, item, self.subscribed)
            tid = item.tightening_id
            if tid is not None:
                if tid in self.caught_up:        # fetched while the subscription was renewed
                    self.caught_up.discard(tid)
                    self._owed += 1              # the station has it: acknowledged, not
                    return                       # handed out again
                self.last_pushed = max(tid, self.last_pushed or 0)
            habit = self._untyped.habit(item, msg.revision)
            if isinstance(item, UnreadableResult) and item.laid_out_as is not None:
                self._log.warning(
                    "%s: MID 0061 %s, which carries no result type; kept with its raw text "
                    "for the station (tightening id %s), its bolt held: it may be a "
                    "loosening", self.device, layout_words(msg.revision, item.laid_out_as,
                                                           self.subscribed),
                    item.tightening_id if item.tightening_id is not None else "?")
                # an honest label is no byte lost on the line: renewed at the first (still
                # held); a body laid out otherwise than labelled, at the second in a row
                if habit or item.laid_out_as == msg.revision:
                    self._lower(msg.mid, msg.revision, item.laid_out_as)
            elif isinstance(item, UnreadableResult):
                self._log.warning(
                    "%s: MID 0061 revision %d does not read at any revision (%s); kept with "
                    "its raw text for the station (tightening id %s)", self.device,
                    msg.revision, item.error,
                    item.tightening_id if item.tightening_id is not None else "?")
            elif item.header_revision is not None:
                self._lower(msg.mid, item.header_revision, item.revision)
            self._queue(item, self._channel.epoch)

    def _lower(self, mid: int, header: int, read_at: int) -> None:
        """Results labelled ``header`` are laid out as ``read_at``: said once, and the
        subscription renewed there (``cond`` held)."""
        self.lowered(mid, header, read_at)
        if self.subscribed is not None and read_at < self.subscribed:
            self.cap = min(self.cap, read_at)
            self.renew_at = self.cap

    def lowered(self, mid: int, header: int, read_at: int) -> None:
        """Say once (a wrench's life) that ``mid`` labelled ``header`` read as ``read_at``."""
        if (mid, header, read_at) in self._lowered_said:
            return
        self._lowered_said.add((mid, header, read_at))
        self._log.warning(
            "%s: MID %04d %s%s", self.device, mid,
            f"labelled revision {header} is laid out as revision {read_at} (with fields "
            "appended)" if header != read_at else f"comes at revision {read_at}, below the "
            "one asked for",
            "; results are subscribed at that revision from now on"
            if mid == op.MID_RESULT else "")

    def pushed(self, tid: int) -> bool:
        """Whether tightening ``tid`` (or a later one) was pushed on this link (``cond``
        held)."""
        return self.last_pushed is not None and tid <= self.last_pushed

    def caught(self, tid: int, result: Received) -> bool:
        """Queue ``result``, fetched by the renewal's catch-up (nothing to acknowledge),
        unless it was pushed meanwhile: whether it was queued.  Handed out as pushed (an
        unreadable one not ``fetched``): made with the link up, while the subscription was
        renewed, it is the result of the enable owed now, not one made during a link cut."""
        if isinstance(result, UnreadableResult) and result.fetched:
            result = dataclasses.replace(result, fetched=False)
        with self._cond:
            if self.pushed(tid):
                return False
            if result.tightening_id == tid:
                # a push of it later is acknowledged, not handed out twice; one fetched
                # without its id (it did not read) is not known to be it: its push, a
                # result of its own, is handed out (a reviewer: acknowledged and dropped)
                self.caught_up.add(tid)
            self._queue(result, NO_ACK)
            return True

    def acknowledge(self, token: int, timeout: float) -> None:
        """MID 0062 on the link the result came on (``token``: its epoch).  A result fetched
        by the driver itself (``NO_ACK``) has none."""
        if token == NO_ACK:
            return
        self._channel.send(Message(op.MID_RESULT_ACK), epoch=token, timeout=timeout)

    def flush(self) -> bool:
        """Send the 0062s owed for pushes of results already fetched (the supervisor):
        never waiting for the one-outstanding slot, which a caller may hold while this
        thread reads its acknowledgement.  Whether none is left owed."""
        while True:
            with self._cond:
                if not self._owed:
                    return True
            if not self._channel.send(Message(op.MID_RESULT_ACK), block=False):
                return False
            with self._cond:
                self._owed -= 1


