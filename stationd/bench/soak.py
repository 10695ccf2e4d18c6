"""``stationd bench soak --bolts N [--faults] [--load N]``: the daemon through a long shift.

The daemon runs as ``stationd run`` runs it (the serve loop of :mod:`stationd.shell.serve`,
one event bus for its life, a station file it reloads), on a copy of config/sim whose lift PLC
(Modbus TCP) and tightening controller (Open Protocol) are *independent* servers on loopback,
as on a line: a reload reopens the daemon's connections, not the devices.  Eight 20 MP
cameras compose placements rendered ahead.  The shift is a seeded script
(:func:`stationd.sim.soak.plan_soak`): ``N`` tightenings over vehicles of up to
``--per-vehicle`` bolts, with hovering between two bolts and leaving before tightening; with
``--faults`` also lift, controller (also mid-tightening) and camera-pair outages, reloads (a
valid file; a bolt table with a duplicate id, refused while the running station stays; a lift
URL where nothing answers, a fault of the new station until the next reload) and vehicles
whose closed VIN comes back (rework).  ``--load N`` keeps N busy processes on the cores.
The daemon is observed only through its typed events.  It prints what a shift must show:
bolts tightened, refusals by reason, parameters sent for a wrong bolt (must be 0), daemon
exits (must be 0), results lost (made by the controller, never recorded: must be 0).
"""

from __future__ import annotations

import argparse
import asyncio
import secrets
import shutil
import socket
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from drivers.lift.sim import SimulatedPlc
from drivers.wrench.sim.controller import SimController
from stationd.bench.wait import until as _until
from stationd.boltfile import load_bolts
from stationd.bus import EventBus
from stationd.demo.station import SIM_CONFIG, _kind
from stationd.errors import InputError
from stationd.jsonout import strict_json
from stationd.reasons import Reason
from stationd.shell.sdnotify import Notifier
from stationd.shell.serve import Screens, serve_station
from stationd.sim.devices_cli import psets_of
from stationd.sim.load import cpu_load
from stationd.sim.soak import (
    Device,
    ReloadKind,
    SimDevices,
    SoakTally,
    Step,
    plan_soak,
)
from stationd.sim.soak import (
    run_soak as play,
)
from stationd.sim.world import World
from stationd.station.events import (
    BoltSelected,
    DeviceHealth,
    Refused,
    ResultRecorded,
    State,
    StateChanged,
    StationEvent,
    ToolDisabled,
    ToolEnabled,
    VehicleClosed,
    VehicleOpened,
)
from stationd.stationcheck import validate_station
from stationd.words import state_words

RELOAD_SETTLE_S = 0.5    # after a reload is taken, before the shift goes on
LIFT_DOWN_S = 1.5        # how long a station reloaded onto a dead lift runs before it is fixed


def _free_port() -> int:
    """A free TCP port on loopback *outside* the kernel's ephemeral range: a client that keeps
    reconnecting to a port in that range while nothing listens can be given that very port as
    its own (TCP simultaneous open; the link layer refuses such a socket, but it held the port
    for that moment)."""
    try:
        low = int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        low = 32768
    for _ in range(200):
        port = 10000 + secrets.randbelow(max(1, low - 10000))
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            return port
    raise OSError("no free TCP port below the ephemeral range")


class Watch:
    """What the daemon said, from its typed events: state, vehicle, tool, and every selection
    checked by ``tally`` against where the simulated wrench really is at that instant (the
    bus calls :meth:`see` as the daemon publishes, on the loop the shift runs on)."""

    def __init__(self, bus: EventBus, tally: SoakTally) -> None:
        self.state, self.reason = "starting", ""
        self.vin: str | None = None
        self.enabled: str | None = None       # the bolt the tool is enabled for
        self.tally = tally
        self.refusal: Reason | None = None    # the last reason nothing was selected
        self.stations = 0                     # stations started (the first, each reload's)
        self.closed = 0                       # vehicles closed
        bus.subscribe(self.see)

    def see(self, ev: StationEvent) -> None:
        if isinstance(ev, StateChanged):
            self.state, self.reason = ev.state, state_words(ev.reason)
            if ev.state in (State.WAITING_VEHICLE, State.STARTING):
                self.vin = None
            if ev.state == State.STARTING:
                # a new station (a reload's): the last one's tool is not this one's (it
                # closed with the tool off, saying nothing: its "enabled" was stale)
                self.stations += 1
                self.enabled = None
        elif isinstance(ev, VehicleClosed):
            self.closed += 1
        elif isinstance(ev, VehicleOpened):
            self.vin = ev.vin
        elif isinstance(ev, Refused):
            self.refusal = ev.reason
        elif isinstance(ev, ToolEnabled):
            self.enabled = ev.bolt
        elif isinstance(ev, ToolDisabled):
            self.enabled = None
        elif isinstance(ev, BoltSelected):
            wrong = len(self.tally.wrong_sends)
            self.tally.check_send(ev.bolt)
            if len(self.tally.wrong_sends) > wrong:
                print(f"WRONG BOLT: {self.tally.wrong_sends[-1]}", flush=True)


