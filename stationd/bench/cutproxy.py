"""A TCP proxy the link-cut benchmark puts between the station and its simulated controller,
to cut the link and restore it.

Why a proxy and not the controller's power switch: a cut link is not a controller that is
off.  Behind a cut cable the controller goes on working: the tool it was told to enable stays
enabled and makes tightenings, whose results it pushes to nobody (its session is gone) and
keeps in its store.  That is the case the station's catch-up is for (MID 0064 after the
reconnect); a power cycle would also reset the tool and make nothing to catch up.

While cut, every connection through the proxy is closed at both ends (each side sees the
other close, as after a switch port went down and the peers' keep-alives gave up), and a
new one is accepted and closed at once (the station's reconnects fail until the link is
restored).  One thread per direction and connection; everything closes with :meth:`close`.
"""

from __future__ import annotations

import socket
import threading


class CutProxy:
    """Listens on 127.0.0.1 (an ephemeral ``port``) and forwards to ``target``."""

    def __init__(self, target: tuple[str, int]) -> None:
        self.target = target
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port: int = self._listener.getsockname()[1]
        self._lock = threading.Lock()
        self._pairs: list[tuple[socket.socket, socket.socket]] = []
        self._threads: list[threading.Thread] = []
        self._cut = False
        self._closed = False
        self.cuts = 0                  # connections closed by a cut
        self.refused = 0               # connections refused while cut
        self._accepting = threading.Thread(target=self._accept, name="cut-proxy", daemon=True)
        self._accepting.start()

    @property
    def is_cut(self) -> bool:
        with self._lock:
            return self._cut

    def cut(self) -> None:
        """The link goes down: every connection closed, new ones refused."""
        with self._lock:
            self._cut = True
            pairs, self._pairs = self._pairs, []
        for a, b in pairs:
            self.cuts += 1
            _close(a)
            _close(b)

    def restore(self) -> None:
        """The link is back: new connections go through again."""
        with self._lock:
            self._cut = False

    def close(self) -> None:
        with self._lock:
            self._closed = True
        self.cut()
        _close(self._listener)
        self._accepting.join(timeout=5)
        for t in list(self._threads):
            t.join(timeout=5)

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self._listener.accept()
            except OSError:
                return                       # closed
            with self._lock:
                refuse = self._cut or self._closed
            if refuse:
                self.refused += 1
                _close(conn)
                continue
            try:
                upstream = socket.create_connection(self.target, timeout=5)
            except OSError:
                _close(conn)
                continue
            for s in (conn, upstream):
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                s.settimeout(None)
            with self._lock:
                if self._cut or self._closed:
                    _close(conn)
                    _close(upstream)
                    continue
                self._pairs.append((conn, upstream))
            for src, dst in ((conn, upstream), (upstream, conn)):
                t = threading.Thread(target=_pump, args=(src, dst), daemon=True,
                                     name="cut-proxy-pump")
                self._threads = [x for x in self._threads if x.is_alive()] + [t]
                t.start()


def _pump(src: socket.socket, dst: socket.socket) -> None:
    """Copy ``src`` to ``dst`` until either closes; then close both."""
    try:
        while True:
            data = src.recv(65536)
            if not data:
                break
            dst.sendall(data)
    except OSError:
        pass
    _close(src)
    _close(dst)


def _close(s: socket.socket) -> None:
    try:
        s.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    try:
        s.close()
    except OSError:
        pass


__all__ = ["CutProxy"]
