"""A simulated register-driven tightening controller, and ``sim+modbus://wrench``.

:class:`SimRegisterController` is a real pymodbus server (Modbus TCP on 127.0.0.1, a free
port; Modbus RTU on one end of a pty pair) whose registers follow the handshake documented
in ``modbus.py``, written from the controller's side: it latches the parameter registers
when the request number changes, validates them against its pset table (the Open Protocol
simulator's :class:`SimPset`), writes ack code then ack; it follows the tool-enable bit; it
publishes one result at a time and the next only once the station wrote the counter back.

Its own state (``_regs``) is the truth; pymodbus's block is refreshed from it on every
request by the device ``action`` (the server around it, event loop thread, TCP, RTU and pty
pair, comes from ``drivers.modbus_server``, as for the lift's PLC), and the controller's
registers are read-only on the wire (a write is exception 2).  Time-dependent behaviour is
evaluated lazily on each request or world call, so there is no scan thread.

Faults for tests: ``set_silent`` (no answers), ``hang`` (Modbus answers, the logic stops:
no acks, the tool bit does not follow), ``set_ack_delay``, one-shot ``inject`` on the next
write covering an address ("exception": answered with a Modbus exception and not applied,
"drop": neither applied nor answered, "lost_answer": applied but not answered), and
``power_off`` / ``power_on`` (volatile registers cleared; same TCP port and pty path).

``sim+modbus://wrench[?transport=tcp|rtu&seed=0&nok_rate=0.05&unit=1]`` starts one and
talks to it through the real :class:`ModbusWrench` (a separate scheme, because ``sim://``
belongs to the Open Protocol simulation).
"""

from __future__ import annotations

import random
import threading
import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal, cast

from drivers.counting import noun
from drivers.identity import DeviceIdentity
from drivers.modbus_link import LinkSpec
from drivers.modbus_server import SimServer
from drivers.url import DeviceUrl
from drivers.wrench.modbus import KEYWORDS, ModbusWrench
from drivers.wrench.modbus_map import WrenchRegisterMap, next_sequence, pack_status, spans
from drivers.wrench.sim.controller import DEFAULT_PSETS, SimPset

Fault = Literal["exception", "drop", "lost_answer"]
WRITES = (6, 16)        # the function codes the controller accepts besides 3 (read)
ILLEGAL_FUNCTION = 1    # the Modbus exception code for any other function


@dataclass(frozen=True)
class SimParameters:
    """A parameter set the controller accepted; targets 0 = the pset's own."""

    pset: int
    torque_nm: float
    angle_deg: float


@dataclass(frozen=True)
class SimResult:
    """One tightening as the controller published it (the simulation's ground truth)."""

    tightening_id: int
    pset: int
    ok: bool
    torque_nm: float
    angle_deg: float
    torque_status: int
    angle_status: int
    result_type: int = 1


