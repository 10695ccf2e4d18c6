"""``stationd bench station``: the daemon's latency and memory on the simulated station.

The daemon runs as in ``stationd demo`` (config/sim: eight 20 MP cameras in four pairs, the
lift PLC on Modbus TCP and the controller on Open Protocol, both on loopback), but the world
renders every wrench placement *before* the run: during it, a camera's frame is the cached
background or a pool buffer with a pre-rendered window pasted, as a camera fills its queued
DMA buffers at no cost to the host.  (A Bayer camera demosaiced on the host costs that
conversion on top: ``drivers/camera/pixels.py``; the README gives its figure.)
The demo cannot measure latency this way, because its ray-casting shares the two cores with
the daemon; here the cores are the daemon's.

Latency is counted from the exposure of the stereo frames that decided a selection to the
controller's acknowledgement of that bolt's parameters, with its stages: localize (the
slowest pair's grab-to-bolt-end, all pairs at once), decide (matching and the cycle), and
acknowledge (the Open Protocol round trip).  Memory is the process's resident set: peak and
at the end, with the simulated world's own frame buffers counted separately.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import resource
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from drivers.counting import noun
from stationd import progress
from stationd.bench.plan import wrench_plan
from stationd.bench.wait import until as _until
from stationd.config import StationConfig, load_station_config
from stationd.demo.station import SIM_CONFIG, simulators
from stationd.errors import InputError
from stationd.jsonout import finite, strict_json
from stationd.outfile import write_atomic
from stationd.shell.daemon import Station
from stationd.shell.serve import Screens
from stationd.sim.devices_cli import psets_of
from stationd.sim.world import World, WrenchPose
from stationd.station.actions import SendParams
from stationd.station.events import ParamsSent, ResultRecorded, State
from stationd.web.bench import ScreenClients
from stationd.web.config import HttpConfig
from stationd.words import state_words

FRAME_ROUTE = "/api/cameras/{pair}/{side}/frame.jpg"


def _rss_mb() -> float:
    """The resident set now (VmRSS), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KB on Linux




IDLE_S = 3.0   # how long the idle station is watched


async def _idle(st: Station, plc: Any) -> dict[str, float]:
    """The station idle (the lift up but not at working height, as between two cars): the
    Modbus requests its PLC serves per second and the process's CPU, over ``IDLE_S``."""
    plc.set_height(400.0)
    await _until(lambda: st.core.status().state is State.WAITING_VEHICLE, 30)
    n0, c0, t0 = plc.requests, time.process_time(), time.monotonic()
    await asyncio.sleep(IDLE_S)
    dt = time.monotonic() - t0
    return {"plc_requests_per_s": (plc.requests - n0) / dt,
            "cpu_pct_of_a_core": 100.0 * (time.process_time() - c0) / dt}


async def _operator(st: Station, world: World, plan: list[tuple[str, WrenchPose]],
                    out: dict[str, Any], on_bolt: Any = None, idle: bool = True) -> None:
    """The simulated operator through ``plan``; ``on_bolt(i)`` before the i-th bolt; with
    ``idle``, the idle station watched first (:func:`_idle`)."""
    plc, ctl = simulators(st)
    if idle and "idle" not in out:
        out["idle"] = await _idle(st, plc)
    plc.set_vehicle(1, "BENCHVIN000000001")
    plc.raise_lift()
    if not await _until(lambda: st.vin is not None, 60):
        raise RuntimeError("the station did not start the vehicle: "
                           f"{state_words(st.core.status().reason)}")
    for i, (bolt, pose) in enumerate(progress.track(plan, "bench station: bolts",
                                                    unit="bolt")):
        if on_bolt is not None:
            await on_bolt(i)
        world.set_wrench(pose)
        out["truth"] = bolt
        def on_it(b: str = bolt) -> bool:
            return st.core.status().state is State.TIGHTENING and st.core.status().bolt == b \
                and bool(ctl.tool_enabled)

        selected = await _until(on_it, 30)
        if not selected:
            out["not_selected"].append(f"{bolt}: {state_words(st.core.status().reason)}")
        else:
            n = st.bus.count(ResultRecorded)
            if ctl.pull_trigger() is not None:
                def recorded(before: int = n) -> bool:
                    return st.bus.count(ResultRecorded) > before

                await _until(recorded, 10)
        out["truth"] = None
        world.set_wrench(None)
        await _until(lambda: st.core.status().state is State.TRACKING, 10)
    plc.lower_lift()
    await _until(lambda: st.vin is None, 10)


