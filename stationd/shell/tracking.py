"""Grab and localize while the core tracks the wrench: the station's eyes.

Why apart from the daemon: the rules of a pair's health live here, next to the grabs that
show it.  A skewed stereo pair or one bad frame is a failed grab to retry; a pair failing
``BAD_GRABS`` grabs in a row is lost (its keeper reconnects it, with backoff); a pair that
grabs again has worked.  Which pairs are grabbed each cycle is the scan plan's choice
(:mod:`stationd.station.scan`), the localization and the fusion of pairs are the pure
:mod:`stationd.localize`; this module only times them and feeds the result to the core.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from drivers.camera.pair import StereoGrabber, StereoSkewError
from drivers.errors import DeviceError
from drivers.keeper import DeviceKeeper, one_line
from stationd.bus import EventBus
from stationd.config import StationConfig
from stationd.localize import (
    Localization,
    PairSetup,
    PairView,
    frame_summary,
    fuse_views,
    localize_pair,
    with_references,
)
from stationd.localize.check import PairCheck, check_pair, not_checked
from stationd.result import Refusal
from stationd.shell.blocking import Blocking
from stationd.shell.devices import Pair
from stationd.shell.records import xyz
from stationd.station.core import StationCore
from stationd.station.events import PairFrames
from stationd.station.inputs import Event, LocalizedIn
from stationd.station.scan import ScanPlan
from stationd.station.trust import MeasureReferences, ReferencesChecked

BAD_GRABS = 3               # a pair failing this many grabs in a row is a fault
IDLE_S = 0.1                # the loop's wait while the core is not tracking
PAIR_FRAMES_S = 0.5         # a pair's detection summary is published at most this often


class FrameStore(Protocol):
    """The screens' latest-frame store (``stationd.web.frames.LatestFrames``)."""

    def put(self, pair: str, side: str, image: np.ndarray,
            summary: dict[str, Any] | None = None, grabbed_at: float | None = None,
            preview: np.ndarray | None = None) -> None: ...


