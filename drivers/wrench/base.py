"""The tightening-controller interface every backend implements (like python-can's ``BusABC``).

The public methods do the shared work (state checks, argument checks, default timeouts) and
call one small ``_hook`` each backend overrides, so every backend refuses the same bad calls
with the same errors.

Why blocking calls with timeouts rather than asyncio: the station's cycle issues one command
at a time and waits for its acknowledgement; a blocking API with a timeout is the simplest
contract that says "acknowledged or failed" and is directly usable from the CLI and tests.
The daemon's asyncio loop calls it through ``asyncio.to_thread`` (STYLE 4).  Backends are
thread-safe: a command may be issued from one thread while another waits for results.

Both backends (Open Protocol, Modbus registers) read their link with a supervisor thread and
queue results as they arrive; a lost link stays down until ``reconnect()`` (one attempt; the
station's :class:`drivers.keeper.DeviceKeeper` retries with backoff).
:class:`SupervisedWrench` is the bookkeeping they share (link status, waiting for the link or
a result, error wording).
"""

from __future__ import annotations

import logging
import threading
import time
from abc import abstractmethod
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import datetime
from enum import IntEnum, StrEnum
from typing import Any, TypeVar

from drivers.counting import counted
from drivers.errors import ConnectionLostError, DeviceError, RefusedError
from drivers.identity import DeviceIdentity
from drivers.lifecycle import Openable

log = logging.getLogger(__name__)
T = TypeVar("T")


class Status(IntEnum):
    """Torque or angle status of a tightening (Open Protocol: 0 low, 1 OK, 2 high)."""

    LOW = 0
    OK = 1
    HIGH = 2


class ResultType(IntEnum):
    """What a result reports (Open Protocol MID 0061 revision 3+, parameter 49): a loosening
    or a batch counter change is a result too, and must never be taken for a tightening."""

    TIGHTENING = 1
    LOOSENING = 2
    BATCH_INCREMENT = 3
    BATCH_DECREMENT = 4
    BYPASS_PSET = 5
    ABORT_JOB = 6
    SYNC_TIGHTENING = 7
    REFERENCE_SETUP = 8

    @property
    def closes_a_bolt(self) -> bool:
        """Only a tightening (synchronized spindles included) can close a bolt."""
        return self in (ResultType.TIGHTENING, ResultType.SYNC_TIGHTENING)


class ResultKind(StrEnum):
    """What the station makes of a result, from its type (:func:`result_kind`)."""

    TIGHTENING = "tightening"    # can close a bolt
    LOOSENING = "loosening"      # recorded as a loosening (may reopen the bolt)
    EVENT = "event"              # a controller event (batch step, bypass, abort, reference)
    UNKNOWN = "unknown"          # a type code the specification does not name: never a rundown


def result_kind(code: int | None, sent_loosen: bool = False) -> ResultKind:
    """The kind of a result whose type code is ``code`` (None: the revision carries no type,
    MID 0061 revisions 1-2 or a register map without one: then what the station sent, a
    loosen pset or a tightening one, decides)."""
    if code is None:
        return ResultKind.LOOSENING if sent_loosen else ResultKind.TIGHTENING
    try:
        t = ResultType(code)
    except ValueError:
        return ResultKind.UNKNOWN
    if t.closes_a_bolt:
        return ResultKind.TIGHTENING
    return ResultKind.LOOSENING if t is ResultType.LOOSENING else ResultKind.EVENT


class TorqueUnit(IntEnum):
    """The unit the controller shows torques in (MID 0061 revision 3+, parameter 48).  The
    result's ``*_nm`` fields are converted to Nm whatever it is (see ``to_nm``)."""

    NM = 1
    LBF_FT = 2
    LBF_IN = 3
    KPM = 4
    KGF_CM = 5
    OZF_IN = 6
    PERCENT = 7
    NCM = 8

    @property
    def to_nm(self) -> float | None:
        """Nm per unit; None for a percentage of the tool's maximum (not convertible)."""
        return _NM_PER_UNIT.get(self)


_NM_PER_UNIT = {TorqueUnit.NM: 1.0, TorqueUnit.LBF_FT: 1.3558179483314004,
                TorqueUnit.LBF_IN: 0.1129848290276167, TorqueUnit.KPM: 9.80665,
                TorqueUnit.KGF_CM: 0.0980665, TorqueUnit.OZF_IN: 0.00706155181422604,
                TorqueUnit.NCM: 0.01}


