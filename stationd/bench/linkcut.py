"""``stationd bench linkcut``: no result lost across a cut link, and what curves cost.

The daemon runs as in ``stationd bench station`` (config/sim's pairs and lift, the world
pre-rendered so the cores are the daemon's), with its controller on Open Protocol over TCP:
a simulated controller this benchmark owns, reached through a proxy (``cutproxy.py``) that
can cut the link.  Three kinds of pass over one plan of placements:

- **link cut** (curves on): at the plan's first third, once the station has enabled the tool
  for its bolt, the link is cut for ``--cut-s`` seconds and the operator pulls the trigger:
  that tightening's result goes to nobody.  He goes on at ``--pace-s`` per placement while
  the link is down, pulling the trigger each time, and the controller, whose tool nobody
  could disable, tightens each time (results kept only in its store).  Then the link is
  restored and the rest of the plan runs as usual.  Counted from the controller's tightening
  ids and the station's database: made, recorded live (pushed, MID 0061), fetched late
  (asked for after the reconnect, MID 0064/0065), of those to a bolt or unattributed, gaps
  (ids the controller no longer had), recorded twice, and lost (made, neither recorded nor a
  gap: must be 0).
- **curves on and off, paired** (no cut, ``--passes`` of them): within one pass the curves
  are subscribed for every other bolt and unsubscribed for the others (MID 0008/0009 between
  two bolts, not timed), which half swapping from pass to pass; the latency from the frames'
  exposure to the controller's acknowledgement of the parameters (p50, p95) of the bolts with
  curves against those without, and the curves stored.  Paired because on a shared 2-core
  machine the load drifts between passes by more than curves could cost (a first version
  compared whole passes: its difference changed sign from run to run).  Curves come after
  each result on the same link, queued apart in the driver and stored by a thread of their
  own: the difference is their cost.

Exit 1 if a result was lost, recorded twice or recorded to a bolt the wrench was not on, or
parameters went to a wrong bolt.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from db.engine import make_engine
from db.models import Bolt, ResultGap, TighteningCurve, TighteningRecord, UnattributedResult
from drivers.lift.sim import SimLift
from drivers.wrench.openprotocol.client import OpenProtocolWrench
from drivers.wrench.sim.controller import SimController
from stationd import progress
from stationd.bench.cutproxy import CutProxy
from stationd.bench.plan import wrench_plan
from stationd.bench.wait import until as _until
from stationd.config import StationConfig, load_station_config
from stationd.demo.station import SIM_CONFIG
from stationd.errors import InputError
from stationd.jsonout import finite, strict_json
from stationd.outfile import write_atomic
from stationd.shell.daemon import Station
from stationd.sim.devices_cli import psets_of
from stationd.sim.world import World, WrenchPose
from stationd.station.actions import Record, SendParams, StoreUnattributed
from stationd.station.events import ParamsSent, ResultRecorded, State
from stationd.words import state_words

SELECT_S = 30.0        # the longest wait for a bolt's selection with the link up
RECORD_S = 10.0        # ... for its result to be recorded
SETTLE_S = 30.0        # after the plan: the longest wait for the catch-up to account for all


@dataclass
class Pass:
    """What one pass saw."""

    curves: bool
    cut_s: float | None
    paired: int | None = None        # curves on every other bolt, from this offset
    by_bolt: list[tuple[bool, float]] = field(default_factory=list)   # (curves on, ms)
    made: list[int] = field(default_factory=list)          # tightening ids, in order
    made_in_cut: list[int] = field(default_factory=list)
    made_on: dict[int, str | None] = field(default_factory=dict)   # id -> the wrench's bolt
    fetched: dict[int, bool] = field(default_factory=dict)   # id -> came by MID 0064
    wrong: int = 0
    not_selected: list[str] = field(default_factory=list)
    latency_ms: list[float] = field(default_factory=list)
    cut_at: float | None = None                            # monotonic: cut, restored
    restored_at: float | None = None
    back_after_s: float | None = None                      # restore -> reconnected
    accounted_after_s: float | None = None                 # restore -> every id accounted
    db: dict[str, Any] = field(default_factory=dict)
    truth: str | None = None


def run_linkcut_bench(args: argparse.Namespace) -> int:
    cycles, cut_s, pace_s, passes = int(args.cycles), float(args.cut_s), float(args.pace_s), \
        int(args.passes)
    if cycles < 3:
        raise InputError("--cycles must be at least 3 (before, during and after the cut)")
    if not 0 < cut_s <= 300:
        raise InputError("--cut-s must be in (0, 300]")
    if not 0.1 <= pace_s <= 30:
        raise InputError("--pace-s must be in [0.1, 30]")
    if passes < 1:
        raise InputError("--passes must be at least 1")
    tmp = tempfile.TemporaryDirectory(prefix="stationd-linkcut-")
    cfg = replace(load_station_config(SIM_CONFIG), http=None)
    assert cfg.bolts_path is not None  # noqa: S101 - the simulated station names its bolts
    plan = wrench_plan(cfg, args.seed, cycles)
    if cycles > len(plan):
        raise InputError(f"--cycles: the simulated vehicle has {len(plan)} bolts")
    if not args.json:
        print(f"rendering {len(plan)} placements ahead for {2 * len(cfg.pairs)} cameras "
              f"(not timed) ...", flush=True)
    world = World(cfg, seed=args.seed)
    psets = psets_of(cfg.bolts_path)
    runs: list[Pass] = []
    try:
        world.prerender([p for _, p in plan])
        for k in range(passes):
            db = f"sqlite:///{tmp.name}/paired{k}.db"
            runs.append(_run(replace(cfg, database_url=db), world, plan, psets, True, None,
                             pace_s, args.seed, bool(args.json), paired=k))
        cut = _run(replace(cfg, database_url=f"sqlite:///{tmp.name}/cut.db"), world, plan,
                   psets, True, cut_s, pace_s, args.seed, bool(args.json))
    finally:
        world.close()
        tmp.cleanup()
    summary = _summary(cut, runs, cycles, cut_s, pace_s)
    # whole or not at all: a Ctrl-C or a full disk while writing left half a JSON
    write_atomic(Path(args.out), json.dumps(finite(summary), indent=2, allow_nan=False) + "\n")
    if args.json:
        sys.stdout.write(strict_json(summary) + "\n")
    else:
        _print(summary)
    ok = (summary["link_cut"]["lost"] == 0 and summary["link_cut"]["recorded_twice"] == 0
          and summary["wrong_bolt_sends"] == 0
          and not summary["link_cut"]["recorded_to_a_wrong_bolt"])
    return 0 if ok else 1


def _run(cfg: StationConfig, world: World, plan: list[tuple[str, WrenchPose]],
         psets: dict[int, Any], curves: bool, cut_s: float | None, pace_s: float, seed: int,
         quiet: bool, paired: int | None = None) -> Pass:
    """One pass through a fresh daemon, controller (and proxy, for a cut)."""
    p = Pass(curves, cut_s, paired)
    ctl = SimController(psets, seed=seed, nok_rate=0.0, name="BenchController")
    ctl.start()
    proxy: CutProxy | None = None
    try:
        port = ctl.listen_tcp()
        if cut_s is not None:
            proxy = CutProxy(("127.0.0.1", port))
            port = proxy.port
        url = f"openprotocol://127.0.0.1:{port}" + ("?curves=1" if curves else "")
        cfg = replace(cfg, wrench=replace(cfg.wrench, url=url))
        station = Station(cfg)

        def check(action: Any) -> None:
            if isinstance(action, SendParams) and action.bolt != p.truth:
                p.wrong += 1
            if isinstance(action, Record | StoreUnattributed):
                p.fetched.setdefault(int(action.result.tightening_id),
                                     bool(action.result.fetched))

        station.on_action = check
        station.open()
        try:
            asyncio.run(_main(station, world, plan, ctl, proxy, p, pace_s, quiet))
        finally:
            station.close()
        p.latency_ms = [e.latency_ms["total"] for e in station.bus.of(ParamsSent)
                        if isinstance(e, ParamsSent)]
        p.db = _read_db(cfg.database_url)
    finally:
        if proxy is not None:
            proxy.close()
        ctl.close()
    return p


async def _main(st: Station, world: World, plan: list[tuple[str, WrenchPose]],
                ctl: SimController, proxy: CutProxy | None, p: Pass, pace_s: float,
                quiet: bool) -> None:
    stop = asyncio.Event()
    task = asyncio.create_task(st.run(stop))
    try:
        await _operator(st, world, plan, ctl, proxy, p, pace_s, quiet)
        await _curves_settled(st.cfg.database_url)
    finally:
        stop.set()
        await task


async def _curves_settled(url: str, timeout_s: float = 10.0) -> None:
    """The curves in flight stored before the station stops: the curve loop stores each
    apart from its result, so the count is read until it holds still for 1.5 s."""
    loop = asyncio.get_running_loop()
    last, still, t0 = -1, 0, time.monotonic()
    while time.monotonic() - t0 < timeout_s and still < 3:
        n = (await loop.run_in_executor(None, _read_db, url))["curves"]
        still, last = (still + 1 if n == last else 0), n
        await asyncio.sleep(0.5)


async def _operator(st: Station, world: World, plan: list[tuple[str, WrenchPose]],
                    ctl: SimController, proxy: CutProxy | None, p: Pass, pace_s: float,
                    quiet: bool) -> None:
    lift = st.lift
    if not isinstance(lift, SimLift):
        raise InputError("bench linkcut needs the simulated lift")
    plc = lift.plc
    plc.set_vehicle(1, "BENCHVIN000000001")
    plc.raise_lift()
    if not await _until(lambda: st.vin is not None, 60):
        raise InputError("the station did not start the vehicle: "
                         f"{state_words(st.core.status().reason)}")
    cut_index = len(plan) // 3 if p.cut_s is not None else -1
    restoring: asyncio.Task[None] | None = None
    what = "bench linkcut: " + ("link cut" if p.cut_s is not None else
                                "curves on and off")
    items = plan if quiet else progress.track(plan, what, unit="bolt")
    for i, (bolt, pose) in enumerate(items):
        sent = st.bus.count(ParamsSent)
        want = p.paired is not None and (i + p.paired) % 2 == 0
        if p.paired is not None:
            await _curves(st, want)
        world.set_wrench(pose)
        p.truth = bolt
        if proxy is not None and proxy.is_cut:
            # the link is down: the station cannot select, the operator tightens anyway
            await asyncio.sleep(pace_s / 2)
            _made(p, ctl.pull_trigger(), cut=True)
            await asyncio.sleep(pace_s / 2)
        else:
            def on_it(b: str = bolt) -> bool:
                return st.core.status().state is State.TIGHTENING and st.core.status().bolt == b \
                    and bool(ctl.tool_enabled)

            if not await _until(on_it, SELECT_S):
                p.not_selected.append(f"{bolt}: {state_words(st.core.status().reason)}")
            elif i == cut_index and proxy is not None and p.cut_s is not None:
                proxy.cut()     # the link goes as the operator pulls the trigger
                p.cut_at = time.monotonic()
                restoring = asyncio.create_task(_restore(proxy, p.cut_s, p))
                _made(p, ctl.pull_trigger(), cut=True)
                await asyncio.sleep(pace_s / 2)
            else:
                n = st.bus.count(ResultRecorded)
                made = ctl.pull_trigger()
                _made(p, made, cut=False)

                def recorded(before: int = n) -> bool:
                    return st.bus.count(ResultRecorded) > before

                if made is not None:
                    await _until(recorded, RECORD_S)
        p.truth = None
        world.set_wrench(None)
        if p.paired is not None:
            new = list(st.bus.of(ParamsSent))[sent:]
            p.by_bolt += [(want, e.latency_ms["total"]) for e in new
                          if isinstance(e, ParamsSent)]
        if proxy is None or not proxy.is_cut:
            await _until(lambda: st.core.status().state is State.TRACKING, 10)
    if restoring is not None:
        await restoring
        assert p.restored_at is not None  # noqa: S101 - set by _restore
        restored = p.restored_at
        await _until(lambda: st.wrench_keeper.up, SETTLE_S)
        p.back_after_s = time.monotonic() - restored
        await _until(lambda: _accounted(p, st), SETTLE_S, poll_s=0.05)
        p.accounted_after_s = time.monotonic() - restored
    else:
        await _until(lambda: _accounted(p, st), SETTLE_S, poll_s=0.05)
    plc.lower_lift()
    await _until(lambda: st.vin is None, 10)


async def _curves(st: Station, on: bool) -> None:
    """Subscribe to the curves (MID 0008) or stop them (0009) between two bolts."""
    wrench = st.wrench
    if not isinstance(wrench, OpenProtocolWrench) or wrench.curves_on == on:
        return
    loop = asyncio.get_running_loop()
    await loop.run_in_executor(None, wrench.subscribe_curves if on else
                               wrench.unsubscribe_curves)
    if wrench.curves_on != on:
        raise InputError(f"bench linkcut: curves could not be turned {'on' if on else 'off'}")


async def _restore(proxy: CutProxy, cut_s: float, p: Pass) -> None:
    await asyncio.sleep(cut_s)
    proxy.restore()
    p.restored_at = time.monotonic()


def _made(p: Pass, made: Any, cut: bool) -> None:
    if made is not None:
        p.made.append(int(made.tightening_id))
        p.made_on[int(made.tightening_id)] = p.truth
        if cut:
            p.made_in_cut.append(int(made.tightening_id))


def _accounted(p: Pass, st: Station) -> bool:
    """Every tightening made has been through the core (recorded or stored unattributed)
    or is a gap: nothing is still on its way."""
    repo = st.records.repo
    gaps: set[int] = set()
    if repo is not None:
        try:
            gaps = _gap_ids(_gap_rows(repo.engine))
        except Exception:       # the database busy: asked again at the next poll
            return False
    return all(t in p.fetched or t in gaps for t in p.made)


def _gap_rows(engine: Any) -> list[tuple[int, int]]:
    with Session(engine) as s:
        return [(g.first_id, g.last_id) for g in s.scalars(select(ResultGap))]


def _gap_ids(rows: list[tuple[int, int]]) -> set[int]:
    return {t for a, b in rows for t in range(a, b + 1)}


def _read_db(url: str) -> dict[str, Any]:
    """What the station's database holds: tightening ids recorded to a bolt and
    unattributed (each occurrence), gap ranges, curves stored."""
    engine = make_engine(url)
    try:
        with Session(engine) as s:
            rows = s.execute(select(TighteningRecord.tightening_id, Bolt.code)
                             .join(Bolt, TighteningRecord.bolt_id == Bolt.id)).all()
            bolted = [int(t) for t, _ in rows if t is not None]
            bolt_of = {int(t): str(b) for t, b in rows if t is not None}
            loose = [int(t) for t in s.scalars(select(UnattributedResult.tightening_id))
                     if t is not None]
            curves = len(list(s.scalars(select(TighteningCurve.id))))
        gaps = _gap_rows(engine)
    finally:
        engine.dispose()
    return {"to_a_bolt": bolted, "unattributed": loose, "gaps": gaps, "curves": curves,
            "bolt_of": bolt_of}


def _pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def accounting(p: Pass) -> dict[str, Any]:
    """The link-cut pass's figures (every count over the controller's tightening ids)."""
    bolted, loose = p.db.get("to_a_bolt", []), p.db.get("unattributed", [])
    everything = bolted + loose
    recorded = set(everything)
    gaps = _gap_ids(p.db.get("gaps", []))
    fetched = {t for t in recorded if p.fetched.get(t)}
    return {
        "made": len(p.made), "made_while_cut": len(p.made_in_cut),
        "recorded": len(recorded & set(p.made)),
        "recorded_live": len((recorded - fetched) & set(p.made)),
        "fetched_late": len(fetched & set(p.made)),
        "fetched_to_a_bolt": len(fetched & set(bolted)),
        "fetched_unattributed": len(fetched & set(loose)),
        # recorded to a bolt the wrench was not on when the trigger was pulled (must be 0)
        "recorded_to_a_wrong_bolt": sorted(
            t for t, b in p.db.get("bolt_of", {}).items()
            if t in p.made_on and p.made_on[t] != b),
        "gaps": len(gaps & set(p.made)),
        "recorded_twice": len(everything) - len(recorded),
        "lost": len(set(p.made) - recorded - gaps),
        "not_made_by_the_controller": sorted(recorded - set(p.made)),
        "curves_stored": p.db.get("curves", 0),
        "cut_s": p.cut_s,
        "reconnected_after_restore_s": p.back_after_s,
        "all_accounted_after_restore_s": p.accounted_after_s,
        "not_selected": p.not_selected,
    }


def _summary(cut: Pass, runs: list[Pass], cycles: int, cut_s: float, pace_s: float
             ) -> dict[str, Any]:
    def lat(curves: bool) -> dict[str, Any]:
        xs = [ms for r in runs for on, ms in r.by_bolt if on is curves]
        return {"n": len(xs), "p50": _pct(xs, 50), "p95": _pct(xs, 95)}
    off, on = lat(False), lat(True)
    return {
        "placements": cycles, "pace_s": pace_s, "passes": len(runs),
        "curves_stored": sum(r.db.get("curves", 0) for r in runs),
        "not_selected": [m for r in runs for m in r.not_selected],
        "wrong_bolt_sends": cut.wrong + sum(r.wrong for r in runs),
        "link_cut": accounting(cut),
        "latency_ms": {"without_curves": off, "with_curves": on,
                       "delta_p50": on["p50"] - off["p50"], "delta_p95": on["p95"] - off["p95"]},
    }


def _print(s: dict[str, Any]) -> None:
    c = s["link_cut"]
    print(f"link cut for {c['cut_s']:g} s during a run of {s['placements']} placements "
          f"(one every {s['pace_s']:g} s while the link was down):")
    print(f"  tightenings made {c['made']} ({c['made_while_cut']} while the link was down); "
          f"recorded {c['recorded']}: live {c['recorded_live']}, fetched late "
          f"{c['fetched_late']} (to a bolt {c['fetched_to_a_bolt']}, unattributed "
          f"{c['fetched_unattributed']}); gaps {c['gaps']}; recorded twice "
          f"{c['recorded_twice']}; lost {c['lost']} (must be 0); recorded to a bolt the "
          f"wrench was not on {len(c['recorded_to_a_wrong_bolt'])} (must be 0)")
    back, done = c["reconnected_after_restore_s"], c["all_accounted_after_restore_s"]
    if back is not None and done is not None:
        print(f"  after the link came back: reconnected in {back:.1f} s, every tightening "
              f"accounted for in {done:.1f} s; curves stored {c['curves_stored']}")
    for miss in c["not_selected"]:
        print(f"  not selected: {miss}")
    lat = s["latency_ms"]
    off, on = lat["without_curves"], lat["with_curves"]
    print(f"latency frame exposure -> parameters acknowledged, curves on every other bolt "
          f"({s['passes']} pass(es)): with curves p50 {on['p50']:.1f} ms, p95 "
          f"{on['p95']:.1f} ms ({on['n']} bolts, {s['curves_stored']} curves stored); without "
          f"p50 {off['p50']:.1f} ms, p95 {off['p95']:.1f} ms ({off['n']} bolts): p50 "
          f"{lat['delta_p50']:+.1f} ms, p95 {lat['delta_p95']:+.1f} ms")
    for miss in s["not_selected"]:
        print(f"  not selected: {miss}")
    print(f"parameters sent for a wrong bolt: {s['wrong_bolt_sends']}")


__all__ = ["CutProxy", "Pass", "accounting", "run_linkcut_bench"]