#: the browsers have settled once they use less than this many CPU seconds in a second (a
#: connected operator page and cameras page use about 0.1-0.2), or after SETTLE_MAX_S
SETTLED_CPU_S = 0.35
SETTLE_MAX_S = 20.0
#: after a pass with the screens, the clients stay this long before the served counts are read
DRAIN_S = 2.0
#: --paired: after the clients are held or resumed, this long before the wrench moves, s (a
#: resumed browser's catch-up burst is not what a running one costs)
PAIRED_SETTLE_S = 1.5

T = TypeVar("T")


def run_station_bench(args: argparse.Namespace) -> int:
    cycles = int(args.cycles)
    if cycles < 1:
        raise InputError("--cycles must be at least 1")
    browsers = int(getattr(args, "browsers", 0) or 0)
    if browsers < 0:
        raise InputError("--browsers must be 0 or more")
    passes = int(getattr(args, "passes", 1))
    if passes < 1:
        raise InputError("--passes must be at least 1")
    paired = bool(getattr(args, "paired", False))
    opcua, line = bool(getattr(args, "opcua", False)), bool(getattr(args, "line", False))
    if browsers and (opcua or line):
        raise InputError("--browsers and --opcua/--line: one comparison at a time")
    if not browsers and (getattr(args, "clients", "chromium") != "chromium" or paired
                         or (passes != 1 and not (opcua or line))):
        raise InputError("--clients, --passes and --paired go with --browsers N (the "
                         "screens' clients); --passes also with --opcua or --line")
    tmp = tempfile.TemporaryDirectory(prefix="stationd-bench-")
    cfg = replace(load_station_config(SIM_CONFIG),
                  database_url=f"sqlite:///{tmp.name}/stationd.db", http=None)
    plan = wrench_plan(cfg, args.seed, cycles)
    if not args.json:
        print(f"rendering {len(plan)} placements ahead for {2 * len(cfg.pairs)} cameras "
              f"(not timed) ...", flush=True)
    world = World(cfg, seed=args.seed)
    t0 = time.perf_counter()
    world.prerender([p for _, p in plan])
    prerender_s = time.perf_counter() - t0
    world_mb = float("nan")
    pg = None
    try:
        pg = _line_server() if line else None
        base = _run_once(cfg, world, plan, 0, bool(args.json))
        serveds: list[dict[str, Any]] = []
        agains: list[dict[str, Any]] = []
        if browsers:
            # the same plan on a fresh database with the screens served and their clients on,
            # then once more without, ``passes`` times: the passes without frame those with
            # (warm-up and a drifting machine load do not all fall on one side), and a p95
            # over several passes is less at the mercy of one slow frame
            kind = str(getattr(args, "clients", "chromium") or "chromium")
            for k in range(passes):
                serveds.append(_run_once(
                    replace(cfg, database_url=f"sqlite:///{tmp.name}/screens{k}.db"), world,
                    plan, browsers, bool(args.json), kind,
                    getattr(args, "browser_nice", 0) or 0, paired, k))
                agains.append(_run_once(
                    replace(cfg, database_url=f"sqlite:///{tmp.name}/again{k}.db"), world,
                    plan, 0, bool(args.json)))
        if opcua or line:
            # the same plan with the services, then again without, ``passes`` times
            for k in range(passes):
                # (the idle station is watched in the first pass alone: the summary reports
                # that pass's figure, and this comparison is of latencies, not of CPU)
                on = _with_services(cfg, opcua, None if pg is None else pg.url(), k)
                serveds.append(_run_once(
                    replace(on, database_url=f"sqlite:///{tmp.name}/services{k}.db"), world,
                    plan, 0, bool(args.json), services=True, idle=False))
                agains.append(_run_once(
                    replace(cfg, database_url=f"sqlite:///{tmp.name}/again{k}.db"), world,
                    plan, 0, bool(args.json), idle=False))
    finally:
        if pg is not None:
            pg.stop()
        world_mb = world.buffer_bytes() / 2**20  # with the cameras' frame pools, now filled
        world.close()
        tmp.cleanup()
    station, out = base["station"], base["out"]
    lat = [e.latency_ms for e in station.bus.of(ParamsSent) if isinstance(e, ParamsSent)]
    summary = _summary(lat, cycles, out, station, prerender_s, base["run_s"], world_mb,
                       base["rss_open"], base["rss_end"])
    summary["cpu_pct"] = base["cpu_pct"]
    ok = summary["wrong_bolt_sends"] == 0 and not out["not_selected"]
    if serveds and (opcua or line):
        from stationd.bench.services import services_summary

        summary["services"] = services_summary(
            serveds, [base, *agains], opcua, line,
            p95_delta_interval([x for r in serveds for x in r["by_bolt"]],
                               [x for b in (base, *agains) for x in b["by_bolt"]]))
        for run in (*serveds, *agains):
            ok = ok and run["out"]["wrong"] == 0 and not run["out"]["not_selected"]
    elif serveds:
        summary["screens"] = _screens_summary([base, *agains], _pooled(serveds), browsers)
        summary["screens"]["passes"] = passes
        if paired:
            summary["screens"]["paired"] = _paired_summary(serveds)
        for run in (*serveds, *agains):
            ok = ok and run["out"]["wrong"] == 0 and not run["out"]["not_selected"]
    # whole or not at all: a Ctrl-C or a full disk while writing left half a JSON
    write_atomic(Path(args.out), json.dumps(finite(summary), indent=2, allow_nan=False) + "\n")
    if args.json:
        sys.stdout.write(strict_json(summary) + "\n")
    else:
        _print(summary)
        if "services" in summary:
            from stationd.bench.services import print_services

            print_services(summary["services"])
    return 0 if ok else 1


