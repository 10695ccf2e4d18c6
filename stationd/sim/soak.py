"""A soak test's script and scorekeeping: many vehicles, an operator, devices that fail.

``stationd bench soak --bolts 500 --faults`` (:mod:`stationd.bench.soak`) runs the station
for hours' worth of an ordinary line day in minutes and must end with 0 wrong sends, 0 exits
and 0 lost results.  This module holds what does not depend on the daemon's internals, so it
is tested on its own:

- :func:`plan_soak`: a seeded script of :class:`Step` s -- vehicles arriving (some with a VIN
  already closed: rework), the wrench taken to bolts (sometimes hovering between two, or
  leaving before tightening), the lift PLC, the controller (also mid-tightening) or a camera
  pair going down and coming back, configuration reloads (valid, refused, onto a lift that
  is down) -- with a given number of tightenings;
- :class:`SoakTally`: the figures, including the wrong-send check against the truth (where
  the wrench really is when parameters are sent);
- :func:`run_soak`: plays a plan through :class:`SoakHooks`, the station-side actions the
  caller provides; :class:`SimDevices` implements the world's side of them (wrench poses,
  rendered ahead by :meth:`SimDevices.prepare`, the simulated PLC, controller and cameras).
"""

from __future__ import annotations

import asyncio
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from stationd.sim.world import World, WrenchPose, wrench_at

Device = Literal["lift", "wrench", "cameras"]
ReloadKind = Literal["valid", "bad bolt table", "lift down"]
RELOAD_KINDS: tuple[ReloadKind, ...] = ("valid", "bad bolt table", "lift down")


@dataclass(frozen=True)
class Arrive:
    """A vehicle comes to the station and the lift rises; ``rework``: its VIN was closed
    here before (the station must reopen it or fault with a reason, never exit)."""

    vin: str
    model_code: int
    rework: bool = False


@dataclass(frozen=True)
class Visit:
    """The operator takes the wrench to ``bolt``, first hovering halfway to ``hover_with``
    if given; ``leave``: goes away before tightening (the tool must go off); ``power_cut``:
    the controller powers off once the tool is enabled and comes back (the station must
    select again before the rundown)."""

    bolt: str
    hover_with: str | None = None
    leave: bool = False
    power_cut: bool = False


@dataclass(frozen=True)
class Depart:
    """The lift lowers and the vehicle leaves (its VIN is closed)."""


@dataclass(frozen=True)
class Outage:
    """``device`` goes down (PLC silent, controller powered off, a camera pair delivering
    nothing) for ``seconds``."""

    device: Device
    seconds: float


@dataclass(frozen=True)
class Reload:
    """The configuration is reloaded (SIGHUP): ``valid`` (a changed, valid file: the station
    reopens), ``bad bolt table`` (a duplicate bolt id: refused, the running station stays),
    ``lift down`` (a valid file whose lift does not answer: the new station runs in fault
    until a reload with the good file, which the hooks do after a while)."""

    kind: ReloadKind = "valid"


Step = Arrive | Visit | Depart | Outage | Reload


def plan_soak(bolts: Sequence[str], tightenings: int, *, model_code: int = 1,
              per_vehicle: int = 10, faults: bool = False, seed: int = 0) -> list[Step]:
    """A script with ``tightenings`` visits meant to end in a tightening (plus visits that
    leave early), ``per_vehicle`` per vehicle at most, over distinct bolts of ``bolts``.
    With ``faults``: about one PLC, one controller and one camera-pair outage per 25 visits,
    one power cut mid-tightening per 25, a reload per 25 (of each kind as often), and one
    vehicle in 8 a rework of an earlier VIN."""
    if tightenings < 0 or per_vehicle < 1 or not bolts:
        raise ValueError("tightenings >= 0, per_vehicle >= 1 and at least one bolt")
    rng = np.random.default_rng(seed)
    steps: list[Step] = []
    closed: list[str] = []
    done = 0
    vehicle = 0
    while done < tightenings:
        if faults and closed and rng.random() < 1 / 8:
            arrival = Arrive(closed[int(rng.integers(len(closed)))], model_code, True)
        else:
            vehicle += 1
            arrival = Arrive(f"SOAK{seed:04d}{vehicle:09d}", model_code)
        steps.append(arrival)
        n = min(per_vehicle, tightenings - done, len(bolts))
        for b in rng.permutation(len(bolts))[:n]:
            bolt = bolts[int(b)]
            cut = False
            if faults:
                devices: tuple[Device, ...] = ("lift", "wrench", "cameras")
                for device in devices:
                    if rng.random() < 1 / 25:
                        steps.append(Outage(device, float(rng.uniform(0.5, 3.0))))
                if rng.random() < 1 / 25:
                    steps.append(Reload(RELOAD_KINDS[int(rng.integers(len(RELOAD_KINDS)))]))
                cut = bool(rng.random() < 1 / 25)
            if rng.random() < 0.1:  # leaves before tightening, then comes back to it
                steps.append(Visit(bolt, leave=True))
            hover = bolts[int(rng.integers(len(bolts)))] if rng.random() < 0.2 else None
            steps.append(Visit(bolt, hover_with=hover if hover != bolt else None,
                               power_cut=cut))
            done += 1
        steps.append(Depart())
        if arrival.vin not in closed:
            closed.append(arrival.vin)
    return steps


