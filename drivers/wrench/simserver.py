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
"""

from __future__ import annotations

import os
import selectors
import socket
import threading
import time
import tty
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from queue import SimpleQueue
from typing import Any, Literal, TypeVar

T = TypeVar("T")
Fault = Literal["silent", "garbage", "partial", "truncate", "close"]
PREFIX, STX, ETX = b"\x07\x09\x07\x09", b"\x02", b"\x03"
MAX_MESSAGE = 9999


@dataclass(frozen=True)
class Received:
    """A message the controller received from the integrator."""

    mid: int
    revision: int
    data: bytes


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
    return Received(int(head[4:8]), max(int(rev or b"1"), 1), raw[20:])


def message(mid: int, data: bytes = b"") -> bytes:
    """Header (length, MID, revision 001, the other fields blank) + data; no NUL."""
    return f"{20 + len(data):04d}{mid:04d}001         ".encode() + data


class Session:
    """One integrator: a TCP connection, or the controller's end of a pty."""

    def __init__(self, kind: Literal["tcp", "serial"], fd: int, sock: socket.socket | None,
                 slave: int | None = None, link: str | None = None) -> None:
        self.kind, self.fd, self.sock, self.slave, self.link = kind, fd, sock, slave, link
        self.inbuf, self.out = bytearray(), bytearray()
        self.started = self.subscribed = False
        self.last_rx = time.monotonic()
        self.unacked: list[int] = []    # results (tightening ids) sent, awaiting MID 0062

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

    def __init__(self) -> None:
        self.errors: list[str] = []            # protocol violations the controller saw
        self.drops = 0                          # clients dropped for silence
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

    def reply(self, s: Session, answering: int, mid: int, data: bytes = b"") -> None:
        """Answer the command ``answering`` with ``mid``, unless a fault is armed for it."""
        frame = s.frame(message(mid, data))
        armed = next((i for i, (_, only) in enumerate(self._faults)
                      if only == answering or (only is None and answering != 9999)), None)
        if armed is None:
            self.write(s, frame)
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