class SimRegisterController(SimServer):
    """The simulated controller: ``start_tcp()`` / ``start_rtu()``, then drive it with
    :meth:`pull_trigger` and the fault controls; ``refusals`` maps a pset to an ack code."""

    def __init__(self, register_map: WrenchRegisterMap | None = None,
                 psets: Mapping[int, SimPset] | None = None, *, unit: int = 1, seed: int = 0,
                 nok_rate: float = 0.05, refusals: Mapping[int, int] | None = None) -> None:
        if not 0.0 <= nok_rate <= 1.0:
            raise ValueError(f"nok_rate must be in [0, 1], not {nok_rate}")
        super().__init__(thread_name="wrench-sim-modbus", pty_name="wrench-sim-pty")
        self.map = register_map if register_map is not None else WrenchRegisterMap()
        self.psets = dict(DEFAULT_PSETS if psets is None else psets)
        self.unit, self.nok_rate = unit, nok_rate
        self._rng = random.Random(seed)  # noqa: S311 - seeded simulation scatter, not security
        self._refusals = dict(refusals or {})
        self._lock = threading.Lock()
        self._station = self.map.station_addresses()
        self._regs = dict.fromkeys(self._station | self.map.controller_addresses(), 0)
        self.active: SimParameters | None = None
        self.history: list[SimParameters] = []      # every set it accepted, in order
        self._pending: tuple[int, SimParameters, float] | None = None  # seq, latched, due
        self._queue: deque[SimResult] = deque()
        self._tid = 0
        self._ack_delay, self._hung, self._silent, self._mute = 0.0, False, False, False
        self._garble = False             # the next result published with a torque status 3
        self._fault: tuple[Fault, int, int] | None = None
        self._serving = (False, False)               # TCP, RTU before power_off()

    # -- the world's side ------------------------------------------------------------------
    def registers(self) -> dict[int, int]:
        """What the controller serves right now (address -> value)."""
        with self._lock:
            self._refresh()
            return dict(self._regs)

    def pull_trigger(self, result_type: int = 1) -> SimResult | None:
        """The operator pulls the trigger: a tightening with the active parameters, queued
        for publication; None (nothing happens) if the tool is disabled or none are active.
        ``result_type`` (Open Protocol's codes) goes to the map's ``result_type`` register,
        where it has one."""
        with self._lock:
            self._refresh()
            if self.active is None or not self.map.bit("tool_enabled", self._regs):
                return None
            result = replace(self._tighten(self.active), result_type=result_type)
            if self._garble:
                self._garble = False
                result = replace(result, torque_status=3)
            self._queue.append(result)
            self._refresh()
            return result

    def garble_next_result(self) -> None:
        """The next trigger pull's result is published with a torque status 3 in its status
        register, a code the layout does not define (a result the station cannot read)."""
        with self._lock:
            self._garble = True

    def refuse_pset(self, pset: int, code: int) -> None:
        with self._lock:
            self._refusals[pset] = code

    def set_ack_delay(self, seconds: float) -> None:
        """Acknowledge requests ``seconds`` after they arrive (``math.inf``: never)."""
        with self._lock:
            self._ack_delay = seconds

    def hang(self, hung: bool = True) -> None:
        """Stop (or resume) the controller's logic; Modbus keeps answering."""
        with self._lock:
            self._hung = hung
            self._refresh()

    def set_silent(self, silent: bool = True) -> None:
        """Receive and apply requests but answer none: the master times out."""
        self._silent = silent

    def inject(self, fault: Fault, address: int, code: int = 4) -> None:
        """A one-shot fault on the next write that covers ``address`` (``code``: the Modbus
        exception code for "exception", a member of pymodbus's ExcCodes)."""
        with self._lock:
            self._fault = (fault, address, code)

    def power_off(self) -> None:
        """The controller disappears: servers stop, volatile registers and queued results
        are lost (the tightening id counter is kept, like a controller's result store)."""
        if self._tcp is not None or self._rtu is not None:
            self._serving = (self._tcp is not None, self._rtu is not None)
        self.stop_tcp()
        self.stop_rtu()
        with self._lock:
            self._regs = dict.fromkeys(self._regs, 0)
            self.active, self._pending, self._fault = None, None, None
            self._queue.clear()

    def power_on(self) -> None:
        """Back on the same TCP port and pty path."""
        tcp, rtu = self._serving
        if tcp:
            self.start_tcp(self.tcp_port or 0)
        if rtu:
            self.start_rtu()

    # -- the controller ---------------------------------------------------------------------
    def _set(self, name: str, value: float) -> None:
        self._regs.update(self.map.encode(name, value))

    def _set_bit(self, name: str, on: bool) -> None:
        b = getattr(self.map, name)
        self._regs[b.address] = b.applied(self._regs[b.address], on)

    def _written(self, addresses: set[int], before: dict[int, int]) -> None:
        """React to the station's writes (called with the new values in place)."""
        m = self.map
        seq = m.integer("request", self._regs)
        if m.request.address in addresses and seq not in (0, m.integer("request", before)):
            latched = SimParameters(m.integer("pset", self._regs),
                                    m.decode("torque_target", self._regs),
                                    m.decode("angle_target", self._regs))
            self._pending = (seq, latched, time.monotonic() + self._ack_delay)

    def _validate(self, p: SimParameters) -> int:
        pset = self.psets.get(p.pset)
        if pset is None:
            return 1
        if p.pset in self._refusals:
            return self._refusals[p.pset]
        if p.torque_nm and not pset.torque_min_nm <= p.torque_nm <= pset.torque_max_nm:
            return 2
        if p.angle_deg and not pset.angle_min_deg <= p.angle_deg <= pset.angle_max_deg:
            return 3
        return 0

    def _refresh(self) -> None:
        """Run what is due: a pending request, the tool bit, publishing a queued result."""
        if self._hung:
            return
        m, regs = self.map, self._regs
        if self._pending is not None and time.monotonic() >= self._pending[2]:
            seq, params, _ = self._pending
            self._pending = None
            code = self._validate(params)
            if code == 0:
                self.active = params
                self.history.append(params)
                self._set_bit("parameters_valid", True)
            self._set("ack_code", code)          # the code first, then the ack
            self._set("ack", seq)
        self._set_bit("tool_enabled", m.bit("tool_enable", regs))
        counter = m.integer("result_counter", regs)
        if self._queue and m.integer("result_ack", regs) == counter:
            r = self._queue.popleft()
            for name, value in (("result_status", pack_status(r.ok, r.torque_status,
                                                               r.angle_status)),
                                ("result_pset", r.pset), ("result_torque", r.torque_nm),
                                ("result_angle", r.angle_deg), ("result_id", r.tightening_id)):
                self._set(name, value)
            if m.result_type is not None:
                self._set("result_type", r.result_type)
            self._set("result_counter", next_sequence(counter))

    def _tighten(self, active: SimParameters) -> SimResult:
        p, rng, m = self.psets[active.pset], self._rng, self.map
        limits = ((active.torque_nm or p.torque_nm, p.torque_min_nm, p.torque_max_nm),
                  (active.angle_deg or p.angle_deg, p.angle_min_deg, p.angle_max_deg))
        values = [min(max(rng.gauss(t, (hi - lo) / 12), lo), hi) for t, lo, hi in limits]
        if rng.random() < self.nok_rate:          # a NOK: one value just outside its limits
            i = rng.randrange(2)
            _, lo, hi = limits[i]
            miss = rng.uniform(0.02, 0.2) * (hi - lo)
            values[i] = lo - miss if rng.random() < 0.5 else hi + miss
        stats = []
        for i, name in enumerate(("result_torque", "result_angle")):
            # what the registers can hold is what the station will read
            values[i] = m.decode(name, m.encode(name, max(values[i], 0.0)))
            _, lo, hi = limits[i]
            stats.append(0 if values[i] < lo else 2 if values[i] > hi else 1)
        self._tid += 1
        return SimResult(self._tid, active.pset, stats == [1, 1], values[0], values[1],
                         stats[0], stats[1])

    # -- the server's side -------------------------------------------------------------------
    def _action(self, function_code: int, start: int, address: int, count: int,
                registers: list[int], values: list[int] | list[bool] | None) -> int | None:
        """Called before each request is served, for reads and writes."""
        if function_code != 3 and function_code not in WRITES:
            return ILLEGAL_FUNCTION
        with self._lock:
            if values is not None:
                covered = set(range(address, address + len(values)))
                fault, self._fault = self._fault, None
                if fault is not None and fault[1] not in covered:
                    self._fault, fault = fault, None
                if fault is not None and fault[0] == "exception":
                    return fault[2]
                self._mute = fault is not None
                if fault is None or fault[0] == "lost_answer":
                    before = dict(self._regs)
                    self._regs.update((a, int(v)) for a, v in zip(sorted(covered), values,
                                                                  strict=True))
                    self._written(covered, before)
            self._refresh()
            for a, v in self._regs.items():
                registers[a - start] = v
            if values is not None:   # pymodbus stores the values after this returns
                cast(list[int], values)[:] = [self._regs[a] for a in sorted(covered)]
        return None

    def _trace(self, sending: bool, packet: bytes) -> bytes:
        if sending and (self._silent or self._mute):
            self._mute = False
            return b""
        return packet

    def _blocks(self) -> list[tuple[int, int, bool]]:
        """One block per contiguous run of mapped registers: the gaps answer exception 2,
        and the controller's registers are read-only on the wire."""
        station = self._station
        return [(a, n, a not in station)
                for run in (spans(station), spans(set(self._regs) - station)) for a, n in run]


