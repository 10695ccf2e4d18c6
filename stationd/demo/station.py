"""``stationd demo``: the simulated station, end to end, over real protocols on loopback.

The daemon runs on ``config/sim`` (four pairs, one model with 50 bolts) with its lift as a
Modbus server, its controller as an Open Protocol server and its cameras rendering at full
resolution; a simulated operator raises the lift and takes the wrench to bolts in a random
order, with placement noise and tilt, sometimes hovering between two bolts or leaving before
tightening.  It sometimes tightens NOK (seeded: a joint that fails now and then, and now and
then a stubborn one that fails until the bolt locks), so the NOK policy runs: the operator
repeats, loosens first where the policy says so, and a simulated supervisor releases a
locked bolt through the same command path as the screens' (``Station.submit``).  One line per
bolt, then a summary; ``--json`` prints it as the last line.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
import tempfile
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from drivers.wrench.sim import SimPset
from stationd import progress
from stationd.boltfile import load_bolts
from stationd.config import RecordsConfig, StationConfig, load_station_config
from stationd.errors import InputError
from stationd.jsonout import strict_json
from stationd.reasons import Reason, Why
from stationd.serve import Screens
from stationd.sim.devices_cli import psets_of
from stationd.sim.load import cpu_load
from stationd.sim.operator import (
    LOOSEN_PROGRAM,
    SUPERVISOR,
    loosen_programs,
    operate,
    simulators,
    stand_ins,
)
from stationd.sim.vin import make_vin
from stationd.sim.world import World
from stationd.station.core import SendParams
from stationd.station.daemon import Station
from stationd.station.events import (
    BoltLocked,
    BoltReleased,
    Localized,
    ParamsSent,
    ResultRecorded,
    WrongBolt,
)
from stationd.station.policy import NokPolicy, NokRule
from stationd.web.config import DEFAULT_LISTEN, HttpConfig, open_bind_problem

SIM_CONFIG = Path(__file__).resolve().parents[2] / "config" / "sim" / "station.yaml"
#: shared with ``stationd run --sim-operator`` (:mod:`stationd.sim.operator`), named here as before
__all__ = ["LOOSEN_PROGRAM", "SIM_CONFIG", "SUPERVISOR", "demo_policy", "loosen_programs",
           "policy_words", "run_station_demo", "simulated", "simulators", "stand_ins"]


def demo_policy(cfg: StationConfig, psets: dict[int, SimPset]) -> NokPolicy | None:
    """The NOK policy the demo runs with a station file that has none (``cfg.nok`` the
    default): three NOKs in a row lock a bolt; a NOK bolt of the table's first pset is
    tightened again, one of any other pset (the larger joints, on config/sim) is loosened
    first, with a loosen pset no bolt uses; None: the file's own policy runs."""
    if cfg.nok != NokPolicy() or not psets or max(psets) >= 999:
        return None
    rule = NokRule(max_nok=3, strategy="loosen", loosen_pset=max(psets) + 1)
    return NokPolicy(NokRule(max_nok=3), {n: rule for n in sorted(psets)[1:]})


def policy_words(policy: NokPolicy) -> str:
    """The policy in one line, for the demo's start."""
    d = policy.default
    parts = [f"max_nok {d.max_nok}, {d.strategy}"]
    parts += [f"pset {n}: {r.strategy}" + (f" with loosen pset {r.loosen_pset}"
                                           if r.strategy == "loosen" else "")
              for n, r in policy.psets.items()]
    parts += [f"bolt {b}: {r.strategy}" for b, r in policy.bolts.items()]
    return "; ".join(parts)


