"""The curves of an earlier tightening (a result fetched after a link cut), asked for with the
generic subscription's "stored data between two indexes" (MID 0008 for MID 0900, send
alternative 3, first = last = the tightening id; R2.8.0 table 158).

Why the live subscription is stopped for it: a controller holds one subscription per MID, so
the replay's 0008 would replace the live one.  It is made again after; a curve of a new
tightening made in that moment is not sent (its result still is).  The curves asked for are
handed back, not queued for ``wait_curve``.
"""

from __future__ import annotations

from drivers.counting import counted
from drivers.errors import RefusedError
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.channel import Channel
from drivers.wrench.openprotocol.curve import (
    MID_DATA_SUBSCRIBE,
    MID_DATA_UNSUBSCRIBE,
    STATION_TRACES,
    Curve,
    replay_data,
    subscribe_data,
    unsubscribe_data,
)
from drivers.wrench.openprotocol.curvefeed import CurveFeed, CurveFetch
from drivers.wrench.openprotocol.message import Message


class CurveReplay:
    """Fetches earlier tightenings' curves on one wrench's link, with ``feed`` collecting
    them as they are read."""

    def __init__(self, channel: Channel, feed: CurveFeed) -> None:
        self._channel = channel
        self._feed = feed
        self._log = channel.log
        self.device = channel.device

    def fetch(self, tightening_id: int, timeout: float) -> list[Curve]:
        """The angle and torque curves of tightening ``tightening_id``, one per trace type:
        the controller answers 0005 and sends that tightening's traces, then the
        subscription is stopped (MID 0009).  Empty, logged, when the controller refuses (it
        keeps none, or not that one: MID 0004) or its traces do not come within
        ``timeout``, and over RS-232 (binary samples).  Other failures raise as commands do
        (a timeout or a lost link resets the link)."""
        what = f"fetch the curves of tightening {tightening_id}"
        if self._channel.link.kind == "serial":
            return []
        return self._channel.request(
            what, lambda epoch: self._collect(tightening_id, epoch, timeout, what))

    def _collect(self, tightening_id: int, epoch: int, timeout: float, what: str
                 ) -> list[Curve]:
        """The feed collects the tightening's curves while the exchange runs (holding the
        request lock)."""
        fetch = CurveFetch(tightening_id, len(STATION_TRACES))
        with self._channel.cond:
            live, self._feed.fetch = self._feed.on, fetch
        try:
            return self._exchange(fetch, live, epoch, timeout, what)
        finally:
            with self._channel.cond:
                self._feed.fetch = None

    def _exchange(self, fetch: CurveFetch, live: bool, epoch: int, timeout: float,
                  what: str) -> list[Curve]:
        """Stop the live subscription, ask for the replay, wait for its traces, stop it,
        subscribe again."""
        transact = self._channel.transact
        expect = {op.MID_ACCEPTED, op.MID_ERROR}
        stop = Message(MID_DATA_UNSUBSCRIBE, data=unsubscribe_data())
        if live:
            transact(stop, expect, timeout, epoch)
        refused: RefusedError | None = None
        try:
            transact(Message(MID_DATA_SUBSCRIBE, data=replay_data(
                fetch.tightening_id, fetch.tightening_id)), expect, timeout, epoch)
        except RefusedError as e:
            refused = e
        else:
            fetch.done.wait(timeout)
            try:
                transact(stop, expect, timeout, epoch)
            except RefusedError:
                pass                     # a controller that ended the replay by itself
        if live:
            try:
                transact(Message(MID_DATA_SUBSCRIBE, data=subscribe_data()), expect, timeout,
                         epoch)
            except RefusedError as e:
                if e.code != 71:         # 71: it exists, which is the goal
                    self._feed.off(f"the curves' subscription was refused again after "
                                   f"fetching old ones: {op.refusal_text(int(e.code or 0))}")
        with self._channel.cond:
            got = list(fetch.curves)
        if refused is not None:
            self._log.info("%s: %s: none (MID 0008 refused: %s)", self.device, what,
                           op.refusal_text(int(refused.code or 0)))
        elif len(got) < fetch.wanted:
            self._log.warning("%s: %s: %d of %s came within %g s", self.device, what,
                              len(got), counted(fetch.wanted, "trace"), timeout)
        return sorted(got, key=lambda c: c.trace_type)