def _run_once(cfg: StationConfig, world: World, plan: list[tuple[str, WrenchPose]],
              browsers: int, quiet: bool, kind: str = "chromium", nice: int | str = 0,
              paired: bool = False, pass_index: int = 0, services: bool = False,
              idle: bool = True) -> dict[str, Any]:
    """One pass of the plan through a freshly opened daemon; with ``browsers``, the screens
    are served from the daemon's loop (as ``http:`` in the station file does) and that many
    clients are connected before the first bolt and stay for the whole pass; with
    ``services``, the OPC UA server and the forwarder of ``cfg``'s sections run beside it
    (:mod:`stationd.bench.services`); ``idle``: the idle station watched before the plan
    (:func:`_idle`, ``IDLE_S``)."""
    assert cfg.bolts_path is not None  # noqa: S101 - checked by the caller
    station = Station(cfg, device_kw={"wrench": {"psets": psets_of(cfg.bolts_path)}})
    out: dict[str, Any] = {"truth": None, "wrong": 0, "not_selected": []}
    info: dict[str, Any] = {"station": station, "out": out, "browsers": browsers}

    def check(action: Any) -> None:
        if isinstance(action, SendParams) and action.bolt != out["truth"]:
            out["wrong"] += 1

    station.on_action = check

    async def main() -> None:
        stop = asyncio.Event()
        screens = Screens(station.bus)
        clients: ScreenClients | None = None
        if browsers:
            await screens.follow(replace(cfg, http=HttpConfig("127.0.0.1:0")))
            if screens.server is None:
                raise InputError("bench station --browsers: the screens could not be served")
            station.frames = screens.frames
        task = asyncio.create_task(station.run(stop))
        try:
            if browsers:
                clients = await _connect(screens.server, browsers, info, quiet, kind, nice)
                info["nice"] = nice
            b0 = 0.0 if clients is None else clients.cpu_s()
            c0, w0 = time.process_time(), time.perf_counter()
            on_bolt = None
            if paired and clients is not None:
                held_from: list[tuple[int, bool]] = info.setdefault("held_from", [])
                hold = clients.hold

                async def on_bolt(i: int) -> None:
                    # every other bolt with the clients held: the two halves of one pass see the
                    # same machine, so its drift between passes leaves the difference.  A
                    # resumed browser first works off what piled up while it was stopped
                    # (queued snapshots, late timers): a burst no running browser has, let
                    # pass before the wrench moves
                    # the plan is the same in every pass: which half of it is held swaps
                    # from pass to pass, else a bolt slow to localize (seen by two pairs)
                    # would always count on one side (a first version did: +86 ms)
                    held = (i + pass_index) % 2 == 1
                    held_from.append((station.bus.count(ParamsSent), held))
                    hold(held)
                    await asyncio.sleep(PAIRED_SETTLE_S)
            if services:
                from stationd.bench.services import services_on

                async with services_on(cfg, station, info):
                    await _operator(station, world, plan, out, on_bolt, idle)
            else:
                await _operator(station, world, plan, out, on_bolt, idle)
            info["cpu_s"], info["wall_s"] = time.process_time() - c0, time.perf_counter() - w0
            if clients is not None:
                clients.hold(False)
                info["browser_cpu_s"] = clients.cpu_s() - b0
                info["frames_encoded"] = screens.frames.encoded
                info["encode_wall_s"] = screens.frames.encode_wall_s
                # the figures are taken; a page whose last refresh is under way may still
                # fetch the frames it listed (the counts below prove the screens were served)
                await asyncio.sleep(DRAIN_S)
            info["cpu_pct"] = 100.0 * info["cpu_s"] / info["wall_s"]
            if clients is not None:
                info["clients_alive"] = clients.kind != "chromium" or clients.alive()
                info["sse_clients_end"] = screens.server.clients
                info["frames_served"] = screens.server.requests[FRAME_ROUTE]
                info["snapshots"] = screens.server.snapshots
        finally:
            stop.set()
            await task
            if clients is not None:
                clients.close()
            await screens.stop()

    station.open()
    try:
        info["rss_open"] = _rss_mb()
        t_run = time.perf_counter()
        asyncio.run(main())
        info["run_s"] = time.perf_counter() - t_run
        info["rss_end"] = _rss_mb()
    finally:
        station.close()
    sent = [e for e in station.bus.of(ParamsSent) if isinstance(e, ParamsSent)]
    info["latency"] = [e.latency_ms["total"] for e in sent]
    info["by_bolt"] = [(e.bolt, e.latency_ms["total"]) for e in sent]
    if "held_from" in info:
        info["running"], info["held"] = _split_held(info["by_bolt"], info["held_from"])
    return info