def run_station_demo(args: argparse.Namespace) -> int:
    cycles = int(args.cycles)
    if cycles < 1:
        raise InputError("--cycles must be at least 1")
    if int(getattr(args, "load", 0)) < 0:
        raise InputError("--load must be 0 or more busy processes")
    given = getattr(args, "http", None)
    if given is not None:
        problem = open_bind_problem(HttpConfig(str(given)))
        if problem is not None:
            raise InputError(f"--http: {problem}")
    logging.basicConfig(level=logging.WARNING, format="%(message)s")
    cfg = load_station_config(args.config or SIM_CONFIG)
    bolts_path = cfg.bolts_path
    if bolts_path is None:
        raise InputError(f"{cfg.path}: the demo needs a bolt table (bolts:)")
    _check_demo_station(cfg)
    instead = stand_ins(cfg)
    if instead:
        print(f"demo: {cfg.path} names real devices ({', '.join(instead)}): the demo runs its "
              "own simulators instead and never opens them; its records go to a temporary "
              f"database, not {cfg.database_url}", file=sys.stderr if args.json else sys.stdout,
              flush=True)
    tmp = tempfile.TemporaryDirectory(prefix="stationd-demo-")
    cfg = simulated(cfg, Path(tmp.name))
    psets = psets_of(bolts_path)
    policy = demo_policy(cfg, psets)
    if policy is not None:
        cfg = replace(cfg, nok=policy)
    whose = "the demo's, the station file has none" if policy is not None else cfg.path
    print(f"NOK policy ({whose}): {policy_words(cfg.nok)}",
          file=sys.stderr if args.json else sys.stdout, flush=True)
    station = Station(cfg, device_kw={"wrench": {"psets": {**loosen_programs(cfg.nok),
                                                            **psets}}})
    rng = np.random.default_rng(args.seed)
    # the NOKs have their own stream: the plan (bolts, placements) is the seed's as before
    nok_rng = np.random.default_rng([args.seed, 21])
    report: list[dict[str, Any]] = []
    codes = [m.code for m in load_bolts(bolts_path).models if m.code is not None and m.bolts]
    if not codes:
        raise InputError(f"{bolts_path}: the demo needs a model with a lift code and bolts")
    truth: dict[str, Any] = {"bolt": None, "wrong": 0, "model_code": codes[0],
                             "vin": make_vin(1), "locked_sends": 0}

    def check(action: Any) -> None:
        """Every parameter send is compared with where the wrench really is, at that moment;
        a wrong one is published, counted and printed where it happens."""
        if isinstance(action, SendParams) and action.bolt != truth["bolt"]:
            truth["wrong"] += 1
            station.bus.publish(WrongBolt(action.bolt, truth["bolt"]))
            line = f"WRONG BOLT: parameters for {action.bolt} while the wrench is on " \
                   f"{truth['bolt'] or 'no bolt'}"
            print(line, file=sys.stderr, flush=True)
            if not args.json:
                print(line, flush=True)
        matcher = station.core.matcher
        if isinstance(action, SendParams) and matcher is not None \
                and action.bolt in matcher.locked:
            truth["locked_sends"] += 1
            print(f"LOCKED BOLT: parameters for {action.bolt}, locked", file=sys.stderr,
                  flush=True)

    station.on_action = check

    def say(line: dict[str, Any]) -> None:
        if not args.json:
            if line.get("before"):   # the NOK policy at work on this bolt, then its line
                print(f"  {line['bolt']} first: {'; '.join(line['before'])}", flush=True)
            err = line.get("xy_error_mm")
            print(f"{line['bolt']}: pset {line['pset']}, XY error "
                  f"{'-' if err is None else f'{err:.3f} mm'}, {line['result']}", flush=True)

    async def main() -> None:
        stop = asyncio.Event()
        screens = Screens(station.bus)
        listen = _listen(args, cfg)
        if listen is not None:
            await screens.follow(replace(cfg, http=HttpConfig(listen)))
            station.frames = screens.frames
            if screens.server is not None:
                print(f"screens: {screens.server.url} (operator), {screens.server.url}cameras, "
                      f"{screens.server.url}vehicles", file=sys.stderr if args.json else
                      sys.stdout, flush=True)
        world = World(cfg, seed=args.seed)
        try:
            task = asyncio.create_task(station.run(stop))
            # people's commands (the screens, stationd skip|reopen|release|loosen) go to the
            # demo's station as they go to the daemon's in run, for the run and the hold
            screens.attach(station, cfg)
            await operate(station, world, rng, cycles, report, say, truth, nok_rng)
            if getattr(args, "hold", False) and screens.server is not None:
                await _hold(screens.server.url, report, int(truth.get("cycles", cycles)),
                            truth, args.json)
            screens.attach(None, cfg)
            stop.set()
            await task
        finally:
            world.close()
            await screens.stop()

    progress.note("demo: opening the station (database, bolt table, simulated PLC, controller "
                  "and 8 cameras)")
    station.open()
    progress.note("demo: the simulated operator starts; each camera renders its background "
                  "once (about a second each), then frames at the trigger instant")
    try:
        with cpu_load(int(args.load)):
            asyncio.run(main())
    finally:
        station.close()
        tmp.cleanup()
    cycles = int(truth.get("cycles", cycles))
    summary = _summary(station, report, cycles, truth["wrong"], truth["locked_sends"])
    summary["simulated_instead"] = instead
    if args.json:
        sys.stdout.write(strict_json(summary) + "\n")
    else:
        print(f"summary: {summary['ok']}/{cycles} bolts OK, parameters sent for a wrong bolt: "
              f"{summary['wrong_bolt_sends']}, XY error mean "
              f"{_ms(summary['xy_error_mm']['mean'], '.3f')} mm max "
              f"{_ms(summary['xy_error_mm']['max'], '.3f')} mm, latency from exposure p50 "
              f"{_ms(summary['latency_ms']['p50'], '.0f')} ms p95 "
              f"{_ms(summary['latency_ms']['p95'], '.0f')} ms")
        n = summary["nok_policy"]
        print(f"NOK policy: {n['nok']} NOK result(s), {n['loosenings']} loosening(s), "
              f"{n['locks']} lock(s), {n['releases']} release(s)")
        if instead:
            devices = ", ".join(d.rsplit(" ", 1)[0] for d in instead)
            print(f"simulated, not the station file's devices: {devices} (the records went "
                  "to a temporary database)")
        print(summary["verdict"])
    return 0 if summary["verdict"].startswith("PASS") else 1


