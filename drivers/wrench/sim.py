"""A simulated tightening controller, and ``sim://wrench``, the backend that talks to it.

``SimController`` is a real Open Protocol server (``simserver.py``: TCP on loopback, RS-232
on a pty) with a controller's behaviour written from docs/PROTOCOLS.md: it knows a set of
psets, answers 0001 with 0002, commands with 0005 or 0004 and the specification's error
codes, mirrors 9999, drops a client silent for 15 s, and, when the operator pulls the
trigger with the tool enabled and a pset selected, reports a MID 0061 revision 1 result with
seeded scatter around the pset's targets and NOKs at ``nok_rate``.  Its 0061 writer is a
table of tags and widths, independent of the client's byte-position parser.

``SimWrench`` is the real client (``client.OpenProtocolWrench``) plus the lifecycle of an
in-process controller: ``sim://wrench`` exercises the whole protocol path.
"""

from __future__ import annotations

import os
import random
import shutil
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

from drivers.link import Link, SerialLink, TcpLink
from drivers.url import DeviceUrl
from drivers.wrench.client import OPTIONS, REFUSED, OpenProtocolWrench, Spec, keyword_options
from drivers.wrench.simserver import OpenProtocolServer, Received, Session, message

_TIME = "%Y-%m-%d:%H:%M:%S"
VIN_WIDTH = 25


@dataclass(frozen=True)
class SimPset:
    """A parameter set as programmed on the controller: targets and limits."""

    torque_nm: float
    torque_min_nm: float
    torque_max_nm: float
    angle_deg: float
    angle_min_deg: float
    angle_max_deg: float
    batch_size: int = 1


DEFAULT_PSETS: dict[int, SimPset] = {
    1: SimPset(25.0, 22.5, 27.5, 90.0, 60.0, 120.0),
    2: SimPset(45.0, 40.5, 49.5, 120.0, 90.0, 150.0),
    3: SimPset(110.0, 99.0, 121.0, 45.0, 30.0, 60.0),
}


@dataclass(frozen=True)
class SimTightening:
    """What the controller reported for one trigger pull (the simulation's ground truth)."""

    tightening_id: int
    pset: int
    ok: bool
    torque_nm: float
    angle_deg: float
    torque_status: int
    angle_status: int
    vin: str
    timestamp: datetime
    message: bytes = field(repr=False)     # header + data, without NUL or framing


def _fixed(value: float, width: int) -> str:
    return f"{min(max(round(value), 0), 10**width - 1):0{width}d}"


def _text(value: str, width: int) -> str:
    return value[:width].ljust(width)