@dataclass(frozen=True)
class TighteningResult:
    """One tightening as the controller reported it; units are Nm and degrees.

    ``ok`` is the controller's verdict (not recomputed here: the controller owns the limits).
    ``timestamp`` is the controller's local clock, naive, as it sent it.

    The fields after ``raw`` come with Open Protocol revisions 2 to 7 of MID 0061/0065 (and
    are None, empty or 0 when the revision, or the backend, does not carry them):
    ``revision`` is the one the result came in, ``fetched`` says it was asked for after the
    fact (MID 0064/0065) rather than pushed.  A result whose ``torque_unit`` is
    ``PERCENT`` keeps its torques as sent (percent of the tool's maximum), not in Nm.
    MID 0065 revision 1 carries no limits, cell, channel or controller name: they are 0 or
    empty there.
    """

    ok: bool
    torque_nm: float
    angle_deg: float
    torque_status: Status
    angle_status: Status
    tightening_id: int
    pset: int
    vin: str
    timestamp: datetime
    torque_min_nm: float
    torque_max_nm: float
    torque_target_nm: float
    angle_min_deg: float
    angle_max_deg: float
    angle_target_deg: float
    cell_id: int = 0
    channel_id: int = 0
    controller_name: str = ""
    job: int = 0
    batch_size: int = 0
    batch_counter: int = 0
    batch_status: int = 0
    pset_changed: datetime | None = None
    raw: str = field(default="", repr=False, compare=False)
    # -- revision 2 and later (Open Protocol) -------------------------------------------------
    revision: int = 1
    fetched: bool = False
    strategy: int | None = None              # 1 torque control, 2 torque/angle monitoring, ...
    strategy_options: int | None = None      # a bit field, as sent
    result_type: ResultType | None = None
    #: the type code as sent (revision 3+), also one the specification does not name (then
    #: ``result_type`` is None): never read a result without a known type as a tightening
    result_type_code: int | None = None
    pset_name: str = ""
    torque_unit: TorqueUnit | None = None
    rundown_angle_status: Status | None = None
    current_monitoring_status: Status | None = None
    selftap_status: Status | None = None
    prevail_torque_monitoring_status: Status | None = None
    prevail_torque_compensate_status: Status | None = None
    tightening_error_status: int | None = None     # a bit field: why a NOK stopped
    tightening_error_status2: int | None = None
    rundown_angle_min_deg: float | None = None
    rundown_angle_max_deg: float | None = None
    rundown_angle_deg: float | None = None
    current_monitoring_min_pct: float | None = None
    current_monitoring_max_pct: float | None = None
    current_monitoring_pct: float | None = None
    selftap_min_nm: float | None = None
    selftap_max_nm: float | None = None
    selftap_nm: float | None = None
    prevail_torque_min_nm: float | None = None
    prevail_torque_max_nm: float | None = None
    prevail_torque_nm: float | None = None
    prevail_torque_compensate_nm: float | None = None
    job_sequence_number: int | None = None
    sync_tightening_id: int | None = None
    tool_serial: str = ""
    identifiers: tuple[str, ...] = ()          # identifier result parts 2-4 (revision 4+)
    customer_error_code: str = ""
    compensated_angle_deg: float | None = None
    angle_decimal_deg: float | None = None     # the final angle with its decimals (rev 7)
    #: the revision the header claimed, when the body was laid out as a lower one (read at
    #: ``revision``: ``drivers.wrench.openprotocol.reading``); None when it matched its label
    header_revision: int | None = None
    #: whether ``timestamp`` is the controller's own time of the tightening (False: a
    #: controller without a clock, register-driven, whose results the station stamps as it
    #: reads them): only the controller's own time tells a copy it sends again from another
    #: result under the same id
    controller_clock: bool = True


