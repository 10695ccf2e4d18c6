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

import cv2
import numpy as np

from db.bolts import Parameters
from db.repository import BoltInfo, Repository
from drivers.camera import open_camera
from drivers.camera.pair import StereoGrabber
from drivers.errors import DeviceError, RefusedError
from drivers.lift import open_lift
from drivers.wrench import open_wrench
from stationd.boltfile import import_bolts
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
from stationd.station.matching import BoltMatcher, BoltRule, MatchParams
from stationd.station.sdnotify import Notifier
from stationd.vision.types import Refusal

log = logging.getLogger("stationd")
TRACKING_STATES = (State.TRACKING, State.BOLT_SELECTED, State.TIGHTENING)
EVENT_HISTORY = 100_000
# a result this long after the tool went off is not the last bolt's late one: the tool cannot
# tighten while disabled, and the controller reports within milliseconds
LATE_RESULT_S = 5.0


@dataclass
class Localization:
    point_mm: np.ndarray | None
    tilt_deg: float = 0.0
    reason: str | None = None
    t: float = 0.0
    # the marker's neighbourhood in each frame used ("pair1/left" -> crop): the evidence kept
    # with a tightening record when records.save_images is on (a crop, not 60 MB frames)
    crops: dict[str, np.ndarray] = field(default_factory=dict)
    camera_fault: bool = False       # a camera stopped delivering (``reason`` says which)
    done_t: float = 0.0              # when the localization was ready (monotonic)
    timings_ms: dict[str, float] = field(default_factory=dict)  # slowest pair's stages


@dataclass(frozen=True)
class Selection:
    """What decided a bolt's selection, kept with its record: a result may arrive after the
    wrench left (or after the next localization), and must carry this bolt's evidence."""

    bolt: str
    pset: int | None
    point_mm: np.ndarray
    tilt_deg: float
    match_distance_mm: float
    sent_at: datetime
    crops: dict[str, np.ndarray]


