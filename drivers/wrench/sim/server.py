"""The server side of Open Protocol for the simulated controller: wire, sessions, transports.

Written from docs/PROTOCOLS.md, not from the client (``openprotocol.py``): its own framing,
written the way a controller reads an integrator (TCP: length-prefixed, NUL-terminated;
RS-232: ``BEL HT BEL HT STX message ETX``, the wake-up prefix required), so a misreading
would have to be made twice, differently, to go unnoticed.

``OpenProtocolServer`` serves any number of TCP listeners and ptys from one selector thread
that owns all state; public methods hand it work and wait for the answer, so they are safe
from any thread.  Transport faults for tests live here: one-shot ``inject`` ("silent",
"garbage", "partial", "truncate", "close") and ``power_off``/``power_on`` (the device
disappears; it comes back on the same TCP port and, for a pty, behind the same symlink).
The controller's behaviour (what each MID does) is the subclass's ``handle``.

Link-level acknowledgement (MID 9997/9998), when the subclass switches it on for a session
(``Session.start_link_level``), lives here too, because it is transport work: every message
the controller sends is numbered 1-99 (wrapping) and the next one waits for the integrator's
9997; no 9997 within ``link_timeout``: resent with the same number, up to 3 times, then the
connection is dropped.  Every numbered message from the integrator is acknowledged (a 9998
if it has no number, or one that is neither the next expected nor a repeat: error 0003),
and one that repeats the last number is acknowledged again but not handled twice.  A
9997/9998 carries the number its sender expects next, the received one + 1 (the
specification's figures: "MID 0060 seq. 01" is answered by "MID 9997 seq. 02"), both ways:
the integrator's 9997 for message N must say N + 1.  ``link_fault`` spoils this for tests
("ignore_ack", "no_ack", "nak", "deaf").
"""

from __future__ import annotations

import os
import selectors
import socket
import threading
import time
import tty
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from queue import SimpleQueue
from typing import Any, Literal, TypeVar

T = TypeVar("T")
Fault = Literal["silent", "garbage", "partial", "truncate", "close"]
LinkFault = Literal["ignore_ack", "no_ack", "nak", "deaf"]
PREFIX, STX, ETX = b"\x07\x09\x07\x09", b"\x02", b"\x03"
MAX_MESSAGE = 9999
LINK_ACK, LINK_ERROR, KEEPALIVE = 9997, 9998, 9999
NOT_NUMBERED = {1, 2, LINK_ACK, LINK_ERROR, KEEPALIVE}   # outside the link level
LINK_RESENDS = 3


@dataclass(frozen=True)
class Received:
    """A message the controller received from the integrator."""

    mid: int
    revision: int
    data: bytes
    sequence: int | None = None     # the header's sequence number, if any


def split_tcp(buf: bytearray) -> tuple[list[bytes], str | None]:
    """Take complete messages (length-prefixed, NUL-terminated) off the front of ``buf``."""
    out: list[bytes] = []
    while len(buf) >= 4:
        if not bytes(buf[:4]).isdigit() or int(buf[:4]) < 20:
            return out, f"bad length field {bytes(buf[:4])!r}"
        n = int(buf[:4])
        if len(buf) <= n:
            break
        if buf[n] != 0:
            return out, f"message of {n} bytes not followed by NUL"
        out.append(bytes(buf[:n]))
        del buf[:n + 1]
    return out, None