class SimController(OpenProtocolServer):
    """The simulated controller; ``start()`` it (or use ``with``), then ``listen_tcp()``
    and/or ``open_pty()``.  ``refusals`` maps a pset to the error code its selection gets."""

    def __init__(self, psets: Mapping[int, SimPset] | None = None, *, seed: int = 0,
                 nok_rate: float = 0.05, name: str = "SimController", cell: int = 1,
                 channel: int = 1, silence_timeout: float = 15.0,
                 refusals: Mapping[int, int] | None = None,
                 clock: Callable[[], datetime] | None = None,
                 resend_unacked: bool = False) -> None:
        if not 0.0 <= nok_rate <= 1.0:
            raise ValueError(f"nok_rate must be in [0, 1], not {nok_rate}")
        if silence_timeout <= 0:
            raise ValueError("silence_timeout must be > 0")
        super().__init__()
        self.psets = dict(DEFAULT_PSETS if psets is None else psets)
        self.nok_rate, self.name, self.cell, self.channel = nok_rate, name, cell, channel
        self.silence_timeout = silence_timeout
        self._rng = random.Random(seed)  # noqa: S311 - seeded simulation scatter, not security
        self._clock = clock or (lambda: datetime.now().replace(microsecond=0))
        self._refuse_pset: dict[int, int] = dict(refusals or {})
        self._refuse_mid: dict[int, int] = {}
        self.pset: int | None = None
        self.tool_enabled = False
        self.vin = ""
        self.acks = 0                            # MID 0062 received
        self.acked_ids: list[int] = []           # the tightenings those 0062 acknowledged
        self._pset_changed = self._clock()
        self._batch_counter = self._tid = 0
        # as some controllers do: results nobody acknowledged (MID 0062) are sent again to
        # the next subscriber, oldest first
        self.resend_unacked = resend_unacked
        self._unacked: dict[int, bytes] = {}     # tightening id -> its MID 0061
        self._rundown: int | None = None         # the pset of a rundown under way

    def __enter__(self) -> SimController:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- controls for the simulation and tests ----------------------------------------------
    def pull_trigger(self) -> SimTightening | None:
        """The operator pulls the trigger: a tightening with the selected pset, reported to
        subscribed integrators; None (nothing happens) if the tool is disabled or no pset."""
        return self.call(self._tighten)

    def start_rundown(self) -> bool:
        """The trigger pulled, the rundown under way (its result comes with
        :meth:`finish_rundown`, whatever happens to the tool meanwhile: a rundown started
        is finished); False (nothing happens) if the tool is disabled or no pset."""
        def do() -> bool:
            if not self.tool_enabled or self.pset is None:
                return False
            self._rundown = self.pset
            return True
        return self.call(do)

    def finish_rundown(self) -> SimTightening:
        """The rundown started by :meth:`start_rundown` ends: its result is reported."""
        def do() -> SimTightening:
            if self._rundown is None:
                raise RuntimeError("no rundown under way")
            pset, self._rundown = self._rundown, None
            return self._result(pset)
        return self.call(do)

    def refuse_pset(self, pset: int, code: int) -> None:
        self.call(lambda: self._refuse_pset.__setitem__(pset, code))

    def refuse_mid(self, mid: int, code: int) -> None:
        """Refuse every command ``mid`` with ``code`` (MID 0004)."""
        self.call(lambda: self._refuse_mid.__setitem__(mid, code))

    def clear_refusals(self) -> None:
        def do() -> None:
            self._refuse_pset.clear()
            self._refuse_mid.clear()
        self.call(do)

    def on_power_on(self) -> None:
        """Volatile state is lost in a power cycle; the selected pset is kept."""
        self.tool_enabled, self.vin = False, ""

    # -- the controller ---------------------------------------------------------------------
    def _refuse(self, s: Session, mid: int, code: int) -> None:
        self.reply(s, mid, 4, f"{mid:04d}{code:02d}".encode())

    def _ok(self, s: Session, mid: int) -> None:
        self.reply(s, mid, 5, f"{mid:04d}".encode())

    def handle(self, s: Session, msg: Received) -> None:
        mid, data = msg.mid, msg.data
        if mid == 9999:
            self.reply(s, 9999, 9999)
        elif mid == 1:
            if msg.revision > 1:
                self._refuse(s, mid, 97)
            elif s.started and s.kind == "tcp":
                self._refuse(s, mid, 96)
            else:   # on a serial line a new 0001 starts a new session
                s.started, s.subscribed = True, False
                s.out.clear()
                ident = f"01{self.cell:04d}02{self.channel:02d}03{_text(self.name, 25)}"
                self.reply(s, mid, 2, ident.encode())
        elif not s.started:
            self.errors.append(f"MID {mid:04d} before communication start ignored")
        elif mid in self._refuse_mid:
            self._refuse(s, mid, self._refuse_mid[mid])
        elif mid == 3:
            self._ok(s, mid)
            s.started = s.subscribed = False
        elif mid == 18:
            self._select(s, data)
        elif mid in (42, 43):
            self.tool_enabled = mid == 43
            self._ok(s, mid)
        elif mid == 50:
            if len(data) > VIN_WIDTH or not data.isascii():
                self._refuse(s, mid, 1)
            else:
                self.vin = data.decode().strip()
                self._ok(s, mid)
        elif mid in (60, 63):
            if msg.revision > 1:
                self._refuse(s, mid, 97)
            elif s.subscribed == (mid == 60):    # already (un)subscribed
                self._refuse(s, mid, 9 if mid == 60 else 10)
            else:
                s.subscribed = mid == 60
                self._ok(s, mid)
                if s.subscribed and self.resend_unacked:
                    for tid, raw in self._unacked.items():
                        if tid not in s.unacked:
                            self.write(s, s.frame(raw))
                            s.unacked.append(tid)
        elif mid == 62:   # 0062 names no result: it acknowledges the oldest one sent
            self.acks += 1
            if s.unacked:
                tid = s.unacked.pop(0)
                self.acked_ids.append(tid)
                self._unacked.pop(tid, None)
        else:
            self._refuse(s, mid, 99)

    def _select(self, s: Session, data: bytes) -> None:
        if len(data) != 3 or not data.isdigit():
            self._refuse(s, 18, 1)
        elif int(data) in self._refuse_pset:
            self._refuse(s, 18, self._refuse_pset[int(data)])
        elif int(data) not in self.psets:
            self._refuse(s, 18, 2)
        else:
            if int(data) != self.pset:
                self.pset, self._pset_changed = int(data), self._clock()
                self._batch_counter = 0
            self._ok(s, 18)

    def _tighten(self) -> SimTightening | None:
        if not self.tool_enabled or self.pset is None:
            return None
        return self._result(self.pset)

    def _result(self, pset: int) -> SimTightening:
        """A tightening with ``pset``, reported to every subscribed session."""
        p, rng = self.psets[pset], self._rng
        t_lo, t_hi = round(p.torque_min_nm * 100), round(p.torque_max_nm * 100)
        a_lo, a_hi = round(p.angle_min_deg), round(p.angle_max_deg)
        torque = min(max(rng.gauss(p.torque_nm * 100, (t_hi - t_lo) / 12), t_lo), t_hi)
        angle = min(max(rng.gauss(p.angle_deg, (a_hi - a_lo) / 12), a_lo), a_hi)
        if rng.random() < self.nok_rate:        # a NOK: one value just outside its limits
            side = rng.choice(("torque_low", "torque_high", "angle_low", "angle_high"))
            miss = rng.uniform(0.02, 0.2)
            lo, hi = (t_lo, t_hi) if side.startswith("torque") else (a_lo, a_hi)
            value = lo - miss * (hi - lo) - 1 if side.endswith("low") else \
                hi + miss * (hi - lo) + 1
            torque, angle = (value, angle) if side.startswith("torque") else (torque, value)
        t_val, a_val = max(round(torque), 0), max(round(angle), 0)
        t_stat = 0 if t_val < t_lo else 2 if t_val > t_hi else 1
        a_stat = 0 if a_val < a_lo else 2 if a_val > a_hi else 1
        ok = t_stat == a_stat == 1
        self._batch_counter += int(ok)
        self._tid += 1
        now = self._clock()
        values = (  # MID 0061 revision 1: parameters 01-23 in order, fixed widths
            _fixed(self.cell, 4), _fixed(self.channel, 2), _text(self.name, 25),
            _text(self.vin, VIN_WIDTH), "00", _fixed(pset, 3), _fixed(p.batch_size, 4),
            _fixed(self._batch_counter, 4), str(int(ok)), str(t_stat), str(a_stat),
            _fixed(t_lo, 6), _fixed(t_hi, 6), _fixed(p.torque_nm * 100, 6), _fixed(t_val, 6),
            _fixed(a_lo, 5), _fixed(a_hi, 5), _fixed(p.angle_deg, 5), _fixed(a_val, 5),
            now.strftime(_TIME), self._pset_changed.strftime(_TIME),
            "1" if self._batch_counter >= p.batch_size else "0", _fixed(self._tid, 10))
        raw = message(61, "".join(f"{tag:02d}{v}" for tag, v in enumerate(values, 1))
                      .encode("ascii"))
        if self.resend_unacked:
            self._unacked[self._tid] = raw
        for s in self.sessions():
            if s.started and s.subscribed:
                self.write(s, s.frame(raw))
                s.unacked.append(self._tid)
        return SimTightening(self._tid, pset, ok, t_val / 100, float(a_val), t_stat,
                             a_stat, self.vin, now, raw)