async def _hold(url: str, report: list[dict[str, Any]], cycles: int, truth: dict[str, Any],
                json_out: bool) -> None:
    """``--hold``: the run is over (results recorded); the screens keep serving its results
    from the run's temporary database until SIGINT or SIGTERM, so they can be browsed (and
    exported) before the demo's folder is removed, and the station keeps taking people's
    commands (a skip, a reopen, a release, a loosen) as a daemon would."""
    done = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, done.set)
    ok = sum(1 for r in report if r.get("ok"))
    print(f"run over ({ok}/{cycles} bolts OK); still serving {url}vehicles/"
          f"{truth['vin']} until Ctrl-C (--hold)", file=sys.stderr if json_out else sys.stdout,
          flush=True)
    try:
        await done.wait()
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)


def _listen(args: argparse.Namespace, cfg: StationConfig) -> str | None:
    """Where the demo serves its screens: ``--http``, else the station file's, else
    127.0.0.1:8080; None with ``--no-http``."""
    if getattr(args, "no_http", False):
        return None
    given = getattr(args, "http", None)
    if given is not None:
        return str(given)
    return cfg.http.listen if cfg.http is not None else DEFAULT_LISTEN


def _ms(v: float | None, fmt: str) -> str:
    return "-" if v is None else format(v, fmt)


def _check_demo_station(cfg: StationConfig) -> None:
    """The demo simulates the lift, the controller and the cameras; it needs each pair's
    calibration and its transform into the vehicle frame to render and localize."""
    missing = [n for n, pc in cfg.pairs.items() if pc.to_vehicle is None]
    if not cfg.pairs or missing:
        raise InputError(f"{cfg.path}: the demo needs pairs registered into the vehicle frame "
                         f"(to_vehicle missing for: {', '.join(missing) or 'no pairs'})")
    # the simulated world places its cameras with the inverse of a rigid map; an affine one
    # (scale, shear) would render a world the daemon then measures elsewhere
    affine = [n for n, pc in cfg.pairs.items() if pc.to_vehicle is not None
              and not np.allclose(pc.to_vehicle.A.T @ pc.to_vehicle.A, np.eye(3), atol=1e-6)]
    if affine:
        raise InputError(f"{cfg.path}: the demo simulates cameras through rigid vehicle "
                         f"transforms only; {', '.join(affine)}: to_vehicle is affine (scale or "
                         "shear): run the demo on a rigid registration (kind: rigid in the "
                         "points file of stationd calibrate vehicle)")


