"""The station daemon: I/O and timing around the pure core (:mod:`stationd.station.core`).

Every decision is the core's.  This module runs the station's clocks (the lift every
``lift.poll_ms``, the controller's results as it pushes them, the cameras while the core is
tracking, a tick), feeds what happened to the core one event at a time and hands the actions
it answers to :class:`~stationd.shell.effects.Effects`.  The parts have a module each: the
devices opened from the configuration (:mod:`~stationd.shell.devices`), the vision loop
(:mod:`~stationd.shell.tracking`), the controller's results, missed results and curves
(:mod:`~stationd.shell.controller`), the persistence policy
(:mod:`~stationd.shell.records`).

A device or data fault is never an exception out of the loop: a device that is down at boot,
vanishes, or returns garbage is a fault (DeviceHealth, STATUS=) and is retried with backoff.
Each device (the lift, the wrench, every camera pair, the database) has one
:class:`drivers.keeper.DeviceKeeper`: the one task that opens it, reports its faults and
reconnects it with backoff.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from typing import Any, TypeVar

from db.errors import DbError
from db.repository import Repository
from drivers.errors import DeviceError
from drivers.keeper import DeviceKeeper, FaultKind, one_line
from drivers.lift import Lift
from drivers.wrench import Wrench, fetches
from stationd.bus import EventBus
from stationd.config import StationConfig
from stationd.localize import Localization
from stationd.shell.blocking import Blocking
from stationd.shell.controller import ControllerFeed, result_input
from stationd.shell.devices import Devices, Pair, reconnect_lift
from stationd.shell.devices import close as close_device
from stationd.shell.effects import Effects
from stationd.shell.records import STATION_FAULTS, Records, Unsaved
from stationd.shell.sdnotify import Notifier
from stationd.shell.tracking import FrameStore, Tracker
from stationd.station.actions import Action, NoteLock, Publish
from stationd.station.commands import Answer, Command, Issuer, ReopenVehicle
from stationd.station.core import StationCore
from stationd.station.events import State
from stationd.station.inputs import (
    DATABASE,
    LIFT,
    WRENCH,
    Announce,
    CommandIn,
    DeviceBack,
    DeviceFault,
    Event,
    LiftRead,
    ModelsKnown,
    OperatorBack,
    Started,
    Tick,
    Written,
)
from stationd.station.trust import PairTrust
from stationd.words import state_line

log = logging.getLogger("stationd")
D = TypeVar("D")
T = TypeVar("T")
#: any of the station's keepers (the lift's, the wrench's, a pair's, the database's)
Keeper = (DeviceKeeper[Lift] | DeviceKeeper[Wrench] | DeviceKeeper[Pair]
          | DeviceKeeper[Repository])
TICK_S = 0.5
#: how often the SQLite file is checked to be the one opened (a stat: cheap)
FILE_CHECK_S = 2.0
#: the longest a command waits for the database to say whether it knows the VIN named (a
#: database slow or hanging: the command is decided without, as before)
KNOWS_TIMEOUT_S = 1.0
#: what opening a device may raise besides (a port that does not exist, a bad option)
OPEN_ERRORS: tuple[type[Exception], ...] = (*STATION_FAULTS, OSError, ValueError)


@dataclass
class Station:
    """A running station: ``open()``, ``await run(stop)``, ``close()``."""

    cfg: StationConfig
    notifier: Notifier = field(default_factory=Notifier)
    #: options per device kind for the backends (a simulated controller's psets, timeouts)
    device_kw: dict[str, dict[str, Any]] = field(default_factory=dict)
    bus: EventBus = field(default_factory=EventBus)
    on_action: Callable[[Action], None] | None = None  # sees each action first (demo, tests)
    records: Records = field(init=False)
    core: StationCore = field(init=False)
    #: one event and its actions at a time (commands before run() included)
    _lock: asyncio.Lock = field(default_factory=asyncio.Lock)
    _pending: list[Event] = field(default_factory=list)    # faults found before run()
    _requests: int = 0                   # commands numbered for their answers
    _told: set[asyncio.Future[None]] = field(default_factory=set)   # tell()'s, on their way
    #: ``close`` has begun: what is told now is dropped (the line forwarder and OPC UA end as
    #: the devices close, and a late word from them must not reach a station shutting down)
    _closing: bool = False

    def __post_init__(self) -> None:
        self.records = Records(self.cfg)
        refs = self.cfg.references
        self.core = StationCore(self.cfg.matching, self.cfg.matching.leave_frames,
                                nok=self.cfg.nok, trust=None if refs is None
                                else PairTrust(refs.pairs, refs.period_s),
                                operator_required=self.cfg.access.operator_required,
                                operator_idle_s=self.cfg.access.operator_idle_s)
        self._pool = ThreadPoolExecutor(max_workers=4, thread_name_prefix="station")
        call = Blocking(self._pool)
        self.devices = Devices(self.cfg, self.device_kw, pins=self.records.pin_cameras)
        # the cameras' own threads, one per pair: their grabs (a 20 MP frame, a simulated
        # world's first renders: seconds) took every thread of the pool above, and the lift's
        # poll, the controller's and the database's calls and a stop waited behind them
        self._camera_pool = ThreadPoolExecutor(
            max_workers=max(1, len(self.devices.pair_names())), thread_name_prefix="cameras")
        cameras = Blocking(self._camera_pool)
        self.lift_keeper: DeviceKeeper[Lift] = self._keeper(
            LIFT, self.devices.open_lift, reconnect_lift, close_device)
        self.wrench_keeper: DeviceKeeper[Wrench] = self._keeper(
            WRENCH, self.devices.open_wrench, _reconnect, close_device)
        self.pair_keepers: dict[str, DeviceKeeper[Pair]] = {
            n: self._keeper(n, partial(self.devices.open_pair, n),
                            partial(self.devices.reconnect_pair, n), close_device, cameras)
            for n in self.devices.pair_names()}
        # the database too: opened by ``open`` (a first start that cannot open it exits), then
        # kept like a device: a failed query reports it lost, the keeper probes it with
        # backoff and the core hears it back
        self.database_keeper: DeviceKeeper[Repository] = self._keeper(
            DATABASE, self._database, self.records.probe, _leave_open)
        self.tracker = Tracker(self.cfg, self.core, self.pair_keepers, self.bus, self.feed,
                               cameras)
        self.controller = ControllerFeed(self.core, self.records, self.wrench_keeper,
                                         self.feed, self.tell, call)
        self.effects = Effects(self.core, self.records, self.wrench_keeper,
                               self.database_keeper, self.bus, self.notifier, call,
                               self.tracker.request_check, self.controller.check_newest)

    def _keeper(self, device: str, opener: Callable[[], D], reconnect: Callable[[D], None],
                close: Callable[[D], None], blocking: Blocking | None = None
                ) -> DeviceKeeper[D]:
        """The device's keeper: its faults and returns go to the core as typed events; its
        driver calls run in ``blocking`` (the station's pool unless told)."""
        async def on_fault(kind: FaultKind, reason: str) -> None:
            await self.feed(DeviceFault(time.time(), device, kind, reason))

        async def on_back(reconnects: int) -> None:
            if device == DATABASE:
                await self._recorded_late()
            await self.feed(DeviceBack(time.time(), device,
                                       reconnects if device == WRENCH else None))
            if device == WRENCH:
                self.controller.came_back()

        return DeviceKeeper(device, open=opener, reconnect=reconnect, close=close,
                            on_fault=on_fault, on_back=on_back,
                            blocking=blocking or self._call, logger=log)

    @property
    def keepers(self) -> dict[str, Keeper]:
        """Every device's keeper by name: the lift, the wrench, each pair, the database."""
        return {LIFT: self.lift_keeper, WRENCH: self.wrench_keeper, **self.pair_keepers,
                DATABASE: self.database_keeper}

    @property
    def lift(self) -> Lift | None:
        """The lift PLC once opened (also while its link is down), else None."""
        return self.lift_keeper.device

    @property
    def wrench(self) -> Wrench | None:
        """The controller once opened (also while its link is down), else None."""
        return self.wrench_keeper.device

    @property
    def vin(self) -> str | None:
        return self.core.status().vin

    @property
    def repo(self) -> Repository | None:
        """The station's database once opened."""
        return self.records.repo

    @property
    def last(self) -> Localization | None:
        """The latest localization."""
        return self.tracker.last

    @property
    def frames(self) -> FrameStore | None:
        """The screens' latest-frame store; None while the screens are off."""
        return self.tracker.frames

    @frames.setter
    def frames(self, store: FrameStore | None) -> None:
        self.tracker.frames = store

    # -- devices -----------------------------------------------------------------------------
    def open(self) -> None:
        """Open the database (and import the bolt table), then try every device once: a
        device that does not open is a fault retried by ``run``, never an exception here."""
        repo = self.records.open()
        # the models the bolt tables name: what a teach-in may name
        self._pending.append(ModelsKnown(time.time(), frozenset(repo.models())))
        signed = self.records.operator()
        if signed is not None and signed[0] in self.cfg.access.users:
            # still signed in (a reload, a restart): their rundowns carry their name on
            self._pending.append(OperatorBack(time.time(), signed[0], signed[1].timestamp()))
        # a controller that keeps no results to fetch: nothing to catch up on after the
        # restart, its result (within the window) only as it is read
        owed = self.records.owed(self.core.late_result_s, cut=fetches(self.cfg.wrench.url))
        if owed is not None:   # its result is recorded to that bolt, not into nothing
            self.core.resume(owed)
        for device, keeper in self.keepers.items():
            fault = keeper.open_now()
            if fault is not None:
                self._pending.append(DeviceFault(time.time(), device, *fault))

    def announce(self) -> None:
        """A new station, before it opens anything: the core tells its state as it stands
        (the screens forget the last configuration's device reports)."""
        for a in self.core.feed(Announce(time.time())):
            if isinstance(a, Publish):
                self.effects.publish(a.event)

    def still_signed_in(self, user: str, since: float) -> None:
        """``user`` signed in before this station (a reload) and stays signed in although
        the station file does not name them (:meth:`open` keeps only its users): the
        simulated operator's own name (``stationd run --sim-operator`` on a station file
        without an operator-role user), which the simulation knows it signed in.  Why: it
        was signed in anew at each reload, a journal line each time, as no person is.
        Before :meth:`run`."""
        self._pending.append(OperatorBack(time.time(), user, since))

    def heard_before_run(self, ev: DeviceFault | DeviceBack) -> None:
        """What the serve loop saw before this station's loop runs (the database not open,
        then open): the core decides, and what it publishes is published.  Its other actions
        wait for the loop (nothing is open to carry them out; ``run`` starts with the tool
        off)."""
        for a in self.core.feed(ev):
            if isinstance(a, Publish):
                self.effects.publish(a.event)

    def carry(self, unsaved: list[Unsaved], locks: list[NoteLock] | None = None) -> None:
        """Results the last station (a reload) received and could not write: this one writes
        them once its database takes them, then acknowledges them (before ``run``); and the
        NOK policy's locks it could not record, written first."""
        self.records.carry(unsaved, locks)

    def unsaved(self) -> list[Unsaved]:
        """The results this station could not write (after ``close``: for the next one)."""
        return self.records.unsaved()

    def locks_owed(self) -> list[NoteLock]:
        """The locks this station could not record (after ``close``: for the next one)."""
        return self.records.locks_owed()

    def journal_unsaved(self) -> None:
        """Each result and lock the database never took, in full, one line each: the only
        copy left once the daemon stops (quality re-enters them from the journal)."""
        for u in self.records.unsaved():
            log.error("UNSAVED at shutdown: %s", u.describe())
        for lock in self.records.locks_owed():
            log.error("UNSAVED at shutdown: the lock of %s of %s after %d NOK in a row (a "
                      "supervisor releases it; read back from its NOKs under this max_nok)",
                      lock.bolt, lock.vin, lock.count)

    def _database(self) -> Repository:
        """The database for its keeper: opened by ``open`` before any device."""
        if self.repo is None:
            raise DeviceError("not open", device=DATABASE)
        return self.repo

    def close(self, final: bool = True) -> None:
        """Tool off first, then every device, then the database; a failure is logged and the
        shutdown goes on.  ``final``: the daemon stops (not a reload, which carries what is
        unsaved to the next station): results the database never took are journaled in
        full, one line each, the only copy left (quality re-enters them from the journal);
        at a reload they are counted (an IT administrator's trial: "UNSAVED at shutdown"
        at every reload)."""
        self._closing = True
        unsaved, owed = self.records.unsaved(), self.records.locks_owed()
        if not final and (unsaved or owed):
            log.warning("reload: %d results and %d locks not written yet go on to the "
                        "reloaded station", len(unsaved), len(owed))
        if final:
            self.journal_unsaved()
        steps: list[tuple[str, Callable[[], None]]] = []
        if self.wrench is not None and self.wrench_keeper.up:
            steps.append(("disable tool", self.wrench.disable_tool))
        first_pair = next(iter(self.pair_keepers), None)
        for device, keeper in self.keepers.items():
            if device == first_pair:
                # a grab under way ends before its camera closes (none queued is started)
                steps.append(("the cameras' grabs", partial(
                    self._camera_pool.shutdown, wait=True, cancel_futures=True)))
            steps.append((device, keeper.close))
        if self.repo is not None:
            steps += [("noting the tool off", self.records.note_off),
                      ("database", self.repo.close)]
        for what, fn in steps:
            try:
                fn()
            except Exception as exc:
                log.warning("closing %s: %s", what, one_line(exc))
        self._camera_pool.shutdown(wait=True, cancel_futures=True)   # (no pairs: not yet)
        self._pool.shutdown(wait=True)
        self.controller.close()

    # -- the loop ----------------------------------------------------------------------------
    async def run(self, stop: asyncio.Event) -> None:
        """Serve until ``stop``: READY=1 at once, whatever the devices do."""
        pending, self._pending = self._pending, []
        for ev in pending:
            await self.feed(ev)
        await self.feed(Started(time.time()))
        if self.wrench_keeper.up:   # the reconnect count the core compares from now on
            await self.feed(DeviceBack(time.time(), WRENCH, self.wrench_keeper.reconnects))
            self.controller.came_back()
        now = self.core.status()
        self.notifier.ready(state_line(now.state, now.reason))
        if self.unsaved():   # a reload's: written (then acknowledged) by the database keeper
            self.database_keeper.lost(DeviceError("results received before the reload "
                                                  "not stored yet"))
        # (the pairs' and the database's keepers have no ``use``: the vision loop and the
        # database's callers tell them when their device failed or worked)
        keep = [self.lift_keeper.run(self._poll_lift),
                self.wrench_keeper.run(self.controller.results),
                *(k.run() for k in self.pair_keepers.values()), self.database_keeper.run()]
        tasks = [asyncio.create_task(c) for c in (*keep, self.tracker.loop(stop),
                                                    self._tick_loop(stop),
                                                    self.controller.curves(stop))]
        try:
            await stop.wait()
        finally:
            async with self._lock:   # never cut an event's actions (a record) in half
                tasks += self.controller.tasks()
                for t in tasks:
                    t.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)
                for r in await self.controller.drain():
                    ev = await self.controller.checked(result_input(time.time(), r))
                    await self._apply(self.core.feed(ev))
        # no STOPPING=1 here: a reload ends this station too, and STOPPING=1 tells systemd
        # the service is going down (it would kill it at TimeoutStopSec); the serve loop says
        # RELOADING=1 or STOPPING=1

    async def submit(self, command: Command, issuer: Issuer,
                     timeout: float = 30.0) -> Answer:
        """A person's command into the core, on the path of the devices' events; its answer
        (accepted once recorded, or refused with why).  ``TimeoutError`` when the station
        does not answer in ``timeout`` (a database waiting on a lock)."""
        self._requests += 1
        request = self._requests
        answer: asyncio.Future[Answer] = asyncio.get_running_loop().create_future()
        self.effects.answers[request] = answer
        try:
            known, meant = await self._knows(command)
            await asyncio.wait_for(self.feed(
                CommandIn(time.time(), request, command, issuer, known, meant)), timeout)
            return await asyncio.wait_for(answer, timeout)
        finally:
            self.effects.answers.pop(request, None)

    async def _knows(self, command: Command) -> tuple[bool | None, str | None]:
        """Whether the database has the VIN ``command`` names, and the one meant in another
        case (:meth:`Records.knows_vehicle`): facts the core decides a refusal with (a VIN
        mistyped is unknown, not one to reopen).  Asked only where they tell: a VIN other
        than the vehicle at the station's, of a bolt command (a reopen's own record says
        it), the database up; within a second (else not known: None)."""
        vin = getattr(command, "vin", None)
        if not isinstance(vin, str) or isinstance(command, ReopenVehicle) or vin == self.vin \
                or not self.database_keeper.up:
            return None, None
        try:
            return await asyncio.wait_for(self._call(lambda: self.records.knows_vehicle(vin)),
                                          KNOWS_TIMEOUT_S)
        except TimeoutError:
            return None, None

    async def _call(self, fn: Callable[[], T]) -> T:
        return await asyncio.get_running_loop().run_in_executor(self._pool, fn)

    async def feed(self, ev: Event) -> None:
        """Feed the core one event and carry out its actions (one event at a time)."""
        async with self._lock:
            await self._apply(self.core.feed(ev))

    def tell(self, ev: Event) -> None:
        """:meth:`feed` from a callback that cannot wait (what a device said as it came back,
        the line forwarder's link), on the station's loop: fed in its turn, its task kept
        until it is.  Dropped once the station closes (a reviewer: the line forwarder's last
        word reached a station whose pools and database were closing)."""
        if self._closing:
            log.debug("told as the station closes, dropped: %s", type(ev).__name__)
            return
        task = asyncio.ensure_future(self.feed(ev))
        self._told.add(task)
        task.add_done_callback(self._told.discard)

    async def _apply(self, actions: list[Action]) -> None:
        for a in actions:
            if self.on_action is not None:
                self.on_action(a)
            follow = await self.effects.do(a)
            if follow is not None:
                await self._apply(self.core.feed(follow))

    async def _poll_lift(self, lift: Lift) -> None:
        """One read of the PLC, then the rest of ``lift.poll_ms`` (never faster); a failure
        raises to the lift's keeper."""
        t0 = time.monotonic()
        s = await self._call(lambda: lift.read_state(1.0))
        await self.feed(LiftRead(time.time(), bool(s.ready), bool(s.at_working_height),
                                 int(s.model_code), s.vin, s.why_not_ready, bool(s.fault)))
        await asyncio.sleep(max(0.0, self.cfg.lift.poll_ms / 1e3 - (time.monotonic() - t0)))

    async def _recorded_late(self) -> None:
        """The results the keeper wrote on its way back: the core publishes and acknowledges
        them."""
        for u in await self._call(self.records.take_saved_late):
            await self.feed(Written(time.time(), u.record, tuple(u.images), u.again,
                                    u.stored_vin, u.stored_bolt))

    async def _tick_loop(self, stop: asyncio.Event) -> None:
        """Time for the core.  (The systemd watchdog is ``run.keep_watchdog``'s: a feed may
        wait seconds on a locked database, and the daemon must not be killed for that.)"""
        checked = time.monotonic()
        while not stop.is_set():
            await self.feed(Tick(time.time()))
            if time.monotonic() - checked >= FILE_CHECK_S:
                checked = time.monotonic()
                self._check_database_file()
            await asyncio.sleep(TICK_S)

    def _check_database_file(self) -> None:
        """The SQLite file removed or replaced under the running daemon is a database fault
        now, not at the next write (a maintenance trial: the station said "tracking" with
        its file gone until a command failed; its connection goes on writing into the
        deleted file, and what it writes there is lost at the next start)."""
        keeper = self.database_keeper
        if keeper.up and not keeper.losing:
            try:
                self.records.check_file()
            except DbError as exc:
                keeper.lost(exc)


def _reconnect(wrench: Wrench) -> None:
    wrench.reconnect()


def _leave_open(repo: Repository) -> None:
    """The database is closed by the station (after the tool is noted off), not its keeper."""


__all__ = ["Localization", "State", "Station"]