@dataclass(frozen=True)
class PairView:
    """One pair's grab and localization: the bolt end or why not, when the frames arrived,
    and the crops around the marker."""

    end: BoltEnd | str
    arrived: float
    crops: dict[str, np.ndarray] = field(default_factory=dict)
    camera_fault: bool = False
    timings_ms: dict[str, float] = field(default_factory=dict)  # grab, vision


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
    _last_log: str | None = None
    _selection: Selection | None = None  # the bolt whose parameters were sent last
    _enabled: Selection | None = None    # the bolt the tool was last enabled for
    _disabled_at: float | None = None    # when the tool went off since (monotonic)
    _vin_sent: tuple[str, int] | None = None  # (VIN, controller reconnect count) it went with

    def __post_init__(self) -> None:
        self.cycle = Cycle(BoltMatcher({}, self._match_params()), self.cfg.matching.leave_frames)
        self._pool = ThreadPoolExecutor(max_workers=4, thread_name_prefix="station")

    def _match_params(self) -> MatchParams:
        return self.cfg.matching

    # -- devices -----------------------------------------------------------------------------
    def open(self) -> None:
        self.repo = Repository.open(self.cfg.database_url)
        if self.cfg.bolts_path is not None:
            r = import_bolts(self.repo, self.cfg.bolts_path,
                             tolerance_mm=self.cfg.matching.tolerance_mm)
            log.info("bolt table %s: %d added, %d changed, %d unchanged, %d removed, "
                     "%d new parameter versions", self.cfg.bolts_path, len(r.added),
                     len(r.changed), len(r.unchanged), len(r.removed), len(r.new_versions))
        self.lift = open_lift(self.cfg.lift.url, self.cfg.lift.registers,
                              **self.device_kw.get("lift", {}))
        self.wrench = open_wrench(self.cfg.wrench.url, **self.cfg.wrench.open_options(),
                                  **self.device_kw.get("wrench", {}))
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
        if self.vin is not None and self.cycle.state is not State.FAULT:
            await self._send_vin()
        if self.cycle.state in TRACKING_STATES:
            loc = await self._localize()
            self.last = loc
            if loc.camera_fault:
                await self._apply(self.cycle.fault(f"cameras: {loc.reason}"))
            else:
                await self._apply(self.cycle.localized(loc.point_mm, loc.reason,
                                                       time.monotonic() - loc.t))
        if self.cycle.state is not State.FAULT:
            await self._results()
        if (self.cycle.state, self.cycle.reason) != before:
            self.notifier.status(f"{self.cycle.state.value}: {self.cycle.reason}")
            log.info("%s: %s", self.cycle.state.value, self.cycle.reason)

    async def _results(self) -> None:
        """Take the controller's results, in every state: one that arrives after the wrench
        left its bolt must never wait in the queue to be taken for the next bolt's."""
        wait = 0.05 if self.cycle.state is State.TIGHTENING else 0.0
        try:
            result = await self._call(lambda: self.wrench.wait_result(wait, acknowledge=False))
        except DeviceError as exc:
            await self._apply(self.cycle.fault(f"wrench: {exc}"))
            return
        if result is None:
            return
        en = self._enabled
        ours = en is not None and (en.pset is None or result.pset == en.pset)
        if self.cycle.state is State.TIGHTENING and self.cycle.bolt is not None and ours:
            await self._apply(self.cycle.result(self.cycle.bolt, result, bool(result.ok)))
        elif ours and en is not None and self.vin and self._disabled_at is not None \
                and time.monotonic() - self._disabled_at < LATE_RESULT_S:
            # the trigger was pulled as the wrench left: the result is that bolt's
            await self._apply(self.cycle.result(en.bolt, result, bool(result.ok)))
        else:
            log.warning("result %d (pset %d, VIN %r, %s) outside any tightening: not "
                        "attributable to a bolt, acknowledged (the controller keeps its own "
                        "record)", result.tightening_id, result.pset, result.vin,
                        "OK" if result.ok else "NOK")
            self.events.append(("unattributed result", result))
            await self._acknowledge(result)

    async def _acknowledge(self, result: Any) -> None:
        """Tell the controller a result is stored; a failure leaves it with the controller
        (it is recorded here already, and a resent copy is recognised by its id)."""
        try:
            await self._call(self.wrench.acknowledge_result, result)
        except (DeviceError, ValueError) as exc:
            log.warning("tightening %d stored, not acknowledged: %s", result.tightening_id, exc)

    async def _send_vin(self) -> None:
        """The controller tags its results with the VIN: sent once per vehicle and again
        after the controller reconnects (a power cycle forgets it)."""
        assert self.vin is not None  # noqa: S101 - called only with a vehicle
        try:
            status = await self._call(self.wrench.status)
        except DeviceError:
            return
        if not status.connected or self._vin_sent == (self.vin, status.reconnects):
            return
        try:
            await self._call(self.wrench.send_vin, self.vin)
        except ValueError as exc:   # the controller cannot take it (no VIN registers, length)
            log.info("VIN %s not sent to the controller: %s", self.vin, exc)
        except RefusedError as exc:
            log.warning("the controller refused VIN %s: %s", self.vin, exc)
        except DeviceError as exc:
            await self._apply(self.cycle.fault(f"wrench: {exc}"))
            return
        self._vin_sent = (self.vin, status.reconnects)

    async def _recover(self) -> None:
        """Leave a fault when its device answers again: the lift just did (this step read it);
        the controller when its link is up (a refusal needs nothing more: its bolt is skipped);
        the cameras when every pair grabs again.  A fault whose cause persists (an unknown
        vehicle model) is raised again in this step."""
        reason = self.cycle.reason
        if reason.startswith("wrench:") or reason.startswith("controller refused"):
            status = await self._call(self.wrench.status)
            if not status.connected:
                return
        if reason.startswith("cameras:"):
            grabs = await asyncio.gather(*(self._call(self._grab_ok, g)
                                           for g in self.grabbers.values()))
            if not all(grabs):
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
            self.cycle.matcher = BoltMatcher(
                {k: np.array(b.position) for k, b in self.bolts.items()}, self._match_params(),
                done, rules={b.bolt_id: BoltRule(b.order, b.batch) for b in infos})
            self.vin = vin
            self.events.append(("vehicle", vin))
        elif not state.at_working_height and self.vin is not None:
            report = await self._call(self.repo.close_vehicle, self.vin)
            self.events.append(("vehicle closed", (self.vin, report.missing, report.nok)))
            log.info("vehicle %s closed: missing %s, NOK %s", self.vin, report.missing,
                     report.nok)
            self.vin, self.bolts, self._enabled = None, {}, None

    async def _localize(self) -> Localization:
        """Grab and localize in every pair at once; the result's time ``t`` is the earliest
        arrival of the frames it used (its age, and the latency to the acknowledgement, are
        counted from there: from the frames, not from the request).  A pair whose cameras
        stopped delivering is a fault, not a refusal: the station is blind there."""
        names = list(self.grabbers)
        got: list[PairView] = await asyncio.gather(*(self._call(self._localize_pair, n)
                                                     for n in names))
        done = time.monotonic()
        timings = {k: max((g.timings_ms.get(k, 0.0) for g in got), default=0.0)
                   for k in ("grab", "vision")}
        broken = [f"{n}: {g.end}" for n, g in zip(names, got, strict=True) if g.camera_fault]
        if broken:
            return Localization(None, reason="; ".join(broken), camera_fault=True)
        ends = [g.end for g in got if isinstance(g.end, BoltEnd)]
        used = [g for g in got if isinstance(g.end, BoltEnd)] or got
        arrived = min((g.arrived for g in used), default=time.monotonic())
        crops = {k: c for g in used for k, c in g.crops.items()}
        reasons = [f"{n}: {g.end}" for n, g in zip(names, got, strict=True)
                   if isinstance(g.end, str)]
        if not ends:
            return Localization(None, reason="; ".join(reasons) or "no pair", t=arrived,
                                done_t=done, timings_ms=timings)
        fused = fuse([e.point_mm for e in ends], [1.0] * len(ends), max_spread_mm=2.0)
        if isinstance(fused, Refusal):
            return Localization(None, reason=fused.reason, t=arrived, done_t=done,
                                timings_ms=timings)
        return Localization(fused.point_mm, float(np.mean([e.tilt_deg for e in ends])),
                            t=arrived, crops=crops, done_t=done, timings_ms=timings)

    def _grab_ok(self, grabber: StereoGrabber) -> bool:
        """Whether a pair delivers frames again (recovery from a camera fault)."""
        try:
            grabber.grab(1.0)
        except DeviceError:
            return False
        return True

    def _localize_pair(self, name: str) -> PairView:
        """Grab and localize in one pair (an executor thread)."""
        pc: PairConfig = self.cfg.pairs[name]
        t0 = time.monotonic()
        try:
            left, right = self.grabbers[name].grab(1.0)
        except DeviceError as exc:
            return PairView(str(exc), time.monotonic(), camera_fault=True)
        arrived = time.monotonic()
        res = localize(pc.calibration, left.image, right.image, self.cfg.vision, self.cfg.marker)
        timings = {"grab": (arrived - t0) * 1e3, "vision": (time.monotonic() - arrived) * 1e3}
        if not res.found or res.point_mm is None or res.normal is None:
            return PairView(str(res.reason), arrived, timings_ms=timings)
        crops = {}
        if self.cfg.records.save_images:
            crops = {f"{name}/{side}": crop(frame.image, det.roi)
                     for side, frame, det in (("left", left, res.left), ("right", right,
                                                                         res.right))
                     if det.roi is not None}
        if pc.to_vehicle is None:
            return PairView("pair not registered into the vehicle frame", arrived,
                            timings_ms=timings)
        end = bolt_end(pc.to_vehicle.apply(res.point_mm),
                       pc.to_vehicle.apply_direction(res.normal), self.cfg.tool)
        return PairView(end.reason if isinstance(end, Refusal) else end, arrived, crops,
                        timings_ms=timings)

    async def _apply(self, actions: list[Action]) -> None:
        for a in actions:
            self.events.append((type(a).__name__, a))
            if self.on_action is not None:
                self.on_action(a)
            try:
                if isinstance(a, SendParams):
                    params = self.bolts[a.bolt].parameters
                    loc = self.last
                    match = self.cycle.selected_match
                    self._selection = Selection(
                        a.bolt, params.pset,
                        loc.point_mm if loc is not None and loc.point_mm is not None
                        else np.zeros(3),
                        loc.tilt_deg if loc is not None else 0.0,
                        float(match.distance_mm or 0.0) if match is not None else 0.0,
                        datetime.now(UTC), loc.crops if loc is not None else {})
                    t_send = time.monotonic()
                    try:
                        await self._call(self._send_parameters, params)
                    except RefusedError as exc:
                        await self._apply(self.cycle.params_refused(a.bolt, str(exc)))
                        continue
                    if self.last is not None:  # frame arrived -> parameters acknowledged
                        self.events.append(("latency", self._latency(self.last, t_send)))
                    await self._apply(self.cycle.params_acknowledged(a.bolt))
                elif isinstance(a, EnableTool):
                    if self._selection is not None and self._selection.bolt == a.bolt:
                        self._enabled, self._disabled_at = self._selection, None
                    await self._call(self.wrench.enable_tool)
                elif isinstance(a, DisableTool):
                    if self._disabled_at is None:
                        self._disabled_at = time.monotonic()
                    await self._call(self.wrench.disable_tool)
                elif isinstance(a, Record):
                    await self._record(a)          # on disk first,
                    await self._acknowledge(a.result)  # then the controller may forget it
                elif isinstance(a, Log) and a.message != self._last_log:
                    # one journal line per change: the same refusal frame after frame is
                    # logged once, with its reason, until the reason changes
                    log.info("%s", a.message)
                    self._last_log = a.message
            except DeviceError as exc:
                await self._apply(self.cycle.fault(f"wrench: {exc}"))

    @staticmethod
    def _latency(loc: Localization, t_send: float) -> dict[str, float]:
        """The selection's latency, from the arrival of the frames that decided it to the
        controller's acknowledgement, and its stages (ms)."""
        now = time.monotonic()
        return {"total": (now - loc.t) * 1e3, "localize": (loc.done_t - loc.t) * 1e3,
                "decide": (t_send - loc.done_t) * 1e3, "acknowledge": (now - t_send) * 1e3,
                "vision_slowest_pair": loc.timings_ms.get("vision", 0.0),
                "grab_slowest_pair": loc.timings_ms.get("grab", 0.0)}

    def _send_parameters(self, params: Parameters) -> None:
        """A register-driven controller takes the pset with the torque and angle targets; a
        pset-driven one (Open Protocol) its pset.  A bolt without a pset on a pset-driven
        controller is refused like a pset the controller does not know."""
        if hasattr(self.wrench, "set_parameters"):
            self.wrench.set_parameters(params.pset or 0, params.torque.target,
                                       params.angle.target if params.angle else 0.0, 2.0)
        elif params.pset is None:
            raise RefusedError("the bolt has no pset and this controller takes psets only",
                               device=self.wrench.device)
        else:
            self.wrench.select_pset(params.pset, 2.0)

    async def _record(self, a: Record) -> None:
        assert self.repo is not None and self.vin is not None  # noqa: S101
        r = a.result
        sel = self._enabled if self._enabled is not None and self._enabled.bolt == a.bolt \
            else None
        if sel is not None:
            self._enabled = None   # its result is in: a later one is not this bolt's
        info = self.bolts.get(a.bolt)
        repo = self.repo
        images = await self._call(self._save_images, a.bolt, int(r.tightening_id), sel)
        if sel is None:  # not expected: a result is taken only for an enabled selection
            log.warning("result %d for %s without its selection: recorded without position",
                        r.tightening_id, a.bolt)
        await self._call(lambda: repo.record_tightening(
            self.vin, a.bolt, ok=bool(r.ok),
            position_mm=[float(v) for v in sel.point_mm] if sel else [0.0, 0.0, 0.0],
            match_distance_mm=sel.match_distance_mm if sel else 0.0,
            tilt_deg=sel.tilt_deg if sel else 0.0,
            torque_nm=float(r.torque_nm), angle_deg=float(r.angle_deg),
            parameters_id=info.parameters_id if info else None,
            tightening_id=int(r.tightening_id), sent_at=sel.sent_at if sel else None,
            result_at=datetime.now(UTC), images=images))

    def _save_images(self, bolt: str, tightening_id: int, sel: Selection | None) -> list[str]:
        """Write the selection's crops beside the records (an executor thread); a failure is
        logged and the tightening is recorded without them, never lost."""
        folder = self.cfg.records.images_dir
        if not self.cfg.records.save_images or folder is None or sel is None:
            return []
        out = []
        for key, img in sorted(sel.crops.items()):
            path = folder / str(self.vin) / f"{bolt}-{tightening_id}-{key.replace('/', '-')}.png"
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                if not cv2.imwrite(str(path), img):
                    raise OSError("the PNG encoder refused it")
            except (OSError, cv2.error) as exc:
                log.warning("image %s not saved: %s", path, exc)
                continue
            out.append(str(path))
        return out


def crop(image: np.ndarray, roi: tuple[int, int, int, int], margin: int = 16) -> np.ndarray:
    """The marker's neighbourhood (``roi`` x, y, w, h plus ``margin``), a copy."""
    x, y, w, h = roi
    hh, ww = image.shape[:2]
    x0, y0 = max(0, x - margin), max(0, y - margin)
    return image[y0:min(hh, y + h + margin), x0:min(ww, x + w + margin)].copy()
