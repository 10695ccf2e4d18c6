"""The Open Protocol backend: ``openprotocol://HOST[:4545]``, ``openprotocol+serial:///dev/tty..``.

Threads: one supervisor thread per wrench owns the link's reading side.  It dispatches answers
to the one command in flight, queues every MID 0061 result and acknowledges it with 0062,
sends the keep-alive (9999) after ``keepalive`` seconds without traffic, and when the link
fails it closes it and waits: ``reconnect()`` (0001, then 0060) brings it back, one attempt
at a time (the station's keeper retries with backoff).  Commands run in the caller's thread,
one at a time, and wait for their answer.

"Acknowledged or reported failed": a command returns only on its 0005.  A 0004 is a
RefusedError with the controller's code.  Any other failure (timeout, lost link, garbage)
raises and also resets the link: the controller's state is then unknown, and a late answer
must never be taken as the answer to the next command.  Sends carry the link's epoch, so a
command can never leak onto a reconnected link before its session started.

Revisions: the session asks for the highest revision of 0001 (6) and 0060 (7: results come
as MID 0061 revision 7) this driver reads, and one lower each time the controller answers
MID 0004 "revision unsupported" (97, 76 or 74), as integrators' clients do; ``revisions``
says what was agreed.  ``fetch_result`` asks for an old result (MID 0064 -> 0065) the same
way.  A result is read by its own header's revision (``reading.py``): one laid out as a
lower revision is read so, said once, and the subscription renewed at that revision; one
that reads at no revision is queued as an ``UnreadableResult``, acknowledged (0062) like a
result once the station has stored it.  Each session start also asks the controller's clock
(MID 0080 -> 0081: ``clock_offset_s``).  Link-level acknowledgement (``link.py``) is on
when the controller's 0002 says it supports it (or the URL says ``link_ack=1``).

Tightening curves (``curve.py``), optional: ``subscribe_curves()`` (or ``curves=1`` in the
URL) asks for the angle and torque traces with the generic subscription (MID 0008 for MID
0900), again at every session start; a controller that refuses it (MID 0004 "unknown MID",
"subscription on specific data not supported", ...) leaves curves off (``curves_on``,
``curves_reason``) and nothing else changes.  A curve is read on the same link as the results
but queued apart (``wait_curve``): it never delays a result.  Each MID 0900 is acknowledged
with MID 0005 naming it (the generic acknowledgement of subscribed data) unless its header's
no-ack flag is set, sent by the supervisor without waiting for anyone; ``close()`` stops the
subscription (MID 0009) before the communication stop.  Curves are binary, so they are asked
for over TCP only.  A curve longer than one message comes in parts (``parts.py``): put
together before it is read, and acknowledged once, after its last part.  ``fetch_curve``
asks for an earlier tightening's traces (MID 0008, send alternative 3).  MID 0901 (plot
parameters) and 0902 (the result database's extent) are not asked for; one that comes anyway
is read (``tracedata.py``), acknowledged and logged, never used (that module says why).
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from drivers.errors import (
    ConnectionLostError,
    DeviceError,
    DeviceTimeoutError,
    ProtocolError,
    RefusedError,
)
from drivers.link import Link, SerialLink, TcpLink
from drivers.url import DeviceUrl, OptionError
from drivers.wrench.base import (
    Received,
    SupervisedWrench,
    UnreadableResult,
    check_positive,
)
from drivers.wrench.openprotocol import link as op_link
from drivers.wrench.openprotocol import message as op
from drivers.wrench.openprotocol.curve import (
    CURVE_REFUSALS,
    MID_DATA_SUBSCRIBE,
    MID_DATA_UNSUBSCRIBE,
    MID_TRACE,
    STATION_TRACES,
    Curve,
    parse_curve_data,
    replay_data,
    subscribe_data,
    unsubscribe_data,
)
from drivers.wrench.openprotocol.identity import ControllerIdentity, parse_identity
from drivers.wrench.openprotocol.message import Message, SerialFramer, TcpFramer
from drivers.wrench.openprotocol.parts import BrokenParts, PartAssembler
from drivers.wrench.openprotocol.reading import receive
from drivers.wrench.openprotocol.tracedata import (
    MID_DB_INFO,
    MID_PLOT,
    ResultDbInfo,
    parse_db_info,
    parse_plot,
)

log = logging.getLogger(__name__)

POLL = 0.05            # the supervisor's read granularity: bounds reaction to close() and resets
DEFAULT_PORT = 4545
REFUSED = "controller off, or Open Protocol not enabled on this port?"
VIN_LENGTH = 25        # MID 0050 revision 1 carries a 25-character VIN
#: revisions asked for, highest first (0001: 6, whose 0002 says whether the controller does
#: link-level acknowledgement; 0061/0065: 1-7, all that ``op_result`` reads)
START_REVISIONS = (6, 5, 4, 3, 2, 1)
RESULT_REVISIONS = (7, 6, 5, 4, 3, 2, 1)
MAX_TIGHTENING_ID = 9_999_999_999            # 10 digits
CATCH_UP = 10          # results fetched after a renewal of the subscription, at most
TYPED_REVISION = 3     # MID 0061 carries the result type (parameter 49) from this revision on
NO_ACK = -1            # the acknowledgement token of a fetched result: no 0062 to send
CLOCK_TIMEOUT = 1.0    # the most MID 0080 (the controller's clock) is waited for at connect
CURVE_QUEUE = 64       # curves held for the reader; past that the oldest is dropped (logged)
#: subscribed data acknowledged with MID 0005 naming its MID (the generic acknowledgement)
DATA_MIDS = frozenset({MID_TRACE, MID_PLOT, MID_DB_INFO})
Spec = dict[str, tuple[Callable[[str], Any], Any]]   # option -> (converter, default)


def link_ack_option(text: str) -> str:
    """``link_ack``: auto (as the controller's 0002 says), 1/on (always), 0/off (never)."""
    value = {"auto": "auto", "1": "on", "on": "on", "true": "on", "yes": "on", "0": "off",
             "off": "off", "false": "off", "no": "off"}.get(text.strip().lower())
    if value is None:
        raise OptionError("expected auto, 1 or 0")
    return value


def flag_option(text: str) -> bool:
    """A yes/no option: 1, on, true, yes or 0, off, false, no."""
    value = {"1": True, "on": True, "true": True, "yes": True, "0": False, "off": False,
             "false": False, "no": False}.get(text.strip().lower())
    if value is None:
        raise OptionError("expected 1 or 0")
    return value


OPTIONS: Spec = {
    "timeout": (float, 2.0), "connect_timeout": (float, 5.0), "keepalive": (float, 10.0),
    "link_ack": (link_ack_option, "auto"), "curves": (flag_option, False),
}


@dataclass
class _Pending:
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


@dataclass
class _CurveFetch:
    """The curves of one earlier tightening being asked for (``fetch_curve``)."""

    tightening_id: int
    wanted: int
    curves: list[Curve] = field(default_factory=list)
    done: threading.Event = field(default_factory=threading.Event)


@dataclass
class _LinkWait:
    """The one sequenced message awaiting its link-level acknowledgement (9997/9998)."""

    seq: int
    done: threading.Event = field(default_factory=threading.Event)
    error_code: int | None = None           # a 9998's code
    lost: DeviceError | None = None         # the link went down meanwhile


class OpenProtocolWrench(SupervisedWrench):
    """A tightening controller over Open Protocol (TCP or RS-232)."""

    def __init__(self, link: Link | None, *, device: str, timeout: float = 2.0,
                 connect_timeout: float = 5.0, keepalive: float = 10.0,
                 link_ack: str = "auto", curves: bool = False) -> None:
        super().__init__(device, timeout=timeout)
        check_positive(connect_timeout=connect_timeout, keepalive=keepalive)
        if link_ack not in ("auto", "on", "off"):
            raise ValueError(f"link_ack must be auto, on or off, not {link_ack!r}")
        self._given_link = link
        self._link: Link = link or TcpLink("127.0.0.1", DEFAULT_PORT, REFUSED)
        self._connect_timeout = connect_timeout
        self._keepalive = keepalive
        self._framer: TcpFramer | SerialFramer = TcpFramer()
        self._write_lock = threading.Lock()     # one message on the wire at a time
        self._tx_lock = threading.Lock()        # one sequenced message outstanding (link level)
        self._request_lock = threading.Lock()   # one command in flight
        self._reader = threading.Lock()         # the link's reading side: supervisor or session
        self._reader_owner: threading.Thread | None = None
        self._connected = False                 # these guarded by _cond too
        self._epoch = 0
        self._pending: _Pending | None = None
        self._link_wait: _LinkWait | None = None
        self._link_ack_mode = link_ack
        self._linking = False                   # link-level acknowledgement on this session
        self._tx_seq = 0
        self._rx = op_link.RxSequence()         # the reading thread's only
        # results read at a lower revision than their header's (op_reading): the highest
        # revision results are subscribed at from then on in this session (renewed by the
        # supervisor); every new session asks for the highest again (the controller on the
        # other end may be another one, or updated: a revision below 3 carries no result
        # type, and a batch increment then reads as a tightening), and what was said once
        self._result_cap = RESULT_REVISIONS[0]
        self._renew_at: int | None = None       # a renewal owed (guarded by _cond)
        self._renewer: threading.Thread | None = None   # the thread doing it
        # the newest tightening id pushed on this link, and those fetched by the renewal's
        # catch-up (a push of one of them is acknowledged at once, not handed out twice)
        self._last_pushed: int | None = None
        self._caught_up: set[int] = set()
        self._owed_acks = 0                     # 0062s for those pushes, sent by the supervisor
        self._lowered_said: set[tuple[int, int, int]] = set()   # (MID, header, read at)
        self._ident: ControllerIdentity | None = None
        self._clock_offset: float | None = None   # MID 0081 minus the station's clock
        self._revisions: dict[int, int] = {}
        self._last_sent = 0.0
        self._keepalive_sent: float | None = None
        # curves (guarded by _cond): asked for, subscribed this session, why not
        self._curves_wanted = curves
        self._curves_on = False
        self._curves_reason: str | None = "not asked for" if not curves else None
        self._curves: deque[Curve] = deque()
        self._curves_dropped = 0
        self._owed_data_acks: deque[int] = deque()   # MID 0005 "0900" ... to send (supervisor)
        self._curve_fetch: _CurveFetch | None = None  # curves asked for after the fact
        # the communication stop is being sent (closing): subscribed data that arrives after
        # it (curves in flight) is no longer acknowledged: the session is ending, and a 0005
        # after the 0003 reaches a controller that has stopped listening to this session
        self._stopping = False
        self._parts = PartAssembler()           # the reading thread's only
        self._db_info: ResultDbInfo | None = None
        self._data_seen: set[int] = set()       # 0901/0902 logged once per session

    @classmethod
    def from_url(cls, url: DeviceUrl, **kw: Any) -> OpenProtocolWrench:
        """``openprotocol://HOST[:PORT]`` or ``openprotocol+serial:///dev/ttyUSB1?baud=9600``;
        options (URL query or keywords): timeout, connect_timeout, keepalive (seconds),
        link_ack (auto, 1, 0), curves (1: subscribe to the tightening curves at every
        session start; 0 by default), and baud for serial."""
        link: Link
        if url.scheme == "openprotocol+serial":
            spec: Spec = {**OPTIONS, "baud": (int, 9600)}
            opts = url.typed_options(spec, "openprotocol+serial:///dev/ttyUSB1?baud=9600")
            if url.host or not url.path:
                raise url.error("expected a device path: openprotocol+serial:///dev/ttyUSB1")
            opts.update(keyword_options(kw, spec))
            link = SerialLink(url.path, opts.pop("baud"))
        else:
            opts = url.typed_options(OPTIONS, "openprotocol://192.168.10.30:4545?timeout=2")
            if not url.host or url.path not in ("", "/"):
                raise url.error("expected openprotocol://HOST[:PORT] (port 4545 by default)")
            opts.update(keyword_options(kw, OPTIONS))
            link = TcpLink(url.host, url.port or DEFAULT_PORT, REFUSED)
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
            return self._ident

    @property
    def revisions(self) -> dict[int, int]:
        """MID -> the revision agreed with the controller this session (0001, 0060, and 0064
        once ``fetch_result`` was used)."""
        with self._cond:
            return dict(self._revisions)

    @property
    def result_db_info(self) -> ResultDbInfo | None:
        """The last MID 0902 the controller sent of its own accord (never asked for)."""
        with self._cond:
            return self._db_info

    @property
    def link_level(self) -> bool:
        """Whether this session acknowledges at link level (MID 9997/9998)."""
        with self._cond:
            return self._linking

    # -- lifecycle -------------------------------------------------------------------------
    def _make_link(self) -> Link:
        """The link to use; the simulated backend overrides this to start its server first."""
        if self._given_link is None:
            raise DeviceError("no link to the controller", device=self.device)
        return self._given_link

    def _open(self) -> None:
        self._link = self._make_link()
        try:
            with self._reading():
                self._start_session()
        except DeviceError as e:
            raise self._surface(e, "open") from None
        with self._cond:
            self._connected = True
        self._thread = threading.Thread(target=self._supervise, daemon=True,
                                        name=f"wrench-link {self.device}")
        self._thread.start()

    def _close(self) -> None:
        with self._cond:
            curves = self._curves_on
        if curves:   # the subscription stopped first (0009 -> 0005); best effort, briefly
            try:
                self._command(Message(MID_DATA_UNSUBSCRIBE, data=unsubscribe_data()),
                              "stop the curves", min(self.timeout, 0.5))
            except DeviceError:
                pass
        with self._cond:
            self._stopping = True
        try:    # orderly communication stop (0003 -> 0005); best effort, briefly
            self._command(Message(op.MID_STOP), "communication stop", min(self.timeout, 0.5))
        except DeviceError:
            pass
        self._stop.set()
        self._fail_link(DeviceError("closed"), closing=True)
        if self._thread is not None:
            self._thread.join()
        if self._renewer is not None:      # its command failed with the link: it ends
            self._renewer.join()
        with self._write_lock:
            self._link.close()

    @contextmanager
    def _reading(self) -> Iterator[None]:
        """Hold the link's reading side; a sequenced send from this thread then reads its
        own link-level acknowledgement instead of waiting for the supervisor."""
        with self._reader:
            self._reader_owner = threading.current_thread()
            try:
                yield
            finally:
                self._reader_owner = None

    def _start_session(self) -> None:
        """Connect, communication start (0001 -> 0002), result subscription (0060 -> 0005),
        each at the highest revision the controller accepts (called holding ``_reading``)."""
        link = self._link
        link.connect(self._connect_timeout)
        self._framer = SerialFramer() if link.kind == "serial" else TcpFramer()
        self._last_sent, self._keepalive_sent = time.monotonic(), None
        with self._cond:      # 0001/0002 reset the link level: decided anew below
            self._linking, self._tx_seq, self._renew_at = False, 0, None
            self._last_pushed, self._owed_acks = None, 0
            self._caught_up.clear()
            self._result_cap = cap = RESULT_REVISIONS[0]
            self._curves_on = False
            self._owed_data_acks.clear()
        self._rx.reset()
        self._parts.reset()
        self._data_seen.clear()
        revisions: dict[int, int] = {}
        try:
            reply, revisions[op.MID_START] = self._negotiate(
                op.MID_START, START_REVISIONS, {op.MID_START_ACK, op.MID_ERROR})
            ident = parse_identity(reply.revision, reply.data)
            linking = self._link_ack_mode == "on" or (
                self._link_ack_mode == "auto" and ident.sequence_number_support is True)
            with self._cond:
                self._linking = linking
            try:
                _, revisions[op.MID_RESULT_SUBSCRIBE] = self._negotiate(
                    op.MID_RESULT_SUBSCRIBE, [r for r in RESULT_REVISIONS if r <= cap],
                    {op.MID_ACCEPTED, op.MID_ERROR})
            except RefusedError as e:
                if e.code != 9:                 # 09: already subscribed, which is the goal
                    raise
            with self._cond:
                curves = self._curves_wanted
            if curves:
                try:
                    self._curves_session(None)
                except DeviceTimeoutError:
                    pass        # curves off (logged); the session goes on without them
            offset = self._read_clock()
        except DeviceError as e:
            link.close()
            what = "communication start" if self._ident is None else "session restart"
            raise type(e)(f"{what}: {e}", code=e.code) from None
        except BaseException:
            link.close()
            raise
        with self._cond:
            new = self._ident != ident
            self._ident, self._revisions = ident, revisions
            self._clock_offset = offset
        rev = revisions.get(op.MID_RESULT_SUBSCRIBE)
        if new:
            log.info("%s: controller %s; MID 0002 revision %d, results as MID 0061 revision "
                     "%s, link-level acknowledgement %s", self.device, ident.describe(),
                     ident.revision, "?" if rev is None else rev, "on" if linking else "off")
        if rev is not None and rev < TYPED_REVISION:
            log.warning("%s: results subscribed at MID 0061 revision %d, which carries no "
                        "result type: a batch increment or a bypass at the controller reads "
                        "as a tightening", self.device, rev)

    def _read_clock(self) -> float | None:
        """The controller's clock minus the station's (MID 0080 -> 0081, in the
        specification since revision 1), measured at the answer, to within a second (the
        controller says whole seconds); None, logged, when it refuses or does not answer in
        ``CLOCK_TIMEOUT``: never a reason to fail the session (called holding the reading
        side, in the session start).  A late 0081 is then an unexpected MID, ignored."""
        try:
            reply = self._transact(Message(op.MID_TIME_REQUEST), {op.MID_TIME, op.MID_ERROR},
                                   min(self.timeout, CLOCK_TIMEOUT))
            offset = (op.controller_time(reply) - datetime.now()).total_seconds()
        except (RefusedError, DeviceTimeoutError, ProtocolError) as e:
            log.info("%s: the controller's clock is not known (MID 0080: %s): results "
                     "fetched late are placed by their tightening ids only", self.device, e)
            return None
        if round(offset) == 0:
            log.info("%s: controller clock agrees with the station's (within 1 s)",
                     self.device)
        else:
            log.info("%s: controller clock %+.0f s from the station's", self.device, offset)
        return offset

    @property
    def clock_offset_s(self) -> float | None:
        """The controller's clock minus the station's in seconds, measured at the start of
        the current (or last) session (MID 0080/0081); None when it did not say."""
        with self._cond:
            return self._clock_offset

    def _curves_session(self, epoch: int | None, timeout: float | None = None) -> bool:
        """MID 0008 for the angle and torque traces on this session: whether curves are on.
        A refusal that says the controller gives none turns them off, for good; no answer
        too (a controller that hangs on it must not be asked at every reconnect), and the
        timeout is raised: the link is then in an unknown state."""
        if self._link.kind == "serial":
            self._curves_off("curves are binary messages: asked for over TCP only")
            return False
        try:
            self._transact(Message(MID_DATA_SUBSCRIBE, data=subscribe_data()),
                           {op.MID_ACCEPTED, op.MID_ERROR}, timeout or self.timeout, epoch)
        except RefusedError as e:
            if e.code in CURVE_REFUSALS:
                self._curves_off(f"the controller gives none (MID 0008 refused: "
                                 f"{op.refusal_text(e.code or 0)})")
                return False
            if e.code != 71:                    # 71: subscription already exists
                raise
        except DeviceTimeoutError as e:
            self._curves_off(f"no answer to the curves' subscription (MID 0008): {e}")
            raise
        with self._cond:
            new = self._curves_reason is not None or not self._curves_on
            self._curves_on, self._curves_reason = True, None
        if new:
            log.info("%s: tightening curves subscribed (MID 0008 for MID 0900: angle and "
                     "torque traces)", self.device)
        return True

    def _curves_off(self, why: str) -> None:
        with self._cond:
            was = self._curves_reason
            self._curves_wanted = self._curves_on = False
            self._curves_reason = why
        if was != why:
            log.info("%s: no tightening curves: %s", self.device, why)

    def _negotiate(self, mid: int, revisions: Sequence[int], expect: set[int]
                   ) -> tuple[Message, int]:
        """Send ``mid`` at each of ``revisions`` until one is not refused as unsupported:
        (the answer, the revision asked)."""
        for rev in revisions:
            try:
                return self._transact(Message(mid, revision=rev), expect, self.timeout), rev
            except RefusedError as e:
                if e.code not in op.REVISION_REFUSALS or rev == revisions[-1]:
                    raise
                log.info("%s: MID %04d revision %d refused (%s), asking for %d", self.device,
                         mid, rev, op.refusal_text(e.code or 0), rev - 1)
        raise AssertionError("unreachable: the last revision's refusal is raised")

    # -- the supervisor thread -------------------------------------------------------------
    def _supervise(self) -> None:
        """Read while the link is up; when it is down, close it and wait for
        ``reconnect()`` (which holds the reading side while it starts a session)."""
        while not self._stop.is_set():
            with self._reading():
                with self._cond:
                    up = self._connected
                if up:
                    try:
                        self._read_once()
                        self._flush_owed()
                        self._renew_subscription()
                        self._keepalive_tick()
                    except DeviceError as e:
                        self._fail_link(e)
                    continue
                with self._write_lock:
                    self._link.close()
            self._stop.wait(POLL)

    def _reconnect(self) -> None:
        """Drop the link if it is up, then connect and start a session (0001, 0060)."""
        self._fail_link(ConnectionLostError("reconnect asked for"))
        with self._reading():
            self._attempt(self._start_session)
            with self._cond:
                self._connected = True
                self._link_restored()

    def _read_once(self) -> None:
        """Read for up to POLL seconds and dispatch every complete message."""
        try:
            data = self._link.recv(POLL)
        except ConnectionLostError as e:
            if self._framer.pending:
                raise ConnectionLostError(f"{e} in the middle of a message ("
                                          f"{self._framer.pending} bytes of it received)") \
                    from None
            raise
        for item in self._framer.feed(data) if data else ():
            if isinstance(item, ProtocolError):
                raise item
            self._dispatch(item)

    def _dispatch(self, msg: Message) -> None:
        if msg.mid in (op.MID_LINK_ACK, op.MID_LINK_ERROR):
            self._link_answer(msg)
            return
        with self._cond:
            linking = self._linking
        if linking and op_link.is_sequenced(msg.mid):
            self._write(op_link.link_ack(msg))       # before anything: the controller waits
            if not self._rx.is_new(msg.sequence):
                log.warning("%s: MID %04d repeated (sequence %s): acknowledged again, not "
                            "processed twice", self.device, msg.mid, msg.sequence)
                return
        for item in self._parts.feed(msg):      # a message in parts: once it is whole
            if isinstance(item, BrokenParts):
                self._broken_parts(item)
            else:
                self._handle(item)

    def _broken_parts(self, broken: BrokenParts) -> None:
        """A message in parts that did not add up: lost, logged; subscribed data is still
        acknowledged (the controller keeps its own record, and waits for the 0005)."""
        log.warning("%s: MID %04d in parts given up: %s", self.device, broken.mid,
                    broken.reason)
        if broken.mid in DATA_MIDS and not broken.no_ack:
            with self._cond:
                self._owed_data_acks.append(broken.mid)

    def _handle(self, msg: Message) -> None:
        """One whole message (its link-level work done)."""
        if msg.mid == op.MID_RESULT:
            self._result_in(msg)
            return
        if msg.mid == op.MID_KEEPALIVE:
            self._keepalive_sent = None
            return
        if msg.mid == MID_TRACE:
            self._curve_in(msg)
            return
        if msg.mid in (MID_PLOT, MID_DB_INFO):
            self._trace_data_in(msg)
            return
        with self._cond:
            slot = self._pending
            if slot is not None and slot.matches(msg):
                slot.reply, self._pending = msg, None
                slot.done.set()
                return
        log.warning("%s: unexpected MID %04d ignored (data %r)", self.device, msg.mid,
                    msg.data[:40])

    def _result_in(self, msg: Message) -> None:
        """A MID 0061: queued, read or not (``op_reading``), and acknowledged (0062) only
        when the station has it, on this same link: an unreadable one is stored with its
        raw text before the controller may forget it.  One read at a lower revision than
        the one subscribed has its subscription renewed at that revision (by the
        supervisor: never from here, which may be the thread that has to read the
        answers)."""
        item = receive(msg)
        with self._cond:
            tid = item.tightening_id
            if tid is not None:
                if tid in self._caught_up:       # fetched while the subscription was renewed
                    self._caught_up.discard(tid)
                    self._owed_acks += 1         # the station has it: acknowledged, not
                    return                       # handed out again
                self._last_pushed = max(tid, self._last_pushed or 0)
            subscribed = self._revisions.get(op.MID_RESULT_SUBSCRIBE)
            if isinstance(item, UnreadableResult):
                log.warning("%s: MID 0061 revision %d does not read at any revision (%s); "
                            "kept with its raw text for the station (tightening id %s)",
                            self.device, msg.revision, item.error,
                            item.tightening_id if item.tightening_id is not None else "?")
            elif item.header_revision is not None:
                self._lowered(msg.mid, item.header_revision, item.revision)
                if subscribed is not None and item.revision < subscribed:
                    self._result_cap = min(self._result_cap, item.revision)
                    self._renew_at = self._result_cap
            self._queue_result(item, self._epoch)

    def _lowered(self, mid: int, header: int, read_at: int) -> None:
        """Say once (a wrench's life) that ``mid`` labelled ``header`` read as ``read_at``."""
        if (mid, header, read_at) in self._lowered_said:
            return
        self._lowered_said.add((mid, header, read_at))
        log.warning("%s: MID %04d labelled revision %d is laid out as revision %d (with fields "
                    "appended): read as revision %d%s", self.device, mid, header, read_at,
                    read_at, "; results are subscribed at that revision from now on"
                    if mid == op.MID_RESULT else "")

    def _renew_subscription(self) -> None:
        """The supervisor's turn: start the renewal owed (``_result_in``) in a thread of its
        own, one at a time.  Not on this thread, which reads the link: the renewal waits
        for the one command in flight to finish (a caller's, whose answer this thread must
        read) and, at link level, for the one numbered message outstanding (a caller's
        0062, whose 9997 this thread must read)."""
        with self._cond:
            rev, epoch = self._renew_at, self._epoch
            busy = self._renewer is not None and self._renewer.is_alive()
            if rev is None or busy or not self._connected or self._stopping:
                return
            self._renew_at = None
            self._renewer = threading.Thread(target=self._renew, args=(rev, epoch),
                                             daemon=True, name=f"wrench-renew {self.device}")
            self._renewer.start()

    def _renew(self, rev: int, epoch: int) -> None:
        """Unsubscribe (0063) and subscribe (0060) at revision ``rev`` or lower, as a command
        (the supervisor dispatches the answers), so the next results read cleanly.  A result
        the controller makes between the two is not pushed (fetch it by its tightening id,
        MID 0064).  A failure resets the link; the next session asks for ``rev`` at most."""
        expect = {op.MID_ACCEPTED, op.MID_ERROR}
        agreed: int | None = None
        with self._request_lock:
            try:
                try:
                    self._transact(Message(op.MID_RESULT_UNSUBSCRIBE), expect, self.timeout,
                                   epoch)
                except RefusedError as e:
                    if e.code != 10:            # 10: no subscription, which is the goal
                        raise
                with self._cond:                # nothing is pushed after the 0063's answer
                    before = self._last_pushed
                for r in [r for r in RESULT_REVISIONS if r <= rev]:
                    try:
                        self._transact(Message(op.MID_RESULT_SUBSCRIBE, revision=r), expect,
                                       self.timeout, epoch)
                    except RefusedError as e:
                        if e.code not in op.REVISION_REFUSALS or r == 1:
                            raise
                        continue
                    agreed = r
                    break
                if before is not None:
                    self._catch_up(before, epoch)
            except DeviceError as e:
                self._fail_link(type(e)(f"renewing the result subscription at revision "
                                        f"{rev}: {e}", code=e.code), epoch)
                return
        if agreed is not None:
            with self._cond:
                if epoch == self._epoch:
                    self._revisions[op.MID_RESULT_SUBSCRIBE] = agreed
            log.info("%s: results subscribed again at MID 0061 revision %d", self.device,
                     agreed)

    def _catch_up(self, before: int, epoch: int) -> None:
        """The results made while the subscription was being renewed (after the 0063, before
        the 0060: never pushed), fetched by tightening id from ``before`` + 1 (MID 0064) and
        queued as fetched (nothing to acknowledge), up to ``CATCH_UP`` of them; it stops at
        the first the controller does not have, or that was pushed meanwhile (the ones after
        it are pushed too).  One fetched and then pushed as well (made just after the 0060)
        is acknowledged when pushed and not handed out twice.  Called holding the request
        lock, in the renewal's thread."""
        for tid in range(before + 1, before + 1 + CATCH_UP):
            with self._cond:
                if self._last_pushed is not None and tid <= self._last_pushed:
                    return
            result = self._fetch(tid, self.timeout, epoch, f"fetch tightening {tid}")
            if result is None:
                return
            with self._cond:
                if self._last_pushed is not None and tid <= self._last_pushed:
                    return                       # pushed while it was being fetched
                self._caught_up.add(tid)
                self._queue_result(result, NO_ACK)
            log.warning("%s: tightening %d made while the result subscription was renewed: "
                        "fetched (MID 0064)", self.device, tid)

    def _curve_in(self, msg: Message) -> None:
        """A MID 0900: queued apart from the results (bounded: the oldest goes), and its
        acknowledgement owed (sent by the supervisor, never from here)."""
        try:
            curve: Curve | None = parse_curve_data(msg.data)
        except ProtocolError as e:
            log.warning("%s: unreadable tightening curve, acknowledged anyway: %s",
                        self.device, e)
            curve = None
        with self._cond:
            fetch = self._curve_fetch
            if curve is not None and fetch is not None \
                    and curve.tightening_id == fetch.tightening_id:
                fetch.curves.append(curve)           # asked for: handed to fetch_curve
                if len(fetch.curves) >= fetch.wanted:
                    fetch.done.set()
            elif curve is not None:
                if len(self._curves) >= CURVE_QUEUE:
                    self._curves.popleft()
                    self._curves_dropped += 1
                    log.warning("%s: %d curve(s) dropped: nobody reads them", self.device,
                                self._curves_dropped)
                self._curves.append(curve)
            if not msg.no_ack:
                self._owed_data_acks.append(MID_TRACE)
            self._cond.notify_all()

    def _trace_data_in(self, msg: Message) -> None:
        """A MID 0901 or 0902 nobody asked for: read, logged (once a session at info),
        acknowledged (by the supervisor), not used."""
        try:
            what = (parse_plot(msg.revision, msg.data) if msg.mid == MID_PLOT
                    else parse_db_info(msg.revision, msg.data))
        except ProtocolError as e:
            log.warning("%s: unreadable MID %04d, acknowledged anyway: %s", self.device,
                        msg.mid, e)
        else:
            first = msg.mid not in self._data_seen
            self._data_seen.add(msg.mid)
            log.log(logging.INFO if first else logging.DEBUG, "%s: MID %04d received, "
                    "acknowledged, not used: %s", self.device, msg.mid, what.describe())
            if isinstance(what, ResultDbInfo):
                with self._cond:
                    self._db_info = what
        if not msg.no_ack:
            with self._cond:
                self._owed_data_acks.append(msg.mid)

    def _link_answer(self, msg: Message) -> None:
        """A 9997/9998 from the controller: it answers the outstanding sequenced message."""
        with self._cond:
            wait = self._link_wait
            if wait is not None and op_link.answers(msg.sequence, wait.seq):
                if msg.mid == op.MID_LINK_ERROR:
                    wait.error_code = op_link.link_error_code(msg)
                wait.done.set()
                return
        log.warning("%s: MID %04d expecting sequence %s next, which answers no outstanding "
                    "message, ignored", self.device, msg.mid, msg.sequence)

    def _flush_owed(self) -> None:
        """Send the 0062s owed for pushes of results already fetched, and the MID 0005s
        owed for subscribed data ("0900", ...) (supervisor only): never waiting for the
        one-outstanding slot, which a caller may hold while this thread reads its
        acknowledgement."""
        while True:
            with self._cond:
                if not self._owed_acks:
                    break
            if not self._send(Message(op.MID_RESULT_ACK), block=False):
                return
            with self._cond:
                self._owed_acks -= 1
        while True:
            with self._cond:
                if not self._owed_data_acks or self._stopping:
                    return
                mid = self._owed_data_acks[0]
            ack = Message(op.MID_ACCEPTED, data=f"{mid:04d}".encode())
            if not self._send(ack, block=False):
                return
            with self._cond:
                if self._owed_data_acks and self._owed_data_acks[0] == mid:
                    self._owed_data_acks.popleft()

    def _keepalive_tick(self) -> None:
        now = time.monotonic()
        if self._keepalive_sent is not None:
            if now - self._keepalive_sent > self.timeout:
                raise DeviceTimeoutError(f"keep-alive (MID 9999) not mirrored within "
                                         f"{self.timeout:g} s")
        elif now - self._last_sent >= self._keepalive:
            self._keepalive_sent = now
            self._send(Message(op.MID_KEEPALIVE))

    def _fail_link(self, err: DeviceError, epoch: int | None = None,
                   closing: bool = False) -> None:
        """Mark the link down (the supervisor then reconnects) and fail the command in flight."""
        with self._cond:
            if epoch is not None and epoch != self._epoch:
                return                                   # that link is already gone
            was_up = self._connected
            if was_up and not closing:   # logged before anyone can see the link down
                log.warning("%s: link lost: %s", self.device, err)
            self._connected = False
            self._closing = self._closing or closing
            self._epoch += 1
            if was_up:
                self._link_lost(str(err))
            if self._pending is not None:
                self._pending.error = err
                self._pending.done.set()
                self._pending = None
            if self._link_wait is not None:
                self._link_wait.lost = err
                self._link_wait.done.set()
            self._cond.notify_all()

    # -- sending and commands --------------------------------------------------------------
    def _write(self, msg: Message, epoch: int | None = None) -> None:
        """Put one message on the wire (nothing waited for)."""
        data = op.frame_serial(msg) if self._link.kind == "serial" else op.frame_tcp(msg)
        with self._write_lock:
            if epoch is not None:
                with self._cond:
                    if epoch != self._epoch:
                        raise ConnectionLostError("the link was reset before sending")
            self._link.send(data)
            self._last_sent = time.monotonic()

    def _send(self, msg: Message, epoch: int | None = None, block: bool = True,
              timeout: float | None = None) -> bool:
        """Send ``msg``; with link-level acknowledgement on, numbered and returning only
        once the controller acknowledged it (MID 9997), waiting ``timeout`` (the response
        timeout by default) for each try.  ``block=False``: False, nothing sent, if another
        sequenced message is outstanding."""
        with self._cond:
            linking = self._linking
        if not linking or not op_link.is_sequenced(msg.mid):
            self._write(msg, epoch)
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
            if epoch is not None and epoch != self._epoch:   # session counts from 1
                raise ConnectionLostError("the link was reset before sending")
            self._tx_seq = seq = op_link.next_seq(self._tx_seq)
        numbered = dataclasses.replace(msg, sequence=seq)
        why = ""
        for attempt in range(1 + op_link.RESENDS):
            if attempt:
                log.warning("%s: MID %04d sequence %d: %s; resending (%d of %d)", self.device,
                            msg.mid, seq, why, attempt, op_link.RESENDS)
            wait = _LinkWait(seq)
            with self._cond:
                self._link_wait = wait
            try:
                self._write(numbered, epoch)
                self._await_link(wait, timeout)
            finally:
                with self._cond:
                    if self._link_wait is wait:
                        self._link_wait = None
            if wait.lost is not None:
                raise wait.lost
            if wait.done.is_set() and wait.error_code is None:
                return
            why = (op_link.link_error_text(wait.error_code) if wait.error_code is not None
                   else f"no link-level acknowledgement within {timeout:g} s")
        err = DeviceTimeoutError(f"MID {msg.mid:04d} sequence {seq}: {why} after "
                                 f"{op_link.RESENDS} resends; the link is taken as lost")
        if epoch is not None:
            self._fail_link(err, epoch)
        raise err

    def _await_link(self, wait: _LinkWait, timeout: float) -> None:
        """Wait up to ``timeout`` for the answer to ``wait``: read it ourselves if this
        thread holds the reading side, else the supervisor dispatches it."""
        if self._reader_owner is not threading.current_thread():
            wait.done.wait(timeout)
            return
        deadline = time.monotonic() + timeout
        while not wait.done.is_set() and time.monotonic() < deadline:
            if self._stop.is_set():
                raise ConnectionLostError("closing")
            self._read_once()

    def _transact(self, msg: Message, expect: set[int], timeout: float,
                  epoch: int | None = None) -> Message:
        """Send ``msg`` and return its answer.  With ``epoch`` (a caller's thread) the
        supervisor dispatches the answer; without (open, reconnect) this thread reads."""
        slot = _Pending(msg.mid, frozenset(expect))
        with self._cond:
            if epoch is not None and epoch != self._epoch:
                raise ConnectionLostError("the link was reset; nothing was sent")
            self._pending = slot
        try:
            self._send(msg, epoch, timeout=timeout)
            if epoch is not None:
                slot.done.wait(timeout)
            else:
                deadline = time.monotonic() + timeout
                while not slot.done.is_set() and time.monotonic() < deadline:
                    if self._stop.is_set():
                        raise ConnectionLostError("closing")
                    self._read_once()
        finally:
            with self._cond:
                if self._pending is slot:
                    self._pending = None
        if slot.error is not None:
            raise slot.error
        if slot.reply is None:
            noise = getattr(self._framer, "noise", 0)
            hint = f" ({noise} bytes of line noise received)" if noise else ""
            raise DeviceTimeoutError(f"no answer to MID {msg.mid:04d} within {timeout:g} s"
                                     + hint)
        if slot.reply.mid == op.MID_ERROR:
            _, code = op.refusal(slot.reply)
            raise RefusedError(f"refused by the controller: {op.refusal_text(code)}", code=code)
        return slot.reply

    def _command(self, msg: Message, what: str, timeout: float) -> None:
        with self._request_lock:
            epoch = self._current_epoch(what)
            try:
                self._transact(msg, {op.MID_ACCEPTED, op.MID_ERROR}, timeout, epoch)
            except RefusedError as e:
                raise self._surface(e, what) from None
            except DeviceError as e:
                self._fail_link(e, epoch)
                raise self._surface(e, what, "; not acknowledged, treat it as not done (the "
                                    "link is reset and reconnects)") from None

    def _current_epoch(self, what: str) -> int:
        """The link's epoch, or the "link down" error for ``what``."""
        with self._cond:
            if not self._connected:
                raise self._down(what)
            return self._epoch

    # -- tightening curves (MID 0008 -> 0900) ----------------------------------------------
    can_curves = True

    @property
    def curves_on(self) -> bool:
        """Whether this session is subscribed to the tightening curves."""
        with self._cond:
            return self._curves_on

    @property
    def curves_reason(self) -> str | None:
        """Why curves are off (not asked for, refused by the controller, ...); None when
        they are on, or asked for and waiting for the link."""
        with self._cond:
            return self._curves_reason

    def subscribe_curves(self, timeout: float | None = None) -> bool:
        """Ask for the angle and torque traces of every tightening from now on (MID 0008
        for MID 0900), on this session and every later one: True when subscribed; False,
        with ``curves_reason``, when the controller gives none (MID 0004 error 78, 99, ...)
        or the link is serial.  Other failures raise as commands do (a timeout resets the
        link, and curves stay off: a controller that hangs on it is not asked again)."""
        self._check_open()
        with self._cond:
            self._curves_wanted, self._curves_reason = True, None
        with self._request_lock:
            try:
                epoch = self._current_epoch("subscribe to curves")
            except ConnectionLostError:
                return False                    # asked at the next session start
            try:
                return self._curves_session(epoch, self._timeout(timeout))
            except RefusedError as e:
                raise self._surface(e, "subscribe to curves") from None
            except DeviceError as e:
                self._fail_link(e, epoch)
                raise self._surface(e, "subscribe to curves", "; the link is reset and "
                                    "reconnects") from None

    def unsubscribe_curves(self, timeout: float | None = None) -> None:
        """Stop the curves (MID 0009), on this session and later ones."""
        self._check_open()
        with self._cond:
            on = self._curves_on
        self._curves_off("unsubscribed")
        if on:
            self._command(Message(MID_DATA_UNSUBSCRIBE, data=unsubscribe_data()),
                          "stop the curves", self._timeout(timeout))

    def wait_curve(self, timeout: float) -> Curve | None:
        """The next tightening curve received (oldest first), or None if none came within
        ``timeout`` seconds.  Never raises for a link that is down (curves received before
        are still handed out; the results' wait reports the link); raises DeviceError once
        closed."""
        if timeout < 0:
            raise ValueError("timeout must be >= 0")
        self._check_open()
        deadline = time.monotonic() + timeout
        with self._cond:
            while not self._curves:
                if self._closing:
                    raise DeviceError("closed", device=self.device)
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                self._cond.wait(remaining)
            return self._curves.popleft()

    def fetch_curve(self, tightening_id: int, timeout: float | None = None) -> list[Curve]:
        """The angle and torque curves of an earlier tightening (a result fetched after a
        link cut), asked for with the generic subscription's "stored data between two
        indexes" (MID 0008 for MID 0900, send alternative 3, first = last = the tightening
        id; R2.8.0 table 158): the controller answers 0005 and sends that tightening's
        traces, then the subscription is stopped (MID 0009).  A live curve subscription
        (``curves_on``) is stopped for it and made again after (a controller holds one
        subscription per MID); a curve of a new tightening made in that moment is not
        sent, the result still is.  Empty, logged, when the controller refuses (it keeps
        none, or not that one: MID 0004) or its traces do not come within ``timeout``, and
        over RS-232 (binary samples); the curves are not queued for ``wait_curve``.  Other
        failures raise as commands do (a timeout or a lost link resets the link)."""
        if isinstance(tightening_id, bool) or not isinstance(tightening_id, int) \
                or not 1 <= tightening_id <= MAX_TIGHTENING_ID:
            raise ValueError(f"tightening_id must be an integer 1-{MAX_TIGHTENING_ID}, not "
                             f"{tightening_id!r}")
        self._check_open()
        timeout = self._timeout(timeout)
        what = f"fetch the curves of tightening {tightening_id}"
        if self._link.kind == "serial":
            return []
        with self._request_lock:
            epoch = self._current_epoch(what)
            fetch = _CurveFetch(tightening_id, len(STATION_TRACES))
            with self._cond:
                live, self._curve_fetch = self._curves_on, fetch
            try:
                return self._replay_curves(fetch, live, epoch, timeout, what)
            except RefusedError as e:
                raise self._surface(e, what) from None
            except DeviceError as e:
                self._fail_link(e, epoch)
                raise self._surface(e, what, "; the link is reset and reconnects") from None
            finally:
                with self._cond:
                    self._curve_fetch = None

    def _replay_curves(self, fetch: _CurveFetch, live: bool, epoch: int, timeout: float,
                       what: str) -> list[Curve]:
        """``fetch_curve``'s exchange (holding the request lock)."""
        expect = {op.MID_ACCEPTED, op.MID_ERROR}
        stop = Message(MID_DATA_UNSUBSCRIBE, data=unsubscribe_data())
        if live:
            self._transact(stop, expect, timeout, epoch)
        refused: RefusedError | None = None
        try:
            self._transact(Message(MID_DATA_SUBSCRIBE, data=replay_data(
                fetch.tightening_id, fetch.tightening_id)), expect, timeout, epoch)
        except RefusedError as e:
            refused = e
        else:
            fetch.done.wait(timeout)
            try:
                self._transact(stop, expect, timeout, epoch)
            except RefusedError:
                pass                     # a controller that ended the replay by itself
        if live:
            try:
                self._transact(Message(MID_DATA_SUBSCRIBE, data=subscribe_data()), expect,
                               timeout, epoch)
            except RefusedError as e:
                if e.code != 71:         # 71: it exists, which is the goal
                    self._curves_off(f"the curves' subscription was refused again after "
                                     f"fetching old ones: {op.refusal_text(int(e.code or 0))}")
        with self._cond:
            got = list(fetch.curves)
        if refused is not None:
            log.info("%s: %s: none (MID 0008 refused: %s)", self.device, what,
                     op.refusal_text(int(refused.code or 0)))
        elif len(got) < fetch.wanted:
            log.warning("%s: %s: %d of %d trace(s) came within %g s", self.device, what,
                        len(got), fetch.wanted, timeout)
        return sorted(got, key=lambda c: c.trace_type)

    # -- old results (MID 0064 -> 0065) ----------------------------------------------------
    can_fetch = True

    def fetch_result(self, tightening_id: int, timeout: float | None = None
                     ) -> Received | None:
        """The controller's stored result ``tightening_id`` (0: its newest), or None if it
        answers "tightening id not found" (it no longer has it, or has none yet).

        For filling a gap in the tightening ids after a reconnect.  The result is not
        queued and needs no acknowledgement; it says ``fetched=True``.  A MID 0065 is read
        as a pushed result is (``op_reading``): laid out as a lower revision, it is read so
        and later fetches ask for that revision; one that reads at no revision comes back
        as an :class:`UnreadableResult` (fetched, its raw text kept), not as an error: it is
        the controller's record of a tightening, to be stored and looked at like a pushed
        one.  Raises as commands do: RefusedError for another refusal, a ProtocolError for
        an answer about another tightening, and a timeout or lost link resets the link.
        """
        if isinstance(tightening_id, bool) or not isinstance(tightening_id, int) \
                or not 0 <= tightening_id <= MAX_TIGHTENING_ID:
            raise ValueError(f"tightening_id must be an integer 0-{MAX_TIGHTENING_ID}, not "
                             f"{tightening_id!r}")
        self._check_open()
        timeout = self._timeout(timeout)
        what = f"fetch tightening {tightening_id or '(newest)'}"
        with self._request_lock:
            epoch = self._current_epoch(what)
            try:
                return self._fetch(tightening_id, timeout, epoch, what)
            except RefusedError as e:
                raise self._surface(e, what) from None
            except ProtocolError:
                raise
            except DeviceError as e:
                self._fail_link(e, epoch)
                raise self._surface(e, what, "; the link is reset and reconnects") from None

    def _fetch(self, tightening_id: int, timeout: float, epoch: int, what: str
               ) -> Received | None:
        """MID 0064 -> 0065 at the agreed revision (or the highest not refused), holding the
        request lock: the result, or None for "not found"; other refusals and failures
        raise as they come."""
        data = f"{tightening_id:010d}".encode()
        with self._cond:
            agreed = self._revisions.get(op.MID_OLD_RESULT_REQUEST)
        for rev in (agreed,) if agreed else RESULT_REVISIONS:
            try:
                reply = self._transact(Message(op.MID_OLD_RESULT_REQUEST, revision=rev,
                                               data=data),
                                       {op.MID_OLD_RESULT, op.MID_ERROR}, timeout, epoch)
            except RefusedError as e:
                if e.code in op.REVISION_REFUSALS and rev > 1:
                    continue
                if e.code == op.NOT_FOUND:
                    self._agree(op.MID_OLD_RESULT_REQUEST, rev)
                    return None
                raise
            self._agree(op.MID_OLD_RESULT_REQUEST, rev)
            return self._old_result(reply, tightening_id, what)
        raise AssertionError("unreachable: revision 1's refusal is raised")

    def _agree(self, mid: int, rev: int) -> None:
        with self._cond:
            self._revisions[mid] = rev

    def _old_result(self, reply: Message, tightening_id: int, what: str) -> Received:
        result = receive(reply)
        if isinstance(result, UnreadableResult):
            log.warning("%s: %s: MID 0065 revision %d does not read at any revision (%s); "
                        "kept with its raw text", self.device, what, reply.revision,
                        result.error)
        elif result.header_revision is not None:
            self._lowered(reply.mid, result.header_revision, result.revision)
            self._agree(op.MID_OLD_RESULT_REQUEST, result.revision)   # ask for that one
        if tightening_id and result.tightening_id not in (tightening_id, None):
            raise ProtocolError(f"{what}: the controller answered with tightening "
                                f"{result.tightening_id}", device=self.device)
        return result

    # -- the Wrench hooks ------------------------------------------------------------------
    def _link_up(self) -> bool:
        return self._connected

    def _identity(self) -> str:
        with self._cond:
            return self._ident.describe() if self._ident is not None else ""

    def _send_ack(self, token: int, timeout: float) -> None:
        """MID 0062 on the link the result came on: 0062 names no result, so on a new
        session it would acknowledge whatever that session sent, not this one.  A result
        fetched by the driver itself (``NO_ACK``) has none."""
        if token == NO_ACK:
            return
        self._send(Message(op.MID_RESULT_ACK), epoch=token, timeout=timeout)

    def _select_pset(self, pset: int, timeout: float) -> None:
        self._command(Message(op.MID_PSET_SELECT, data=f"{pset:03d}".encode()),
                      f"select pset {pset}", timeout)

    def _set_tool(self, enabled: bool, timeout: float) -> None:
        mid, what = (op.MID_TOOL_ENABLE, "enable tool") if enabled else (op.MID_TOOL_DISABLE,
                                                                      "disable tool")
        self._command(Message(mid), what, timeout)

    def _send_vin(self, vin: str, timeout: float) -> None:
        if len(vin) > VIN_LENGTH or not vin.isascii() or not vin.isprintable():
            raise ValueError(f"VIN must be printable ASCII, at most {VIN_LENGTH} characters: "
                             f"{vin!r}")
        self._command(Message(op.MID_VIN, data=vin.ljust(VIN_LENGTH).encode("ascii")),
                      f"send VIN {vin}", timeout)


def keyword_options(kw: dict[str, Any], spec: Spec) -> dict[str, Any]:
    """Keyword overrides of URL options: the same names, already typed."""
    unknown = sorted(set(kw) - set(spec))
    if unknown:
        raise TypeError(f"unknown option(s) {', '.join(unknown)} (accepted: "
                        f"{', '.join(sorted(spec))})")
    return kw
