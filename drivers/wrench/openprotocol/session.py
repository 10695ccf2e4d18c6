"""A session's start on a freshly connected link: communication start (MID 0001 -> 0002),
the result subscription (0060), the curves when asked for (0008), the controller's clock
(0080 -> 0081); each at the highest revision the controller accepts.

Why revisions are negotiated: the session asks for the highest revision of 0001 (6) and 0060
(7: results come as MID 0061 revision 7) this driver reads, and one lower each time the
controller answers MID 0004 "revision unsupported" (97, 76 or 74), as integrators' clients
do.  Link-level acknowledgement is on when the controller's 0002 says it supports it (or the
URL says ``link_ack=1``).  The clock is asked so that results fetched late can be placed in
the station's time; a controller that does not say it is never a reason to fail the
session.  Everything is decided anew at each session: the controller on the other end may
be another one, or updated.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from datetime import datetime

from drivers.errors import DeviceError, DeviceTimeoutError, ProtocolError, RefusedError
from drivers.wrench.base import CLOCK_FAR_S, clock_seconds
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.channel import Channel
from drivers.wrench.openprotocol.curvefeed import CurveFeed
from drivers.wrench.openprotocol.identity import ControllerIdentity, parse_identity
from drivers.wrench.openprotocol.message import Message
from drivers.wrench.openprotocol.oldresults import OldResults
from drivers.wrench.openprotocol.resultfeed import RESULT_REVISIONS, ResultFeed

#: revisions of 0001 asked for, highest first (6, whose 0002 says whether the controller does
#: link-level acknowledgement)
START_REVISIONS = (6, 5, 4, 3, 2, 1)
TYPED_REVISION = 3     # MID 0061 carries the result type (parameter 49) from this revision on
CLOCK_TIMEOUT = 1.0    # the most MID 0080 (the controller's clock) is waited for at connect


class Session:
    """Starts the sessions of one wrench.  What the last one agreed is guarded by the
    channel's ``cond``: ``identity`` (its MID 0002), ``revision`` (of 0001),
    ``clock_offset`` (the controller's clock minus the station's, seconds); the result
    subscription's revision is the feed's, MID 0064's the old results'.  ``fresh`` is what
    each part of the driver forgets of the last session, called once the link is
    connected."""

    def __init__(self, channel: Channel, feed: ResultFeed, old: OldResults, curves: CurveFeed,
                 *, connect_timeout: float, link_ack: str,
                 fresh: Sequence[Callable[[], None]]) -> None:
        self._channel = channel
        self._feed = feed
        self._old = old
        self._curves = curves
        self._connect_timeout = connect_timeout
        self._link_ack = link_ack
        self._fresh = tuple(fresh)
        self._log = channel.log
        self.device = channel.device
        self.identity: ControllerIdentity | None = None
        self.revision: int | None = None
        self.clock_offset: float | None = None

    def start(self) -> None:
        """Connect and start a session (called holding the reading side: this thread reads
        the answers).  A failure closes the link and is raised as "communication start: ..."
        (the first session) or "session restart: ..."."""
        channel = self._channel
        channel.begin(self._connect_timeout)
        for forget in self._fresh:
            forget()
        try:
            agreed = self._negotiate_all()
        except DeviceError as e:
            channel.link.close()
            what = "communication start" if self.identity is None else "session restart"
            # silence to MID 0001 from a port that took the connection: another device's
            # port, most likely (a technician's trial: the lift's and the controller's ports
            # swapped, told as "no answer" alone)
            hint = " (a port that takes the connection and stays silent to MID 0001 is not " \
                "an Open Protocol controller's: another device's port, or Open Protocol off " \
                "on it?)" if isinstance(e, DeviceTimeoutError) and \
                f"MID {op.MID_START:04d}" in str(e) and self.identity is None else ""
            raise type(e)(f"{what}: {e}{hint}", code=e.code) from None
        except BaseException:
            channel.link.close()
            raise
        ident, start_rev, result_rev, offset = agreed
        with channel.cond:
            new = self.identity != ident
            self.identity, self.revision, self.clock_offset = ident, start_rev, offset
            self._feed.subscribed = result_rev
            self._old.new_session()
            linking = channel.links.on
        if new:
            self._log.info("%s: controller %s; MID 0002 revision %d, results as MID 0061 "
                           "revision %s, link-level acknowledgement %s", self.device,
                           ident.describe(), ident.revision,
                           "?" if result_rev is None else result_rev,
                           "on" if linking else "off")
        if result_rev is not None and result_rev < TYPED_REVISION:
            self._log.warning("%s: results subscribed at MID 0061 revision %d, which carries "
                              "no result type: a batch increment or a bypass at the "
                              "controller reads as a tightening", self.device, result_rev)

    def _negotiate_all(self) -> tuple[ControllerIdentity, int, int | None, float | None]:
        """0001, 0060, 0008 if curves are wanted, 0080: (the controller's identity, the 0001
        and 0060 revisions agreed, None for 0060 when already subscribed, the clock
        offset)."""
        channel = self._channel
        reply, start_rev = self._negotiate(op.MID_START, START_REVISIONS,
                                           {op.MID_START_ACK, op.MID_ERROR})
        ident = parse_identity(reply.revision, reply.data)
        linking = self._link_ack == "on" or (
            self._link_ack == "auto" and ident.sequence_number_support is True)
        with channel.cond:
            channel.links.on = linking
        result_rev: int | None = None
        try:
            _, result_rev = self._negotiate(op.MID_RESULT_SUBSCRIBE, RESULT_REVISIONS,
                                            {op.MID_ACCEPTED, op.MID_ERROR})
        except RefusedError as e:
            if e.code != 9:                 # 09: already subscribed, which is the goal
                raise
        with channel.cond:   # results pushed from now on are judged against it
            self._feed.subscribed = result_rev
            curves = self._curves.wanted
        if curves:
            try:
                self._curves.subscribe(None)
            except DeviceTimeoutError:
                pass        # curves off (logged); the session goes on without them
        return ident, start_rev, result_rev, self._read_clock()

    def _negotiate(self, mid: int, revisions: Sequence[int], expect: set[int]
                   ) -> tuple[Message, int]:
        """Send ``mid`` at each of ``revisions`` until one is not refused as unsupported:
        (the answer, the revision asked)."""
        for rev in revisions:
            try:
                return self._channel.transact(Message(mid, revision=rev), expect,
                                              self._channel.timeout), rev
            except RefusedError as e:
                if e.code not in op.REVISION_REFUSALS or rev == revisions[-1]:
                    raise
                self._log.info("%s: MID %04d revision %d refused (%s), asking for %d",
                               self.device, mid, rev, op.refusal_text(e.code or 0), rev - 1)
        raise AssertionError("unreachable: the last revision's refusal is raised")

    def check_clock(self, epoch: int) -> float | None:
        """The controller's clock measured again on the live session ``epoch`` (the
        supervisor reads the answer): the new offset, kept (:attr:`clock_offset`); where it
        moved by a second or more since the last measure, said.  Not answered or refused:
        the last measure stays (logged), as good as it was."""
        try:
            offset = self._measure_clock(epoch)
        except (RefusedError, DeviceTimeoutError, ProtocolError) as e:
            with self._channel.cond:
                kept = self.clock_offset
            # (a trial: "its last measure stays" of a clock never measured)
            self._log.info("%s: the controller's clock not measured again (MID 0080: %s): %s",
                           self.device, e, "its last measure stays" if kept is not None else
                           "still not known (results fetched late are placed by their ids)")
            return kept
        with self._channel.cond:
            before, self.clock_offset = self.clock_offset, offset
        if before is None or abs(offset - before) >= 1.0:
            self._log.info("%s: controller clock now %+d s from the station's (%s)",
                           self.device, clock_seconds(offset), "not known before" if before is None
                           else f"{clock_seconds(before):+d} s at the last measure")
        return offset

    def _measure_clock(self, epoch: int | None = None) -> float:
        """The controller's clock minus the station's (MID 0080 -> 0081, in the
        specification since revision 1), measured at the answer, to within a second (the
        controller says whole seconds).  A refusal, or no answer in ``CLOCK_TIMEOUT``,
        raises (a late 0081 is then an unexpected MID, ignored).  ``epoch``: on a live
        session (:meth:`check_clock`); None at the session's start."""
        reply = self._channel.transact(Message(op.MID_TIME_REQUEST),
                                       {op.MID_TIME, op.MID_ERROR},
                                       min(self._channel.timeout, CLOCK_TIMEOUT), epoch)
        return (op.controller_time(reply) - datetime.now()).total_seconds()

    def _read_clock(self) -> float | None:
        """The controller's clock at the session's start (:meth:`_measure_clock`), said;
        None, logged, where it is not known."""
        try:
            offset = self._measure_clock()
        except (RefusedError, DeviceTimeoutError, ProtocolError) as e:
            self._log.info("%s: the controller's clock is not known (MID 0080: %s): results "
                           "fetched late are placed by their tightening ids only",
                           self.device, e)
            return None
        # its whole seconds are its clock cut down: an agreeing clock measures -1..0 s, so
        # the words take the middle of that second (they alternated between "agrees" and
        # "-1 s" for a clock in step: a line engineer's trial)
        if clock_seconds(offset) == 0:
            self._log.info("%s: controller clock agrees with the station's (within 1 s)",
                           self.device)
        elif abs(offset) < CLOCK_FAR_S:
            self._log.info("%s: controller clock %+d s from the station's", self.device,
                           clock_seconds(offset))
        else:   # said as a warning (a technician's trial: an hour off was an INFO line)
            self._log.warning("%s: controller clock %+d s from the station's: set the "
                              "controller's clock (the station places results fetched late "
                              "through this offset meanwhile)", self.device, clock_seconds(offset))
        return offset