class SimWrench(OpenProtocolWrench):
    """``sim://wrench[?transport=tcp|serial&seed=0&nok_rate=0.05]``: starts a SimController
    in-process and talks to it with the real Open Protocol client.  ``controller`` is the
    simulation's handle on it (pull the trigger, refuse, inject faults, power cycle)."""

    def __init__(self, controller: SimController, *, transport: str = "tcp",
                 device: str = "sim://wrench", **kw: Any) -> None:
        if transport not in ("tcp", "serial"):
            raise ValueError(f"transport must be tcp or serial, not {transport!r}")
        super().__init__(None, device=device, **kw)
        self.controller = controller
        self.transport = transport
        self._pty_dir: str | None = None

    @classmethod
    def from_url(cls, url: DeviceUrl, **kw: Any) -> SimWrench:
        """Options: transport, seed, nok_rate and the client's; keywords: those, plus the
        controller's psets, refusals, clock and silence_timeout."""
        if url.host != "wrench" or url.path not in ("", "/"):
            raise url.error("expected sim://wrench")
        spec: Spec = {**OPTIONS, "transport": (str, "tcp"), "seed": (int, 0),
                      "nok_rate": (float, 0.05)}
        sim_kw = {k: kw.pop(k) for k in ("psets", "refusals", "clock", "silence_timeout")
                  if k in kw}
        opts = url.typed_options(spec, "sim://wrench?transport=serial&seed=1&nok_rate=0.1")
        opts.update(keyword_options(kw, spec))
        try:
            controller = SimController(seed=opts.pop("seed"), nok_rate=opts.pop("nok_rate"),
                                       **sim_kw)
            return cls(controller, device=url.text, **opts)
        except ValueError as e:
            raise url.error(str(e)) from None

    def _make_link(self) -> Link:
        self.controller.start()
        if self.transport == "serial":   # behind a symlink, so a power cycle keeps the path
            self._pty_dir = tempfile.mkdtemp(prefix="sim-wrench-")
            return SerialLink(self.controller.open_pty(os.path.join(self._pty_dir, "tty")))
        return TcpLink("127.0.0.1", self.controller.listen_tcp(), REFUSED)

    def _open(self) -> None:
        try:
            super()._open()
        except BaseException:
            self._release()
            raise

    def _close(self) -> None:
        try:
            super()._close()
        finally:
            self._release()

    def _release(self) -> None:
        self.controller.close()
        if self._pty_dir is not None:
            shutil.rmtree(self._pty_dir, ignore_errors=True)
