"""Results asked for after the fact (MID 0064 -> 0065): a gap in the tightening ids filled
after a reconnect, and the renewal's catch-up.

Why its own revision: a controller may keep its old results at a revision other than the one
it pushes at.  The first fetch of a session asks for the highest revision and one lower each
time the controller answers "revision unsupported", and the session keeps the one agreed; a
MID 0065 laid out as a lower revision than its header says is read at that one (as a pushed
result is, ``reading.py``) and later fetches ask for it; where that lower revision carries
no result type and the header's does, only after two such answers in a row (the first held
as unreadable: it may be a loosening).  One that reads at no revision is
the controller's record of a tightening all the same: handed back as an ``UnreadableResult``,
to be stored and looked at, not raised.

A controller that does not answer MID 0064 at all (no 0065, no refusal: one that ignores a MID
it does not know) refuses it by its silence (``Channel.ask``): taken for a dead link, every
reconnect's catch-up asked again and reset it again, every 2.5 s, and no tool went on (a
trial against an emulator).
"""

from __future__ import annotations

import dataclasses

from drivers.errors import ProtocolError, RefusedError
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
from drivers.wrench.openprotocol.resultfeed import RESULT_REVISIONS, ResultFeed


class OldResults:
    """MID 0064 on one wrench's sessions; ``agreed`` (guarded by the channel's ``cond``) is
    the revision agreed this session, None before the first fetch."""

    def __init__(self, channel: Channel, feed: ResultFeed) -> None:
        self._channel = channel
        self._feed = feed                       # says a lowered revision once, as for pushes
        self._log = channel.log
        self.device = channel.device
        self.agreed: int | None = None
        self._untyped = UntypedInARow()   # answers laid out without a type, in a row

    def new_session(self) -> None:
        """Nothing agreed yet (``cond`` held): the controller may be another one."""
        self.agreed = None
        self._untyped.reset()

    def fetch(self, tightening_id: int, timeout: float, epoch: int, what: str
              ) -> Received | None:
        """MID 0064 -> 0065 at the agreed revision (or the highest not refused), holding the
        request lock: the result, or None for "not found"; other refusals and failures
        raise as they come, and a ProtocolError for a readable answer about another
        tightening (an unreadable one whose id reads as another is kept, its id unknown)."""
        data = f"{tightening_id:010d}".encode()
        with self._channel.cond:
            agreed = self.agreed
        for rev in (agreed,) if agreed else RESULT_REVISIONS:
            try:
                reply = self._channel.ask(
                    Message(op.MID_OLD_RESULT_REQUEST, revision=rev, data=data),
                    {op.MID_OLD_RESULT, op.MID_ERROR}, timeout, epoch)
            except RefusedError as e:
                if e.code in op.REVISION_REFUSALS and rev > 1:
                    continue
                if e.code == op.NOT_FOUND:
                    self._agree(rev)
                    return None
                raise
            self._agree(rev)
            return self._read(reply, tightening_id, what, rev)
        raise AssertionError("unreachable: revision 1's refusal is raised")

    def _agree(self, rev: int) -> None:
        with self._channel.cond:
            self.agreed = rev

    def _read(self, reply: Message, tightening_id: int, what: str, asked: int) -> Received:
        with self._channel.cond:
            pushed = self._feed.subscribed
        result = untyped_below(reply, receive(reply), asked, pushed)
        habit = self._untyped.habit(result, reply.revision)
        if isinstance(result, UnreadableResult) and result.laid_out_as is not None \
                and result.laid_out_as == reply.revision == asked:
            # the revision agreed carries no type, the pushes' does: each such answer held
            self._log.warning("%s: %s: MID 0065 revision %d carries no result type, though "
                              "the pushed results (revision %s) do; kept with its raw text "
                              "(tightening %s), never taken for a tightening (it may be a "
                              "loosening: the station holds the bolt it may be of, if any)",
                              self.device, what, asked, pushed, result.tightening_id)
        elif isinstance(result, UnreadableResult) and result.laid_out_as is not None:
            self._log.warning("%s: %s: MID 0065 %s, which carries no result type; kept with "
                              "its raw text", self.device, what,
                              layout_words(reply.revision, result.laid_out_as, asked))
            if habit or result.laid_out_as == reply.revision:   # honest: at the first
                self._feed.lowered(reply.mid, reply.revision, result.laid_out_as)
                self._agree(result.laid_out_as)
        elif isinstance(result, UnreadableResult):
            self._log.warning("%s: %s: MID 0065 revision %d does not read at any revision "
                              "(%s); kept with its raw text", self.device, what,
                              reply.revision, result.error)
        elif result.header_revision is not None:
            self._feed.lowered(reply.mid, result.header_revision, result.revision)
            self._agree(result.revision)                 # ask for that one
        if tightening_id and result.tightening_id not in (tightening_id, None):
            if isinstance(result, UnreadableResult) and result.laid_out_as is None:
                # an id picked out of a body that does not read may be another field: the
                # message is kept (the controller's record of a tightening), its id unknown;
                # one that read (laid out as a revision without a type) has its own id, and
                # an answer about another tightening is refused as any readable one
                self._log.warning("%s: %s: the unreadable answer reads as tightening %d: "
                                  "kept without an id", self.device, what,
                                  result.tightening_id)
                return dataclasses.replace(
                    result, tightening_id=None,
                    error=f"{result.error} (asked for tightening {tightening_id}, its body "
                          f"reads as {result.tightening_id})")
            raise ProtocolError(f"{what}: the controller answered with tightening "
                                f"{result.tightening_id}", device=self.device)
        return result