class StationFiles:
    """A private copy of config/sim whose devices are the soak's own servers; rewrites its
    station file for reloads the way an engineer would."""

    def __init__(self, root: Path, lift_port: int, wrench_port: int) -> None:
        self.lift_port, self.wrench_port = lift_port, wrench_port
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


class DaemonHooks(SimDevices):
    """The station's side of the soak's hooks, over the running daemon: what it enabled and
    why not (its events), reloads by rewriting its station file and asking as SIGHUP does."""

    def __init__(self, watch: Watch, files: StationFiles, reload: asyncio.Event,
                 recorded: set[int], *args: Any, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.watch, self.files, self._reload, self._recorded = watch, files, reload, recorded
        self.daemon: asyncio.Task[None] | None = None
        #: how many reloads the daemon refused so far (its notifier's count)
        self.refusals: Callable[[], int] = lambda: 0

    async def arrive(self, vin: str, model_code: int) -> None:
        await super().arrive(vin, model_code)
        await _until(lambda: self.watch.vin == vin and self.watch.state == State.TRACKING, 30)

    async def depart(self) -> None:
        closed = self.watch.closed
        await super().depart()
        # the vehicle closed, not only a station waiting (the next station of a reload
        # waits too, and closes nothing)
        await _until(lambda: self.watch.closed > closed, 30)
        await _until(lambda: self.watch.state == State.WAITING_VEHICLE, 30)
        t = self.watch.tally    # one line per vehicle on stderr: a long soak is never silent
        print(f"soak: {t.tightened} tightened, {len(t.wrong_sends)} wrong, "
              f"{t.results_made - len(self._recorded)} unrecorded, "
              f"{time.monotonic() - t.started:.0f} s", file=sys.stderr, flush=True)

    async def wait_enabled(self, bolt: str, timeout: float) -> bool:
        return await _until(lambda: self.watch.state == "tightening"
                            and self.watch.enabled == bolt
                            and bool(self.controller.tool_enabled), timeout)

    async def wait_disabled(self, timeout: float) -> bool:
        return await _until(lambda: self.watch.enabled is None
                            and not self.controller.tool_enabled, timeout)

    async def device_up(self, device: Device) -> None:
        await super().device_up(device)
        await _until(lambda: self.watch.state in (State.TRACKING, State.WAITING_VEHICLE), 30)

    async def _reloaded(self, taken: bool = True) -> None:
        """Reload (what SIGHUP sets) and wait for its outcome: the next station started
        (``taken``) or the refusal said; the serve loop's taking the request is not it (the
        shift went on with the station about to be replaced, and pulled a trigger under its
        enable as it closed: no operator can)."""
        stations, refused = self.watch.stations, self.refusals()
        self._reload.set()
        await _until(lambda: not self._reload.is_set(), 15)
        if taken:
            await _until(lambda: self.watch.stations > stations
                         and self.watch.state != State.STARTING, 60)
        else:
            await _until(lambda: self.refusals() > refused, 30)
        await asyncio.sleep(RELOAD_SETTLE_S)

    async def reload(self, kind: ReloadKind) -> None:
        if kind == "valid":
            self.files.toggle_stable_frames()
            await self._reloaded()
        elif kind == "bad bolt table":
            self.files.duplicate_bolt()
            await self._reloaded(taken=False)   # refused: the running station stays
            self.files.restore_bolts()
        else:
            self.files.lift_url(f"modbus-tcp://127.0.0.1:{_free_port()}?unit=1&timeout=0.3")
            await self._reloaded()
            await asyncio.sleep(LIFT_DOWN_S)    # the new station runs in fault, lift unreachable
            self.files.lift_url(self.files.good_lift)
            await self._reloaded()
        await _until(lambda: self.watch.state in (State.TRACKING, State.WAITING_VEHICLE), 30)

    def recorded(self) -> int:
        return len(self._recorded)

    def alive(self) -> bool:
        return self.daemon is not None and not self.daemon.done()

    def why_not(self) -> str:
        w = self.watch
        if w.refusal is not None:
            return f"{w.state}: {_kind(w.refusal)}"
        return f"{w.state}: {w.reason}" if w.reason else w.state


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
    if int(args.per_vehicle) < 1:
        raise InputError("--per-vehicle must be at least 1")
    if not 0 <= load <= 64:
        raise InputError("--load must be 0-64 busy processes")
    table = load_bolts(SIM_CONFIG.parent / "bolts.yaml")
    model = table.models[0]
    code = model.code if model.code is not None else 1
    plan = plan_soak([b.bolt_id for b in model.bolts], total, model_code=code,
                     per_vehicle=int(args.per_vehicle), faults=bool(args.faults),
                     seed=int(args.seed))
    tally = soak_station(plan, load=load, seed=int(args.seed))
    summary = {"bolts": total, **tally.summary(), "load_processes": load}
    if args.json:
        sys.stdout.write(strict_json(summary) + "\n")
    else:
        print(f"{tally.tightened}/{total} bolts tightened in {summary['duration_s']:.0f} s "
              f"(load: {load} busy processes); reworks {tally.reworks}")
        print(f"outages: {dict(tally.outages) or 'none'}; reloads: {dict(tally.reloads) or 'none'}"
              f" (refused: {summary['reloads_refused']}); device faults seen: "
              f"{summary['device_faults'] or 'none'}")
        print(f"refusals by reason: {summary['refusals']}")
        for why, n in tally.not_tightened.items():
            print(f"  not tightened ({n}): {why}")
        for w in tally.wrong_sends[:10]:
            print(f"  WRONG BOLT: {w}")
        print(f"parameters sent for a wrong bolt: {len(tally.wrong_sends)}; daemon exits: "
              f"{tally.exits}; results lost: {tally.results_lost} "
              f"(made {tally.results_made}, recorded {tally.results_recorded})")
        if "harness_error" in summary:
            print(f"the simulated world failed (not the daemon): {summary['harness_error']}")
        ok = tally.passed and "harness_error" not in summary
        print(f"{'PASS' if ok else 'FAIL'}: {len(tally.wrong_sends)} wrong, "
              f"{tally.exits} exits, {tally.results_lost} lost")
    return 0 if tally.passed and "harness_error" not in summary else 1


def soak_station(plan: list[Step], *, load: int = 0, seed: int = 0) -> SoakTally:
    """Play ``plan`` on the daemon serving a private copy of the simulated station, beside
    ``load`` busy processes; the tally (its summary has the daemon's refusals, device faults
    and refused reloads too)."""
    tmp = tempfile.TemporaryDirectory(prefix="stationd-soak-")
    plc = SimulatedPlc()
    ctl = SimController(psets=psets_of(SIM_CONFIG.parent / "bolts.yaml"), seed=seed)
    ctl.start()
    files = StationFiles(Path(tmp.name), plc.start_tcp(_free_port()),
                         ctl.listen_tcp(port=_free_port()))
    cfg = validate_station(files.path)
    assert cfg.bolts_path is not None  # noqa: S101 - the simulated station names its bolts
    plc.register_map = cfg.lift.registers
    world = World(cfg, seed=seed)
    bus = EventBus()
    tally = SoakTally()
    watch = Watch(bus, tally)
    recorded: set[int] = set()
    bus.subscribe(lambda e: recorded.add(e.tightening_id)
                  if isinstance(e, ResultRecorded) else None)
    model = load_bolts(cfg.bolts_path).models[0]
    notifier = _QuietNotifier()

    async def main(hooks: DaemonHooks) -> None:
        stop, reload = asyncio.Event(), hooks._reload
        hooks.daemon = asyncio.create_task(serve_station(str(files.path), cfg, notifier, bus,
                                                         Screens(bus), stop, reload))
        tally.started = time.monotonic()
        try:
            await play(plan, hooks, tally)
        except OSError as exc:  # the simulated world failed, not the daemon: say so, stop
            tally.extra["harness_error"] = f"{type(exc).__name__}: {exc}"
        finally:
            stop.set()
            try:
                await hooks.daemon
            except Exception as exc:  # counted: an exit is what the soak must never see
                print(f"the daemon ended: {type(exc).__name__}: {exc}", file=sys.stderr)
                tally.exits += 1

    try:
        hooks = DaemonHooks(watch, files, asyncio.Event(), recorded, world, plc, ctl,
                            {b.bolt_id: b.position for b in model.bolts}, cfg.tool.length_mm,
                            seed=seed)
        hooks.refusals = lambda: sum(x.startswith("reload refused") for x in notifier.said)
        print(f"rendering {hooks.prepare(plan)} placements ahead (not timed) ...",
              file=sys.stderr, flush=True)
        # spawned, never forked: a forked child would hold the simulated devices' sockets open
        # (a controller powered off would keep listening in it, and could not come back)
        with cpu_load(load):
            asyncio.run(main(hooks))
    finally:
        world.close()
        ctl.close()
        plc.close()
        tmp.cleanup()
    tally.results_recorded = len(recorded)
    for e in bus.of(Refused):
        if isinstance(e, Refused):
            tally.refused(_kind(e.reason))
    tally.extra.update({
        "device_faults": dict(Counter(e.device for e in bus.of(DeviceHealth)
                                      if isinstance(e, DeviceHealth) and not e.ok)),
        "reloads_refused": sum(x.startswith("reload refused") for x in notifier.said)})
    return tally
