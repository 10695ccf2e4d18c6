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
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from drivers.errors import (
    ConnectionLostError,
    DeviceError,
    DeviceTimeoutError,
    ProtocolError,
    RefusedError,
)
from drivers.link import Link, SerialLink, TcpLink
from drivers.url import DeviceUrl
from drivers.wrench import openprotocol as op
from drivers.wrench.base import SupervisedWrench, check_positive
from drivers.wrench.openprotocol import Message, SerialFramer, TcpFramer

log = logging.getLogger(__name__)

POLL = 0.05            # the supervisor's read granularity: bounds reaction to close() and resets
DEFAULT_PORT = 4545
REFUSED = "controller off, or Open Protocol not enabled on this port?"
VIN_LENGTH = 25        # MID 0050 revision 1 carries a 25-character VIN
Spec = dict[str, tuple[Callable[[str], Any], Any]]   # option -> (converter, default)
OPTIONS: Spec = {
    "timeout": (float, 2.0), "connect_timeout": (float, 5.0), "keepalive": (float, 10.0),
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


class OpenProtocolWrench(SupervisedWrench):
    """A tightening controller over Open Protocol (TCP or RS-232)."""

    def __init__(self, link: Link | None, *, device: str, timeout: float = 2.0,
                 connect_timeout: float = 5.0, keepalive: float = 10.0) -> None:
        super().__init__(device, timeout=timeout)
        check_positive(connect_timeout=connect_timeout, keepalive=keepalive)
        self._given_link = link
        self._link: Link = link or TcpLink("127.0.0.1", DEFAULT_PORT, REFUSED)
        self._connect_timeout = connect_timeout
        self._keepalive = keepalive
        self._framer: TcpFramer | SerialFramer = TcpFramer()
        self._send_lock = threading.Lock()      # one message on the wire at a time
        self._request_lock = threading.Lock()   # one command in flight
        self._reader = threading.Lock()         # the link's reading side: supervisor or session
        self._connected = False                 # these two guarded by _cond too
        self._epoch = 0
        self._pending: _Pending | None = None
        self._ident = ""
        self._last_sent = 0.0
        self._keepalive_sent: float | None = None

    @classmethod
    def from_url(cls, url: DeviceUrl, **kw: Any) -> OpenProtocolWrench:
        """``openprotocol://HOST[:PORT]`` or ``openprotocol+serial:///dev/ttyUSB1?baud=9600``;
        options (URL query or keywords): timeout, connect_timeout, keepalive (seconds), and
        baud for serial."""
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

    # -- lifecycle -------------------------------------------------------------------------
    def _make_link(self) -> Link:
        """The link to use; the simulated backend overrides this to start its server first."""
        if self._given_link is None:
            raise DeviceError("no link to the controller", device=self.device)
        return self._given_link

    def _open(self) -> None:
        self._link = self._make_link()
        try:
            self._start_session()
        except DeviceError as e:
            raise self._surface(e, "open") from None
        with self._cond:
            self._connected = True
        self._thread = threading.Thread(target=self._supervise, daemon=True,
                                        name=f"wrench-link {self.device}")
        self._thread.start()

    def _close(self) -> None:
        try:    # orderly communication stop (0003 -> 0005); best effort, briefly
            self._command(Message(op.MID_STOP), "communication stop", min(self.timeout, 0.5))
        except DeviceError:
            pass
        self._stop.set()
        self._fail_link(DeviceError("closed"), closing=True)
        if self._thread is not None:
            self._thread.join()
        with self._send_lock:
            self._link.close()

    def _start_session(self) -> None:
        """Connect, communication start (0001 -> 0002), result subscription (0060 -> 0005)."""
        link = self._link
        link.connect(self._connect_timeout)
        self._framer = SerialFramer() if link.kind == "serial" else TcpFramer()
        self._last_sent, self._keepalive_sent = time.monotonic(), None
        try:
            reply = self._transact(Message(op.MID_START), {op.MID_START_ACK, op.MID_ERROR},
                                   self.timeout)
            ident = op.identity(reply)
            try:
                self._transact(Message(op.MID_RESULT_SUBSCRIBE), {op.MID_ACCEPTED, op.MID_ERROR},
                               self.timeout)
            except RefusedError as e:
                if e.code != 9:                 # 09: already subscribed, which is the goal
                    raise
        except DeviceError as e:
            link.close()
            what = "communication start" if not self._ident else "session restart"
            raise type(e)(f"{what}: {e}", code=e.code) from None
        except BaseException:
            link.close()
            raise
        self._ident = ident

    # -- the supervisor thread -------------------------------------------------------------
    def _supervise(self) -> None:
        """Read while the link is up; when it is down, close it and wait for
        ``reconnect()`` (which holds the reading side while it starts a session)."""
        while not self._stop.is_set():
            with self._reader:
                with self._cond:
                    up = self._connected
                if up:
                    try:
                        self._read_once()
                        self._keepalive_tick()
                    except DeviceError as e:
                        self._fail_link(e)
                    continue
                with self._send_lock:
                    self._link.close()
            self._stop.wait(POLL)

    def _reconnect(self) -> None:
        """Drop the link if it is up, then connect and start a session (0001, 0060)."""
        self._fail_link(ConnectionLostError("reconnect asked for"))
        with self._reader:
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
        if msg.mid == op.MID_RESULT:
            try:
                result = op.parse_result(msg.raw)
            except ProtocolError as e:
                with self._cond:
                    self._results.append(ProtocolError(
                        f"unreadable tightening result, acknowledged anyway (the controller "
                        f"keeps its own record): {e}"))
                    self._cond.notify_all()
                self._send(Message(op.MID_RESULT_ACK))
                return
            with self._cond:   # acknowledged (0062) when taken, on this same link only
                self._queue_result(result, self._epoch)
            return
        if msg.mid == op.MID_KEEPALIVE:
            self._keepalive_sent = None
            return
        with self._cond:
            slot = self._pending
            if slot is not None and slot.matches(msg):
                slot.reply, self._pending = msg, None
                slot.done.set()
                return
        log.warning("%s: unexpected MID %04d ignored (data %r)", self.device, msg.mid,
                    msg.data[:40])

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
            self._connected = False
            self._closing = self._closing or closing
            self._epoch += 1
            if was_up:
                self._link_lost(str(err))
            if self._pending is not None:
                self._pending.error = err
                self._pending.done.set()
                self._pending = None
            self._cond.notify_all()
        if was_up and not closing:
            log.warning("%s: link lost: %s", self.device, err)

    # -- sending and commands --------------------------------------------------------------
    def _send(self, msg: Message, epoch: int | None = None) -> None:
        data = op.frame_serial(msg) if self._link.kind == "serial" else op.frame_tcp(msg)
        with self._send_lock:
            if epoch is not None:
                with self._cond:
                    if epoch != self._epoch:
                        raise ConnectionLostError("the link was reset before sending")
            self._link.send(data)
            self._last_sent = time.monotonic()

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
            self._send(msg, epoch)
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
            with self._cond:
                if not self._connected:
                    raise self._down(what)
                epoch = self._epoch
            try:
                self._transact(msg, {op.MID_ACCEPTED, op.MID_ERROR}, timeout, epoch)
            except RefusedError as e:
                raise self._surface(e, what) from None
            except DeviceError as e:
                self._fail_link(e, epoch)
                raise self._surface(e, what, "; not acknowledged, treat it as not done (the "
                                    "link is reset and reconnects)") from None

    # -- the Wrench hooks ------------------------------------------------------------------
    def _link_up(self) -> bool:
        return self._connected

    def _identity(self) -> str:
        return self._ident

    def _send_ack(self, token: int, timeout: float) -> None:
        """MID 0062 on the link the result came on: 0062 names no result, so on a new
        session it would acknowledge whatever that session sent, not this one."""
        self._send(Message(op.MID_RESULT_ACK), epoch=token)

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