@dataclass(frozen=True)
class UnreadableResult:
    """A result message the driver could not read at any revision: kept whole, so that it is
    stored (raw text, revision, the parse error) before the controller is told it may forget
    it, and the bolt it may belong to is held for a person to check on the controller.

    ``tightening_id``, ``pset`` and ``vin`` are what could still be picked out of it (None or
    empty when not even that).  Handed out by ``wait_result`` like a result and acknowledged
    the same way (``acknowledge_result``)."""

    raw: str
    mid: int
    revision: int
    error: str
    tightening_id: int | None = None
    pset: int | None = None
    vin: str = ""
    timestamp: datetime | None = None
    fetched: bool = False
    #: the lower revision its body read as, had that revision carried a result type (its
    #: header's does, 3+; a result without its type may be a loosening): None otherwise
    laid_out_as: int | None = None
    #: how many of ``raw``'s first characters are the message's header (Open Protocol's 20,
    #: a sequence number among them): the same message sent again has the same ``body``
    header_len: int = 0

    @property
    def body(self) -> str:
        """The message without its header: what a copy the controller sends again repeats."""
        return self.raw[self.header_len:]


#: what ``wait_result`` hands out: a result, or one that could not be read
Received = TighteningResult | UnreadableResult


@dataclass(frozen=True)
class LinkStatus:
    """What the daemon shows while a device is faulty: up or down, why, and retry counts."""

    connected: bool
    reason: str | None = None
    attempts: int = 0        # failed reconnect attempts since the link went down
    reconnects: int = 0      # successful reconnects since open()



#: a controller clock this far from the station's is worth a person's look (a clock not
#: set, or a time zone): the journal warns of it and ``probe wrench`` says to set it, s
CLOCK_FAR_S = 60.0


def clock_seconds(offset: float) -> int:
    """A controller clock's offset (:attr:`Wrench.clock_offset_s`) in whole seconds as the
    words say it: the controller's whole seconds are its clock cut down, so a clock in step
    measures -1..0 s, said 0 (the middle of that second)."""
    return round(offset + 0.5)


