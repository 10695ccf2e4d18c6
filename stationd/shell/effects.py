"""The core's actions carried out: the controller told, the database written, events
published, answers given; what came of each goes back to the core as an event.

Why apart from the daemon's loops: this is the one place where an action meets a device or
the database, so what a failure means is decided once.  A controller that drops its link is
a fault its keeper reconnects (a refusal is the controller's answer, not a lost link); a
database that refuses a write is a fault its keeper probes back, and the result stays with the
station (:mod:`stationd.shell.records`) or with the controller (not acknowledged), never
lost.  Every blocking call runs through ``call`` (the daemon's executor).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import Any, TypeVar, assert_never

from db.bolts import Parameters
from db.repository import Repository
from drivers.errors import DeviceError, RefusedError
from drivers.keeper import DeviceKeeper, FaultKind, fault_kind, one_line
from drivers.wrench import Received, Wrench
from stationd.bus import EventBus
from stationd.localize import Localization
from stationd.reasons import Reason, UncheckedKind, Why
from stationd.shell.blocking import Blocking
from stationd.shell.journal import RefusalJournal
from stationd.shell.records import STATION_FAULTS, Records
from stationd.shell.sdnotify import Notifier
from stationd.station.actions import (
    Acknowledge,
    Action,
    CheckNewest,
    CloseVehicle,
    DisableTool,
    EnableTool,
    LoadVehicle,
    NoteLock,
    Publish,
    Record,
    RecordCommand,
    RecordRefusal,
    Reply,
    SendParams,
    SendVin,
    SettleClosing,
    SettleEnable,
    StoreControllerEvent,
    StoreCutUnknown,
    StoreGap,
    StoreUnattributed,
    StoreUnreadable,
)
from stationd.station.commands import Answer
from stationd.station.core import StationCore
from stationd.station.events import (
    BoltToLoosen,
    DeviceHealth,
    Notice,
    OperatorChanged,
    PairChecked,
    Refused,
    State,
    StateChanged,
    StationEvent,
    VehicleClosed,
    VehicleOpened,
)
from stationd.station.inputs import (
    DATABASE,
    WRENCH,
    CommandDone,
    DeviceFault,
    Event,
    NotStored,
    ParamsAcked,
    ParamsRefused,
    ToolOn,
    VinSent,
    Written,
)
from stationd.station.trust import MeasureReferences, RecordCheck
from stationd.words import (
    answer_words,
    check_words,
    notice_words,
    operator_words,
    reason_words,
    state_line,
    stored_what,
    worded,
)

log = logging.getLogger("stationd")
#: every command's line, accepted or refused: its own logger, so a front that journals only
#: warnings (the demo) still journals the accepted ones, as the daemon does
commands_log = logging.getLogger("stationd.commands")


class _Prefixed(logging.LoggerAdapter):  # type: ignore[type-arg]
    """A station's journal lines with its name first (see :meth:`Effects.label`)."""

    def process(self, msg: Any, kwargs: Any) -> tuple[Any, Any]:
        return f"{self.extra['prefix'] if self.extra else ''} {msg}", kwargs

    def __init__(self, logger: logging.Logger, prefix: str) -> None:
        super().__init__(logger, {"prefix": prefix})


Journal = logging.Logger | _Prefixed
A = TypeVar("A")
#: a notice's level (:attr:`Notice.level`) as the journal's
NOTICE_LEVELS = {"info": logging.INFO, "warning": logging.WARNING, "error": logging.ERROR}
#: a pair not checked for these reasons is being checked as the station works (its start, a
#: vehicle's arrival): the journal's INFO, where a pair moved or never measurable is a WARNING
ROUTINE_UNCHECKED = frozenset({UncheckedKind.SINCE_START, UncheckedKind.ARRIVAL})
#: how long the controller may take to confirm parameters, s
SEND_TIMEOUT_S = 2.0