@dataclass
class SoakTally:
    """The soak test's figures.  ``truth`` is the bolt the wrench is really on (None: on no
    bolt), kept by :func:`run_soak`; call :meth:`check_send` from the station's action hook
    for every parameter send."""

    tightened: int = 0
    not_tightened: Counter[str] = field(default_factory=Counter)
    refusals: Counter[str] = field(default_factory=Counter)
    wrong_sends: list[str] = field(default_factory=list)
    exits: int = 0
    results_made: int = 0
    results_recorded: int = 0
    outages: Counter[str] = field(default_factory=Counter)
    reloads: Counter[str] = field(default_factory=Counter)
    reworks: int = 0
    truth: str | None = None
    started: float = field(default_factory=time.monotonic)
    extra: dict[str, Any] = field(default_factory=dict)   # the runner's own figures

    def check_send(self, bolt: str) -> None:
        """Parameters for ``bolt`` are being sent: wrong unless the wrench is on it now."""
        if bolt != self.truth:
            self.wrong_sends.append(f"parameters for {bolt} while the wrench is on "
                                    f"{self.truth or 'no bolt'}")

    def refused(self, kind: str) -> None:
        """The station refused to select (its reason's category: stale, ambiguous, ...)."""
        self.refusals[kind] += 1

    @property
    def results_lost(self) -> int:
        return max(self.results_made - self.results_recorded, 0)

    def summary(self) -> dict[str, Any]:
        """The figures as one JSON-able object (``bench soak --json``)."""
        return {"bolts_tightened": self.tightened,
                "not_tightened": dict(self.not_tightened.most_common()),
                "refusals": dict(self.refusals.most_common()),
                "wrong_sends": len(self.wrong_sends), "wrong": self.wrong_sends[:10],
                "exits": self.exits, "results_made": self.results_made,
                "results_recorded": self.results_recorded, "results_lost": self.results_lost,
                "outages": dict(self.outages), "reloads": dict(self.reloads),
                "reworks": self.reworks,
                "duration_s": round(time.monotonic() - self.started, 1), **self.extra}

    @property
    def passed(self) -> bool:
        return not self.wrong_sends and self.exits == 0 and self.results_lost == 0


class SoakHooks(Protocol):
    """What :func:`run_soak` asks of the station and its simulated world."""

    async def arrive(self, vin: str, model_code: int) -> None:
        """Put the vehicle on the lift and raise it."""

    async def depart(self) -> None:
        """Lower the lift (the station closes the VIN)."""

    def wrench_to(self, bolt: str | None, halfway_to: str | None = None) -> None:
        """Place the wrench on ``bolt`` (None: away, on no bolt), or halfway to another."""

    async def wait_enabled(self, bolt: str, timeout: float) -> bool:
        """Whether the station selected ``bolt`` and enabled the tool within ``timeout``."""

    async def wait_disabled(self, timeout: float) -> bool:
        """Whether the tool went off within ``timeout``."""

    def pull_trigger(self) -> bool:
        """The operator pulls the trigger: whether the controller made a result."""

    async def device_down(self, device: Device) -> None: ...

    async def device_up(self, device: Device) -> None: ...

    async def reload(self, kind: ReloadKind) -> None:
        """Reload the station's configuration (SIGHUP) with a file of ``kind``."""

    def recorded(self) -> int:
        """How many results the station has recorded so far."""

    def alive(self) -> bool:
        """Whether the station is still running (not exited)."""

    def why_not(self) -> str:
        """The station's current reason for not selecting (for ``not_tightened``)."""


async def run_soak(plan: Sequence[Step], hooks: SoakHooks, tally: SoakTally | None = None, *,
                   select_timeout: float = 15.0, hover_s: float = 0.6,
                   settle_s: float = 0.3) -> SoakTally:
    """Play ``plan`` through ``hooks``; stop early only if the station exited."""
    t = tally or SoakTally()
    for step in plan:
        if not hooks.alive():
            t.exits += 1
            break
        if isinstance(step, Arrive):
            t.reworks += step.rework
            await hooks.arrive(step.vin, step.model_code)
        elif isinstance(step, Depart):
            t.truth = None
            hooks.wrench_to(None)
            await hooks.depart()
        elif isinstance(step, Outage):
            t.outages[step.device] += 1
            await hooks.device_down(step.device)
            await asyncio.sleep(step.seconds)
            await hooks.device_up(step.device)
        elif isinstance(step, Reload):
            t.reloads[step.kind] += 1
            await hooks.reload(step.kind)
        else:
            await _visit(step, hooks, t, select_timeout, hover_s, settle_s)
    if hooks.alive():
        t.results_recorded = hooks.recorded()
    return t


