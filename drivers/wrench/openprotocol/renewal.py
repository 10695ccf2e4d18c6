"""The result subscription renewed at a lower revision (MID 0063, then 0060), and the results
made in between fetched (MID 0064).

Why: a controller that accepts a subscription at a revision it does not implement sends its
results laid out as a lower one (``reading.py`` reads them).  Renewing the subscription at
the revision it really sends makes the next results read cleanly, and says so.  A result the
controller makes between the 0063 and the 0060 is never pushed: the catch-up fetches it by
its tightening id.

Why a thread of its own: the renewal is a command, and its answers are read by the
supervisor thread, which therefore must not run it.  It waits for the one command in flight
(a caller's, whose answer the supervisor reads) and, at link level, for the one numbered
message outstanding.
"""

from __future__ import annotations

import threading

from drivers.errors import DeviceError, RefusedError
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.channel import Channel
from drivers.wrench.openprotocol.message import Message
from drivers.wrench.openprotocol.oldresults import OldResults
from drivers.wrench.openprotocol.resultfeed import RESULT_REVISIONS, ResultFeed

CATCH_UP = 10          # results fetched after a renewal of the subscription, at most


class Renewal:
    """Renews the result subscription ``feed`` owes, one renewal at a time."""

    def __init__(self, channel: Channel, feed: ResultFeed, old: OldResults) -> None:
        self._channel = channel
        self._feed = feed
        self._old = old
        self._log = channel.log
        self.device = channel.device
        self._thread: threading.Thread | None = None    # the renewal running (``cond``)

    def tick(self) -> None:
        """The supervisor's turn: start the renewal owed in a thread of its own, unless one
        runs, the link is down or the wrench is closing."""
        with self._channel.cond:
            rev, epoch = self._feed.renew_at, self._channel.epoch
            busy = self._thread is not None and self._thread.is_alive()
            if rev is None or busy or not self._channel.connected or self._channel.stopping:
                return
            self._feed.renew_at = None
            self._thread = threading.Thread(target=self._renew, args=(rev, epoch),
                                            daemon=True, name=f"wrench-renew {self.device}")
            self._thread.start()

    def join(self) -> None:
        """Wait for the renewal running, if any (its command fails with the link: it ends)."""
        if self._thread is not None:
            self._thread.join()

    def _renew(self, rev: int, epoch: int) -> None:
        """Unsubscribe (0063) and subscribe (0060) at revision ``rev`` or lower, as a command
        (the supervisor reads the answers).  A failure resets the link; the next session
        asks for the highest revision again."""
        channel = self._channel
        expect = {op.MID_ACCEPTED, op.MID_ERROR}
        agreed: int | None = None
        with channel.request_lock:
            try:
                try:
                    channel.transact(Message(op.MID_RESULT_UNSUBSCRIBE), expect,
                                     channel.timeout, epoch)
                except RefusedError as e:
                    if e.code != 10:            # 10: no subscription, which is the goal
                        raise
                with channel.cond:              # nothing is pushed after the 0063's answer
                    before = self._feed.last_pushed
                for r in [r for r in RESULT_REVISIONS if r <= rev]:
                    try:
                        channel.transact(Message(op.MID_RESULT_SUBSCRIBE, revision=r), expect,
                                         channel.timeout, epoch)
                    except RefusedError as e:
                        if e.code not in op.REVISION_REFUSALS or r == 1:
                            raise
                        continue
                    agreed = r
                    break
                if before is not None:
                    self._catch_up(before, epoch)
            except DeviceError as e:
                channel.fail(type(e)(f"renewing the result subscription at revision "
                                     f"{rev}: {e}", code=e.code), epoch)
                return
        if agreed is not None:
            with channel.cond:
                if epoch == channel.epoch:
                    self._feed.subscribed = agreed
            self._log.info("%s: results subscribed again at MID 0061 revision %d",
                           self.device, agreed)

    def _catch_up(self, before: int, epoch: int) -> None:
        """The results made while the subscription was being renewed (after the 0063, before
        the 0060: never pushed), fetched by tightening id from ``before`` + 1 and queued as
        fetched (nothing to acknowledge), up to ``CATCH_UP`` of them; it stops at the first
        the controller does not have, or that was pushed meanwhile (the ones after it are
        pushed too), or at a refusal of MID 0064.  One fetched and then pushed as well (made
        just after the 0060) is acknowledged when pushed and not handed out twice.  Called
        holding the request lock."""
        for tid in range(before + 1, before + 1 + CATCH_UP):
            with self._channel.cond:
                if self._feed.pushed(tid):
                    return
            try:
                result = self._old.fetch(tid, self._channel.timeout, epoch,
                                         f"fetch tightening {tid}")
            except RefusedError as e:
                # a controller without MID 0064 (or refusing it now): the renewal stands and
                # the link with it; a result made in between skips its id, which the
                # station's gap check says (dropping the link would lose the subscription
                # and renew it again at every session)
                self._log.warning("%s: results made while the result subscription was "
                                  "renewed cannot be fetched (MID 0064: %s); a tightening id "
                                  "skipped is a gap", self.device, e)
                return
            if result is None or not self._feed.caught(tid, result):
                return                       # not kept, or pushed while it was fetched
            self._log.warning("%s: tightening %d made while the result subscription was "
                              "renewed: fetched (MID 0064)", self.device, tid)
