"""The station daemon: I/O and timing around the pure core (:mod:`stationd.station.core`).

Every decision is the core's.  This module reads the devices on their own clocks (the lift every
``lift.poll_ms``, the controller's results as it pushes them, the cameras while the core is
tracking), feeds what happened to the core, carries out the actions it answers and publishes
typed events on :attr:`Station.bus`.  Blocking work runs in executor threads.

A device or data fault is never an exception out of the loop: a device that is down at boot,
vanishes, or returns garbage is a fault (DeviceHealth, STATUS=) and is retried with backoff; a
skewed stereo pair or one bad frame is retried, a camera that keeps failing is a fault.  Each
device (the lift, the wrench, every camera pair) has one :class:`drivers.keeper.DeviceKeeper`:
the one task that opens it, reports its faults and reconnects it with backoff.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from functools import partial
from typing import Any

from db.bolts import Parameters
from db.curves import store_curve
from db.errors import DataError, NotFoundError, VehicleClosedError
from db.report import MISSING
from db.repository import Repository
from drivers.camera import open_camera
from drivers.camera.pair import StereoGrabber, StereoSkewError
from drivers.errors import DeviceError, ProtocolError, RefusedError
from drivers.keeper import DeviceKeeper, fault_kind, one_line
from drivers.lift import open_lift
from drivers.wrench import open_wrench
from stationd.config import StationConfig
from stationd.geometry.tool import BoltEnd
from stationd.localize import (
    Localization,
    PairSetup,
    PairView,
    frame_summary,
    fuse_views,
    localize_pair,
    size_problem,
)
from stationd.reasons import Reason, Why
from stationd.result import Refusal
from stationd.station.commands import (
    KIND,
    Answer,
    Command,
    Issuer,
    ReopenVehicle,
    TeachStart,
    skip_note,
)
from stationd.station.core import (
    CAMERAS_ON,
    DATABASE,
    LIFT,
    WRENCH,
    Acknowledge,
    Action,
    BoltSpec,
    CloseVehicle,
    CommandDone,
    CommandIn,
    DeviceBack,
    DeviceFault,
    DisableTool,
    EnableTool,
    Event,
    LiftRead,
    LoadVehicle,
    LocalizedIn,
    ParamsAcked,
    ParamsRefused,
    Publish,
    Record,
    RecordCommand,
    Reply,
    ResultIn,
    SendParams,
    SendVin,
    Started,
    State,
    StationCore,
    StoreUnattributed,
    Tick,
    ToolOn,
    VehicleEnded,
    VehicleLoaded,
    VehicleRejected,
    VinSent,
    Written,
)
from stationd.station.events import (
    DeviceHealth,
    DeviceIdentified,
    EventBus,
    Notice,
    PairFrames,
    Refused,
    StateChanged,
)
from stationd.station.gaps import MAX_FETCH
from stationd.station.gaps import plan as plan_gaps
from stationd.station.records import STATION_FAULTS, Records, Unsaved, xyz
from stationd.station.scan import ScanPlan
from stationd.station.sdnotify import Notifier
from stationd.words import answer_words, reason_words

log = logging.getLogger("stationd")
NOT_PAIRS = (LIFT, WRENCH, DATABASE)   # the keepers that are not camera pairs
RESULT_WAIT_S = 0.5         # one blocking wait for pushed results (a condition, not a poll)
CURVE_WAIT_S = 0.5          # one blocking wait for curves, in their own thread
CURVE_IDLE_S = 1.0          # the curve loop's wait while the controller sends none
TICK_S = 0.5
BAD_GRABS = 3               # a pair failing this many grabs in a row is a fault
IDLE_S = 0.1                # the vision loop's wait while the core is not tracking
PAIR_FRAMES_S = 0.5         # a pair's detection summary is published at most this often


#: how long the read that proves a (re)connected PLC answers may take, s
LIFT_CHECK_S = 1.0
#: and what opening a device may raise besides (a port that does not exist, a bad option)
OPEN_ERRORS: tuple[type[Exception], ...] = (*STATION_FAULTS, OSError, ValueError)


class Pair:
    """A stereo pair as the station keeps it: its two cameras and their grabber."""

    def __init__(self, cams: list[Any], grabber: StereoGrabber) -> None:
        self.cams = cams
        self.grabber = grabber

    def close(self) -> None:
        for cam in self.cams:
            _quiet(cam.close)


@dataclass
class Station:
    """A running station: ``open()``, ``await run(stop)``, ``close()``."""

    cfg: StationConfig
    notifier: Notifier = field(default_factory=Notifier)
    device_kw: dict[str, dict[str, Any]] = field(default_factory=dict)
    records: Records = field(init=False)
    core: StationCore = field(init=False)
    bus: EventBus = field(default_factory=EventBus)
    # the screens' latest-frame store (stationd.web.LatestFrames): put(pair, side, image,
    # summary, exposure) per grab; None when the screens are off
    frames: Any = None
    last: Localization | None = None
    on_action: Any = None  # called with each action before it is carried out (demo, tests)
    _pool: ThreadPoolExecutor = field(init=False)
    _results_pool: ThreadPoolExecutor = field(init=False)
    _curves_pool: ThreadPoolExecutor = field(init=False)
    _lock: asyncio.Lock | None = field(default_factory=asyncio.Lock)
    _pending: list[Event] = field(default_factory=list)    # faults found before run()
    _bad: dict[str, int] = field(default_factory=dict)     # pair -> failed grabs in a row
    keepers: dict[str, DeviceKeeper[Any]] = field(init=False)  # device -> its one keeper
    _next_frames: dict[str, float] = field(default_factory=dict)  # pair -> next PairFrames
    _scan: ScanPlan = field(default_factory=ScanPlan)   # which pairs to localize per cycle
    # results taken from the controller and not yet through the core (a stop mid-way feeds
    # them before the link closes), and the wait for the next one running in its thread
    _received: list[Any] = field(default_factory=list)
    _waiting: Any = None
    _requests: int = 0                   # commands numbered for their answers
    _catching_up: asyncio.Task[None] | None = None   # results missed while the link was down
    _answers: dict[int, asyncio.Future[Answer]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.records = Records(self.cfg)
        self.core = StationCore(self.cfg.matching, self.cfg.matching.leave_frames,
                                nok=self.cfg.nok)
        c = self.cfg
        self._setups = {n: PairSetup(pc.calibration, pc.to_vehicle, c.vision, c.marker, c.tool,
                                     c.records.save_images)
                        for n, pc in c.pairs.items() if pc.calibration is not None}
        self._pool = ThreadPoolExecutor(max_workers=4, thread_name_prefix="station")
        self._results_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="results")
        # the curves' wait and store: a thread of their own, never the results' one
        self._curves_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="curves")
        self.keepers = {LIFT: self._keeper(LIFT, self._open_lift, _reconnect_lift),
                        WRENCH: self._keeper(WRENCH, self._open_wrench, _reconnect)}
        for name in self._pair_names():
            self.keepers[name] = self._keeper(name, partial(self._open_pair, name),
                                              partial(self._reconnect_pair, name))
        # the database too: opened by ``open`` (a first start that cannot open it exits), then
        # kept like a device: a failed query reports it lost, the keeper probes it with
        # backoff and the core hears it back
        self.keepers[DATABASE] = self._keeper(DATABASE, self._database, self.records.probe,
                                              close=lambda repo: None)

    def _keeper(self, device: str, opener: Callable[[], Any],
                reconnect: Callable[[Any], None],
                close: Callable[[Any], None] | None = None) -> DeviceKeeper[Any]:
        """The device's keeper: its faults and returns go to the core as typed events."""
        async def on_fault(kind: str, reason: str) -> None:
            await self.feed(DeviceFault(time.time(), device, kind, reason))

        async def on_back(reconnects: int) -> None:
            if device == DATABASE:
                await self._recorded_late()
            await self.feed(DeviceBack(time.time(), device,
                                       reconnects if device == WRENCH else None))
            if device == WRENCH:
                self._catch_up_soon()

        return DeviceKeeper(device, open=opener, reconnect=reconnect, close=close or _close,
                            on_fault=on_fault, on_back=on_back, blocking=self._call,
                            logger=log)

    @property
    def lift(self) -> Any:
        """The lift PLC once opened (also while its link is down), else None."""
        return self.keepers[LIFT].device

    @property
    def wrench(self) -> Any:
        """The controller once opened (also while its link is down), else None."""
        return self.keepers[WRENCH].device

    @property
    def grabbers(self) -> dict[str, StereoGrabber]:
        """The grabbers of the pairs that are up."""
        return {n: k.device.grabber for n, k in self.keepers.items()
                if n not in NOT_PAIRS and k.up and k.device is not None}

    @property
    def cycle(self) -> StationCore:
        """The core (the name the cycle had)."""
        return self.core

    @property
    def vin(self) -> str | None:
        return self.core.vin

    @property
    def repo(self) -> Repository | None:
        """The station's database once opened."""
        return self.records.repo

    # -- devices -----------------------------------------------------------------------------
    def open(self) -> None:
        """Open the database (and import the bolt table), then try every device once: a
        device that does not open is a fault retried by ``run``, never an exception here."""
        self.records.open()
        owed = self.records.owed(self.core.late_result_s)
        if owed is not None:   # its result is recorded to that bolt, not into nothing
            self.core.resume(owed)
        for device, keeper in self.keepers.items():
            fault = keeper.open_now()
            if fault is not None:
                self._pending.append(DeviceFault(time.time(), device, *fault))

    def carry(self, unsaved: list[Unsaved]) -> None:
        """Results the last station (a reload) received and could not write: this one writes
        them once its database takes them, then acknowledges them (before ``run``)."""
        self.records.carry(unsaved)

    def unsaved(self) -> list[Unsaved]:
        """The results this station could not write (after ``close``: for the next one)."""
        return self.records.unsaved()

    def _database(self) -> Repository:
        """The database for its keeper: opened by ``open`` before any device."""
        if self.repo is None:
            raise DeviceError("not open", device=DATABASE)
        return self.repo

    def _pair_names(self) -> list[str]:
        return [n for n, pc in self.cfg.pairs.items() if pc.left and pc.right]

    def _open_lift(self) -> Any:
        """The PLC, opened and read once: it is up when it answers, not when its port
        accepts a connection (a peer answering garbage was "back" every few seconds)."""
        lift = open_lift(self.cfg.lift.url, self.cfg.lift.registers,
                         **self.device_kw.get("lift", {}))
        try:
            lift.read_state(LIFT_CHECK_S)
        except BaseException:
            _quiet(lift.close)
            raise
        return lift

    def _open_wrench(self) -> Any:
        return open_wrench(self.cfg.wrench.url, **self.cfg.wrench.open_options(),
                           **self.device_kw.get("wrench", {}))

    def _open_pair(self, name: str) -> Pair:
        """Open both cameras of ``name`` (an executor thread); the one opened is closed again
        if the other fails."""
        pc = self.cfg.pairs[name]
        assert pc.left is not None and pc.right is not None  # noqa: S101 - _pair_names
        cams: list[Any] = []
        try:
            for side in (pc.left, pc.right):
                cam = open_camera(self.cfg.cameras[side])
                cams.append(cam)
                cam.open()
        except BaseException:
            for cam in cams:
                _quiet(cam.close)
            raise
        return Pair(cams, StereoGrabber(cams[0], cams[1], pc.max_skew_s))

    def _reconnect_pair(self, name: str, pair: Pair) -> None:
        """Reconnect both cameras and grab once: the pair is back only when it delivers
        frames its calibration describes (a DeviceError or ProtocolError otherwise)."""
        for cam in pair.cams:
            cam.reconnect()
        left, right = pair.grabber.grab(1.0)
        problem = size_problem(self.cfg.pairs[name].calibration, left.image, right.image)
        if problem is not None:
            raise ProtocolError(problem)

    def close(self) -> None:
        """Tool off first, then every device, then the database; a failure is logged and the
        shutdown goes on.  Results the database never took are journaled in full, one line
        each: the only copy left (quality re-enters them from the journal)."""
        for u in self.records.unsaved():
            log.error("UNSAVED at shutdown: %s", u.describe())
        steps: list[tuple[str, Any]] = []
        if self.wrench is not None and self.keepers[WRENCH].up:
            steps.append(("disable tool", self.wrench.disable_tool))
        steps += [(device, keeper.close) for device, keeper in self.keepers.items()]
        if self.repo is not None:
            steps += [("noting the tool off", self.records.note_off),
                      ("database", self.repo.close)]
        for what, fn in steps:
            try:
                fn()
            except Exception as exc:
                log.warning("closing %s: %s", what, one_line(exc))
        self._pool.shutdown(wait=True)
        self._results_pool.shutdown(wait=True)
        self._curves_pool.shutdown(wait=True)

    # -- the loop ----------------------------------------------------------------------------
    async def run(self, stop: asyncio.Event) -> None:
        """Serve until ``stop``: READY=1 at once, whatever the devices do."""
        self._lock = asyncio.Lock()
        pending, self._pending = self._pending, []
        for ev in pending:
            await self.feed(ev)
        await self.feed(Started(time.time()))
        if self.keepers[WRENCH].up:   # the reconnect count the core compares from now on
            await self.feed(DeviceBack(time.time(), WRENCH, self.keepers[WRENCH].reconnects))
            self._catch_up_soon()
        self.notifier.ready(f"{self.core.state.value}: {self.core.reason}")
        if self.unsaved():   # a reload's: written (then acknowledged) by the database keeper
            self.keepers[DATABASE].lost(DeviceError("results received before the reload "
                                                    "not stored yet"))
        keep = [self.keepers[LIFT].run(self._poll_lift), self.keepers[WRENCH].run(self._results),
                *(k.run() for n, k in self.keepers.items() if n not in (LIFT, WRENCH))]
        # (the pairs' and the database's keepers have no ``use``: the vision loop and the
        # database's callers tell them when their device failed or worked)
        tasks = [asyncio.create_task(c) for c in (*keep, self._vision_loop(stop),
                                                    self._tick_loop(stop),
                                                    self._curve_loop(stop))]
        try:
            await stop.wait()
        finally:
            async with self._lock:   # never cut an event's actions (a record) in half
                if self._catching_up is not None:
                    tasks.append(self._catching_up)
                for t in tasks:
                    t.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)
                await self._drain_results()
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
        self._answers[request] = answer
        try:
            await asyncio.wait_for(self.feed(CommandIn(time.time(), request, command, issuer)),
                                   timeout)
            return await asyncio.wait_for(answer, timeout)
        finally:
            self._answers.pop(request, None)

    async def _call(self, fn: Any, *args: Any) -> Any:
        return await asyncio.get_running_loop().run_in_executor(self._pool, fn, *args)

    async def feed(self, ev: Event) -> None:
        """Feed the core one event and carry out its actions (one event at a time)."""
        assert self._lock is not None  # noqa: S101 - set by run()
        async with self._lock:
            await self._apply(self.core.feed(ev))

    async def _apply(self, actions: list[Action]) -> None:
        for a in actions:
            if self.on_action is not None:
                self.on_action(a)
            follow = await self._do(a)
            if follow is not None:
                await self._apply(self.core.feed(follow))

    async def _poll_lift(self, lift: Any) -> None:
        """One read of the PLC, then the rest of ``lift.poll_ms`` (never faster); a failure
        raises to the lift's keeper."""
        t0 = time.monotonic()
        s = await self._call(lift.read_state, 1.0)
        await self.feed(LiftRead(time.time(), bool(s.ready), bool(s.at_working_height),
                                 int(s.model_code), s.vin, s.why_not_ready))
        period = float(getattr(self.cfg.lift, "poll_ms", 100.0)) / 1e3
        await asyncio.sleep(max(0.0, period - (time.monotonic() - t0)))

    async def _results(self, wrench: Any) -> None:
        """The controller's results as it pushes them: one blocking wait on the driver's
        queue, in a thread of its own; a link down raises to the wrench's keeper.  A result
        is in ``_received`` until the core has it: a stop (a reload) never drops it."""
        self._waiting = self._results_pool.submit(wrench.wait_result, RESULT_WAIT_S,
                                                  acknowledge=False)
        result = await asyncio.wrap_future(self._waiting)
        self._waiting = None
        if result is not None:
            self._received.append(result)
        if WRENCH in self.core.faults and not self.keepers[WRENCH].losing:
            # a refusal is a fault until the controller answers
            await self.feed(DeviceBack(time.time(), WRENCH, self.keepers[WRENCH].reconnects))
        if result is not None:
            await self.feed(ResultIn(time.time(), result))
            self._received.remove(result)

    async def _curve_loop(self, stop: asyncio.Event) -> None:
        """The controller's tightening curves, when it sends them (``?curves=1`` in the
        wrench's URL): read apart from its results, a blocking wait on the driver's curve
        queue in a thread of its own (never the results' thread: a curve never delays a
        result or the next bolt's parameters), each stored with its rundown by tightening id
        (``db.curves``: a curve stored before its rundown is written is found by that id).
        A curve not stored is logged, never a fault: the rundown stands without it."""
        loop = asyncio.get_running_loop()
        while not stop.is_set():
            wrench, repo = self.wrench, self.repo
            if wrench is None or repo is None or not wrench.can_curves \
                    or not wrench.curves_on:
                await asyncio.sleep(CURVE_IDLE_S)
                continue
            try:
                curve = await loop.run_in_executor(self._curves_pool, wrench.wait_curve,
                                                   CURVE_WAIT_S)
            except (DeviceError, ValueError):     # closed: its keeper opens a new one
                await asyncio.sleep(CURVE_IDLE_S)
                continue
            if curve is None:
                continue
            try:
                await loop.run_in_executor(self._curves_pool, partial(
                    store_curve, repo, tightening_id=curve.tightening_id,
                    trace_type=curve.trace_type, unit=curve.unit, values=curve.values,
                    sample_period_s=curve.time_step_s,
                    times_s=None if curve.time_step_s is not None else curve.times_s,
                    result_at=None if curve.timestamp is None
                    else curve.timestamp.astimezone(UTC)))
            except STATION_FAULTS as exc:
                log.warning("curve (%s) of tightening %d not stored: %s", curve.name,
                            curve.tightening_id, one_line(exc))

    def _catch_up_soon(self) -> None:
        """After the controller came (back): what it says it is (the journal, the devices
        panel), and the results it made meanwhile, fetched."""
        wrench = self.wrench
        if wrench is not None:
            try:
                who = wrench.identity()
            except (DeviceError, ValueError):
                who = ""
            if who:
                log.info("wrench: %s", who)
                self.bus.publish(DeviceIdentified(WRENCH, who))
        if self._catching_up is None or self._catching_up.done():
            self._catching_up = asyncio.get_running_loop().create_task(self._catch_up())

    async def _catch_up(self) -> None:
        """Compare the last tightening id recorded with the controller's newest and fetch
        every one between (MID 0064): each goes through the core as any result (recorded to
        its bolt when the station can tell, else unattributed, never to a guessed bolt); one
        the controller no longer has is recorded as a gap.  A controller that keeps no
        results (register-driven) has nothing to fetch."""
        wrench, repo = self.wrench, self.repo
        if wrench is None or repo is None or not wrench.can_fetch:
            return
        try:
            last = await self._call(repo.last_tightening_id)
            newest = await self._call(wrench.fetch_result, 0)
            if newest is None:
                return
            todo = plan_gaps(last, int(newest.tightening_id))
            if todo.note:
                log.info("results: %s", todo.note)
            if todo.gap is not None:
                await self._gap(*todo.gap, f"more than {MAX_FETCH} results missed")
            for tid in todo.fetch:
                got = newest if tid == newest.tightening_id else \
                    await self._call(wrench.fetch_result, tid)
                if got is None:
                    await self._gap(tid, tid, "the controller no longer has it")
                    continue
                log.info("tightening %d fetched after a reconnect", tid)
                await self.feed(ResultIn(time.time(), got, fetched=True))
        except (DeviceError, ValueError) as exc:   # the link's keeper reports it
            log.warning("results missed while the link was down not fetched yet: %s",
                        one_line(exc))
        except STATION_FAULTS as exc:
            log.error("results missed while the link was down not fetched: %s", one_line(exc))

    async def _gap(self, first: int, last: int, reason: str) -> None:
        repo = self.repo
        assert repo is not None  # noqa: S101 - opened in open()
        await self._call(repo.record_gap, first, last, self.core.vin, reason)
        ids = str(first) if first == last else f"{first}-{last}"
        log.warning("tightening %s missed while the link was down: a gap (%s)", ids, reason)
        self.bus.publish(Notice(f"tightening {ids} missed: a gap ({reason})", "warning"))

    async def _drain_results(self) -> None:
        """At a stop (the lock held, the tasks cancelled): the result the wait was taking and
        those the driver still holds go through the core while the link is open: recorded
        to their bolt and acknowledged (a reload lost a result that arrived as it began)."""
        waiting, self._waiting = self._waiting, None
        if waiting is not None and not waiting.cancelled():
            try:
                got = await asyncio.wrap_future(waiting)
            except Exception:   # the link went down meanwhile: its keeper's, not ours
                got = None
            if got is not None:
                self._received.append(got)
        wrench = self.wrench
        while wrench is not None and self.keepers[WRENCH].up:
            try:
                got = await self._call(lambda: wrench.wait_result(0.05, acknowledge=False))
            except (DeviceError, ValueError):
                break
            if got is None:
                break
            self._received.append(got)
        received, self._received = self._received, []
        for r in received:
            await self._apply(self.core.feed(ResultIn(time.time(), r)))

    async def _tick_loop(self, stop: asyncio.Event) -> None:
        """Time for the core.  (The systemd watchdog is ``run.keep_watchdog``'s: a feed may
        wait seconds on a locked database, and the daemon must not be killed for that.)"""
        while not stop.is_set():
            await self.feed(Tick(time.time()))
            await asyncio.sleep(TICK_S)

    async def _vision_loop(self, stop: asyncio.Event) -> None:
        """Grab and localize while the core tracks and every pair is up (a pair that is down
        is its keeper's to bring back)."""
        while not stop.is_set():
            down = [n for n in self._pair_names() if n in self.core.faults]
            if self.core.state not in CAMERAS_ON or not self.grabbers or down:
                await asyncio.sleep(IDLE_S)
                continue
            cycle = self._scan.choose(list(self.grabbers))
            loc = await self._localize(cycle.decide)
            if loc is not None:
                self.last = loc
                point = None if loc.point_mm is None else xyz(loc.point_mm)
                await self.feed(LocalizedIn(time.time(), loc.exposure_t, point, loc.reason,
                                            loc.tilt_deg, loc))
            if cycle.scout and self._scan.watching:   # after the decision, never before it
                await self._localize(cycle.scout)

    async def _localize(self, names: list[str]) -> Localization | None:
        """Grab and localize at once in the pairs ``names`` (the scan plan's choice: those
        that see the marker, or all: :mod:`stationd.station.scan`) that are up, then fuse
        (:func:`stationd.localize.fuse_views`).  A pair that failed its grab is left out;
        after ``BAD_GRABS`` failures in a row its keeper is told it is lost."""
        grabbers = self.grabbers
        names = [n for n in names if n in grabbers]
        got: list[PairView] = await asyncio.gather(*(self._call(self._grab_pair, n,
                                                                grabbers[n]) for n in names))
        done = time.time()
        self._scan.saw({n: g.saw_marker for n, g in zip(names, got, strict=True)})
        for n, g in zip(names, got, strict=True):
            if g.failed and not g.skew:
                self._bad[n] = self._bad.get(n, 0) + 1
                if self._bad[n] >= BAD_GRABS:
                    self._bad[n] = 0
                    self.keepers[n].lost(DeviceError(_why(g.end)))
            elif not g.failed:
                self._bad[n] = 0
                self.keepers[n].worked()
        for n, g in zip(names, got, strict=True):   # for the commissioning screen
            if g.sides and time.monotonic() >= self._next_frames.get(n, 0.0):
                self._next_frames[n] = time.monotonic() + PAIR_FRAMES_S
                self.bus.publish(PairFrames(n, g.exposure_t, g.sides))
        return fuse_views(names, got, self.cfg.localize, done)

    def _grab_pair(self, name: str, grabber: StereoGrabber) -> PairView:
        """Grab one pair and localize in its frames (an executor thread).  A skewed pair or a
        bad frame is a failed grab to retry."""
        t0 = time.monotonic()
        try:
            left, right = grabber.grab(1.0)
        except StereoSkewError as exc:
            return PairView(Refusal(one_line(exc)), 0.0, failed=True, skew=True)
        except (DeviceError, ValueError) as exc:
            return PairView(Refusal(one_line(exc)), 0.0, failed=True)
        t1 = time.monotonic()
        view, res = localize_pair(name, self._setups[name], left.image, right.image,
                                  min(left.timestamp, right.timestamp))
        if self.frames is not None and res is not None:   # the commissioning screen's
            for side, frame, det in (("left", left, res.left), ("right", right, res.right)):
                self.frames.put(name, side, frame.image, frame_summary(det), frame.timestamp,
                                det.search_image)
        return replace(view, timings_ms={"grab": (t1 - t0) * 1e3,
                                         "vision": (time.monotonic() - t1) * 1e3})

    # -- the actions -------------------------------------------------------------------------
    async def _do(self, a: Action) -> Event | None:
        """Carry out one action; what came of it, for the core (or None)."""
        if isinstance(a, Publish):
            self._publish(a.event)
            return None
        try:
            if isinstance(a, SendParams):
                return await self._send(a)
            if isinstance(a, EnableTool):
                return await self._enable_tool(a)
            if isinstance(a, DisableTool):
                if self.wrench is not None:
                    await self._call(self.wrench.disable_tool)
                if self.records.owes_off_time:
                    await self._call(self.records.note_off)
            elif isinstance(a, SendVin):
                return await self._send_vin(a.vin)
            elif isinstance(a, LoadVehicle):
                return await self._load(a)
            elif isinstance(a, CloseVehicle):
                return await self._close_vehicle(a.vin)
            elif isinstance(a, Record):
                return await self._record(a)
            elif isinstance(a, Acknowledge):
                await self._acknowledge(a.result)
            elif isinstance(a, StoreUnattributed):
                await self._store_unattributed(a)
            elif isinstance(a, RecordCommand):
                return await self._record_command(a)
            elif isinstance(a, Reply):
                self._reply(a.answer)
        except DeviceError as exc:   # the link is reset: its keeper reconnects and reports
            if not isinstance(exc, RefusedError):
                self.keepers[WRENCH].lost(exc)
            return DeviceFault(time.time(), WRENCH, fault_kind(exc), one_line(exc))
        return None

    def _publish(self, ev: Any) -> None:
        self.bus.publish(ev)
        if isinstance(ev, StateChanged):
            self.notifier.status(f"{ev.state}: {ev.reason}")
            if ev.state == State.FAULT.value:   # each device's own line has the reason
                log.info("state: fault (%s)", ", ".join(sorted(self.core.faults)))
            else:
                log.info("%s: %s", ev.state, ev.reason)
        elif isinstance(ev, Notice):
            (log.warning if ev.level == "warning" else log.info)("%s", ev.message)
        elif isinstance(ev, Refused):   # once per change of reason, not frame after frame
            log.info("no bolt: %s", reason_words(ev.reason, full=True))
        elif isinstance(ev, DeviceHealth):
            if ev.ok:
                log.info("%s: back", ev.device)
            else:
                log.warning("fault: %s (%s): %s", ev.device, ev.kind, ev.reason)

    async def _enable_tool(self, a: EnableTool) -> Event | None:
        """What the station owes goes to disk first (the bolt, its pset and version, where
        the wrench was), then the tool is enabled: a reload or a kill from here on still
        records the result to this bolt.  A database that refuses it is a fault of the
        database and the tool stays off."""
        try:
            await self._call(self.records.note_enable, a.selection)
        except STATION_FAULTS as exc:
            self.keepers[DATABASE].lost(DeviceError(one_line(exc)))
            return DeviceFault(time.time(), DATABASE, "down",
                               f"the tool enable not stored: {one_line(exc)}")
        await self._call(self.wrench.enable_tool)
        return ToolOn(time.time(), a.bolt)

    async def _store_unattributed(self, a: StoreUnattributed) -> None:
        """A result no bolt owns: stored, then acknowledged.  A database that refuses it is a
        fault; the result stays with the controller (not acknowledged)."""
        r = a.result
        try:
            await self._call(self.records.store_unattributed, a)
        except STATION_FAULTS as exc:
            log.error("tightening %d (unattributed) NOT stored, left with the controller: %s",
                      r.tightening_id, one_line(exc))
            self.keepers[DATABASE].lost(DeviceError(f"results not stored: {one_line(exc)}"))
            return
        await self._acknowledge(r)

    async def _record_command(self, a: RecordCommand) -> Event:
        """An accepted command on disk with its user (a reopen reopens the vehicle in the same
        transaction); what the database said, for the core."""
        repo, cmd, who = self.repo, a.command, a.issuer
        assert repo is not None  # noqa: S101 - opened in open()
        at = datetime.fromtimestamp(a.t, UTC)
        vin = getattr(cmd, "vin", None) or (self.core.vin if not isinstance(
            cmd, ReopenVehicle) else None)
        bolt = getattr(cmd, "bolt", None)
        comment = cmd.comment
        if isinstance(cmd, TeachStart):   # the model taught is part of the record
            comment = f"model {cmd.model}" + (f": {comment}" if comment else "")
        try:
            if isinstance(cmd, ReopenVehicle):
                await self._call(lambda: repo.reopen_vehicle(
                    cmd.vin, at=at, user=who.user, source=who.source, comment=cmd.comment))
            else:
                await self._call(lambda: repo.ledger.record_command(
                    at=at, user=who.user, source=who.source, kind=KIND[type(cmd)],
                    vin=vin, bolt=bolt, comment=comment))
        except NotFoundError:
            return CommandDone(time.time(), a.request, Reason(Why.UNKNOWN_VEHICLE, vin=vin))
        except DataError:
            return CommandDone(time.time(), a.request, Reason(Why.NOT_CLOSED, vin=vin))
        except STATION_FAULTS as exc:
            self.keepers[DATABASE].lost(DeviceError(one_line(exc)))
            return CommandDone(time.time(), a.request,
                               Reason(Why.NOT_RECORDED, note=one_line(exc)))
        return CommandDone(time.time(), a.request)

    def _reply(self, answer: Answer) -> None:
        """The journal's line for every command, and the answer to who is waiting for it."""
        (log.info if answer.accepted else log.warning)("%s", answer_words(answer))
        waiting = self._answers.get(answer.request)
        if waiting is not None and not waiting.done():
            waiting.set_result(answer)

    async def _send(self, a: SendParams) -> Event:
        if self.wrench is None:
            return DeviceFault(time.time(), WRENCH, "down", "not connected")
        params = a.parameters
        if params is None:   # a vehicle loaded without its parameters: never guessed
            return ParamsRefused(time.time(), a.bolt, "no parameters for this bolt")
        t_send = time.time()
        try:
            await self._call(self._send_parameters, params)
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

    def _send_parameters(self, params: Parameters) -> None:
        """The controller takes them its way (a pset, or registers with the targets)."""
        self.wrench.send_parameters(params.pset, params.torque.target,
                                    params.angle.target if params.angle else None, 2.0)

    async def _send_vin(self, vin: str) -> Event:
        if self.wrench is None:
            return DeviceFault(time.time(), WRENCH, "down", "not connected")
        try:
            await self._call(self.wrench.send_vin, vin)
        except ValueError as exc:   # the controller cannot take it (no VIN registers, length)
            log.info("VIN %s not sent to the controller: %s", vin, exc)
        except RefusedError as exc:
            log.warning("the controller refused VIN %s: %s", vin, one_line(exc))
        return VinSent(time.time(), vin)

    async def _load(self, a: LoadVehicle) -> Event:
        """The vehicle at height, from the database: loaded, rejected (unknown model, a closed
        VIN, another model's VIN) or a database fault."""
        repo = self.repo
        assert repo is not None  # noqa: S101 - opened in open()
        try:
            model = await self._call(repo.model_for_code, a.model_code)
            if model is None:
                return VehicleRejected(time.time(), a.vin,
                                       f"unknown vehicle model code {a.model_code}")
            try:
                started = await self._call(
                    lambda: repo.start_vehicle(a.vin, model, reopen=a.reopen))
            except DataError as exc:   # a closed VIN back, another model's VIN
                return VehicleRejected(time.time(), a.vin, one_line(exc),
                                       closed=isinstance(exc, VehicleClosedError))
            infos = await self._call(repo.bolts_for_model, model)
            report = await self._call(repo.vehicle_report, a.vin)
            since = started.reopened_at or started.started_at
            skipped = await self._call(repo.ledger.skipped, a.vin, since)
            noks = await self._call(repo.nok_streaks, a.vin, since)
        except STATION_FAULTS as exc:
            # its keeper probes it back, with backoff (reported as the same "down" fault)
            self.keepers[DATABASE].lost(DeviceError(one_line(exc)))
            return DeviceFault(time.time(), DATABASE, "down", one_line(exc))
        # the report's "missing" is "no rundown yet": on an open vehicle the bolt is to do
        # (the screens said "missing" for every bolt of a vehicle just loaded)
        status = {b.bolt_id: b.status for b in report.bolts if b.status != MISSING}
        done = frozenset(k for k, s in status.items() if s == "ok")
        specs = {b.bolt_id: BoltSpec(xyz(b.position), b.parameters.pset, b.order, b.batch,
                                     b.parameters_id, b.parameters) for b in infos}
        log.info("vehicle %s (%s) opened%s: %d bolts, %d done", a.vin, model,
                 " for rework" if started.rework else "", len(infos), len(done))
        # a rework resumed after a reload or restart is still one (the database keeps it)
        return VehicleLoaded(time.time(), a.vin, model, specs, done, started.rework,
                             {b: skip_note(*who) for b, who in skipped.items()}, noks, status)

    async def _close_vehicle(self, vin: str) -> Event | None:
        assert self.repo is not None  # noqa: S101
        try:
            report = await self._call(self.repo.close_vehicle, vin)
        except STATION_FAULTS as exc:
            log.error("vehicle %s not closed: %s", vin, one_line(exc))
            return None
        log.info("vehicle %s closed: missing %s, NOK %s", vin, report.missing, report.nok)
        return VehicleEnded(time.time(), vin, tuple(report.missing), tuple(report.nok))

    async def _acknowledge(self, result: Any) -> None:
        """Tell the controller a result is stored; a failure leaves it with the controller
        (it is recorded here already, and a resent copy is recognised by its id)."""
        if self.wrench is None or getattr(result, "fetched", False):
            return   # a fetched result is not awaiting an acknowledgement
        try:
            await self._call(self.wrench.acknowledge_result, result)
        except (DeviceError, ValueError) as exc:
            log.warning("tightening %d stored, not acknowledged: %s", result.tightening_id,
                        one_line(exc))

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
            log.error("tightening %d of %s NOT stored, kept until the database takes it: "
                      "%s; %s", r.tightening_id, a.bolt, one_line(exc), u.describe())
            self.bus.publish(Notice(f"tightening {r.tightening_id} of {a.bolt} not stored: "
                                    f"{one_line(exc)}", "error"))
            self.keepers[DATABASE].lost(DeviceError(f"results not stored: {one_line(exc)}"))
            return None
        return Written(time.time(), a, tuple(u.images))

    async def _recorded_late(self) -> None:
        """The results the keeper wrote on its way back: the core publishes and acknowledges
        them."""
        for u in await self._call(self.records.take_saved_late):
            await self.feed(Written(time.time(), u.record, tuple(u.images)))

def _why(end: BoltEnd | Refusal) -> str:
    return end.reason if isinstance(end, Refusal) else "no failure"


def _reconnect(device: Any) -> None:
    device.reconnect()


def _reconnect_lift(lift: Any) -> None:
    """The PLC's link back, and one read answered: back only on a valid reply."""
    lift.reconnect()
    lift.read_state(LIFT_CHECK_S)


def _close(device: Any) -> None:
    device.close()


def _quiet(fn: Any) -> None:
    try:
        fn()
    except Exception as exc:
        log.warning("closing: %s", one_line(exc))


__all__ = ["Localization", "State", "Station"]