class Wrench(Openable):
    """A tightening controller: select a parameter set, enable the tool, receive results.

    ``open()`` connects (and fails fast with a typed :class:`DeviceError`); after that a lost
    link stays down (every command says so at once) until ``reconnect()``.  ``close()`` may be
    called any number of times; a closed wrench cannot be reopened (make a new one, as with
    python-can).
    It is a context manager (``drivers.lifecycle.Openable``).
    """

    def __init__(self, device: str, *, timeout: float = 2.0) -> None:
        if timeout <= 0:
            raise ValueError("timeout must be > 0")
        self.device = device
        self.timeout = timeout
        self._life = threading.Lock()
        self._opened = False
        self._closed = False

    # -- lifecycle -------------------------------------------------------------------------
    def open(self) -> None:
        """Connect and start the session; a second call does nothing."""
        with self._life:
            if self._closed:
                raise DeviceError("closed; open a new one", device=self.device)
            if self._opened:
                return
            try:
                self._open()
            except BaseException:
                self._release()
                raise
            self._opened = True

    def close(self) -> None:
        """Stop everything and release the link; safe to call twice or before ``open()``."""
        with self._life:
            if self._closed:
                return
            self._closed = True
            if self._opened:
                try:
                    self._close()
                finally:
                    self._release()

    def reconnect(self) -> None:
        """Drop the link (if it is up) and start a new session: one attempt, a DeviceError if
        it fails.  Results already queued stay queued; the controller resends the ones not
        acknowledged."""
        with self._life:
            if self._closed or not self._opened:
                raise DeviceError("not open", device=self.device)
            self._reconnect()

    @abstractmethod
    def _reconnect(self) -> None:
        """One attempt to bring the link back (called with the lifecycle lock held)."""

    @property
    def is_open(self) -> bool:
        return self._opened and not self._closed

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open" if self._opened else "new"
        return f"<{type(self).__name__} {self.device} {state}>"

    # -- commands --------------------------------------------------------------------------
    def identity(self) -> str:
        """The controller's own name (and cell/channel), as it introduced itself: the words
        of :meth:`identification`."""
        return self.identification().words

    def identification(self) -> DeviceIdentity:
        """Who the controller says it is, typed: its words and the nameplate fields the
        backend knows (manufacturer, model, serial number, software revision), one reading
        (words and fields of the same session)."""
        self._check_open()
        return self._identification()

    def status(self) -> LinkStatus:
        """Link state for the station's fault display; never raises once opened."""
        self._check_open()
        return self._status()

    def wait_connected(self, timeout: float) -> bool:
        """Wait until the link is up (e.g. after a reconnect); False on timeout."""
        self._check_open()
        return self._wait_connected(timeout)

    def select_pset(self, pset: int, timeout: float | None = None) -> None:
        """Select parameter set ``pset`` (0-999): returns only once the controller accepted it.

        Raises RefusedError (with the controller's ``code``), DeviceTimeoutError or
        ConnectionLostError; in every failure the selection must be treated as not done.
        """
        if isinstance(pset, bool) or not isinstance(pset, int) or not 0 <= pset <= 999:
            raise ValueError(f"pset must be an integer 0-999, not {pset!r}")
        self._check_open()
        self._select_pset(pset, self._timeout(timeout))

    def enable_tool(self, timeout: float | None = None) -> None:
        """Allow the operator to run the tool; returns once acknowledged."""
        self._check_open()
        self._set_tool(True, self._timeout(timeout))

    def disable_tool(self, timeout: float | None = None) -> None:
        """Lock the tool; returns once acknowledged."""
        self._check_open()
        self._set_tool(False, self._timeout(timeout))

    def send_vin(self, vin: str, timeout: float | None = None) -> None:
        """Tell the controller which vehicle the next results belong to."""
        if not isinstance(vin, str):
            raise TypeError(f"vin must be a str, not {type(vin).__name__}")
        self._check_open()
        self._send_vin(vin, self._timeout(timeout))

    def wait_result(self, timeout: float, *, acknowledge: bool = True
                    ) -> Received | None:
        """The next tightening result, or None if none came within ``timeout`` seconds.

        Results already received are returned even after the link dropped; with none
        pending and the link down, raises ConnectionLostError (the station's fault state).

        The controller is told a result is taken (Open Protocol MID 0062, the Modbus result
        ack register) only when it is handed out, never on mere receipt.  With
        ``acknowledge=False`` the caller does it with :meth:`acknowledge_result` once the
        result is stored: a result lost before that (the process killed) is one the
        controller was never told it could forget.
        """
        if timeout < 0:
            raise ValueError("timeout must be >= 0")
        self._check_open()
        result = self._wait_result(timeout)
        if result is not None and acknowledge:
            try:
                self._ack_result(result, self.timeout)
            except DeviceError as e:  # the result is still the caller's; the controller
                log.warning("%s", e)  # keeps it too, unacknowledged
        return result

    def acknowledge_result(self, result: Received, timeout: float | None = None) -> None:
        """Tell the controller ``result`` (from ``wait_result(..., acknowledge=False)``) is
        stored.  ValueError for a result that is not awaiting acknowledgement (acknowledged
        twice, or not from this wrench); ConnectionLostError when the link it came on is
        gone (the controller still holds it)."""
        self._check_open()
        self._ack_result(result, self._timeout(timeout))

    def send_parameters(self, pset: int | None, torque_nm: float, angle_deg: float | None,
                        timeout: float | None = None) -> None:
        """A bolt's parameters to the controller, the way this controller takes them: here a
        pset (the program is on the controller; Open Protocol's MID 0018); a register-driven
        controller overrides this to take the targets too.  A bolt without a pset is refused
        like a pset the controller does not know."""
        if pset is None:
            raise RefusedError("the bolt has no pset and this controller takes psets only",
                               device=self.device)
        self.select_pset(pset, timeout)

    #: whether :meth:`send_parameters` takes a bolt's own targets (a register-driven
    #: controller); False: the controller selects psets only (its programs are its own, Open
    #: Protocol's MID 0018), and a bolt without a pset is refused
    takes_targets: bool = False

    #: whether the controller is driven through a register map a station file may give
    #: (``wrench.registers``, ``drivers/wrench/modbus_map.py``); False: its protocol has no
    #: registers to map (Open Protocol), and a map given for it is a mistake of the file
    takes_register_map: bool = False

    #: whether :meth:`fetch_result` can ask the controller for a stored result (Open
    #: Protocol's MID 0064); a register-driven controller keeps none
    can_fetch: bool = False

    def fetch_result(self, tightening_id: int, timeout: float | None = None
                     ) -> Received | None:
        """The controller's stored result ``tightening_id`` (0: its newest), or None when it
        no longer has it; an :class:`UnreadableResult` (``fetched=True``, nothing to
        acknowledge) when it answered with one that does not read.  This controller keeps
        none (``can_fetch`` is False)."""
        raise DeviceError("this controller keeps no results to fetch", device=self.device)

    @property
    def clock_offset_s(self) -> float | None:
        """The controller's clock minus the station's, in seconds, as measured at the start
        of the current (or last) session: a result's ``timestamp`` (the controller's naive
        local time) minus this is the station's local time it was made at.  None when the
        controller did not say its time (never asked, refused, no answer), and for a
        controller without a clock (register-driven: results are stamped by the station)."""
        return None

    def check_clock(self) -> float | None:
        """Measure the controller's clock again (:attr:`clock_offset_s` says it from now on)
        and return it.  Why: a connection lasts days, and a controller's clock drifts from
        the station's by seconds in that time, beyond the slack within which results fetched
        late are placed by their time.  A controller without a clock: None, nothing asked."""
        return self.clock_offset_s

    #: whether the controller can send tightening curves (Open Protocol's MID 0900 through
    #: the generic subscription); a register-driven controller sends none
    can_curves: bool = False

    @property
    def curves_on(self) -> bool:
        """Whether curves are subscribed on the current session (never, here)."""
        return False

    def subscribe_curves(self, timeout: float | None = None) -> bool:
        """Ask for the tightening curves; False: this controller sends none."""
        return False

    def wait_curve(self, timeout: float) -> Any:
        """The next tightening curve (``drivers.wrench.openprotocol.curve.Curve``), or None after
        ``timeout``; this controller sends none (``can_curves`` is False)."""
        raise DeviceError("this controller sends no curves", device=self.device)

    def fetch_curve(self, tightening_id: int, timeout: float | None = None) -> list[Any]:
        """The curves (``drivers.wrench.openprotocol.curve.Curve``, one per trace type) of an
        earlier tightening, asked for after the fact (a result fetched after a link cut); empty
        when the controller does not give them (any more).  Not queued for
        :meth:`wait_curve`.  This controller sends none (``can_curves`` is False)."""
        raise DeviceError("this controller sends no curves", device=self.device)

    # -- helpers and hooks -----------------------------------------------------------------
    def _timeout(self, timeout: float | None) -> float:
        if timeout is None:
            return self.timeout
        if timeout <= 0:
            raise ValueError("timeout must be > 0")
        return timeout

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceError("closed", device=self.device)
        if not self._opened:
            raise DeviceError("not open (call open() or use it as a context manager)",
                              device=self.device)

    @abstractmethod
    def _open(self) -> None: ...

    @abstractmethod
    def _close(self) -> None: ...

    def _release(self) -> None:
        """Release what the wrench owns besides its link (the simulated backends: the
        controller they started in-process): after an ``open()`` that failed, and after
        ``close()``, whatever happened in between.  Nothing by default."""

    @abstractmethod
    def _identification(self) -> DeviceIdentity: ...

    @abstractmethod
    def _status(self) -> LinkStatus: ...

    @abstractmethod
    def _wait_connected(self, timeout: float) -> bool: ...

    @abstractmethod
    def _select_pset(self, pset: int, timeout: float) -> None: ...

    @abstractmethod
    def _set_tool(self, enabled: bool, timeout: float) -> None: ...

    @abstractmethod
    def _send_vin(self, vin: str, timeout: float) -> None: ...

    @abstractmethod
    def _wait_result(self, timeout: float) -> Received | None: ...

    @abstractmethod
    def _ack_result(self, result: Received, timeout: float) -> None: ...


