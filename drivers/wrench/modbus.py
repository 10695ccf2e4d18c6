"""Register-driven tightening controllers over Modbus TCP or RTU.

    modbus-tcp://HOST[:502]?unit=1&timeout=1.0
    modbus-rtu:///dev/ttyUSB0?baud=19200&parity=E&stopbits=1&unit=1

Such a controller has no messages, only registers (layout: :class:`WrenchRegisterMap`, from
station.yaml), so "acknowledged" has to be built from them.  The handshake:

1. **Parameters.**  The station writes pset, torque target (0.01 Nm) and angle target
   (0.1 deg; a target 0 means "the pset's own"), then, in a separate write, a new sequence
   number to ``request``.  The controller takes the parameter registers only when
   ``request`` changes, so parameters written half-way (link lost, Modbus exception) are
   never used: nothing changes until the request number is written.  It then validates,
   writes ``ack_code`` (0 accepted, else a refusal code, ``ACK_CODES``) and copies the
   number to ``ack``.  The station polls until ``ack`` equals its number; a refusal leaves
   the previous parameters in effect.  Numbers run 1..65535 and the next one always differs
   from the current ``ack``, so a late ack of an abandoned request is never taken for the
   answer to a new one (what Open Protocol's one-command-in-flight rule does for MIDs).
2. **Tool.**  The station sets or clears the tool-enable bit of its control register; the
   command returns once the controller's ``tool_enabled`` status bit follows.
3. **Results.**  The controller fills the result registers, then increments
   ``result_counter`` (it publishes the next result only once the station has written the
   counter back to ``result_ack``, so none is overwritten unseen).  The station's poller
   reads the status block every ``poll`` seconds, queues a new result and acknowledges it.
   After a lost ack write the same result is seen again: (counter, tightening id) dedupes.
   A result whose status register does not read is queued all the same, as an
   ``UnreadableResult`` with its registers (and acknowledged as one, once stored).
   Registers carry no VIN, limits or controller clock (see ``WrenchRegisterMap.result``).
4. **VIN.**  One multiple-register write; the write's response is the acknowledgement.

Every command returns only once acknowledged as above, or raises, saying at which stage it
failed and so whether the controller can have acted.  A timeout or lost link drops the link
(over RTU a late answer would otherwise be read as the answer to the next request) until
``reconnect()`` (one attempt; the station's keeper retries with backoff) re-reads the
station's own registers (request number, control bits, result ack), which also lets a
restarted station continue the sequence.  A Modbus exception keeps the link.  The link itself
(own socket or serial port, typed errors, reads and writes) is ``drivers.modbus_link``,
shared with the lift;
pymodbus is imported there and in ``drivers.modbus_server`` only.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from datetime import datetime
from typing import Any, TypeVar

from drivers.counting import noun
from drivers.endpoint import Endpoint
from drivers.errors import (
    ConnectionLostError,
    DeviceError,
    DeviceTimeoutError,
    ProtocolError,
    RefusedError,
)
from drivers.identity import DeviceIdentity
from drivers.modbus_link import (
    LinkSpec,
    ModbusLink,
    Wording,
    modbus_endpoint,
    parse_modbus_url,
)
from drivers.url import DeviceUrl
from drivers.wrench.base import Received, SupervisedWrench, check_positive
from drivers.wrench.modbus_map import ACK_CODES, WrenchRegisterMap, next_sequence, spans

log = logging.getLogger(__name__)
T = TypeVar("T")
ACK_POLL = 0.01      # seconds between reads while a command waits for the controller
KEYWORDS = ("timeout", "connect_timeout", "poll", "register_map")
#: the wrench's words in link errors (the refused hint is, as it always was, the lift's)
WORDING = Wording(refused="controller off, or not its Modbus port?")


class RegisterLink(ModbusLink):
    """The shared Modbus link, reading and writing holding registers; every failure is a
    typed DeviceError without the device name (the wrench adds it, with what it was doing)."""

    def __init__(self, spec: LinkSpec) -> None:
        super().__init__(spec, "", WORDING)

    def read_span(self, start: int, count: int, timeout: float) -> dict[int, int]:
        unit = self.spec.unit
        values = self.read("holding", start, count, timeout,
                           f"reading registers {start}-{start + count - 1} of unit {unit}")
        if len(values) != count:
            raise ProtocolError(f"asked for {count} registers at {start}, got {len(values)}")
        return dict(zip(range(start, start + count), values, strict=True))

    def write_span(self, start: int, values: list[int], timeout: float) -> None:
        """One request: function 6 for one register, 16 for more (atomic on the device)."""
        self.write(start, values, timeout, f"writing registers {start}-"
                                           f"{start + len(values) - 1} of unit {self.spec.unit}")


class ModbusWrench(SupervisedWrench):
    """A register-driven tightening controller (see the module docstring for the handshake).
    Beyond the :class:`Wrench` interface: :meth:`set_parameters` (pset with torque and angle
    targets) and :meth:`controller_status` (the last polled status bits)."""

    takes_targets = True
    takes_register_map = True

    def __init__(self, spec: LinkSpec | None, *, device: str,
                 register_map: WrenchRegisterMap | None = None, timeout: float = 1.0,
                 connect_timeout: float = 5.0, poll: float = 0.1) -> None:
        super().__init__(device, timeout=timeout)
        check_positive(connect_timeout=connect_timeout, poll=poll)
        self.spec = spec
        self.register_map = register_map if register_map is not None else WrenchRegisterMap()
        self._connect_timeout, self._poll = connect_timeout, poll
        self._io = threading.Lock()          # one request on the wire
        self._cmd = threading.Lock()         # one handshake at a time
        # guarded by _cond, like the link status the base class keeps:
        self._link: RegisterLink | None = None
        self._request = self._control = self._acked = 0   # images of station registers
        self._regs: dict[int, int] = {}                   # the last status block read
        self._delivered: tuple[int, int] | None = None

    @classmethod
    def _endpoint(cls, url: str) -> Endpoint:
        """One unit of a Modbus TCP host and port (502 by default), or a whole RTU line."""
        return modbus_endpoint(url)

    @classmethod
    def from_url(cls, url: DeviceUrl, **kw: Any) -> ModbusWrench:
        """Link options from the URL (unit, baud, parity, stopbits, timeout); keywords (the
        same timeout, connect_timeout, poll, register_map) override them."""
        unknown = sorted(set(kw) - set(KEYWORDS))
        if unknown:
            raise TypeError(f"unknown {noun(len(unknown), 'option')} {', '.join(unknown)} "
                            f"(accepted: {', '.join(KEYWORDS)})")
        spec, timing = parse_modbus_url(url.text)
        opts: dict[str, Any] = {k: v for k, v in timing.items() if v is not None}
        try:
            return cls(spec, device=url.text, **{**opts, **kw})
        except ValueError as e:
            raise url.error(str(e)) from None

    # -- lifecycle -------------------------------------------------------------------------
    def _where(self) -> LinkSpec:
        """Where to connect (the simulated backend sets it when it starts its controller)."""
        if self.spec is None:
            raise DeviceError("no link to the controller", device=self.device)
        return self.spec

    def _open(self) -> None:
        try:
            link = self._session()
        except DeviceError as e:
            raise self._surface(e, "open") from None
        with self._cond:
            self._link = link
        self._thread = threading.Thread(target=self._supervise, daemon=True,
                                        name=f"wrench-modbus {self.device}")
        self._thread.start()

    def _close(self) -> None:
        self._stop.set()
        with self._cond:
            self._closing = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join()
        with self._io, self._cond:
            if self._link is not None:
                self._link.close()
                self._link = None

    def _session(self) -> RegisterLink:
        """Connect and read the station's own registers back (the request number, control
        bits and result ack survive a station restart) and the status block."""
        m, link = self.register_map, RegisterLink(self._where())
        link.connect(self._connect_timeout)
        try:
            own = {m.request.address, m.tool_enable.address, m.result_ack.address}
            regs = self._read(link, own) | self._read(link, m.controller_addresses())
        except BaseException:
            link.close()
            raise
        with self._cond:
            self._request, self._acked = m.integer("request", regs), m.integer("result_ack", regs)
            self._control, self._regs = regs[m.tool_enable.address], regs
        return link

    def _read(self, link: RegisterLink, addresses: set[int]) -> dict[int, int]:
        out: dict[int, int] = {}
        for start, count in spans(addresses):
            out.update(link.read_span(start, count, self.timeout))
        return out

    # -- the poller thread --------------------------------------------------------------------
    def _supervise(self) -> None:
        """Poll the status block every ``poll`` seconds while the link is up (a failure drops
        it, in ``_io_call``; ``reconnect()`` brings it back)."""
        while not self._stop.is_set():
            with self._cond:
                link = self._link
            if link is not None:
                try:
                    self._poll_once(link)
                except DeviceError:
                    pass                      # _io_call dropped the link
            self._stop.wait(self._poll)

    def _reconnect(self) -> None:
        """Drop the link if it is up, then connect and read the station's registers back."""
        with self._io, self._cond:
            old, self._link = self._link, None
            if old is not None:
                self._link_lost("reconnect asked for")
        if old is not None:
            old.close()
        link = self._attempt(self._session)
        with self._cond:
            self._link = link
            self._link_restored()

    def _poll_once(self, link: RegisterLink) -> None:
        m = self.register_map
        try:
            regs = self._io_call(link, lambda li: self._read(li, m.controller_addresses()))
        except RefusedError as e:     # the link works; the station shows it as a fault
            with self._cond:
                if self._poll_error != str(e):
                    log.warning("%s: polling refused: %s", self.device, e)
                self._poll_error = str(e)
            return
        counter = m.integer("result_counter", regs)
        with self._cond:
            self._regs, self._poll_error = regs, None
            if counter in (0, self._acked):
                return
            key = (counter, m.integer("result_id", regs))
            if key != self._delivered:
                self._delivered = key
                try:
                    result: Received = m.result(regs, datetime.now())
                except ValueError as e:
                    # the controller's record of a rundown all the same: kept whole, to be
                    # stored and its bolt held, never acknowledged before that (it was
                    # raised as a fault and acknowledged at once: lost)
                    result = m.unreadable(regs, str(e))
                    log.warning("%s: result %d does not read (%s); kept with its registers "
                                "for the station", self.device, counter, e)
                self._queue_result(result, counter)
                return    # acknowledged when the station has stored it
            elif counter not in self._ack_wanted:
                return        # queued or handed out, not yet stored
            # else: taken, and its acknowledgement failed with the link: write it again
        self._send_ack(counter, self.timeout)

    def _send_ack(self, token: int, timeout: float) -> None:
        """Write the result's counter back to ``result_ack``: the controller may then publish
        the next result (works on a new link too: the counter names the result)."""
        with self._cond:
            link = self._link
        if link is None:
            raise ConnectionLostError("link down")
        self._io_call(link, lambda li: li.write_span(self.register_map.result_ack.address,
                                                     [token], timeout))
        with self._cond:
            self._acked = token

    # -- requests -----------------------------------------------------------------------------
    def _io_call(self, link: RegisterLink, fn: Callable[[RegisterLink], T]) -> T:
        """Run one exchange on ``link`` if it is still the current link; a failure other
        than a Modbus exception drops it (the supervisor reconnects)."""
        with self._io:
            with self._cond:
                if self._link is not link:
                    raise ConnectionLostError("the link was reset; nothing was sent")
            try:
                return fn(link)
            except RefusedError:
                raise
            except DeviceError as e:
                with self._cond:
                    if self._link is link:
                        self._link = None
                        self._link_lost(str(e))
                        self._cond.notify_all()
                        log.warning("%s: link lost: %s", self.device, e)
                link.close()
                raise

    def _write(self, link: RegisterLink, regs: dict[int, int], timeout: float) -> None:
        """Write ``regs`` (address -> value), one request per contiguous run."""
        for start, count in spans(set(regs)):
            def write(li: RegisterLink, s: int = start, n: int = count) -> None:
                li.write_span(s, [regs[a] for a in range(s, s + n)], timeout)
            self._io_call(link, write)

    def _current(self, what: str) -> RegisterLink:
        with self._cond:
            if self._link is None:
                raise self._down(what, "; nothing was sent")
            return self._link

    def _wait_status(self, link: RegisterLink, done: Callable[[dict[int, int]], bool],
                     timeout: float) -> tuple[bool, dict[int, int]]:
        """Read the status block until ``done`` says yes or ``timeout`` runs out (at least
        one read either way): (done, the last registers read)."""
        deadline = time.monotonic() + timeout
        while True:
            regs = self._io_call(link, lambda li: self._read(
                li, self.register_map.controller_addresses()))
            with self._cond:
                self._regs = regs
            if done(regs) or time.monotonic() >= deadline:
                return done(regs), regs
            time.sleep(ACK_POLL)

    # -- commands -----------------------------------------------------------------------------
    def send_parameters(self, pset: int | None, torque_nm: float, angle_deg: float | None,
                        timeout: float | None = None) -> None:
        """A register-driven controller takes the pset with the torque and angle targets."""
        self.set_parameters(pset or 0, torque_nm, angle_deg or 0.0, timeout)

    def set_parameters(self, pset: int, torque_nm: float = 0.0, angle_deg: float = 0.0,
                       timeout: float | None = None) -> None:
        """Send pset and targets (0 = the pset's own) with the request/ack handshake; returns
        once the controller accepted them.  RefusedError (``code`` from ``ACK_CODES``, or a
        Modbus exception), DeviceTimeoutError, ConnectionLostError: treat as not done; the
        message says whether the request can have reached the controller."""
        if isinstance(pset, bool) or not isinstance(pset, int) or pset < 0:
            raise ValueError(f"pset must be a non-negative integer, not {pset!r}")
        regs = self._parameters(pset, torque_nm, angle_deg)     # ValueError: nothing sent
        self._check_open()
        targets = f" ({torque_nm:g} Nm, {angle_deg:g} deg)" if torque_nm or angle_deg else ""
        self._handshake(regs, f"set parameters pset {pset}{targets}", self._timeout(timeout))

    def _parameters(self, pset: int, torque_nm: float, angle_deg: float) -> dict[int, int]:
        m = self.register_map
        return {**m.encode("pset", pset), **m.encode("torque_target", torque_nm),
                **m.encode("angle_target", angle_deg)}

    def _handshake(self, regs: dict[int, int], what: str, timeout: float) -> None:
        m = self.register_map
        with self._cmd:
            link = self._current(what)
            with self._cond:
                seq = next_sequence(self._request)
                if seq == m.integer("ack", self._regs):
                    seq = next_sequence(seq)
            stage = "parameters"
            try:
                self._write(link, regs, self.timeout)
                with self._cond:     # never reuse a number that may have reached the device
                    self._request = seq
                stage = "request"
                self._io_call(link, lambda li: li.write_span(m.request.address, [seq],
                                                             self.timeout))
                stage = "ack"
                acked, status = self._wait_status(link, lambda r: m.integer("ack", r) == seq,
                                                  timeout)
                if not acked:
                    raise DeviceTimeoutError(f"request {seq} not acknowledged within "
                                             f"{timeout:g} s (ack register holds "
                                             f"{m.integer('ack', status)})")
                if not any(s <= m.ack.address < s + c and s <= m.ack_code.address < s + c
                           for s, c in m.status_spans()):   # apart: it may predate the ack
                    status |= self._io_call(link, lambda li: self._read(
                        li, {m.ack_code.address}))
            except DeviceError as e:
                refused = isinstance(e, RefusedError)
                note = ("; not sent, the previous parameters stay in effect"
                        if stage == "parameters" or (stage == "request" and refused) else
                        f"; request {seq} may have reached the controller: treat it as not "
                        "done")
                raise self._surface(e, what, note) from None
        code = m.integer("ack_code", status)
        if code:
            raise RefusedError(f"{what}: refused by the controller: code {code} ("
                               f"{ACK_CODES.get(code, 'unknown code')}); the previous "
                               "parameters stay in effect", device=self.device, code=code)

    def _select_pset(self, pset: int, timeout: float) -> None:
        self._handshake(self._parameters(pset, 0.0, 0.0), f"select pset {pset}", timeout)

    def _set_tool(self, enabled: bool, timeout: float) -> None:
        m, what = self.register_map, "enable tool" if enabled else "disable tool"
        bit = m.tool_enable
        with self._cmd:
            link = self._current(what)
            with self._cond:
                value = bit.applied(self._control, enabled)
            try:
                self._io_call(link, lambda li: li.write_span(bit.address, [value], self.timeout))
                with self._cond:
                    self._control = value
                done, _ = self._wait_status(
                    link, lambda r: m.bit("tool_enabled", r) == enabled, timeout)
            except DeviceError as e:
                raise self._surface(e, what, "; treat it as not done") from None
            if not done:
                raise DeviceTimeoutError(f"{what}: the controller's tool_enabled bit did not "
                                         f"follow within {timeout:g} s; treat it as not done",
                                         device=self.device)

    def _send_vin(self, vin: str, timeout: float) -> None:
        regs = self.register_map.encode_vin(vin)                 # ValueError: nothing sent
        with self._cmd:
            link = self._current(f"send VIN {vin}")
            try:
                self._write(link, regs, timeout)
            except DeviceError as e:
                raise self._surface(e, f"send VIN {vin}", "; treat it as not done") from None

    # -- the Wrench hooks ----------------------------------------------------------------------
    def _link_up(self) -> bool:
        return self._link is not None

    def _identification(self) -> DeviceIdentity:
        """Words only: the register map has no identity registers (no manufacturer, serial
        or software version to read), and the link's address is no nameplate field."""
        return DeviceIdentity(f"register-driven tightening controller, "
                              f"{self._where().describe()}")

    def controller_status(self) -> tuple[bool, bool]:
        """(tool enabled, parameters valid) as of the last poll."""
        self._check_open()
        with self._cond:
            return (self.register_map.bit("tool_enabled", self._regs),
                    self.register_map.bit("parameters_valid", self._regs))