class SimModbusWrench(ModbusWrench):
    """``sim+modbus://wrench``: a :class:`SimRegisterController` (``controller``, for the
    world to drive) behind the real Modbus backend, over TCP or RTU."""

    simulated = True

    def __init__(self, controller: SimRegisterController, *, transport: str = "tcp",
                 device: str = "sim+modbus://wrench", **kw: Any) -> None:
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"transport must be tcp or rtu, not {transport!r}")
        super().__init__(None, device=device, register_map=controller.map, **kw)
        self.controller, self.transport = controller, transport

    @classmethod
    def from_url(cls, url: DeviceUrl, **kw: Any) -> SimModbusWrench:
        """Options: transport, seed, nok_rate, unit and the backend's timings; keywords:
        those, plus the controller's psets, refusals and register_map."""
        if url.host != "wrench" or url.path not in ("", "/"):
            raise url.error("expected sim+modbus://wrench")
        timing = {k: (float, None) for k in KEYWORDS if k != "register_map"}
        opts = url.typed_options({"transport": (str, "tcp"), "seed": (int, 0),
                                  "nok_rate": (float, 0.05), "unit": (int, 1), **timing},
                                 "sim+modbus://wrench?transport=rtu&seed=1&nok_rate=0.1")
        sim_kw = {k: kw.pop(k) for k in ("psets", "refusals", "register_map") if k in kw}
        unknown = sorted(set(kw) - set(opts))
        if unknown:
            raise TypeError(f"unknown {noun(len(unknown), 'option')} {', '.join(unknown)}")
        opts = {k: v for k, v in {**opts, **kw}.items() if v is not None}
        try:
            controller = SimRegisterController(unit=opts.pop("unit"), seed=opts.pop("seed"),
                                               nok_rate=opts.pop("nok_rate"), **sim_kw)
            return cls(controller, device=url.text, **opts)
        except ValueError as e:
            raise url.error(str(e)) from None

    def _open(self) -> None:
        c = self.controller
        if self.transport == "tcp":
            self.spec = LinkSpec("tcp", "127.0.0.1", c.start_tcp(), c.unit)
        else:       # ptys refuse parity bits: 8N1
            self.spec = LinkSpec("rtu", c.start_rtu(), 0, c.unit, 19200, "N", 1)
        super()._open()

    def _release(self) -> None:
        """The controller started at open (its server and pty)."""
        self.controller.close()

    def _identification(self) -> DeviceIdentity:
        """The real backend's (words only), said to be simulated."""
        ident = super()._identification()
        return replace(ident, words=f"simulated {ident.words}")