def split_serial(buf: bytearray) -> tuple[list[bytes], list[str]]:
    """Take ``BEL HT BEL HT STX message [NUL] ETX`` frames off ``buf``; noise is dropped, a
    frame without the wake-up prefix or cut short by a new STX is an error."""
    out: list[bytes] = []
    errors: list[str] = []
    while True:
        stx = buf.find(STX)
        if stx < 0:
            del buf[:max(0, len(buf) - 4)]          # what is left may be the next prefix
            return out, errors
        etx, nxt = buf.find(ETX, stx + 1), buf.find(STX, stx + 1)
        if nxt >= 0 and (etx < 0 or nxt < etx):
            errors.append("frame cut short by a new STX")
            del buf[:max(stx + 1, nxt - 4)]
            continue
        if etx < 0:
            if len(buf) - stx > MAX_MESSAGE + 2:
                errors.append("frame without ETX")
                del buf[:stx + 1]
                continue
            del buf[:max(0, stx - 4)]
            return out, errors
        prefix, body = bytes(buf[max(0, stx - 4):stx]), bytes(buf[stx + 1:etx])
        del buf[:etx + 1]
        if prefix != PREFIX:
            errors.append(f"frame without BEL HT BEL HT before STX: {body[:24]!r}")
            continue
        out.append(body[:-1] if body.endswith(b"\x00") else body)


def parse_message(raw: bytes) -> Received:
    """Header fields the controller needs: length (checked), MID, revision (spaces = 1)."""
    head = raw[:20]
    if len(head) < 20 or not head[:8].isdigit() or int(head[:4]) != len(raw):
        raise ValueError(f"bad header {head!r}")
    rev = head[8:11].strip(b" ")
    if rev and not rev.isdigit():
        raise ValueError(f"bad revision {head[8:11]!r}")
    seq = head[16:18].strip(b" ")
    if seq and not seq.isdigit():
        raise ValueError(f"bad sequence number {head[16:18]!r}")
    return Received(int(head[4:8]), max(int(rev or b"1"), 1), raw[20:],
                    int(seq) if seq else None)


def message(mid: int, data: bytes = b"", revision: int = 1) -> bytes:
    """Header (length, MID, revision, the other fields blank) + data; no NUL."""
    return f"{20 + len(data):04d}{mid:04d}{revision:03d}         ".encode() + data


def after(seq: int) -> int:
    """The sequence number after ``seq`` (1-99, wrapping; 0: none yet, so 1)."""
    return seq % 99 + 1


def numbered(raw: bytes, seq: int) -> bytes:
    """``raw`` with its header's sequence number (bytes 17-18) set."""
    return raw[:16] + f"{seq:02d}".encode() + raw[18:]


class Session:
    """One integrator: a TCP connection, or the controller's end of a pty."""

    def __init__(self, kind: Literal["tcp", "serial"], fd: int, sock: socket.socket | None,
                 slave: int | None = None, link: str | None = None) -> None:
        self.kind, self.fd, self.sock, self.slave, self.link = kind, fd, sock, slave, link
        self.inbuf, self.out = bytearray(), bytearray()
        self.started = self.subscribed = False
        self.result_revision = 1        # the revision of MID 0060, so of the 0061 pushed
        self.last_rx = time.monotonic()
        self.unacked: list[int] = []    # results (tightening ids) sent, awaiting MID 0062
        self.traces: tuple[int, ...] = ()   # trace types subscribed with MID 0008 (0900)
        self.replaying = False              # a MID 0008 for stored traces (alternative 3)
        self.plot = False                   # MID 0901 subscribed with MID 0008
        # link level: off until the controller says so (after its 0002)
        self.link_level = self.link_capable = False
        self.tx_seq = 0
        self.rx_last: int | None = None
        self.outbox: deque[bytes] = deque()          # numbered messages waiting their turn
        self.outstanding: bytes | None = None        # the one awaiting the integrator's 9997
        self.sent_at = 0.0
        self.resends = 0

    def start_link_level(self, on: bool, capable: bool | None = None) -> None:
        """Communication start: both counters from 1 again, nothing outstanding; ``on``
        now, or (``capable``) as soon as the integrator numbers a message."""
        self.link_level, self.tx_seq, self.rx_last = on, 0, None
        self.link_capable = on if capable is None else capable
        self.outbox.clear()
        self.outstanding = None

    def read(self) -> bytes:
        return self.sock.recv(65536) if self.sock else os.read(self.fd, 65536)

    def write(self, data: bytes) -> int:
        return self.sock.send(data) if self.sock else os.write(self.fd, data)

    def frame(self, raw: bytes) -> bytes:
        """Controller -> integrator: message NUL over TCP, STX message NUL ETX over RS-232."""
        return STX + raw + b"\x00" + ETX if self.kind == "serial" else raw + b"\x00"

    def close(self) -> None:
        if self.sock:
            self.sock.close()
        else:
            os.close(self.fd)
            if self.slave is not None:
                os.close(self.slave)