def _line_server() -> Any:
    """A throw-away PostgreSQL for ``--line`` (durable: commits on disk, as a plant's)."""
    from stationd.pgserver import PgServer, PgServerError

    pg = PgServer(durable=True)
    if pg.missing:
        raise InputError(f"--line needs a PostgreSQL server: {pg.missing}")
    try:
        pg.start()
    except PgServerError as exc:
        raise InputError(f"--line: {exc}") from None
    return pg


def _with_services(cfg: StationConfig, opcua: bool, line_url: str | None, k: int
                   ) -> StationConfig:
    """``cfg`` with the OPC UA and line sections of pass ``k`` (a free port each pass)."""
    from stationd.demo.services import Endpoints, demo_opcua, line_config

    ua_cfg = demo_opcua(Endpoints("127.0.0.1", 0, False).take(set())[0], "BENCH") \
        if opcua else None
    return replace(cfg, opcua=ua_cfg,
                   line=None if line_url is None else line_config(line_url, f"BENCH-{k}"))


def _split_held(latency: list[T], held_from: list[tuple[int, bool]]) -> tuple[list[T], list[T]]:
    """The latencies of the bolts with the clients running and of those with them held:
    ``held_from`` lists (index of the bolt's first latency, held) in bolt order."""
    running: list[T] = []
    held: list[T] = []
    for k, x in enumerate(latency):
        state = False
        for start, h in held_from:
            if start > k:
                break
            state = h
        (held if state else running).append(x)
    return running, held