class Tracker:
    """The vision loop of a station; :attr:`last` is its latest localization."""

    def __init__(self, cfg: StationConfig, core: StationCore,
                 keepers: dict[str, DeviceKeeper[Pair]], bus: EventBus,
                 feed: Callable[[Event], Awaitable[None]], call: Blocking) -> None:
        self.core, self.bus, self._keepers, self._feed, self._call = \
            core, bus, keepers, feed, call
        self.cfg = cfg
        refs = cfg.references
        # with reference markers, each pair's wrench search leaves their places out: a
        # reference is never taken for the wrench
        self.setups = {n: PairSetup(pc.calibration, pc.to_vehicle, cfg.vision, cfg.marker,
                                    cfg.tool, cfg.records.save_images)
                       for n, pc in cfg.pairs.items() if pc.calibration is not None}
        if refs is not None:
            self.setups = {n: with_references(s, refs.of(n), refs.exclusion_mm)
                           for n, s in self.setups.items()}
        self._checks: list[MeasureReferences] = []   # calibration checks asked for
        self.frames: FrameStore | None = None   # set when the screens are on
        self.last: Localization | None = None
        self._bad: dict[str, int] = {}           # pair -> failed grabs in a row
        self._next_frames: dict[str, float] = {}  # pair -> next PairFrames
        self._scan = ScanPlan()

    @property
    def grabbers(self) -> dict[str, StereoGrabber]:
        """The grabbers of the pairs that are up."""
        return {n: k.device.grabber for n, k in self._keepers.items()
                if k.up and k.device is not None}

    async def loop(self, stop: asyncio.Event) -> None:
        """Grab and localize while the core tracks and every pair is up (a pair that is down
        is its keeper's to bring back)."""
        while not stop.is_set():
            if self._checks:   # answered also with every pair down: "not checked", why
                await self._measure(self._checks.pop(0))
            now = self.core.status()
            down = [n for n in self._keepers if n in now.faults]
            if not now.cameras_on or not self.grabbers or down:
                await asyncio.sleep(IDLE_S)
                continue
            cycle = self._scan.choose(list(self.grabbers))
            loc = await self._localize(cycle.decide)
            if loc is not None:
                self.last = loc
                point = None if loc.point_mm is None else xyz(loc.point_mm)
                await self._feed(LocalizedIn(time.time(), loc.exposure_t, point, loc.reason,
                                             loc.tilt_deg, loc, loc.pairs))
            if cycle.scout and self._scan.watching:   # after the decision, never before it
                await self._localize(cycle.scout)

    async def _localize(self, names: list[str]) -> Localization | None:
        """Grab and localize at once in the pairs ``names`` that are up, then fuse.  A pair
        that failed its grab is left out; after ``BAD_GRABS`` failures in a row its keeper is
        told it is lost."""
        grabbers = self.grabbers
        names = [n for n in names if n in grabbers]
        got: list[PairView] = await asyncio.gather(*(self._call(self._grab, n, grabbers[n])
                                                     for n in names))
        done = time.time()
        self._scan.saw({n: g.saw_marker for n, g in zip(names, got, strict=True)})
        for n, g in zip(names, got, strict=True):
            if g.failed and not g.skew:
                self._bad[n] = self._bad.get(n, 0) + 1
                if self._bad[n] >= BAD_GRABS:
                    self._bad[n] = 0
                    self._keepers[n].lost(DeviceError(_why(g.end)))
            elif not g.failed:
                self._bad[n] = 0
                self._keepers[n].worked()
        for n, g in zip(names, got, strict=True):   # for the commissioning screen
            if g.sides and time.monotonic() >= self._next_frames.get(n, 0.0):
                self._next_frames[n] = time.monotonic() + PAIR_FRAMES_S
                self.bus.publish(PairFrames(n, g.exposure_t, g.sides))
        return fuse_views(names, got, self.cfg.localize, done, self.core.status().untrusted)

    def _grab(self, name: str, grabber: StereoGrabber) -> PairView:
        """Grab one pair and localize in its frames (an executor thread)."""
        t0 = time.monotonic()
        try:
            left, right = grabber.grab(1.0)
        except StereoSkewError as exc:
            return PairView(Refusal(one_line(exc)), 0.0, failed=True, skew=True)
        except (DeviceError, ValueError) as exc:
            return PairView(Refusal(one_line(exc)), 0.0, failed=True)
        t1 = time.monotonic()
        view, res = localize_pair(name, self.setups[name], left.image, right.image,
                                  min(left.timestamp, right.timestamp))
        if self.frames is not None and res is not None:   # the commissioning screen's
            for side, frame, det in (("left", left, res.left), ("right", right, res.right)):
                self.frames.put(name, side, frame.image, frame_summary(det), frame.timestamp,
                                det.search_image)
        return replace(view, timings_ms={"grab": (t1 - t0) * 1e3,
                                         "vision": (time.monotonic() - t1) * 1e3})


    # -- the calibration check ---------------------------------------------------------------
    def request_check(self, a: MeasureReferences) -> None:
        """The core asked for a calibration check: done by this loop, between two
        localizations (its grabs are the loop's own), then fed back.  A check asked while
        another waits is merged into it (one grab answers both: the newer's pairs and lift,
        the command's request kept), unless both answer a person's command: then the second
        is measured after the first, each answered with its own grab."""
        for i, waiting in enumerate(self._checks):
            if a.request is None or waiting.request is None:
                self._checks[i] = replace(a, request=a.request if a.request is not None
                                          else waiting.request)
                return
        self._checks.append(a)

    async def _measure(self, a: MeasureReferences) -> None:
        """Grab each pair asked once and check it against its references; a pair that is
        down or fails its grab is "not checked", with why."""
        refs = self.cfg.references
        if refs is None:
            return
        grabbers = self.grabbers

        async def one(name: str) -> PairCheck:
            grabber = grabbers.get(name)
            if grabber is None:
                return not_checked(name, refs.tolerance_mm, "the pair is down")
            return await self._call(self._check_pair, name, grabber, a.lift_at_height)

        checks = await asyncio.gather(*(one(n) for n in a.pairs))
        await self._feed(ReferencesChecked(time.time(), tuple(checks), a.request, a.t))

    def _check_pair(self, name: str, grabber: StereoGrabber, at_height: bool) -> PairCheck:
        refs, pc = self.cfg.references, self.cfg.pairs[name]
        if refs is None or pc.calibration is None:
            raise ValueError(f"pair {name} has no calibration to check")
        try:
            left, right = grabber.grab(1.0)
        except (DeviceError, ValueError) as exc:
            return not_checked(name, refs.tolerance_mm, one_line(exc))
        return check_pair(name, pc.calibration, pc.to_vehicle, left.image, right.image,
                          refs.of(name), tolerance_mm=refs.tolerance_mm,
                          search_mm=refs.exclusion_mm, vision=self.cfg.vision,
                          marker=self.cfg.marker, lift_at_height=at_height)


def _why(end: object) -> str:
    return end.reason if isinstance(end, Refusal) else "no failure"
