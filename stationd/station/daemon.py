"""The station daemon: one asyncio loop wiring devices, vision, the cycle and the database.

Blocking work (device I/O, grabbing, vision, the database) runs in executor threads; the loop
only sequences it.  The rules live in :class:`stationd.station.cycle.Cycle`; this module feeds
it events and carries out its actions.  A device error is a fault state with its reason, never
a crash; the loop keeps polling and leaves the fault when the device answers again.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import Any

import numpy as np

from db.repository import BoltInfo, Repository
from drivers.camera import open_camera
from drivers.camera.pair import StereoGrabber
from drivers.errors import DeviceError, RefusedError
from drivers.lift import open_lift
from drivers.wrench import open_wrench
from stationd.config import PairConfig, StationConfig
from stationd.geometry.stereo import localize
from stationd.geometry.tool import BoltEnd, bolt_end, fuse
from stationd.station.cycle import (
    Action,
    Cycle,
    DisableTool,
    EnableTool,
    Log,
    Record,
    SendParams,
    State,
)
from stationd.station.matching import BoltMatcher, MatchParams
from stationd.station.sdnotify import Notifier
from stationd.vision.types import Refusal

log = logging.getLogger("stationd")
TRACKING_STATES = (State.TRACKING, State.BOLT_SELECTED, State.TIGHTENING)
EVENT_HISTORY = 100_000


@dataclass
class Localization:
    point_mm: np.ndarray | None
    tilt_deg: float = 0.0
    reason: str | None = None
    t: float = 0.0


@dataclass
class Station:
    """A running station; ``open()`` the devices, ``await run(stop)``, ``close()``."""

    cfg: StationConfig
    notifier: Notifier = field(default_factory=Notifier)
    device_kw: dict[str, dict[str, Any]] = field(default_factory=dict)
    lift: Any = None
    wrench: Any = None
    repo: Repository | None = None
    grabbers: dict[str, StereoGrabber] = field(default_factory=dict)
    cycle: Cycle = field(init=False)
    vin: str | None = None
    bolts: dict[str, BoltInfo] = field(default_factory=dict)
    # recent actions and events, for the demo, the tests and a status view; bounded: a daemon
    # runs all shift and would otherwise keep every frame's refusal
    events: deque[tuple[str, Any]] = field(default_factory=lambda: deque(maxlen=EVENT_HISTORY))
    last: Localization | None = None
    on_action: Any = None  # called with each action before it is carried out (demo, tests)
    _pool: ThreadPoolExecutor = field(init=False)
    _sent_at: datetime | None = None
    _last_log: str | None = None

    def __post_init__(self) -> None:
        self.cycle = Cycle(BoltMatcher({}, self._match_params()), self.cfg.matching.leave_frames)
        self._pool = ThreadPoolExecutor(max_workers=4, thread_name_prefix="station")

    def _match_params(self) -> MatchParams:
        return self.cfg.matching

    # -- devices -----------------------------------------------------------------------------
    def open(self) -> None:
        self.repo = Repository.open(self.cfg.database_url)
        if self.cfg.bolts_path is not None:
            r = self.repo.import_bolts(self.cfg.bolts_path)
            log.info("bolt table %s: %d added, %d changed, %d unchanged, %d removed, "
                     "%d new parameter versions", self.cfg.bolts_path, len(r.added),
                     len(r.changed), len(r.unchanged), len(r.removed), len(r.new_versions))
        self.lift = open_lift(self.cfg.lift.url, self.cfg.lift.registers,
                              **self.device_kw.get("lift", {}))
        self.wrench = open_wrench(self.cfg.wrench.url, **self.device_kw.get("wrench", {}))
        for name, pc in self.cfg.pairs.items():
            if pc.left and pc.right:
                left = open_camera(self.cfg.cameras[pc.left])
                right = open_camera(self.cfg.cameras[pc.right])
                left.open()
                right.open()
                self.grabbers[name] = StereoGrabber(left, right, pc.max_skew_s)
        self.cycle.started()

    def close(self) -> None:
        """Tool off first, then every device, then the database; a failure is logged and the
        shutdown goes on."""
        def cameras(g: StereoGrabber) -> None:
            g.left.close()
            g.right.close()

        steps: list[tuple[str, Any]] = []
        if self.wrench is not None:
            steps += [("disable tool", self.wrench.disable_tool), ("wrench", self.wrench.close)]
        if self.lift is not None:
            steps.append(("lift", self.lift.close))
        steps += [(f"{n} cameras", lambda g=g: cameras(g)) for n, g in self.grabbers.items()]
        if self.repo is not None:
            steps.append(("database", self.repo.close))
        for what, fn in steps:
            try:
                fn()
            except Exception as exc:
                log.warning("closing %s: %s", what, exc)
        self._pool.shutdown(wait=True)

    # -- the loop ----------------------------------------------------------------------------
    async def run(self, stop: asyncio.Event) -> None:
        self.notifier.ready(self.cycle.state.value)
        next_ping = time.monotonic()
        while not stop.is_set():
            await self.step()
            now = time.monotonic()
            if self.notifier.watchdog_s and now >= next_ping:
                self.notifier.watchdog()
                next_ping = now + self.notifier.watchdog_s
            await asyncio.sleep(0)
        self.notifier.stopping("stopping")

    async def _call(self, fn: Any, *args: Any) -> Any:
        return await asyncio.get_running_loop().run_in_executor(self._pool, fn, *args)

    async def step(self) -> None:
        before = (self.cycle.state, self.cycle.reason)
        try:
            state = await self._call(self.lift.read_state, 1.0)
        except DeviceError as exc:
            await self._apply(self.cycle.fault(f"lift: {exc}"))
            await asyncio.sleep(0.2)
            return
        if self.cycle.state is State.FAULT:
            await self._recover()
        await self._vehicle(state)
        await self._apply(self.cycle.lift(state.ready))
        if self.cycle.state in TRACKING_STATES:
            loc = await self._localize()
            self.last = loc
            await self._apply(self.cycle.localized(loc.point_mm, loc.reason,
                                                   time.monotonic() - loc.t))
        if self.cycle.state is State.TIGHTENING:
            try:
                result = await self._call(self.wrench.wait_result, 0.05)
            except DeviceError as exc:
                await self._apply(self.cycle.fault(f"wrench: {exc}"))
                return
            if result is not None and self.cycle.bolt is not None:
                await self._apply(self.cycle.result(self.cycle.bolt, result, bool(result.ok)))
        if (self.cycle.state, self.cycle.reason) != before:
            self.notifier.status(f"{self.cycle.state.value}: {self.cycle.reason}")
            log.info("%s: %s", self.cycle.state.value, self.cycle.reason)

    async def _recover(self) -> None:
        """Leave a fault when its device answers again: the lift just did (this step read it);
        the controller when its link is up (a refusal needs nothing more: its bolt is skipped).
        A fault whose cause persists (an unknown vehicle model) is raised again in this step."""
        reason = self.cycle.reason
        if reason.startswith("wrench:") or reason.startswith("controller refused"):
            status = await self._call(self.wrench.status)
            if not status.connected:
                return
        self.cycle.recovered()  # an unknown model code faults again in this very step
        self.events.append(("recovered", reason))

    async def _vehicle(self, state: Any) -> None:
        """Open a vehicle record when a vehicle is at height, close it when the lift lowers."""
        assert self.repo is not None  # noqa: S101 - opened in open()
        if state.ready and self.vin is None:
            model = await self._call(self.repo.model_for_code, state.model_code)
            if model is None:
                await self._apply(self.cycle.fault(f"unknown vehicle model code "
                                                   f"{state.model_code}"))
                return
            vin = state.vin or f"SEQ-{int(time.time())}"
            await self._call(self.repo.start_vehicle, vin, model)
            infos = await self._call(self.repo.bolts_for_model, model)
            self.bolts = {b.bolt_id: b for b in infos}
            report = await self._call(self.repo.vehicle_report, vin)
            done = {b.bolt_id for b in report.bolts if b.status == "ok"}
            self.cycle.matcher = BoltMatcher({k: np.array(b.position) for k, b in
                                              self.bolts.items()}, self._match_params(), done)
            self.vin = vin
            self.events.append(("vehicle", vin))
        elif not state.at_working_height and self.vin is not None:
            report = await self._call(self.repo.close_vehicle, self.vin)
            self.events.append(("vehicle closed", (self.vin, report.missing, report.nok)))
            log.info("vehicle %s closed: missing %s, NOK %s", self.vin, report.missing,
                     report.nok)
            self.vin, self.bolts = None, {}

    async def _localize(self) -> Localization:
        """Grab and localize in every pair at once; the result's time ``t`` is the earliest
        arrival of the frames it used (its age, and the latency to the acknowledgement, are
        counted from there: from the frames, not from the request)."""
        names = list(self.grabbers)
        got = await asyncio.gather(*(self._call(self._localize_pair, n) for n in names))
        ends = [g[0] for g in got if isinstance(g[0], BoltEnd)]
        used = [g[1] for g in got if isinstance(g[0], BoltEnd)] or [g[1] for g in got]
        arrived = min(used, default=time.monotonic())
        reasons = [f"{n}: {g[0]}" for n, g in zip(names, got, strict=True)
                   if isinstance(g[0], str)]
        if not ends:
            return Localization(None, reason="; ".join(reasons) or "no pair", t=arrived)
        fused = fuse([e.point_mm for e in ends], [1.0] * len(ends), max_spread_mm=2.0)
        if isinstance(fused, Refusal):
            return Localization(None, reason=fused.reason, t=arrived)
        return Localization(fused.point_mm, float(np.mean([e.tilt_deg for e in ends])),
                            t=arrived)

    def _localize_pair(self, name: str) -> tuple[BoltEnd | str, float]:
        """Grab and localize in one pair (an executor thread): the bolt end or why not, and
        when the frames arrived (monotonic clock)."""
        pc: PairConfig = self.cfg.pairs[name]
        try:
            left, right = self.grabbers[name].grab(1.0)
        except DeviceError as exc:
            return f"cameras: {exc}", time.monotonic()
        arrived = time.monotonic()
        res = localize(pc.calibration, left.image, right.image, self.cfg.vision, self.cfg.marker)
        if not res.found or res.point_mm is None or res.normal is None:
            return str(res.reason), arrived
        if pc.to_vehicle is None:
            return "pair not registered into the vehicle frame", arrived
        end = bolt_end(pc.to_vehicle.apply(res.point_mm),
                       pc.to_vehicle.apply_direction(res.normal), self.cfg.tool)
        return (end.reason if isinstance(end, Refusal) else end), arrived

    async def _apply(self, actions: list[Action]) -> None:
        for a in actions:
            self.events.append((type(a).__name__, a))
            if self.on_action is not None:
                self.on_action(a)
            try:
                if isinstance(a, SendParams):
                    params = self.bolts[a.bolt].parameters
                    self._sent_at = datetime.now(UTC)
                    try:
                        await self._call(self.wrench.select_pset, params.pset, 2.0)
                    except RefusedError as exc:
                        await self._apply(self.cycle.params_refused(a.bolt, str(exc)))
                        continue
                    if self.last is not None:  # frame grabbed -> parameters acknowledged
                        self.events.append(("latency_ms", (time.monotonic() - self.last.t) * 1e3))
                    await self._apply(self.cycle.params_acknowledged(a.bolt))
                elif isinstance(a, EnableTool):
                    await self._call(self.wrench.enable_tool)
                elif isinstance(a, DisableTool):
                    await self._call(self.wrench.disable_tool)
                elif isinstance(a, Record):
                    await self._record(a)
                elif isinstance(a, Log) and a.message != self._last_log:
                    # one journal line per change: the same refusal frame after frame is
                    # logged once, with its reason, until the reason changes
                    log.info("%s", a.message)
                    self._last_log = a.message
            except DeviceError as exc:
                await self._apply(self.cycle.fault(f"wrench: {exc}"))

    async def _record(self, a: Record) -> None:
        assert self.repo is not None and self.vin is not None  # noqa: S101
        r = a.result
        pos = self.last.point_mm if self.last and self.last.point_mm is not None else np.zeros(3)
        info = self.bolts.get(a.bolt)
        repo = self.repo
        await self._call(lambda: repo.record_tightening(
            self.vin, a.bolt, ok=bool(r.ok), position_mm=[float(v) for v in pos],
            match_distance_mm=float(a.match.distance_mm or 0.0) if a.match else 0.0,
            tilt_deg=self.last.tilt_deg if self.last else 0.0,
            torque_nm=float(r.torque_nm), angle_deg=float(r.angle_deg),
            parameters_id=info.parameters_id if info else None,
            tightening_id=int(r.tightening_id), sent_at=self._sent_at,
            result_at=datetime.now(UTC)))
