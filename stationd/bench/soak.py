"""``stationd bench soak --bolts N [--faults] [--load N]``: the daemon through a long shift.

The simulated station of ``bench station`` (config/sim, the lift PLC on Modbus, the controller
on Open Protocol, eight 20 MP cameras composing pre-rendered placements) tightens ``N`` bolts
over as many vehicles as it takes.  With ``--faults`` a random outage hits before some bolts:
the lift PLC stops answering, the controller powers off (sometimes mid-tightening), a camera
pair stops delivering, or a vehicle whose VIN was closed comes back (a rework).  ``--load N``
keeps N busy processes on the cores meanwhile.  It prints what a shift must show: bolts
tightened, refusals by reason, parameters sent for a wrong bolt (must be 0), daemon loop
exits (must be 0) and results lost (pulled, never recorded: must be 0).
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing
import sys
import tempfile
import time
from collections import Counter
from dataclasses import replace
from typing import Any

import numpy as np

from stationd.boltfile import load_bolts
from stationd.config import load_station_config
from stationd.errors import InputError
from stationd.jsonout import strict_json
from stationd.sim.world import World, WrenchPose, wrench_at
from stationd.station.core import SendParams, State
from stationd.station.daemon import Station
from stationd.station.demo import SIM_CONFIG, _kind, _sim_psets
from stationd.station.events import Refused, ResultRecorded

FAULTS = ("lift", "controller", "controller mid-tightening", "cameras", "closed VIN back")
FAULT_RATE = 0.15       # of bolts preceded by an outage
OUTAGE_S = 1.5


def _busy() -> None:
    while True:
        pass


async def _until(pred: Any, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        await asyncio.sleep(0.01)
    return False


class Shift:
    """The simulated operator and line around one station; counts what happened."""

    def __init__(self, st: Station, world: World, rng: np.random.Generator,
                 poses: dict[str, WrenchPose], faults: bool) -> None:
        self.st, self.world, self.rng, self.poses, self.faults = st, world, rng, poses, faults
        self.truth: str | None = None
        self.wrong = 0
        self.pulled: list[int] = []
        self.injected: Counter[str] = Counter()
        self.skipped: list[str] = []
        self.vehicles = 0

    def check(self, action: Any) -> None:
        if isinstance(action, SendParams) and action.bolt != self.truth:
            self.wrong += 1
            print(f"WRONG BOLT: parameters for {action.bolt} while the wrench is on "
                  f"{self.truth or 'no bolt'}", flush=True)

    def tightening(self, bolt: str) -> bool:
        c = self.st.core
        return c.state is State.TIGHTENING and c.bolt == bolt \
            and bool(self.st.wrench.controller.tool_enabled)

    async def vehicle(self, vin: str) -> None:
        plc = self.st.lift.plc
        plc.set_vehicle(1, vin)
        plc.raise_lift()
        self.vehicles += 1
        await _until(lambda: self.st.vin == vin and self.st.core.state is State.TRACKING, 30)

    async def leave(self) -> None:
        plc = self.st.lift.plc
        plc.lower_lift()
        await _until(lambda: self.st.vin is None, 30)

    async def outage(self, kind: str) -> None:
        st, world = self.st, self.world
        self.injected[kind] += 1
        if kind == "lift":
            plc = st.lift.plc
            port = plc.tcp_port
            plc.stop_tcp()
            await asyncio.sleep(OUTAGE_S)
            plc.start_tcp(port)
        elif kind.startswith("controller"):
            st.wrench.controller.power_off()
            await asyncio.sleep(OUTAGE_S)
            st.wrench.controller.power_on()
        elif kind == "cameras":
            pair = str(self.rng.choice(list(st.cfg.pairs)))
            world.cut_cameras(pair)
            await asyncio.sleep(OUTAGE_S)
            world.restore_cameras(pair)
        elif kind == "closed VIN back":
            vin = st.vin
            if vin is not None:
                await self.leave()
                await self.vehicle(vin)      # the same VIN again: reopened as a rework

    async def bolt(self, bolt: str) -> None:
        fault = str(self.rng.choice(FAULTS)) if self.faults \
            and self.rng.random() < FAULT_RATE else None
        if fault is not None and fault != "controller mid-tightening":
            await self.outage(fault)
        self.world.set_wrench(self.poses[bolt])
        self.truth = bolt
        if not await _until(lambda: self.tightening(bolt), 60):
            self.skipped.append(f"{bolt}: {self.st.core.reason}")
        else:
            if fault == "controller mid-tightening":
                await self.outage(fault)
                await _until(lambda: self.tightening(bolt), 60)
            n = self.st.bus.count(ResultRecorded)
            shot = self.st.wrench.controller.pull_trigger() if self.tightening(bolt) else None
            if shot is not None:
                self.pulled.append(int(shot.tightening_id))
                await _until(lambda: self.st.bus.count(ResultRecorded) > n, 15)
        self.truth = None
        self.world.set_wrench(None)
        await _until(lambda: self.st.core.state in (State.TRACKING, State.FAULT,
                                                    State.WAITING_VEHICLE), 15)


def run_soak(args: argparse.Namespace) -> int:
    total, load = int(args.bolts), int(args.load)
    if total < 1:
        raise InputError("--bolts must be at least 1")
    if int(args.seed) < 0:
        raise InputError("--seed must be >= 0")
    if not 0 <= load <= 64:
        raise InputError("--load must be 0-64 busy processes")
    tmp = tempfile.TemporaryDirectory(prefix="stationd-soak-")
    cfg = replace(load_station_config(SIM_CONFIG),
                  database_url=f"sqlite:///{tmp.name}/stationd.db")
    assert cfg.bolts_path is not None  # noqa: S101 - the simulated station names its bolts
    rng = np.random.default_rng(args.seed)
    model = load_bolts(cfg.bolts_path).models[0]
    per_vehicle = min(int(args.per_vehicle), len(model.bolts))
    chosen = [model.bolts[int(k)] for k in rng.permutation(len(model.bolts))[:per_vehicle]]
    poses = {b.bolt_id: wrench_at(np.array(b.position) + np.append(rng.normal(0, 0.3, 2), 0.0),
                                  rng, cfg.tool.length_mm) for b in chosen}
    print(f"rendering {len(poses)} placements ahead (not timed) ...", file=sys.stderr,
          flush=True)
    world = World(cfg, seed=args.seed)
    world.prerender(list(poses.values()))
    station = Station(cfg, device_kw={"wrench": {"psets": _sim_psets(cfg.bolts_path)}})
    shift = Shift(station, world, rng, poses, bool(args.faults))
    station.on_action = shift.check
    exits: list[str] = []
    busy = [multiprocessing.Process(target=_busy, daemon=True) for _ in range(load)]

    async def main() -> None:
        stop = asyncio.Event()
        task = asyncio.create_task(station.run(stop))
        try:
            done, vin_no = 0, 0
            while done < total:
                vin_no += 1
                await shift.vehicle(f"SOAK{vin_no:013d}")
                for b in list(poses)[:total - done]:
                    if task.done():
                        raise RuntimeError("the station loop ended")
                    await shift.bolt(b)
                    done += 1
                await shift.leave()
        finally:
            stop.set()
            if task.done() and task.exception() is not None:
                exits.append(repr(task.exception()))
            await task

    for p in busy:
        p.start()
    t0 = time.perf_counter()
    station.open()
    try:
        asyncio.run(main())
    except RuntimeError as exc:
        exits.append(str(exc))
    finally:
        for p in busy:
            p.terminate()
        station.close()
        world.close()
        tmp.cleanup()
    recorded = {e.tightening_id for e in station.bus.of(ResultRecorded)
                if isinstance(e, ResultRecorded)}
    refusals = Counter(_kind(e.reason) for e in station.bus.of(Refused)
                       if isinstance(e, Refused))
    summary = {"bolts": total, "tightened": len(recorded), "vehicles": shift.vehicles,
               "faults_injected": dict(shift.injected), "not_tightened": shift.skipped,
               "refusals": dict(refusals.most_common()), "wrong_bolt_sends": shift.wrong,
               "exits": len(exits), "results_lost": len(set(shift.pulled) - recorded),
               "load_processes": load, "run_s": time.perf_counter() - t0}
    if args.json:
        sys.stdout.write(strict_json(summary) + "\n")
    else:
        print(f"{summary['tightened']}/{total} bolts tightened over {shift.vehicles} vehicles "
              f"in {summary['run_s']:.0f} s (load: {load} busy processes)")
        print(f"faults injected: {dict(shift.injected) or 'none'}")
        print(f"refusals by reason: {summary['refusals']}")
        for miss in shift.skipped:
            print(f"  not tightened: {miss}")
        print(f"parameters sent for a wrong bolt: {shift.wrong}; daemon exits: {len(exits)}; "
              f"results lost: {summary['results_lost']}")
        ok = shift.wrong == 0 and not exits and summary["results_lost"] == 0
        print(f"{'PASS' if ok else 'FAIL'}: {shift.wrong} wrong, {len(exits)} exits, "
              f"{summary['results_lost']} lost")
    return 0 if shift.wrong == 0 and not exits and summary["results_lost"] == 0 else 1
