"""``stationd bench soak --bolts N [--faults] [--load N]``: the daemon through a long shift.

The daemon runs as ``stationd run`` runs it (the serve loop of :mod:`stationd.station.run`,
one event bus for its life, a configuration file it reloads), on a copy of config/sim whose
lift PLC (Modbus TCP) and tightening controller (Open Protocol) are *independent* servers on
loopback, as on a line: a reload reopens the daemon's connections, not the devices.  Eight
20 MP cameras compose pre-rendered placements.  It tightens ``N`` bolts over as many vehicles
as it takes.  With ``--faults`` a random disturbance hits before some bolts: the lift PLC stops
answering, the controller powers off (sometimes mid-tightening), a camera pair stops
delivering, a vehicle whose VIN was closed comes back (a rework), the station file is reloaded
(valid: the station reopens; a bolt table with a duplicate id: refused, the running station
stays; a lift URL on a port where nothing answers: the new station runs in fault until the next
reload puts it back).  ``--load N`` keeps N busy processes on the cores meanwhile.  The shift
is observed only through the daemon's typed events.  It prints what a shift must show: bolts
tightened, refusals by reason, parameters sent for a wrong bolt (must be 0), daemon exits
(must be 0), results lost (pulled, never recorded: must be 0) and reloads applied/refused.
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing
import shutil
import socket
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from drivers.lift.sim import SimulatedPlc
from drivers.wrench.sim import SimController
from stationd.boltfile import load_bolts
from stationd.errors import InputError
from stationd.jsonout import strict_json
from stationd.sim.world import World, WrenchPose, wrench_at
from stationd.station.demo import SIM_CONFIG, _kind, _sim_psets
from stationd.station.events import (
    BoltSelected,
    DeviceHealth,
    EventBus,
    Refused,
    ResultRecorded,
    StateChanged,
    StationEvent,
    ToolDisabled,
    ToolEnabled,
    VehicleOpened,
)
from stationd.station.run import Screens, serve_station, validate_station
from stationd.station.sdnotify import Notifier

FAULTS = ("lift", "controller", "controller mid-tightening", "cameras", "closed VIN back",
          "reload", "reload with a bad bolt table", "reload with the lift down")
FAULT_RATE = 0.15       # of bolts preceded by a disturbance (dealt from a shuffled deck)
OUTAGE_S = 1.5


def _busy() -> None:
    while True:
        pass


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _until(pred: Any, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        await asyncio.sleep(0.01)
    return False


class Watch:
    """What the daemon said, from its typed events: state, vehicle, tool, and every selection
    checked against where the simulated wrench really is at that instant."""

    def __init__(self, bus: EventBus) -> None:
        self.state, self.reason = "starting", ""
        self.vin: str | None = None
        self.enabled: str | None = None       # the bolt the tool is enabled for
        self.truth: str | None = None
        self.wrong = 0
        bus.subscribe(self.see)

    def see(self, ev: StationEvent) -> None:
        if isinstance(ev, StateChanged):
            self.state, self.reason = ev.state, ev.reason
            if ev.state in ("waiting for vehicle", "starting"):
                self.vin = None
        elif isinstance(ev, VehicleOpened):
            self.vin = ev.vin
        elif isinstance(ev, ToolEnabled):
            self.enabled = ev.bolt
        elif isinstance(ev, ToolDisabled):
            self.enabled = None
        elif isinstance(ev, BoltSelected) and ev.bolt != self.truth:
            self.wrong += 1
            print(f"WRONG BOLT: parameters for {ev.bolt} while the wrench is on "
                  f"{self.truth or 'no bolt'}", flush=True)


class StationFiles:
    """A private copy of config/sim whose devices are the soak's own servers; rewrites its
    station file for reloads the way an engineer would."""

    def __init__(self, root: Path, lift_port: int, wrench_port: int) -> None:
        self.dir = root / "station"
        shutil.copytree(SIM_CONFIG.parent, self.dir,
                        ignore=shutil.ignore_patterns("*.db*"))
        self.path = self.dir / SIM_CONFIG.name
        self.doc = yaml.safe_load(self.path.read_text())
        self.doc.pop("http", None)
        self.doc["database"] = {"url": f"sqlite:///{root}/stationd.db"}
        self.doc["lift"] = {"url": f"modbus-tcp://127.0.0.1:{lift_port}?unit=1"}
        self.doc["wrench"] = {"url": f"openprotocol://127.0.0.1:{wrench_port}"}
        self.good_lift = self.doc["lift"]["url"]
        self.bolts = self.dir / str(self.doc["bolts"])
        self.good_bolts = self.bolts.read_text()
        self.write()

    def write(self) -> None:
        self.path.write_text(yaml.safe_dump(self.doc, sort_keys=False))

    def toggle_stable_frames(self) -> None:
        m = self.doc["matching"]
        m["stable_frames"] = 4 if int(m["stable_frames"]) == 3 else 3
        self.write()

    def duplicate_bolt(self) -> None:
        doc = yaml.safe_load(self.good_bolts)
        bolts = next(iter(doc["models"].values()))["bolts"]
        bolts.append(dict(bolts[0]))
        self.bolts.write_text(yaml.safe_dump(doc, sort_keys=False))

    def restore_bolts(self) -> None:
        self.bolts.write_text(self.good_bolts)

    def lift_url(self, url: str) -> None:
        self.doc["lift"] = {"url": url}
        self.write()


class Shift:
    """The simulated operator and line around one daemon; counts what happened."""

    def __init__(self, watch: Watch, world: World, plc: SimulatedPlc, ctl: SimController,
                 files: StationFiles, reload: asyncio.Event, rng: np.random.Generator,
                 poses: dict[str, WrenchPose], faults: bool) -> None:
        self.w, self.world, self.plc, self.ctl, self.files = watch, world, plc, ctl, files
        self.reload, self.rng, self.poses, self.faults = reload, rng, poses, faults
        self.pulled: list[int] = []
        self.injected: Counter[str] = Counter()
        self.skipped: list[str] = []
        self.vehicles = 0
        self.deck: list[str] = []
        self.pairs = sorted(yaml.safe_load(files.path.read_text())["pairs"])

    def tightening(self, bolt: str) -> bool:
        return self.w.state == "tightening" and self.w.enabled == bolt \
            and bool(self.ctl.tool_enabled)

    async def vehicle(self, vin: str) -> None:
        self.plc.set_vehicle(1, vin)
        self.plc.raise_lift()
        self.vehicles += 1
        await _until(lambda: self.w.vin == vin and self.w.state == "tracking", 30)

    async def leave(self) -> None:
        self.plc.lower_lift()
        await _until(lambda: self.w.state == "waiting for vehicle", 30)

    async def _reloaded(self) -> None:
        """Ask for a reload (SIGHUP) and give the daemon time to validate and switch."""
        self.reload.set()
        await _until(lambda: not self.reload.is_set(), 15)
        await asyncio.sleep(0.5)

    async def outage(self, kind: str) -> None:
        self.injected[kind] += 1
        if kind == "lift":
            port = self.plc.tcp_port or 0
            self.plc.stop_tcp()
            await asyncio.sleep(OUTAGE_S)
            self.plc.start_tcp(port)
        elif kind.startswith("controller"):
            self.ctl.power_off()
            await asyncio.sleep(OUTAGE_S)
            self.ctl.power_on()
        elif kind == "cameras":
            pair = str(self.rng.choice(self.pairs))
            self.world.cut_cameras(pair)
            await asyncio.sleep(OUTAGE_S)
            self.world.restore_cameras(pair)
        elif kind == "closed VIN back":
            vin = self.w.vin
            if vin is not None:
                await self.leave()
                await self.vehicle(vin)      # the same VIN again: reopened as a rework
        elif kind == "reload":
            self.files.toggle_stable_frames()
            await self._reloaded()
        elif kind == "reload with a bad bolt table":
            self.files.duplicate_bolt()
            await self._reloaded()           # refused: the running station stays
            self.files.restore_bolts()
        elif kind == "reload with the lift down":
            self.files.lift_url(f"modbus-tcp://127.0.0.1:{_free_port()}?unit=1&timeout=0.3")
            await self._reloaded()
            await asyncio.sleep(OUTAGE_S)    # the new station runs in fault, lift unreachable
            self.files.lift_url(self.files.good_lift)
            await self._reloaded()
        await _until(lambda: self.w.state in ("tracking", "waiting for vehicle"), 30)

    def next_fault(self) -> str:
        """Dealt from a shuffled deck of every kind: a shift sees each kind as often."""
        if not self.deck:
            self.deck = [FAULTS[int(k)] for k in self.rng.permutation(len(FAULTS))]
        return self.deck.pop()

    async def bolt(self, bolt: str) -> None:
        fault = self.next_fault() if self.faults and self.rng.random() < FAULT_RATE else None
        if fault is not None and fault != "controller mid-tightening":
            await self.outage(fault)
        self.world.set_wrench(self.poses[bolt])
        self.w.truth = bolt
        if not await _until(lambda: self.tightening(bolt), 60):
            self.skipped.append(f"{bolt}: {self.w.state}: {self.w.reason}")
        else:
            if fault == "controller mid-tightening":
                await self.outage(fault)
                await _until(lambda: self.tightening(bolt), 60)
            shot = self.ctl.pull_trigger() if self.tightening(bolt) else None
            if shot is not None:
                self.pulled.append(int(shot.tightening_id))
                await _until(lambda: self.w.enabled is None, 15)
        await asyncio.sleep(0.2)        # the wrench lifts off after the rundown
        self.w.truth = None
        self.world.set_wrench(None)
        await _until(lambda: self.w.state in ("tracking", "fault", "waiting for vehicle"), 15)


class _QuietNotifier(Notifier):
    """No systemd here: keeps what the daemon would have told it (reload refusals)."""

    def __init__(self) -> None:
        super().__init__(environ={})
        self.said: list[str] = []

    def status(self, text: str) -> bool:
        self.said.append(text)
        return False


def run_soak(args: argparse.Namespace) -> int:
    total, load = int(args.bolts), int(args.load)
    if total < 1:
        raise InputError("--bolts must be at least 1")
    if int(args.seed) < 0:
        raise InputError("--seed must be >= 0")
    if not 0 <= load <= 64:
        raise InputError("--load must be 0-64 busy processes")
    tmp = tempfile.TemporaryDirectory(prefix="stationd-soak-")
    rng = np.random.default_rng(args.seed)
    plc = SimulatedPlc()
    ctl = SimController(psets=_sim_psets(SIM_CONFIG.parent / "bolts.yaml"), seed=args.seed)
    ctl.start()
    files = StationFiles(Path(tmp.name), plc.start_tcp(), ctl.listen_tcp())
    cfg = validate_station(files.path)
    assert cfg.bolts_path is not None  # noqa: S101 - the simulated station names its bolts
    plc.register_map = cfg.lift.registers
    model = load_bolts(cfg.bolts_path).models[0]
    per_vehicle = min(int(args.per_vehicle), len(model.bolts))
    chosen = [model.bolts[int(k)] for k in rng.permutation(len(model.bolts))[:per_vehicle]]
    poses = {b.bolt_id: wrench_at(np.array(b.position) + np.append(rng.normal(0, 0.3, 2), 0.0),
                                  rng, cfg.tool.length_mm) for b in chosen}
    print(f"rendering {len(poses)} placements ahead (not timed) ...", file=sys.stderr,
          flush=True)
    world = World(cfg, seed=args.seed)
    world.prerender(list(poses.values()))
    bus = EventBus()
    watch = Watch(bus)
    recorded: set[int] = set()
    bus.subscribe(lambda e: recorded.add(e.tightening_id)
                  if isinstance(e, ResultRecorded) else None)
    notifier = _QuietNotifier()
    exits: list[str] = []
    busy = [multiprocessing.Process(target=_busy, daemon=True) for _ in range(load)]
    shift: Shift | None = None

    async def main() -> None:
        nonlocal shift
        stop, reload = asyncio.Event(), asyncio.Event()
        shift = Shift(watch, world, plc, ctl, files, reload, rng, poses, bool(args.faults))
        daemon = asyncio.create_task(serve_station(str(files.path), cfg, notifier, bus,
                                                   Screens(bus), stop, reload))
        try:
            done, vin_no = 0, 0
            while done < total:
                vin_no += 1
                await shift.vehicle(f"SOAK{vin_no:013d}")
                for b in list(poses)[:total - done]:
                    if daemon.done():
                        raise RuntimeError("the daemon's serve loop ended")
                    await shift.bolt(b)
                    done += 1
                await shift.leave()
        finally:
            stop.set()
            try:
                await daemon
            except Exception as exc:  # counted: an exit is what the soak must never see
                exits.append(f"{type(exc).__name__}: {exc}")

    for p in busy:
        p.start()
    t0 = time.perf_counter()
    try:
        asyncio.run(main())
    except RuntimeError as exc:
        exits.append(str(exc))
    finally:
        for p in busy:
            p.terminate()
        world.close()
        ctl.close()
        plc.close()
        tmp.cleanup()
    assert shift is not None  # noqa: S101 - main() made it
    refusals = Counter(_kind(e.reason) for e in bus.of(Refused) if isinstance(e, Refused))
    down = Counter(e.device for e in bus.of(DeviceHealth)
                   if isinstance(e, DeviceHealth) and not e.ok)
    refused_reloads = [s for s in notifier.said if s.startswith("reload refused")]
    summary = {"bolts": total, "tightened": len(recorded), "vehicles": shift.vehicles,
               "faults_injected": dict(shift.injected), "not_tightened": shift.skipped,
               "refusals": dict(refusals.most_common()), "wrong_bolt_sends": watch.wrong,
               "reloads_refused": len(refused_reloads), "device_faults": dict(down),
               "exits": len(exits), "results_lost": len(set(shift.pulled) - recorded),
               "load_processes": load, "run_s": time.perf_counter() - t0}
    ok = watch.wrong == 0 and not exits and summary["results_lost"] == 0
    if args.json:
        sys.stdout.write(strict_json(summary) + "\n")
    else:
        print(f"{summary['tightened']}/{total} bolts tightened over {shift.vehicles} vehicles "
              f"in {summary['run_s']:.0f} s (load: {load} busy processes)")
        print(f"disturbances: {dict(shift.injected) or 'none'}; reloads refused: "
              f"{len(refused_reloads)}")
        print(f"device faults seen: {dict(down) or 'none'}")
        print(f"refusals by reason: {summary['refusals']}")
        for miss in shift.skipped:
            print(f"  not tightened: {miss}")
        for e in exits:
            print(f"  exit: {e}")
        print(f"parameters sent for a wrong bolt: {watch.wrong}; daemon exits: {len(exits)}; "
              f"results lost: {summary['results_lost']}")
        print(f"{'PASS' if ok else 'FAIL'}: {watch.wrong} wrong, {len(exits)} exits, "
              f"{summary['results_lost']} lost")
    return 0 if ok else 1
