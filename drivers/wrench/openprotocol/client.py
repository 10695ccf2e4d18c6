"""The Open Protocol backend: ``openprotocol://HOST[:4545]``, ``openprotocol+serial:///dev/tty..``.

:class:`OpenProtocolWrench` is the integrator's driver, the :class:`Wrench` the station uses.
It is a facade: it checks the calls (the base class's rules), and the subjects of a session
are parts of their own, each with its state, composed here around one lock (the wrench's
``_cond``):

- ``channel.py``: the link, one command in flight ("acknowledged or reported failed": a
  command returns only on its 0005, a 0004 is a RefusedError, any other failure resets the
  link), the link's epoch, and what is read routed to its subject; ``linklevel.py``: the
  link-level acknowledgement (9997/9998) under it;
- ``session.py``: a session's start (0001, 0060, the curves, the clock) at the highest
  revisions the controller accepts; ``supervisor.py``: the thread that reads the link, sends
  what is owed, keeps it alive (9999) and closes it when it fails, until ``reconnect()``;
- ``resultfeed.py``: results pushed (0061), queued and acknowledged (0062) once stored;
  ``renewal.py``: the subscription renewed at the revision the controller really sends;
  ``oldresults.py``: results fetched after the fact (0064 -> 0065);
- ``curvefeed.py``: tightening curves (0008 -> 0900), queued apart; ``replay.py``: an
  earlier tightening's curves; ``dataacks.py``: the 0005s owed for subscribed data;
  ``unasked.py``: the 0901/0902 that come unasked;
- ``commands.py``: pset selection, the tool, the VIN as messages; ``options.py``: the URL.

Threads: the supervisor thread owns the link's reading side; commands run in the caller's
thread, one at a time, and wait for their answer (read by the supervisor).
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from drivers.endpoint import Endpoint
from drivers.errors import ConnectionLostError, DeviceError, ProtocolError
from drivers.identity import DeviceIdentity
from drivers.link import Link, TcpLink
from drivers.url import DeviceUrl, parse_url
from drivers.wrench.base import Received, SupervisedWrench, check_positive
from drivers.wrench.openprotocol import commands
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.channel import Channel
from drivers.wrench.openprotocol.curve import MID_DATA_UNSUBSCRIBE, Curve, unsubscribe_data
from drivers.wrench.openprotocol.curvefeed import CurveFeed
from drivers.wrench.openprotocol.dataacks import DataAcks
from drivers.wrench.openprotocol.identity import ControllerIdentity
from drivers.wrench.openprotocol.message import Message
from drivers.wrench.openprotocol.oldresults import OldResults
from drivers.wrench.openprotocol.options import (
    DEFAULT_PORT,
    REFUSED,
    link_endpoint,
    link_from_url,
)
from drivers.wrench.openprotocol.renewal import Renewal
from drivers.wrench.openprotocol.replay import CurveReplay
from drivers.wrench.openprotocol.resultfeed import ResultFeed
from drivers.wrench.openprotocol.session import Session
from drivers.wrench.openprotocol.supervisor import KeepAlive, Supervisor
from drivers.wrench.openprotocol.tracedata import ResultDbInfo
from drivers.wrench.openprotocol.unasked import UnaskedData

log = logging.getLogger(__name__)

MAX_TIGHTENING_ID = 9_999_999_999            # 10 digits
CURVE_QUEUE = 64       # curves held for the reader; past that the oldest is dropped (logged)


class OpenProtocolWrench(SupervisedWrench):
    """A tightening controller over Open Protocol (TCP or RS-232)."""

    def __init__(self, link: Link | None, *, device: str, timeout: float = 2.0,
                 connect_timeout: float = 5.0, keepalive: float = 10.0,
                 link_ack: str = "auto", curves: bool = False) -> None:
        super().__init__(device, timeout=timeout)
        check_positive(connect_timeout=connect_timeout, keepalive=keepalive)
        if link_ack not in ("auto", "on", "off"):
            raise ValueError(f"link_ack must be auto, on or off, not {link_ack!r}")
        self._given_link = link                 # the settings as given
        self._keepalive = keepalive
        self._link_ack_mode = link_ack
        # the parts, each keeping its own state under the one lock (``_cond``); each subject
        # asks the channel for the MIDs it reads as it is made
        self._channel = channel = Channel(
            link or TcpLink("127.0.0.1", DEFAULT_PORT, REFUSED), device=device, cond=self._cond,
            stop=self._stop, timeout=timeout, down=self._down, surface=self._surface,
            went_down=self._went_down, log=log)
        acks = DataAcks(channel)
        self._feed = feed = ResultFeed(channel, self._queue_result)
        self._old = old = OldResults(channel, feed)
        self._renewal = renewal = Renewal(channel, feed, old)
        self._curves = CurveFeed(channel, acks, wanted=curves, queue_size=CURVE_QUEUE)
        self._replay = CurveReplay(channel, self._curves)
        self._unasked = unasked = UnaskedData(channel, acks)
        alive = KeepAlive(channel, interval=keepalive)
        self._session = Session(channel, feed, old, self._curves,
                                connect_timeout=connect_timeout, link_ack=link_ack,
                                fresh=(feed.reset, self._curves.reset, acks.reset,
                                       unasked.reset, alive.reset))
        self._supervisor = Supervisor(channel, self._stop, feed=feed, acks=acks,
                                      renewal=renewal, keepalive=alive)

    @classmethod
    def _endpoint(cls, url: str) -> Endpoint:
        """The TCP host and port (4545 by default) or the serial line the URL names."""
        return link_endpoint(parse_url(url))

    @classmethod
    def from_url(cls, url: DeviceUrl, **kw: Any) -> OpenProtocolWrench:
        """``openprotocol://HOST[:PORT]`` or ``openprotocol+serial:///dev/ttyUSB1?baud=9600``;
        options (URL query or keywords): timeout, connect_timeout, keepalive (seconds),
        link_ack (auto, 1, 0), curves (1: subscribe to the tightening curves at every
        session start; 0 by default), and baud for serial."""
        link, opts = link_from_url(url, kw)
        try:
            return cls(link, device=url.text, **opts)
        except ValueError as e:
            raise url.error(str(e)) from None

    # -- what the controller said ------------------------------------------------------------
    @property
    def controller_identity(self) -> ControllerIdentity | None:
        """The controller's MID 0002 of the current (or last) session, typed; None before
        the first session."""
        with self._cond:
            return self._session.identity

    @property
    def revisions(self) -> dict[int, int]:
        """MID -> the revision agreed with the controller this session (0001, 0060, and 0064
        once ``fetch_result`` was used)."""
        with self._cond:
            agreed = {op.MID_START: self._session.revision,
                      op.MID_RESULT_SUBSCRIBE: self._feed.subscribed,
                      op.MID_OLD_RESULT_REQUEST: self._old.agreed}
        return {mid: rev for mid, rev in agreed.items() if rev is not None}

    @property
    def result_db_info(self) -> ResultDbInfo | None:
        """The last MID 0902 the controller sent of its own accord (never asked for)."""
        with self._cond:
            return self._unasked.db_info

    @property
    def link_level(self) -> bool:
        """Whether this session acknowledges at link level (MID 9997/9998)."""
        with self._cond:
            return self._channel.links.on

    @property
    def clock_offset_s(self) -> float | None:
        """The controller's clock minus the station's in seconds, measured at the start of
        the current (or last) session (MID 0080/0081); None when it did not say."""
        with self._cond:
            return self._session.clock_offset

    def check_clock(self) -> float | None:
        """MID 0080 again on the live session (:meth:`Session.check_clock`): the offset now.
        A link down: the last measure, nothing asked."""
        self._check_open()
        return self._channel.request(
            "read the controller's clock", self._session.check_clock,
            when_down=lambda: self.clock_offset_s)

    @property
    def _link(self) -> Link:
        """The link in use (the given one, or the one ``_make_link`` made at open)."""
        return self._channel.link

    # -- lifecycle -------------------------------------------------------------------------
    def _make_link(self) -> Link:
        """The link to use; the simulated backend overrides this to start its server first."""
        if self._given_link is None:
            raise DeviceError("no link to the controller", device=self.device)
        return self._given_link

    def _open(self) -> None:
        self._channel.link = self._make_link()
        try:
            with self._channel.reading():
                self._session.start()
        except DeviceError as e:
            raise self._surface(e, "open") from None
        with self._cond:
            self._channel.connected = True
        self._thread = threading.Thread(target=self._supervisor.run, daemon=True,
                                        name=f"wrench-link {self.device}")
        self._thread.start()

    def _close(self) -> None:
        channel = self._channel
        with self._cond:
            curves = self._curves.on
        if curves:   # the subscription stopped first (0009 -> 0005); best effort, briefly
            try:
                channel.command(Message(MID_DATA_UNSUBSCRIBE, data=unsubscribe_data()),
                                "stop the curves", min(self.timeout, 0.5))
            except DeviceError:
                pass
        with self._cond:
            channel.stopping = True
        try:    # orderly communication stop (0003 -> 0005); best effort, briefly
            channel.command(Message(op.MID_STOP), "communication stop", min(self.timeout, 0.5))
        except DeviceError:
            pass
        self._stop.set()
        channel.fail(DeviceError("closed"), closing=True)
        if self._thread is not None:
            self._thread.join()
        self._renewal.join()
        with channel.write_lock:
            channel.link.close()

    def _reconnect(self) -> None:
        """Drop the link if it is up, then connect and start a session (0001, 0060)."""
        self._channel.fail(ConnectionLostError("reconnect asked for"))
        with self._channel.reading():
            self._attempt(self._session.start)
            with self._cond:
                self._channel.connected = True
                self._link_restored()

    def _went_down(self, reason: str | None, closing: bool) -> None:
        """The channel reset the link (``_cond`` held): the counts, and whether closing."""
        self._closing = self._closing or closing
        if reason is not None:
            self._link_lost(reason)

    # -- tightening curves (MID 0008 -> 0900) ----------------------------------------------
    can_curves = True

    @property
    def curves_on(self) -> bool:
        """Whether this session is subscribed to the tightening curves."""
        with self._cond:
            return self._curves.on

    @property
    def curves_reason(self) -> str | None:
        """Why curves are off (not asked for, refused by the controller, ...); None when
        they are on, or asked for and waiting for the link."""
        with self._cond:
            return self._curves.reason

    def subscribe_curves(self, timeout: float | None = None) -> bool:
        """Ask for the angle and torque traces of every tightening from now on (MID 0008
        for MID 0900), on this session and every later one: True when subscribed; False,
        with ``curves_reason``, when the controller gives none (MID 0004 error 78, 99, ...)
        or the link is serial.  Other failures raise as commands do (a timeout resets the
        link, and curves stay off: a controller that hangs on it is not asked again)."""
        self._check_open()
        self._curves.want()
        return self._channel.request(               # a link down: asked at the next session
            "subscribe to curves",
            lambda epoch: self._curves.subscribe(epoch, self._timeout(timeout)),
            when_down=lambda: False)

    def unsubscribe_curves(self, timeout: float | None = None) -> None:
        """Stop the curves (MID 0009), on this session and later ones."""
        self._check_open()
        with self._cond:
            on = self._curves.on
        self._curves.off("unsubscribed")
        if on:
            self._channel.command(Message(MID_DATA_UNSUBSCRIBE, data=unsubscribe_data()),
                                  "stop the curves", self._timeout(timeout))

    def wait_curve(self, timeout: float) -> Curve | None:
        """The next tightening curve received (oldest first), or None if none came within
        ``timeout`` seconds.  Never raises for a link that is down (curves received before
        are still handed out; the results' wait reports the link); raises DeviceError once
        closed."""
        if timeout < 0:
            raise ValueError("timeout must be >= 0")
        self._check_open()
        return self._curves.next(timeout, lambda: self._closing)

    def fetch_curve(self, tightening_id: int, timeout: float | None = None) -> list[Curve]:
        """The angle and torque curves of an earlier tightening (a result fetched after a
        link cut), one per trace type (``replay.py``).  A live curve subscription is stopped
        for it and made again after.  Empty, logged, when the controller refuses or its
        traces do not come within ``timeout``, and over RS-232; the curves are not queued
        for ``wait_curve``.  Other failures raise as commands do (a timeout or a lost link
        resets the link)."""
        check_tightening_id(tightening_id, 1)
        self._check_open()
        return self._replay.fetch(tightening_id, self._timeout(timeout))

    # -- old results (MID 0064 -> 0065) ----------------------------------------------------
    can_fetch = True

    def fetch_result(self, tightening_id: int, timeout: float | None = None
                     ) -> Received | None:
        """The controller's stored result ``tightening_id`` (0: its newest), or None if it
        answers "tightening id not found" (it no longer has it, or has none yet).

        For filling a gap in the tightening ids after a reconnect.  The result is not
        queued and needs no acknowledgement; it says ``fetched=True``.  A MID 0065 is read
        as a pushed result is (``oldresults.py``): laid out as a lower revision, it is read
        so and later fetches ask for that revision (one without a result type is held as
        unreadable, twice before that); one that reads at no revision comes
        back as an :class:`UnreadableResult` (fetched, its raw text kept), not as an error.
        Raises as commands do: RefusedError for another refusal, a ProtocolError for an
        answer about another tightening, and a timeout or lost link resets the link.
        """
        check_tightening_id(tightening_id, 0)
        self._check_open()
        timeout = self._timeout(timeout)
        what = f"fetch tightening {tightening_id or '(newest)'}"
        return self._channel.request(
            what, lambda epoch: self._old.fetch(tightening_id, timeout, epoch, what),
            passes=(ProtocolError,))

    # -- the Wrench hooks ------------------------------------------------------------------
    def _link_up(self) -> bool:
        return self._channel.connected

    def _identification(self) -> DeviceIdentity:
        """From the session's MID 0002 (mapping: ``ControllerIdentity.device_identity``);
        empty words before the first session."""
        with self._cond:
            ident = self._session.identity
            return ident.device_identity() if ident is not None else DeviceIdentity("")

    def _send_ack(self, token: int, timeout: float) -> None:
        self._feed.acknowledge(token, timeout)

    def _select_pset(self, pset: int, timeout: float) -> None:
        self._channel.command(*commands.select_pset(pset), timeout)

    def _set_tool(self, enabled: bool, timeout: float) -> None:
        self._channel.command(*commands.set_tool(enabled), timeout)

    def _send_vin(self, vin: str, timeout: float) -> None:
        """MID 0050, whose silence is a refusal (``Channel.ask``: the VIN only labels the
        controller's results; a trial's peer answered it with MID 0052 and never 0005, the
        link reset for it at every reconnect and the vehicle never worked)."""
        msg, what = commands.send_vin(vin)
        channel = self._channel
        channel.request(what, lambda epoch: channel.ask(
            msg, {op.MID_ACCEPTED, op.MID_ERROR}, timeout, epoch))


def check_tightening_id(tightening_id: int, lowest: int) -> None:
    """ValueError unless ``tightening_id`` is an integer ``lowest``-9999999999."""
    if isinstance(tightening_id, bool) or not isinstance(tightening_id, int) \
            or not lowest <= tightening_id <= MAX_TIGHTENING_ID:
        raise ValueError(f"tightening_id must be an integer {lowest}-{MAX_TIGHTENING_ID}, "
                         f"not {tightening_id!r}")