async def _connect(server: Any, n: int, info: dict[str, Any], quiet: bool,
                   kind: str, nice: int | str = 0) -> ScreenClients:
    """Start the clients and wait until they are really served: each operator page holds
    its event stream and each cameras page has loaded frames; a Chromium that does not get
    there in 60 s is replaced by the SSE stand-ins (the output says which ran).  Then wait
    for the browsers to settle (their start-up takes more than a core for seconds): the
    figure is what connected screens cost, not what starting a browser costs."""
    clients = ScreenClients(server.url, n, force_sse=kind == "sse", nice=nice)
    kind = clients.start()
    operators = sum(1 for p in clients.pages if p == "")
    cameras = n - operators

    def served() -> bool:
        # before the lift is up the cameras hand over no frames: a cameras page has
        # connected once it has asked for the cameras' list
        return bool(server.clients >= operators and
                    server.requests["/api/cameras"] >= cameras)
    if not await _until(served, 60):
        if kind == "chromium":
            clients.why_not_chromium = "chromium started but its pages did not connect in 60 s"
            kind = clients.fallback()
            if not await _until(served, 30):
                raise InputError("bench station --browsers: the screens' clients did not "
                                 "connect")
        else:
            raise InputError("bench station --browsers: the screens' clients did not connect")
    t0 = time.monotonic()
    while kind == "chromium" and time.monotonic() - t0 < SETTLE_MAX_S:
        c0 = clients.cpu_s()
        await asyncio.sleep(1.0)
        if clients.cpu_s() - c0 < SETTLED_CPU_S:
            break
    info["settle_s"] = time.monotonic() - t0
    info["clients"] = kind
    info["why_not_chromium"] = clients.why_not_chromium
    info["pages"] = ["/" + p for p in clients.pages]
    if not quiet:
        print(f"screens served at {server.url}: {n} {kind} {noun(n, 'client')} on "
              f"{', '.join(info['pages'])}", flush=True)
    return clients


#: a pass's figures pooled over passes: times as the mean of a pass, counts added
PER_PASS = ("cpu_s", "wall_s", "browser_cpu_s", "settle_s", "encode_wall_s")
COUNTED = ("frames_served", "frames_encoded", "snapshots")