class Effects:
    """Carries out the core's actions; :meth:`do` answers what came of one, for the core."""

    def __init__(self, core: StationCore, records: Records, wrench: DeviceKeeper[Wrench],
                 database: DeviceKeeper[Repository], bus: EventBus, notifier: Notifier,
                 call: Blocking, measure: Callable[[MeasureReferences], None],
                 check_newest: Callable[[int | None, bool], None] = lambda *_: None) -> None:
        self.core, self.records, self.bus, self.notifier = core, records, bus, notifier
        self._measure = measure
        self._check_newest = check_newest    # started, never waited for (it feeds the core)
        self._wrench, self._database, self._call = wrench, database, call
        self.answers: dict[int, asyncio.Future[Answer]] = {}   # request -> who waits
        self.refusals = RefusalJournal()   # each refusal journaled once, then counted
        self.log: Journal = log
        self.commands_log: Journal = commands_log
        self._fault_said = ""   # the last "state: fault (...)" journaled: not said twice

    def label(self, prefix: str) -> None:
        """Each of this station's journal lines starts with ``prefix`` ("DEMO-2"). Why: the
        demo runs a line's stations in one process, one output; a notice of station 2 came
        without its station's name."""
        self.log = _Prefixed(log, prefix)
        self.commands_log = _Prefixed(commands_log, prefix)
        # its records' lines too (a new user's trial: "vehicle ... closed" of two stations,
        # one VIN twice with different counts, neither named)
        self.records.log = _Prefixed(log, prefix)

    async def do(self, a: Action) -> Event | None:
        """Carry out one action; what came of it, for the core (or None)."""
        try:
            return await self._do(a)
        except DeviceError as exc:   # the link is reset: its keeper reconnects and reports
            if not isinstance(exc, RefusedError):
                self._wrench.lost(exc)
            return DeviceFault(time.time(), WRENCH, fault_kind(exc), one_line(exc))

    async def _do(self, a: Action) -> Event | None:
        """Every kind of action has its branch, checked by the type checker (a kind added to
        ``Action`` without one fails ``mypy`` at ``assert_never``)."""
        if isinstance(a, Publish):
            self.publish(a.event)
            return None
        wrench = self._wrench.device
        if isinstance(a, SendParams | SendVin | EnableTool) and wrench is None:
            return DeviceFault(time.time(), WRENCH, FaultKind.DOWN, "not connected")
        if isinstance(a, SendParams):
            assert wrench is not None  # noqa: S101 - checked above
            return await self._send(wrench, a)
        if isinstance(a, EnableTool):
            assert wrench is not None  # noqa: S101 - checked above
            return await self._enable_tool(wrench, a)
        if isinstance(a, SendVin):
            assert wrench is not None  # noqa: S101 - checked above
            return await self._send_vin(wrench, a.vin)
        if isinstance(a, DisableTool):
            if wrench is not None:
                await self._call(wrench.disable_tool)
            if self.records.owes_off_time:
                await self._call(self.records.note_off)
        elif isinstance(a, LoadVehicle):
            return await self._database_step(self.records.load_vehicle, a)
        elif isinstance(a, CloseVehicle):
            try:
                return await self._call(self.records.close_vehicle, a.vin,
                                        a.after_lift_outage, a.due)
            except STATION_FAULTS as exc:
                self.log.error("vehicle %s not closed: %s", a.vin, one_line(exc))
        elif isinstance(a, SettleClosing):
            try:
                return await self._call(self.records.settle_closing, a)
            except STATION_FAULTS as exc:   # its records are right: the report reads them
                self.log.error("vehicle %s: its closing verdict, the result due of %s "
                               "settled, not read: %s", a.vin, ", ".join(a.settled),
                               one_line(exc))
        elif isinstance(a, Record):
            return await self._record(a)
        elif isinstance(a, Acknowledge):
            await self.acknowledge(a.result)
        elif isinstance(a, StoreUnattributed):
            await self._store_unattributed(a)
        elif isinstance(a, StoreGap):
            try:
                await self._call(self.records.record_gap, a.first, a.last, a.vin, a.reason)
            except STATION_FAULTS as exc:   # the database's fault too: seen, not only said
                self._database.lost(DeviceError(one_line(exc)))
                self.log.error("gap %d-%d not stored: %s", a.first, a.last, one_line(exc))
        elif isinstance(a, StoreControllerEvent):
            await self._store_then_ack(self.records.store_controller_event, a, a.result,
                                       f"{stored_what(a)} (a controller event)")
        elif isinstance(a, SettleEnable):
            try:
                await self._call(self.records.settle, a.selection)
            except STATION_FAULTS as exc:
                self.log.warning("the tool enable for %s not settled: %s", a.selection.bolt,
                                 one_line(exc))
        elif isinstance(a, StoreCutUnknown):
            try:
                await self._call(self.records.store_cut_unknown, a)
            except STATION_FAULTS as exc:
                self._database.lost(DeviceError(one_line(exc)))
                self.log.error("the hold of %s after the link cut not stored (held until a "
                               "restart): %s", a.bolt, one_line(exc))
        elif isinstance(a, StoreUnreadable):
            await self._store_then_ack(self.records.store_unreadable, a, a.unreadable,
                                       "an unreadable result")
        elif isinstance(a, RecordCommand):
            return await self._record_command(a)
        elif isinstance(a, RecordRefusal):
            try:
                await self._call(self.records.record_refusal, a)
            except STATION_FAULTS as exc:   # the person has the answer; the trail lacks it
                self.log.warning("the refused command of %s not recorded: %s", a.issuer.user,
                                 one_line(exc))
        elif isinstance(a, NoteLock):
            try:
                await self._call(self.records.note_lock, a)
            except STATION_FAULTS as exc:   # kept: written first when the database is back
                self._database.lost(DeviceError(one_line(exc)))
                self.log.warning("the lock of %s not recorded yet (kept, recorded when the "
                                 "database is back): %s", a.bolt, one_line(exc))
        elif isinstance(a, Reply):
            self._reply(a.answer)
        elif isinstance(a, CheckNewest):
            self._check_newest(a.serial, a.tool_on)
        elif isinstance(a, MeasureReferences):
            self._measure(a)
        elif isinstance(a, RecordCheck):
            try:
                await self._call(self.records.record_check, a)
            except STATION_FAULTS as exc:
                self._database.lost(DeviceError(one_line(exc)))
                self.log.error("calibration check of %s not recorded: %s", a.check.pair,
                               one_line(exc))
        else:
            assert_never(a)
        return None

    def publish(self, ev: StationEvent) -> None:
        """An event of the core to the screens and feeds, and its journal line.  The one path
        from the core to the bus: the words of what the core decided typed (a skip, the
        station's own fault) are written into the event here (:func:`worded`), so the core
        says no English and every reader gets the text it read before."""
        ev = worded(ev)
        self.bus.publish(ev)
        if isinstance(ev, StateChanged | VehicleOpened | VehicleClosed):
            for line in self.refusals.ended(ev.t):   # the refusals' episode ended
                self.log.info("%s", line)
        if isinstance(ev, StateChanged):
            line = state_line(ev.state, ev.reason)
            self.notifier.status(line)
            if ev.state is State.FAULT:   # each device's own line has the reason
                faulty = f"state: fault ({', '.join(sorted(self.core.status().faults))})"
                if faulty != self._fault_said:   # a reason that changed is the device's line
                    self.log.info("%s", faulty)
                self._fault_said = faulty
            else:
                self._fault_said = ""
                self.log.info("%s", line)
        elif isinstance(ev, Notice):
            self.log.log(NOTICE_LEVELS[ev.level], "%s", notice_words(ev))
        elif isinstance(ev, Refused):   # once, then counted (a wrench held between two bolts)
            said = self.refusals.refused(ev.reason, ev.t)
            if said is not None:
                self.log.info("%s", said)
        elif isinstance(ev, PairChecked):   # a pair moved is a warning; one being checked
            routine = ev.why is not None and ev.why.unchecked is not None and \
                ev.why.unchecked.kind in ROUTINE_UNCHECKED       # for a vehicle is not
            (self.log.info if ev.trusted or routine else self.log.warning)(
                "%s", check_words(ev))
        elif isinstance(ev, BoltToLoosen):
            self.log.info("%s", reason_words(ev.reason, full=True))   # it names the bolt
        elif isinstance(ev, OperatorChanged):
            self.log.info("%s", operator_words(ev))
        elif isinstance(ev, DeviceHealth):
            if ev.ok:
                self.log.info("%s: back", ev.device)
            else:
                self.log.warning("fault: %s (%s): %s", ev.device, ev.kind, ev.reason)

    def _database_lost(self, exc: Exception, what: str = "") -> DeviceFault:
        """A database fault: its keeper probes it back, with backoff."""
        self._database.lost(DeviceError(one_line(exc)))
        return DeviceFault(time.time(), DATABASE, FaultKind.DOWN, f"{what}{one_line(exc)}")

    async def _database_step(self, fn: Callable[[A], Event], arg: A) -> Event:
        try:
            return await self._call(fn, arg)
        except STATION_FAULTS as exc:
            return self._database_lost(exc)

    async def _enable_tool(self, wrench: Wrench, a: EnableTool) -> Event:
        """What the station owes goes to disk first (the bolt, its pset and version, where
        the wrench was), then the tool is enabled: a reload or a kill from here on still
        records the result to this bolt.  A database that refuses it is a fault of the
        database and the tool stays off."""
        try:
            await self._call(self.records.note_enable, a.selection)
        except STATION_FAULTS as exc:
            return self._database_lost(exc, "the tool enable not stored: ")
        await self._call(wrench.enable_tool)
        return ToolOn(time.time(), a.bolt)

    async def _send(self, wrench: Wrench, a: SendParams) -> Event:
        params = a.parameters
        if params is None:   # a vehicle loaded without its parameters: never guessed
            return ParamsRefused(time.time(), a.bolt, "no parameters for this bolt")
        t_send = time.time()
        try:
            await self._call(_send_parameters, wrench, params)
        except RefusedError as exc:
            return ParamsRefused(time.time(), a.bolt, one_line(exc))
        now = time.time()
        sel = a.selection
        loc = sel.evidence if isinstance(sel.evidence, Localization) else None
        lat = {"total": (now - sel.exposure_t) * 1e3,
               "localize": (sel.decided_t - sel.exposure_t) * 1e3,
               "decide": (t_send - sel.decided_t) * 1e3, "acknowledge": (now - t_send) * 1e3,
               "vision_slowest_pair": loc.timings_ms.get("vision", 0.0) if loc else 0.0,
               "grab_slowest_pair": loc.timings_ms.get("grab", 0.0) if loc else 0.0}
        return ParamsAcked(now, a.bolt, params.pset, lat)

    async def _send_vin(self, wrench: Wrench, vin: str) -> Event:
        try:
            await self._call(wrench.send_vin, vin)
        except ValueError as exc:   # the controller cannot take it (no VIN registers, length)
            self.log.info("VIN %s not sent to the controller: %s", vin, exc)
        except RefusedError as exc:
            self.log.warning("the controller refused VIN %s: %s", vin, one_line(exc))
        return VinSent(time.time(), vin)

    async def _record(self, a: Record) -> Event | None:
        """On disk first, then the controller may forget it.  A database that refuses the
        write (disk full, server gone) is a fault of the database: nothing more is tightened,
        the result is kept in memory and journaled, its keeper writes it when the database
        takes writes again (then it is published and acknowledged, as any other)."""
        r, sel = a.result, a.selection
        loc = sel.evidence if sel is not None and isinstance(sel.evidence, Localization) \
            else None
        u = await self._call(self.records.unsaved_result, a, loc)
        try:
            await self._call(self.records.write, u)
        except STATION_FAULTS as exc:
            self.records.keep(u)
            self.log.error("tightening %d of %s NOT stored, kept until the database takes it: "
                      "%s; %s", r.tightening_id, a.bolt, one_line(exc), u.describe())
            self._database.lost(DeviceError(f"results not stored: {one_line(exc)}"))
            return NotStored(time.time(), r.tightening_id, a.bolt, one_line(exc))
        return Written(time.time(), a, tuple(u.images), u.again, u.stored_vin, u.stored_bolt)

    async def _store_unattributed(self, a: StoreUnattributed) -> None:
        """A result no bolt owns: stored, then acknowledged.  A database that refuses it is a
        fault; the result stays with the controller (not acknowledged)."""
        try:
            await self._call(self.records.store_unattributed, a)
        except STATION_FAULTS as exc:
            self.log.error("tightening %d (unattributed) NOT stored, left with the controller: %s",
                      a.result.tightening_id, one_line(exc))
            self._database.lost(DeviceError(f"results not stored: {one_line(exc)}"))
            return
        await self.acknowledge(a.result)

    async def _store_then_ack(self, store: Callable[[Any], None], a: Any,
                              result: Received, what: str) -> None:
        """A controller result stored (``store(a)``), then acknowledged; a database that
        refuses it is a fault, and the result stays with the controller (not
        acknowledged: it sends it again)."""
        try:
            await self._call(store, a)
        except STATION_FAULTS as exc:
            self.log.error("tightening %s (%s) NOT stored, left with the controller: %s",
                      result.tightening_id, what, one_line(exc))
            self._database.lost(DeviceError(f"results not stored: {one_line(exc)}"))
            return
        await self.acknowledge(result)

    async def acknowledge(self, result: Received) -> None:
        """Tell the controller a result is stored; a failure leaves it with the controller
        (it is recorded here already, and a resent copy is recognised by its id)."""
        wrench = self._wrench.device
        if wrench is None or result.fetched:
            return   # a fetched result is not awaiting an acknowledgement
        try:
            await self._call(wrench.acknowledge_result, result)
        except (DeviceError, ValueError) as exc:
            self.log.warning("tightening %s stored, not acknowledged: %s",
                             "?" if result.tightening_id is None else result.tightening_id,
                             one_line(exc))

    async def _record_command(self, a: RecordCommand) -> Event:
        """An accepted command on disk with its user; what the database said, for the core."""
        try:
            why = await self._call(self.records.record_command, a,
                                  self.core.status().vin)
        except STATION_FAULTS as exc:
            self._database.lost(DeviceError(one_line(exc)))
            why = Reason(Why.NOT_RECORDED, note=one_line(exc))
        return CommandDone(time.time(), a.request, why)

    def _reply(self, answer: Answer) -> None:
        """The journal's line for every command, and the answer to who is waiting for it."""
        (self.commands_log.info if answer.accepted else self.commands_log.warning)(
            "%s", answer_words(answer))
        waiting = self.answers.get(answer.request)
        if waiting is not None and not waiting.done():
            waiting.set_result(answer)


def _send_parameters(wrench: Wrench, params: Parameters) -> None:
    """The controller takes them its way (a pset, or registers with the targets)."""
    wrench.send_parameters(params.pset, params.torque.target,
                           params.angle.target if params.angle else None, SEND_TIMEOUT_S)
