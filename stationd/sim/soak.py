"""A soak test's script and scorekeeping: many vehicles, an operator, devices that fail.

``stationd bench soak --bolts 500 --faults`` (wired by the daemon's owner) runs the station
for hours' worth of an ordinary line day in minutes and must end with 0 wrong sends, 0 exits
and 0 lost results.  This module holds what does not depend on the daemon's internals, so it
can be tested on its own and survive the daemon's rewrite:

- :func:`plan_soak`: a seeded script of :class:`Step` s -- vehicles arriving (some with a VIN
  already closed: rework), the wrench taken to bolts (sometimes hovering between two, or
  leaving before tightening), the lift PLC or the controller going down and coming back,
  configuration reloads -- with a given number of tightenings;
- :class:`SoakTally`: the figures, including the wrong-send check against the truth (where
  the wrench really is when parameters are sent);
- :func:`run_soak`: plays a plan through :class:`SoakHooks`, the station-side actions the
  caller provides; :class:`SimDevices` implements the world's side of them (wrench poses,
  the simulated PLC and controller) for a station on ``config/sim``.
"""

from __future__ import annotations

import asyncio
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np

from stationd.sim.world import World, wrench_at

Device = Literal["lift", "wrench"]


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
    if given; ``leave``: goes away before tightening (the tool must go off)."""

    bolt: str
    hover_with: str | None = None
    leave: bool = False


@dataclass(frozen=True)
class Depart:
    """The lift lowers and the vehicle leaves (its VIN is closed)."""


@dataclass(frozen=True)
class Outage:
    """``device`` goes down (PLC silent, controller powered off) for ``seconds``."""

    device: Device
    seconds: float


@dataclass(frozen=True)
class Reload:
    """The configuration is reloaded (SIGHUP) with the same, valid files."""


Step = Arrive | Visit | Depart | Outage | Reload


def plan_soak(bolts: Sequence[str], tightenings: int, *, model_code: int = 1,
              per_vehicle: int = 10, faults: bool = False, seed: int = 0) -> list[Step]:
    """A script with ``tightenings`` visits meant to end in a tightening (plus visits that
    leave early), ``per_vehicle`` per vehicle at most, over distinct bolts of ``bolts``.
    With ``faults``: about one PLC and one controller outage per 25 visits, a reload per
    50, and one vehicle in 8 a rework of an earlier VIN."""
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
            if faults:
                for device in ("lift", "wrench"):
                    if rng.random() < 1 / 25:
                        steps.append(Outage(device, float(rng.uniform(0.5, 3.0))))
                if rng.random() < 1 / 50:
                    steps.append(Reload())
            if rng.random() < 0.1:  # leaves before tightening, then comes back to it
                steps.append(Visit(bolt, leave=True))
            hover = bolts[int(rng.integers(len(bolts)))] if rng.random() < 0.2 else None
            steps.append(Visit(bolt, hover_with=hover if hover != bolt else None))
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
    reloads: int = 0
    reworks: int = 0
    truth: str | None = None
    started: float = field(default_factory=time.monotonic)

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
                "outages": dict(self.outages), "reloads": self.reloads,
                "reworks": self.reworks,
                "duration_s": round(time.monotonic() - self.started, 1)}

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

    async def reload(self) -> None:
        """Reload the station's configuration (SIGHUP)."""

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
            t.reloads += 1
            await hooks.reload()
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
    elif hooks.pull_trigger():
        t.results_made += 1
        t.tightened += 1
    else:
        t.not_tightened["the controller made no result"] += 1
    t.truth = None
    hooks.wrench_to(None)
    await asyncio.sleep(settle_s)


class SimDevices:
    """The world's side of :class:`SoakHooks` for a simulated station: wrench poses from the
    bolt table, the simulated PLC (``SimLift.plc``) and controller (``SimWrench``'s server).
    The station's side (``wait_enabled``, ``reload``, ``recorded``, ``alive``, ``why_not``)
    is the caller's: subclass or wrap this."""

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

    async def arrive(self, vin: str, model_code: int) -> None:
        self.plc.set_vehicle(model_code, vin)
        self.plc.raise_lift()

    async def depart(self) -> None:
        self.plc.lower_lift()

    def wrench_to(self, bolt: str | None, halfway_to: str | None = None) -> None:
        if bolt is None:
            self.world.set_wrench(None)
            return
        p = self.bolts[bolt]
        if halfway_to is not None:
            p = 0.5 * (p + self.bolts[halfway_to])
        else:  # placement noise in XY, as a hand puts it
            p = p + np.append(self.rng.normal(0, 0.3, 2), 0.0)
        self.world.set_wrench(wrench_at(p, self.rng, self.length, self.tilt))

    def pull_trigger(self) -> bool:
        return self.controller.pull_trigger() is not None

    async def device_down(self, device: Device) -> None:
        if device == "lift":
            self.plc.set_silent(True)
        else:
            self.controller.power_off()

    async def device_up(self, device: Device) -> None:
        if device == "lift":
            self.plc.set_silent(False)
        else:
            self.controller.power_on()