class OpenProtocolServer:
    """Transports and the selector thread; subclasses implement ``handle``."""

    silence_timeout = 15.0     # the controller drops a client silent for this long
    link_timeout = 2.0         # link level: resend when no 9997 came within this long

    def __init__(self) -> None:
        self.errors: list[str] = []            # protocol violations the controller saw
        self.drops = 0                          # clients dropped for silence
        self.repeats = 0                        # link level: repeated messages not handled
        self.resent = 0                         # link level: messages resent
        self.link_drops = 0                     # link level: clients dropped, no 9997
        self._link_faults: list[tuple[LinkFault, int | None]] = []
        self._log: list[Received] = []
        self._faults: list[tuple[Fault, int | None]] = []
        self._sessions: dict[int, Session] = {}
        self._listeners: list[socket.socket] = []
        self._ports: list[tuple[str, int]] = []
        self._ptys: list[str | None] = []       # symlink (or None) of each pty, for power_on
        self._calls: SimpleQueue[tuple[Callable[[], Any], Future[Any]]] = SimpleQueue()
        self._thread: threading.Thread | None = None
        self._stopping = False
        self._doomed: list[tuple[float, Session]] = []   # (when, session) to drop

    # -- lifecycle and the call bridge ------------------------------------------------------
    def start(self) -> None:
        if self._thread is None:
            self._sel = selectors.DefaultSelector()
            self._wake_r, self._wake_w = socket.socketpair()
            self._sel.register(self._wake_r, selectors.EVENT_READ, None)
            self._thread = threading.Thread(target=self._run, name="sim-wrench", daemon=True)
            self._thread.start()

    def close(self) -> None:
        """Stop serving and release every socket, pty and thread; safe to call twice."""
        thread, self._thread = self._thread, None
        if thread is None:
            return
        self._stopping = True
        self._wake_w.send(b"x")
        thread.join()
        self._shutdown()
        self._sel.unregister(self._wake_r)
        self._sel.close()
        self._wake_r.close()
        self._wake_w.close()
        for link in self._ptys:
            if link and os.path.islink(link):
                os.unlink(link)

    def call(self, fn: Callable[[], T]) -> T:
        """Run ``fn`` on the server thread (which owns all state) and return its result."""
        if self._thread is None:
            raise RuntimeError("the simulated controller is not running (start() it)")
        if threading.current_thread() is self._thread:
            return fn()
        fut: Future[T] = Future()
        self._calls.put((fn, fut))
        self._wake_w.send(b"x")
        return fut.result(timeout=5.0)

    # -- transports -------------------------------------------------------------------------
    def listen_tcp(self, host: str = "127.0.0.1", port: int = 0) -> int:
        """Serve Open Protocol over TCP; returns the port (ephemeral by default)."""
        def do() -> int:
            sock = socket.socket()
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind((host, port))
            except OSError:
                sock.close()
                raise
            sock.listen(4)
            sock.setblocking(False)
            self._sel.register(sock, selectors.EVENT_READ, sock)
            self._listeners.append(sock)
            bound: int = sock.getsockname()[1]
            if (host, bound) not in self._ports:
                self._ports.append((host, bound))
            return bound
        return self.call(do)

    def open_pty(self, link: str | None = None) -> str:
        """Serve Open Protocol over a pty pair made with os.openpty() (the controller holds
        the master, and the slave too, so it survives integrators coming and going); returns
        the path to open: ``link`` (a symlink kept across power cycles) or the slave's name."""
        def do() -> str:
            master, slave = os.openpty()
            tty.setraw(slave)                    # no echo, no line editing: a plain wire
            os.set_blocking(master, False)
            path = os.ttyname(slave)
            if link:
                tmp = f"{link}.tmp{os.getpid()}"
                os.symlink(path, tmp)
                os.replace(tmp, link)
            self._ptys.append(link)
            self._add(Session("serial", master, None, slave, link))
            return link or path
        return self.call(do)

    def power_off(self) -> None:
        """The device disappears: every listener, connection and pty is closed."""
        self.call(self._shutdown)

    def power_on(self) -> None:
        """The device comes back on the same ports and pty symlinks (those that are down:
        a "truncate" fault on a pty closes only that pty)."""
        def do() -> None:
            self.on_power_on()
            listening = {sock.getsockname()[:2] for sock in self._listeners}
            serving = {s.link for s in self._sessions.values() if s.kind == "serial"}
            down = [link for link in self._ptys if link not in serving]
            self._ptys = [link for link in self._ptys if link not in down]
            for host, port in list(self._ports):
                if (host, port) not in listening:
                    self.listen_tcp(host, port)
            for link in down:
                self.open_pty(link)
        self.call(do)

    def drop_connections(self) -> None:
        """Close every TCP connection now (the listener stays): the peer closes."""
        def do() -> None:
            for s in list(self._sessions.values()):
                if s.kind == "tcp":
                    self._drop(s)
        self.call(do)

    def inject(self, fault: Fault, mid: int | None = None) -> None:
        """Spoil the answer to the next command (to the next ``mid`` if given; keep-alives
        only if asked): "silent" (no answer), "garbage", "partial" (half a message, then
        nothing), "truncate" (half a message, then the connection or pty closes), "close"
        (close without answering)."""
        self.call(lambda: self._faults.append((fault, mid)))

    def received(self, mid: int | None = None) -> list[Received]:
        """Every message received so far (or those with this MID), oldest first."""
        return self.call(lambda: [r for r in self._log if mid is None or r.mid == mid])

    # -- for the subclass -------------------------------------------------------------------
    def handle(self, s: Session, msg: Received) -> None:
        raise NotImplementedError

    def on_power_on(self) -> None:
        """Reset volatile state when the device comes back."""

    def sessions(self) -> list[Session]:
        return list(self._sessions.values())

    def reply(self, s: Session, answering: int, mid: int, data: bytes = b"",
              revision: int = 1) -> None:
        """Answer the command ``answering`` with ``mid``, unless a fault is armed for it."""
        raw = message(mid, data, revision)
        frame = s.frame(raw)
        armed = next((i for i, (_, only) in enumerate(self._faults)
                      if only == answering or (only is None and answering != 9999)), None)
        if armed is None:
            self.post(s, raw)
            return
        fault, _ = self._faults.pop(armed)
        if fault == "garbage":
            self.write(s, STX + b"GARBAGE?" + ETX if s.kind == "serial"
                       else b"\xffGARBAGE\r\nnot open protocol\x00")
        elif fault in ("partial", "truncate"):
            self.write(s, frame[:len(frame) // 2])
        if fault == "close" or (fault == "truncate" and s.kind == "tcp"):
            self._drop(s)
        elif fault == "truncate":     # a pty hangup would discard what the peer has not read
            self._doomed.append((time.monotonic() + 0.1, s))

    def write(self, s: Session, data: bytes) -> None:
        s.out += data
        self._flush(s)

    def post(self, s: Session, raw: bytes) -> None:
        """Send a message (header + data, no framing): at once, or, with the link level on,
        numbered and after the messages before it were acknowledged."""
        if not s.link_level or int(raw[4:8]) in NOT_NUMBERED:
            self.write(s, s.frame(raw))
            return
        s.outbox.append(raw)
        self._next_out(s)

    def link_fault(self, fault: LinkFault, mid: int | None = None) -> None:
        """Spoil the link level once (for a message with ``mid`` only, if given):
        "ignore_ack" (the integrator's next 9997 is not heard: the message is resent),
        "no_ack" (the integrator's next message is handled but not acknowledged: it resends
        it), "nak" (it is refused with 9998 and not handled), "deaf" (no 9997 is heard any
        more: resent 3 times, then the connection dropped; until ``clear_link_faults``)."""
        self.call(lambda: self._link_faults.append((fault, mid)))

    def clear_link_faults(self) -> None:
        self.call(self._link_faults.clear)

    def link_quiet(self) -> bool:
        """Every message sent on the link level has its 9997 and none waits its turn: a fault
        armed now meets the next message, not the acknowledgement of one already sent."""
        return self.call(lambda: all(s.outstanding is None and not s.outbox
                                     for s in self._sessions.values()))

    # -- the link level -----------------------------------------------------------------
    def _next_out(self, s: Session) -> None:
        if s.outstanding is not None or not s.outbox:
            return
        s.tx_seq = after(s.tx_seq)
        s.outstanding = numbered(s.outbox.popleft(), s.tx_seq)
        s.resends = 0
        self._send_outstanding(s)

    def _send_outstanding(self, s: Session) -> None:
        if s.outstanding is not None:
            s.sent_at = time.monotonic()
            self.write(s, s.frame(s.outstanding))

    def _link_fault(self, fault: LinkFault, mid: int) -> bool:
        """Whether ``fault`` is armed for ``mid`` (a one-shot one is used up; "deaf"
        stays)."""
        armed = next((f for f in self._link_faults
                      if f[0] == fault and f[1] in (None, mid)), None)
        if armed is None:
            return False
        if fault != "deaf":
            self._link_faults.remove(armed)
        return True

    def _link_in(self, s: Session, msg: Received) -> bool:
        """Link-level work on a received message; whether it is to be handled."""
        if msg.mid in (LINK_ACK, LINK_ERROR):
            out = s.outstanding
            if out is None or msg.sequence != after(int(out[16:18])):
                self.errors.append(f"MID {msg.mid} for sequence {msg.sequence}, which is "
                                   "not outstanding")
            elif msg.mid == LINK_ERROR:
                self._resend(s)
            elif not self._link_fault("ignore_ack", int(out[4:8])) \
                    and not self._link_fault("deaf", int(out[4:8])):
                s.outstanding = None
                self._next_out(s)
            return False
        if msg.mid in NOT_NUMBERED:
            return True
        if not s.link_level and s.link_capable and msg.sequence is not None:
            s.link_level = True        # an integrator that numbers its messages wants it
        if not s.link_level:
            return True
        ack = message(LINK_ACK, f"{msg.mid:04d}".encode())
        expected = after(s.rx_last or 0)
        repeat = msg.sequence is not None and msg.sequence == s.rx_last
        if msg.sequence is None or (not repeat and msg.sequence != expected):
            self.errors.append(f"MID {msg.mid:04d} with sequence number {msg.sequence}, "
                               f"expected {expected}")
            self._nak(s, msg.mid, 3, expected)       # not handled: told what comes next
            return False
        if self._link_fault("nak", msg.mid):
            self._nak(s, msg.mid, 1, after(msg.sequence))
            return False
        self.repeats += repeat          # counted before the 9997 is out: whoever sees it
        s.rx_last = msg.sequence        # may look at the count
        if not self._link_fault("no_ack", msg.mid):
            self.write(s, s.frame(numbered(ack, after(msg.sequence))))
        return not repeat

    def _nak(self, s: Session, mid: int, code: int, seq: int) -> None:
        """MID 9998 refusing ``mid`` with ``code``, numbered ``seq`` (the one expected)."""
        self.write(s, s.frame(numbered(message(LINK_ERROR, f"{mid:04d}{code:04d}".encode()),
                                       seq)))

    def _resend(self, s: Session) -> None:
        if s.resends >= LINK_RESENDS:
            self.link_drops += 1
            self._drop(s)
            return
        s.resends += 1
        self.resent += 1
        self._send_outstanding(s)

    # -- the selector loop ------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stopping:
            for key, mask in self._sel.select(0.05):
                if key.data is None:
                    self._wake_r.recv(4096)
                elif isinstance(key.data, socket.socket):
                    self._accept(key.data)
                elif self._alive(key.data):
                    self._io(key.data, mask)
            while not self._calls.empty():
                fn, fut = self._calls.get()
                try:
                    fut.set_result(fn())
                except Exception as e:
                    fut.set_exception(e)
            now = time.monotonic()
            for when, s in [d for d in self._doomed if d[0] <= now]:
                self._doomed.remove((when, s))
                self._drop(s)
            for s in list(self._sessions.values()):
                if s.outstanding is not None and now - s.sent_at > self.link_timeout:
                    self._resend(s)
                if not self._alive(s):
                    continue
                if now - s.last_rx > self.silence_timeout and (s.kind == "tcp" or s.started):
                    self.drops += 1
                    if s.kind == "tcp":
                        self._drop(s)
                    else:                        # a serial line cannot be closed: reset
                        s.started = s.subscribed = False

    def _shutdown(self) -> None:
        for sock in self._listeners:
            self._sel.unregister(sock)
            sock.close()
        self._listeners.clear()
        for s in list(self._sessions.values()):
            self._drop(s)

    def _add(self, s: Session) -> None:
        self._sessions[s.fd] = s
        self._sel.register(s.fd, selectors.EVENT_READ, s)

    def _alive(self, s: Session) -> bool:
        return self._sessions.get(s.fd) is s      # fds are reused: compare the session

    def _accept(self, listener: socket.socket) -> None:
        try:
            conn, _ = listener.accept()
        except OSError:
            return
        conn.setblocking(False)
        # small messages written back to back (a 9997 then an answer) must not wait for
        # the peer's delayed ACK (Nagle), as a controller's would not
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._add(Session("tcp", conn.fileno(), conn))

    def _drop(self, s: Session) -> None:
        if self._alive(s):
            del self._sessions[s.fd]
            self._sel.unregister(s.fd)
            if s.out:
                try:
                    s.write(bytes(s.out))
                except OSError:
                    pass
            s.close()

    def _io(self, s: Session, mask: int) -> None:
        if mask & selectors.EVENT_WRITE:
            self._flush(s)
        if not mask & selectors.EVENT_READ or not self._alive(s):
            return
        try:
            data = s.read()
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            self._drop(s)
            return
        s.inbuf += data
        if s.kind == "tcp":
            raws, error = split_tcp(s.inbuf)
            errors = [error] if error else []
        else:
            raws, errors = split_serial(s.inbuf)
        for raw in raws:
            if not self._alive(s):                # a fault closed it
                break
            try:
                msg = parse_message(raw)
            except ValueError as e:
                errors.append(str(e))
                if s.kind == "tcp":
                    break
                continue
            s.last_rx = time.monotonic()
            self._log.append(msg)
            if self._link_in(s, msg):
                self.handle(s, msg)
        self.errors.extend(errors)
        if errors and s.kind == "tcp":          # a broken TCP stream cannot be resynchronised
            self._drop(s)

    def _flush(self, s: Session) -> None:
        if not self._alive(s):
            return
        try:
            del s.out[:s.write(bytes(s.out))]
        except BlockingIOError:
            pass
        except OSError:
            self._drop(s)
            return
        events = selectors.EVENT_READ | (selectors.EVENT_WRITE if s.out else 0)
        self._sel.modify(s.fd, events, s)