def simulated(cfg: StationConfig, tmp: Path) -> StationConfig:
    """``cfg`` with simulated devices (lift, controller, one sim camera per pair side), a
    database and an images folder in ``tmp``: any station file's geometry can be demonstrated
    without touching its real devices or records."""
    cams: dict[str, str] = {}
    pairs = {}
    for name, pc in cfg.pairs.items():
        left, right = f"{name}_left", f"{name}_right"
        cams[left], cams[right] = f"sim://{name}/left", f"sim://{name}/right"
        pairs[name] = replace(pc, left=left, right=right)
    return replace(cfg, cameras=cams, pairs=pairs,
                   lift=replace(cfg.lift, url="sim://lift"),
                   wrench=replace(cfg.wrench, url="sim://wrench", registers=None),
                   database_url=f"sqlite:///{tmp}/stationd.db",
                   records=RecordsConfig(images_dir=tmp / "images",
                                         save_images=cfg.records.save_images))


def _summary(st: Station, report: list[dict[str, Any]], cycles: int,
             wrong: int, locked_sends: int = 0) -> dict[str, Any]:
    """The run in figures, from the station's typed events; ``verdict`` is the last line."""
    refusals: Counter[str] = Counter()
    for e in st.bus.of(Localized):
        assert isinstance(e, Localized)  # noqa: S101 - of() filters
        if e.reason:
            refusals[_kind(e.reason)] += 1
    errs = [r["xy_error_mm"] for r in report if "xy_error_mm" in r]
    lat = [e.latency_ms["total"] for e in st.bus.of(ParamsSent) if isinstance(e, ParamsSent)]
    recorded_events = [e for e in st.bus.of(ResultRecorded) if isinstance(e, ResultRecorded)]
    recorded = len(recorded_events)
    ok = sum(1 for r in report if r.get("ok"))
    results = sum(int(r.get("rundowns", "ok" in r)) for r in report)
    # a bolt is handled when the station did its part to the end: selected, and after a NOK
    # selected again (with its loosen pset where the policy says so, released when locked)
    handled = sum(1 for r in report if r["result"] and not str(r["result"]).startswith("not ")
                  and not r.get("unfinished"))
    problems = []
    if wrong:
        problems.append(f"{wrong} parameter send(s) for a wrong bolt")
    if locked_sends:
        problems.append(f"{locked_sends} parameter send(s) for a locked bolt")
    if recorded != results:
        problems.append(f"{results - recorded} result(s) not recorded")
    if handled < cycles:
        problems.append(f"{cycles - handled} of {cycles} bolts not handled (see their lines)")
    if any("STILL ENABLED" in str(r["result"]) for r in report):
        problems.append("the tool stayed enabled after the wrench left")
    verdict = f"FAIL: {'; '.join(problems)}" if problems else \
        f"PASS: {handled}/{cycles} bolts handled, 0 wrong bolts, every result recorded"
    return {"bolts": cycles, "ok": ok, "handled": handled,
            "wrong_bolt_sends": wrong, "parameters_sent": len(lat),
            "results": results, "recorded": recorded,
            "nok_policy": {
                "nok": sum(1 for e in recorded_events if not e.ok),
                "loosenings": sum(1 for e in recorded_events if e.kind == "loosening"),
                "locks": st.bus.count(BoltLocked), "releases": st.bus.count(BoltReleased),
                "locked_sends": locked_sends},
            "refusals": dict(refusals.most_common(8)),
            "xy_error_mm": {"mean": _num(np.mean(errs)) if errs else None,
                            "max": _num(np.max(errs)) if errs else None},
            "latency_ms": {"p50": _num(np.percentile(lat, 50)) if lat else None,
                           "p95": _num(np.percentile(lat, 95)) if lat else None},
            "verdict": verdict}


def _num(v: Any) -> float:
    return float(v)


def _kind(reason: Reason) -> str:
    """A refusal's category, for the summary (the full reasons are in the log)."""
    return _KINDS.get(reason.kind, "marker not localized")


_KINDS = {Why.NOT_STABLE: "not yet stable", Why.AMBIGUOUS: "ambiguous",
          Why.NO_BOLT_NEAR: "no bolt within tolerance", Why.DONE: "bolt already done",
          Why.STALE: "stale", Why.TILTED: "wrench tilted too far",
          Why.PAIRS_DISAGREE: "pairs disagree"}
