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
from typing import Any

import numpy as np

from stationd import progress
from stationd.boltfile import load_bolts
from stationd.config import load_station_config
from stationd.errors import InputError
from stationd.jsonout import finite, strict_json
from stationd.sim.world import World, WrenchPose, wrench_at
from stationd.station.core import SendParams, State
from stationd.station.daemon import Station
from stationd.station.demo import SIM_CONFIG, _sim_psets
from stationd.station.events import ParamsSent, ResultRecorded


def _rss_mb() -> float:
    """The resident set now (VmRSS), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KB on Linux


async def _until(pred: Any, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        await asyncio.sleep(0.005)
    return False


async def _operator(st: Station, world: World, plan: list[tuple[str, WrenchPose]],
                    out: dict[str, Any]) -> None:
    plc, ctl = st.lift.plc, st.wrench.controller
    plc.set_vehicle(1, "BENCHVIN000000001")
    plc.raise_lift()
    if not await _until(lambda: st.vin is not None, 60):
        raise RuntimeError(f"the station did not start the vehicle: {st.cycle.reason}")
    for bolt, pose in progress.track(plan, "bench station: bolts", unit="bolt"):
        world.set_wrench(pose)
        out["truth"] = bolt
        def on_it(b: str = bolt) -> bool:
            return st.cycle.state is State.TIGHTENING and st.cycle.bolt == b \
                and bool(ctl.tool_enabled)

        selected = await _until(on_it, 30)
        if not selected:
            out["not_selected"].append(f"{bolt}: {st.cycle.reason}")
        else:
            n = st.bus.count(ResultRecorded)
            if ctl.pull_trigger() is not None:
                await _until(lambda n=n: st.bus.count(ResultRecorded) > n, 10)
        out["truth"] = None
        world.set_wrench(None)
        await _until(lambda: st.cycle.state is State.TRACKING, 10)
    plc.lower_lift()
    await _until(lambda: st.vin is None, 10)


def run_station_bench(args: argparse.Namespace) -> int:
    cycles = int(args.cycles)
    if cycles < 1:
        raise InputError("--cycles must be at least 1")
    tmp = tempfile.TemporaryDirectory(prefix="stationd-bench-")
    cfg = replace(load_station_config(SIM_CONFIG),
                  database_url=f"sqlite:///{tmp.name}/stationd.db")
    assert cfg.bolts_path is not None  # noqa: S101 - the simulated station names its bolts
    rng = np.random.default_rng(args.seed)
    bolts = load_bolts(cfg.bolts_path).models[0].bolts
    plan = []
    for k in rng.permutation(len(bolts))[:cycles]:
        b = bolts[int(k)]
        target = np.array(b.position) + np.append(rng.normal(0, 0.3, 2), 0.0)
        plan.append((b.bolt_id, wrench_at(target, rng, cfg.tool.length_mm)))
    if not args.json:
        print(f"rendering {len(plan)} placements ahead for {2 * len(cfg.pairs)} cameras "
              f"(not timed) ...", flush=True)
    world = World(cfg, seed=args.seed)
    t0 = time.perf_counter()
    world.prerender([p for _, p in plan])
    prerender_s = time.perf_counter() - t0
    world_mb = float("nan")
    station = Station(cfg, device_kw={"wrench": {"psets": _sim_psets(cfg.bolts_path)}})
    out: dict[str, Any] = {"truth": None, "wrong": 0, "not_selected": []}

    def check(action: Any) -> None:
        if isinstance(action, SendParams) and action.bolt != out["truth"]:
            out["wrong"] += 1

    station.on_action = check

    async def main() -> None:
        stop = asyncio.Event()
        task = asyncio.create_task(station.run(stop))
        try:
            await _operator(station, world, plan, out)
        finally:
            stop.set()
            await task

    station.open()
    try:
        rss_open = _rss_mb()
        t_run = time.perf_counter()
        asyncio.run(main())
        run_s = time.perf_counter() - t_run
        rss_end = _rss_mb()
    finally:
        station.close()
        world_mb = world.buffer_bytes() / 2**20  # with the cameras' frame pools, now filled
        world.close()
        tmp.cleanup()
    lat = [e.latency_ms for e in station.bus.of(ParamsSent) if isinstance(e, ParamsSent)]
    summary = _summary(lat, cycles, out, station, prerender_s, run_s, world_mb, rss_open,
                       rss_end)
    Path(args.out).write_text(json.dumps(finite(summary), indent=2, allow_nan=False) + "\n")
    if args.json:
        sys.stdout.write(strict_json(summary) + "\n")
    else:
        _print(summary)
    ok = summary["wrong_bolt_sends"] == 0 and not out["not_selected"]
    return 0 if ok else 1


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
    print(f"pre-render {s['prerender_s']:.1f} s, run {s['run_s']:.1f} s")