def check_positive(**values: float) -> None:
    """ValueError naming the first of ``values`` (in the order given) that is not > 0."""
    for name, value in values.items():
        if not value > 0:
            raise ValueError(f"{name} must be > 0, not {value}")


class SupervisedWrench(Wrench):
    """A backend whose link a supervisor thread reads (polls, keep-alives) and whose results
    are queued as they arrive.  Everything below is guarded by ``_cond``; the
    backend says whether its link is up (:meth:`_link_up`) and keeps the counts:
    ``_reason`` why the link went down, ``_last_error`` of the last failed attempt,
    ``_attempts`` failed since then, ``_reconnects`` since open, ``_poll_error`` a failure
    that leaves the link up."""

    def __init__(self, device: str, *, timeout: float = 2.0) -> None:
        super().__init__(device, timeout=timeout)
        self._cond = threading.Condition()
        self._closing = False
        self._reason: str | None = None
        self._last_error: str | None = None
        self._poll_error: str | None = None
        self._attempts = self._reconnects = 0
        self._results: deque[Received | DeviceError] = deque()
        # results handed out but not yet acknowledged: id(result) -> (result, the backend's
        # token for the acknowledgement: the link epoch, the result counter)
        self._unacked: dict[int, tuple[Received, int]] = {}
        self._ack_wanted: set[int] = set()  # tokens whose acknowledgement failed: retry them
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @abstractmethod
    def _link_up(self) -> bool:
        """Whether the link is up (called with ``_cond`` held)."""

    @abstractmethod
    def _send_ack(self, token: int, timeout: float) -> None:
        """Acknowledge the result received with ``token`` (not called with ``_cond`` held)."""

    def _queue_result(self, result: Received, token: int) -> None:
        """Queue a received result; it is acknowledged later with ``token`` (``_cond`` held)."""
        self._results.append(result)
        self._unacked[id(result)] = (result, token)
        self._cond.notify_all()

    def _ack_result(self, result: Received, timeout: float) -> None:
        with self._cond:
            entry = self._unacked.get(id(result))
            if entry is None or entry[0] is not result:
                raise ValueError(f"tightening {result.tightening_id} is not awaiting "
                                 "acknowledgement (already acknowledged, or not from "
                                 f"{self.device})")
            token = entry[1]
            self._ack_wanted.add(token)
        try:
            self._send_ack(token, timeout)
        except DeviceError as e:
            raise self._surface(e, f"acknowledge tightening {result.tightening_id}",
                                "; the controller still holds it") from None
        with self._cond:
            self._unacked.pop(id(result), None)
            self._ack_wanted.discard(token)

    # -- the counts, as the supervisor sees the link go and come back (``_cond`` held) -------
    def _link_lost(self, reason: str) -> None:
        self._reason, self._attempts = reason, 0

    def _attempt_failed(self, e: DeviceError) -> int:
        """Count a failed reconnect attempt; the number of them so far."""
        self._attempts += 1
        self._last_error = str(e)
        return self._attempts

    def _link_restored(self) -> None:
        """Count a reconnect (the link is up again) and wake whoever waits for it."""
        self._reason = self._last_error = None
        self._attempts = 0
        self._reconnects += 1
        self._cond.notify_all()
        log.info("%s: reconnected", self.device)

    def _attempt(self, connect: Callable[[], T]) -> T:
        """One reconnect attempt, ``connect()``: a failure is counted and raised as
        "reconnect: ..." with the device's name."""
        try:
            return connect()
        except DeviceError as e:
            with self._cond:
                self._attempt_failed(e)
            raise self._surface(e, "reconnect") from None

    def _surface(self, e: DeviceError, what: str, note: str = "") -> DeviceError:
        """The error as the caller sees it: device name, what was being done, the code."""
        return type(e)(f"{what}: {e}{note}", device=self.device, code=e.code)

    def _down(self, what: str, note: str = "") -> ConnectionLostError:
        """What a caller sees while the link is down (call with ``_cond`` held)."""
        last = f"; last attempt: {self._last_error}" if self._last_error else ""
        tried = f"; {counted(self._attempts, 'failed reconnect')}" if self._attempts else ""
        return ConnectionLostError(f"{what}: link down ({self._reason}){tried}{last}{note}",
                                   device=self.device)

    def _status(self) -> LinkStatus:
        with self._cond:
            up = self._link_up()
            reason = self._poll_error if up else self._reason
            if not up and reason and self._last_error:
                reason = f"{reason}; last attempt: {self._last_error}"
            return LinkStatus(up, reason, self._attempts, self._reconnects)

    def _wait_connected(self, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        with self._cond:
            while not self._link_up() and not self._closing:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._cond.wait(remaining)
            return self._link_up()

    def _wait_result(self, timeout: float) -> Received | None:
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                if self._results:
                    item = self._results.popleft()
                    if isinstance(item, DeviceError):
                        raise self._surface(item, "tightening result")
                    return item
                if self._closing:
                    raise DeviceError("closed", device=self.device)
                if not self._link_up():
                    raise self._down("listening for results")   # the station always does
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return None
                self._cond.wait(remaining)