async def _visit(step: Visit, hooks: SoakHooks, t: SoakTally, select_timeout: float,
                 hover_s: float, settle_s: float) -> None:
    if step.hover_with is not None:  # between two bolts: nothing may be sent
        t.truth = None
        hooks.wrench_to(step.bolt, halfway_to=step.hover_with)
        await asyncio.sleep(hover_s)
    hooks.wrench_to(step.bolt)
    t.truth = step.bolt
    if not await hooks.wait_enabled(step.bolt, select_timeout):
        t.not_tightened[hooks.why_not() or "not selected"] += 1
    elif step.leave:
        t.truth = None
        hooks.wrench_to(None)
        if not await hooks.wait_disabled(select_timeout):
            t.not_tightened["tool stayed enabled after the wrench left"] += 1
    elif step.power_cut and not await _power_cut(step.bolt, hooks, t, select_timeout):
        t.not_tightened[hooks.why_not() or "not selected after the power cut"] += 1
    elif hooks.pull_trigger():
        t.results_made += 1
        t.tightened += 1
    else:
        t.not_tightened["the controller made no result"] += 1
    t.truth = None
    hooks.wrench_to(None)
    await asyncio.sleep(settle_s)


async def _power_cut(bolt: str, hooks: SoakHooks, t: SoakTally, timeout: float) -> bool:
    """The controller powers off with the tool enabled and comes back: whether the station
    selected the bolt again (it must not count the cut as a rundown)."""
    t.outages["controller mid-tightening"] += 1
    await hooks.device_down("wrench")
    await asyncio.sleep(1.0)
    await hooks.device_up("wrench")
    return await hooks.wait_enabled(bolt, timeout)


class SimDevices:
    """The world's side of :class:`SoakHooks` for a simulated station: wrench poses from the
    bolt table, the simulated PLC and controller, the world's camera pairs.  The station's
    side (``wait_enabled``, ``reload``, ``recorded``, ``alive``, ``why_not``) is the
    caller's: subclass or wrap this.

    Each place the wrench goes (a bolt, with its placement noise drawn once, or halfway
    between two) has one pose; :meth:`prepare` renders them all before a timed run, so that
    during it a camera's frame costs what a real camera's buffer does."""

    def __init__(self, world: World, plc: Any, controller: Any,
                 bolts: Mapping[str, Sequence[float]], tool_length_mm: float, *,
                 seed: int = 0, max_tilt_deg: float = 5.0) -> None:
        self.world = world
        self.plc = plc
        self.controller = controller
        self.bolts = {k: np.asarray(v, dtype=np.float64) for k, v in bolts.items()}
        self.length = tool_length_mm
        self.tilt = max_tilt_deg
        self.rng = np.random.default_rng(seed)
        self._poses: dict[tuple[str, str | None], WrenchPose] = {}
        self._cut: str | None = None

    def pose(self, bolt: str, halfway_to: str | None = None) -> WrenchPose:
        """The wrench on ``bolt`` (or halfway to ``halfway_to``): the same pose every time."""
        key = (bolt, halfway_to)
        if key not in self._poses:
            p = self.bolts[bolt]
            if halfway_to is not None:
                p = 0.5 * (p + self.bolts[halfway_to])
            else:  # placement noise in XY, as a hand puts it
                p = p + np.append(self.rng.normal(0, 0.3, 2), 0.0)
            self._poses[key] = wrench_at(p, self.rng, self.length, self.tilt)
        return self._poses[key]

    def prepare(self, plan: Sequence[Step]) -> int:
        """Render every place the plan takes the wrench to, ahead; how many."""
        poses = {}
        for step in plan:
            if isinstance(step, Visit):
                poses[id(self.pose(step.bolt))] = self.pose(step.bolt)
                if step.hover_with is not None:
                    hover = self.pose(step.bolt, step.hover_with)
                    poses[id(hover)] = hover
        self.world.prerender(list(poses.values()), variants=1)   # a soak needs no noise variety
        return len(poses)

    async def arrive(self, vin: str, model_code: int) -> None:
        self.plc.set_vehicle(model_code, vin)
        self.plc.raise_lift()

    async def depart(self) -> None:
        self.plc.lower_lift()

    def wrench_to(self, bolt: str | None, halfway_to: str | None = None) -> None:
        self.world.set_wrench(None if bolt is None else self.pose(bolt, halfway_to))

    def pull_trigger(self) -> bool:
        return self.controller.pull_trigger() is not None

    async def device_down(self, device: Device) -> None:
        if device == "lift":
            self.plc.set_silent(True)
        elif device == "wrench":
            self.controller.power_off()
        else:
            pairs = sorted(self.world.cfg.pairs)
            self._cut = pairs[int(self.rng.integers(len(pairs)))]
            self.world.cut_cameras(self._cut)

    async def device_up(self, device: Device) -> None:
        if device == "lift":
            self.plc.set_silent(False)
        elif device == "wrench":
            self.controller.power_on()
        elif self._cut is not None:
            self.world.restore_cameras(self._cut)
            self._cut = None