def _pooled(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Several passes with the screens as one: latencies pooled, times per pass (mean),
    counts added, the rest (the clients' kind, pages) from the first."""
    out = dict(runs[0])
    out["latency"] = [x for r in runs for x in r["latency"]]
    out["latency_passes"] = [list(r["latency"]) for r in runs]
    out["by_bolt"] = [x for r in runs for x in r["by_bolt"]]
    for key in (*PER_PASS, *COUNTED):
        values = [r[key] for r in runs if r.get(key) is not None]
        total = sum(values)
        out[key] = (total / len(values) if key in PER_PASS else total) if values else None
    out["cpu_pct"] = 100.0 * out["cpu_s"] / out["wall_s"]
    out["clients_alive"] = all(r.get("clients_alive", True) for r in runs)
    return out


def _screens_summary(bases: list[dict[str, Any]], served: dict[str, Any], n: int
                     ) -> dict[str, Any]:
    """Latency and the daemon's CPU without the screens (the passes before and after, pooled)
    and with ``n`` clients on them.  The CPU is the whole bench process's (the simulated
    world's cameras and devices included, the same work in every pass); the screens' cost is
    the extra CPU seconds for the same plan over the pass's duration, in % of one core (a
    plain CPU/wall ratio would fall when the screens slow the pass down)."""
    lat0 = [x for b in bases for x in b["latency"]]
    cpu0 = sum(b["cpu_s"] for b in bases) / len(bases)
    wall0 = sum(b["wall_s"] for b in bases) / len(bases)
    served_passes = served.get("latency_passes", [served["latency"]])
    without = {"latency_ms": {"p50": _pct(lat0, 50), "p95": _pct(lat0, 95)},
               "cpu_s": cpu0, "wall_s": wall0, "cpu_pct": 100.0 * cpu0 / wall0,
               "passes": [{"latency_p95_ms": _pct(b["latency"], 95), "cpu_s": b["cpu_s"],
                           "wall_s": b["wall_s"]} for b in bases]}
    with_ = {"latency_ms": {"p50": _pct(served["latency"], 50),
                            "p95": _pct(served["latency"], 95)},
             "cpu_s": served["cpu_s"], "wall_s": served["wall_s"],
             "cpu_pct": served["cpu_pct"],
             "passes": [{"latency_p95_ms": _pct(p, 95)} for p in served_passes]}
    return {"browsers": n, "clients": served["clients"], "pages": served["pages"],
            "why_not_chromium": served["why_not_chromium"] or None,
            "clients_alive_to_the_end": served.get("clients_alive"),
            "frames_served": served.get("frames_served"),
            "frames_encoded": served.get("frames_encoded"),
            "frames_encode_wall_s": served.get("encode_wall_s"),
            "snapshots_sent": served.get("snapshots"),
            "browser_nice": served.get("nice"), "settle_s": served.get("settle_s"),
            "browser_cpu_pct_of_a_core": 100.0 * served.get("browser_cpu_s", 0.0)
            / served["wall_s"],
            "without": without, "with": with_,
            "delta": {"latency_p95_ms": with_["latency_ms"]["p95"] - without["latency_ms"]["p95"],
                      "latency_p50_ms": with_["latency_ms"]["p50"] - without["latency_ms"]["p50"],
                      "cpu_pct_of_a_core": 100.0 * (served["cpu_s"] - cpu0) / served["wall_s"]},
            "delta_p95_interval_ms": p95_delta_interval(
                served["by_bolt"], [x for b in bases for x in b["by_bolt"]]),
            "targets": {"latency_p95_ms": 10.0, "cpu_pct_of_a_core": 5.0}}


def _paired_summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Within the passes with the screens: the bolts with the clients running against those
    with them held (stopped), pooled over the passes, with the interval of the p95
    difference."""
    on = [x for r in runs for x in r.get("running", [])]
    off = [x for r in runs for x in r.get("held", [])]
    a, b = [ms for _, ms in on], [ms for _, ms in off]
    return {"running": {"n": len(a), "p50": _pct(a, 50), "p95": _pct(a, 95)},
            "held": {"n": len(b), "p50": _pct(b, 50), "p95": _pct(b, 95)},
            "delta_p95_ms": _pct(a, 95) - _pct(b, 95),
            "delta_p50_ms": _pct(a, 50) - _pct(b, 50),
            "delta_p95_interval_ms": p95_delta_interval(on, off)}


#: draws of the bootstrap behind the p95 difference's interval (seeded: the same figures give
#: the same interval)
BOOTSTRAP_DRAWS = 2000


def p95_delta_interval(with_: list[tuple[str, float]], without: list[tuple[str, float]],
                       level: float = 0.9, draws: int = BOOTSTRAP_DRAWS) -> list[float]:
    """The ``level`` interval of p95(with) - p95(without), the latencies given as (bolt,
    ms), by resampling bolts: each draw takes bolts with replacement and, for each, all its
    latencies on both sides.

    Why by bolt: every pass runs the same plan, and a bolt's placement sets much of its
    latency (one seen by two pairs costs twice the vision of one seen by one), so the p95
    of 20-50 bolts is mostly which placements are slow.  Resampling latencies one by one
    on each side, as a first version did, let a slow placement count on one side and not
    the other, an interval 60-130 ms wide; drawn as a whole it weighs the same on both.
    What is left is the machine's own noise and the screens' cost.  Only bolts measured on
    both sides count; ``[nan, nan]`` without one."""
    a: dict[str, list[float]] = {}
    b: dict[str, list[float]] = {}
    for side, pairs in ((a, with_), (b, without)):
        for bolt, ms in pairs:
            side.setdefault(bolt, []).append(float(ms))
    bolts = sorted(set(a) & set(b))
    if not bolts:
        return [float("nan"), float("nan")]
    xa = [np.asarray(a[k]) for k in bolts]
    xb = [np.asarray(b[k]) for k in bolts]
    rng = np.random.default_rng(0)
    d = np.empty(draws)
    for n, pick in enumerate(rng.integers(0, len(bolts), size=(draws, len(bolts)))):
        d[n] = (np.percentile(np.concatenate([xa[k] for k in pick]), 95)
                - np.percentile(np.concatenate([xb[k] for k in pick]), 95))
    lo, hi = np.percentile(d, [50 * (1 - level), 50 * (1 + level)])
    return [float(lo), float(hi)]


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def _summary(lat: list[dict[str, float]], cycles: int, out: dict[str, Any], st: Station,
             prerender_s: float, run_s: float, world_mb: float, rss_open: float,
             rss_end: float) -> dict[str, Any]:
    total = [x["total"] for x in lat]
    stages = {k: {"p50": _pct([x[k] for x in lat], 50), "p95": _pct([x[k] for x in lat], 95)}
              for k in ("localize", "decide", "acknowledge", "grab_slowest_pair",
                        "vision_slowest_pair")}
    peak = _peak_rss_mb()
    return {
        "image_size": "5472x3648", "cameras": 2 * len(st.cfg.pairs), "bolts": cycles,
        "selected": len(total), "recorded": st.bus.count(ResultRecorded),
        "wrong_bolt_sends": out["wrong"], "not_selected": out["not_selected"],
        "latency_ms": {"p50": _pct(total, 50), "p95": _pct(total, 95),
                       "max": max(total, default=float("nan"))},
        "stages_ms": stages,
        "memory_mb": {"peak_rss": peak, "rss_after_open": rss_open, "rss_end": rss_end,
                      "simulated_world_buffers": world_mb,
                      "daemon_peak_estimate": peak - world_mb},
        "prerender_s": prerender_s, "run_s": run_s,
        "idle": out.get("idle", {}),
    }


def _print(s: dict[str, Any]) -> None:
    lat, mem = s["latency_ms"], s["memory_mb"]
    print(f"{s['selected']} selections of {s['bolts']} placements, {s['recorded']} recorded, "
          f"parameters sent for a wrong bolt: {s['wrong_bolt_sends']}")
    for miss in s["not_selected"]:
        print(f"  not selected: {miss}")
    print(f"latency frame exposure -> parameters acknowledged ({s['cameras']} cameras, "
          f"{s['image_size']}): p50 {lat['p50']:.1f} ms, p95 {lat['p95']:.1f} ms, max "
          f"{lat['max']:.1f} ms")
    for name, v in s["stages_ms"].items():
        print(f"  {name:<20} p50 {v['p50']:7.1f} ms   p95 {v['p95']:7.1f} ms")
    print(f"memory: peak RSS {mem['peak_rss']:.0f} MB (of which the simulated world's frame "
          f"buffers {mem['simulated_world_buffers']:.0f} MB: daemon about "
          f"{mem['daemon_peak_estimate']:.0f} MB); after open {mem['rss_after_open']:.0f} MB, "
          f"at the end {mem['rss_end']:.0f} MB")
    idle = s.get("idle") or {}
    if idle:
        print(f"idle (lift up, not at working height; daemon and simulated PLC together): "
              f"{idle['plc_requests_per_s']:.1f} PLC requests/s, "
              f"{idle['cpu_pct_of_a_core']:.1f} % of a core (targets <= 20/s, <= 5 %)")
    print(f"pre-render {s['prerender_s']:.1f} s, run {s['run_s']:.1f} s, the bench process's "
          f"CPU during the run {s['cpu_pct']:.0f} % of a core")
    sc = s.get("screens")
    if sc is not None:
        w, wo, d = sc["with"], sc["without"], sc["delta"]
        lo, hi = sc["delta_p95_interval_ms"]
        what = "headless Chromium" if sc["clients"] == "chromium" else \
            f"SSE readers and frame loaders (no browser: {sc['why_not_chromium']})"
        print(f"screens: {sc['browsers']} {what} on {', '.join(sc['pages'])}, "
              f"{sc['frames_served']} camera frames and {sc['snapshots_sent']} live snapshots "
              f"served")
        if sc.get("frames_encoded") is not None:
            print(f"  overview frames reduced and encoded: {sc['frames_encoded']}, "
                  f"{1e3 * sc['frames_encode_wall_s']:.0f} ms wall per pass "
                  f"({100.0 * sc['frames_encode_wall_s'] / w['wall_s']:.1f} % of the pass)")
        if sc["clients"] == "chromium":
            how = "SCHED_IDLE" if sc["browser_nice"] == "idle" else \
                f"nice {sc['browser_nice']}"
            print(f"  the browsers ({how}, settled {sc['settle_s']:.0f} s "
                  f"after connecting) used {sc['browser_cpu_pct_of_a_core']:.0f} % of a core "
                  f"during the pass, on the daemon's cores")
        else:
            print(f"  the stand-in clients' process used {sc['browser_cpu_pct_of_a_core']:.1f} "
                  f"% of a core during the pass")
        k = sc.get("passes", 1)
        print(f"  latency p50 {w['latency_ms']['p50']:.1f} ms, p95 {w['latency_ms']['p95']:.1f}"
              f" ms with them ({k} pass{'es' if k > 1 else ''}); p50 "
              f"{wo['latency_ms']['p50']:.1f} ms, p95 {wo['latency_ms']['p95']:.1f} ms without "
              f"({k + 1} passes framing them): p95 "
              f"{d['latency_p95_ms']:+.1f} ms (90 % interval {lo:+.1f} to {hi:+.1f} ms; "
              f"target <= +10 ms)")
        print("  p95 of each pass with them: " + ", ".join(
            f"{p['latency_p95_ms']:.1f}" for p in w["passes"]) + " ms; without: " + ", ".join(
            f"{p['latency_p95_ms']:.1f}" for p in wo["passes"]) + " ms")
        pr = sc.get("paired")
        if pr is not None:
            plo, phi = pr["delta_p95_interval_ms"]
            print(f"  paired, within the passes with them: bolts with the clients running "
                  f"({pr['running']['n']}) p50 {pr['running']['p50']:.1f}, p95 "
                  f"{pr['running']['p95']:.1f} ms; held ({pr['held']['n']}) p50 "
                  f"{pr['held']['p50']:.1f}, p95 {pr['held']['p95']:.1f} ms: p95 "
                  f"{pr['delta_p95_ms']:+.1f} ms (90 % interval {plo:+.1f} to {phi:+.1f})")
            print(f"  (--paired passes wait {PAIRED_SETTLE_S:g} s at each bolt: their CPU per "
                  "pass is not comparable with the passes without; run without --paired for "
                  "it)")
        print(f"  daemon CPU {w['cpu_s']:.2f} s in {w['wall_s']:.1f} s per pass with them, "
              f"{wo['cpu_s']:.2f} s in {wo['wall_s']:.1f} s per pass without: "
              f"{d['cpu_pct_of_a_core']:+.1f} % of a core (target <= +5 %)")
