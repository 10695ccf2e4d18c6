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

from db.repository import BoltInfo
from drivers.lift.sim import SimLift, SimulatedPlc
from drivers.wrench.sim import SimController, SimPset, SimWrench
from stationd import progress
from stationd.boltfile import load_bolts
from stationd.config import RecordsConfig, StationConfig, load_station_config
from stationd.errors import InputError
from stationd.jsonout import strict_json
from stationd.reasons import Reason, Why
from stationd.serve import Screens
from stationd.sim.devices_cli import psets_of
from stationd.sim.load import cpu_load
from stationd.sim.vin import make_vin
from stationd.sim.world import World, wrench_at
from stationd.station.commands import Issuer, ReleaseBolt, Right
from stationd.station.core import SendParams, State
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
from stationd.words import reason_words

SIM_CONFIG = Path(__file__).resolve().parents[2] / "config" / "sim" / "station.yaml"
#: a tightening fails now and then; a stubborn joint (a damaged thread) fails until its bolt
#: locks and the supervisor released it; a loosening always comes loose
NOK_P, STUBBORN_P = 0.1, 0.1
#: rundowns the simulated operator makes on one bolt before giving up on it
MAX_RUNDOWNS = 10
#: who releases a locked bolt in the demo (the command path is the screens')
SUPERVISOR = Issuer("supervisor", frozenset({Right.RELEASE}), "demo")
#: the controller's loosening program for a loosen pset: a joint that comes loose is OK
LOOSEN_PROGRAM = SimPset(40.0, 5.0, 150.0, 360.0, 90.0, 720.0, name="loosen")


def demo_policy(cfg: StationConfig, psets: dict[int, SimPset]) -> NokPolicy | None:
    """The NOK policy the demo runs with a station file that has none (``cfg.nok`` the
    default): three NOKs in a row lock a bolt; a NOK bolt of the table's first pset is
    tightened again, one of any other pset (the larger joints, on config/sim) is loosened
    first, with a loosen pset no bolt uses; None: the file's own policy runs."""
    if cfg.nok != NokPolicy() or not psets or max(psets) >= 999:
        return None
    rule = NokRule(max_nok=3, strategy="loosen", loosen_pset=max(psets) + 1)
    return NokPolicy(NokRule(max_nok=3), {n: rule for n in sorted(psets)[1:]})


def loosen_programs(policy: NokPolicy) -> dict[int, SimPset]:
    """The simulated controller's programs for the policy's loosen psets."""
    rules = [policy.default, *policy.psets.values(), *policy.bolts.values()]
    return {r.loosen_pset: LOOSEN_PROGRAM for r in rules if r.loosen_pset is not None}


def policy_words(policy: NokPolicy) -> str:
    """The policy in one line, for the demo's start."""
    d = policy.default
    parts = [f"max_nok {d.max_nok}, {d.strategy}"]
    parts += [f"pset {n}: {r.strategy}" + (f" with loosen pset {r.loosen_pset}"
                                           if r.strategy == "loosen" else "")
              for n, r in policy.psets.items()]
    parts += [f"bolt {b}: {r.strategy}" for b, r in policy.bolts.items()]
    return "; ".join(parts)


def simulators(st: Station) -> tuple[SimulatedPlc, SimController]:
    """The simulated PLC and controller behind a simulated station's lift and wrench."""
    lift, wrench = st.lift, st.wrench
    if not isinstance(lift, SimLift) or not isinstance(wrench, SimWrench):
        raise RuntimeError("the simulated operator needs the simulated lift and controller")
    return lift.plc, wrench.controller


async def _operator(st: Station, world: World, rng: np.random.Generator, cycles: int,
                    report: list[dict[str, Any]], say: Any, truth: dict[str, Any],
                    nok_rng: np.random.Generator) -> None:
    plc, ctl = simulators(st)
    plc.set_vehicle(truth["model_code"], truth["vin"])
    plc.raise_lift()
    for _ in range(200):
        if st.vin is not None and st.core.model is not None:
            break
        await asyncio.sleep(0.05)
    else:
        raise InputError(f"the simulated vehicle was not opened: {st.core.reason}")
    length = st.cfg.tool.length_mm
    bolts: list[BoltInfo] = []
    unseen: list[BoltInfo] = []
    assert st.repo is not None and st.core.model is not None  # noqa: S101 - opened above
    infos = st.repo.bolts_for_model(st.core.model)   # the simulation's truth, from the table
    for b in infos:   # a bolt no pair sees cannot be demonstrated: say so
        pairs = world.seen_by(wrench_at(np.array(b.position), np.random.default_rng(0), length,
                                       max_tilt_deg=0.0))
        (bolts if pairs else unseen).append(b)
    if not bolts:
        raise InputError(f"no bolt of the vehicle (lift code {truth['model_code']}) is in view "
                         "of any pair of this station (check the pairs' to_vehicle transforms "
                         "and the bolt positions)")
    if unseen:
        print(f"note: {len(unseen)} of {len(infos)} bolts are in view of no pair and are "
              f"left out: {', '.join(b.bolt_id for b in unseen[:8])}"
              f"{' ...' if len(unseen) > 8 else ''}", file=sys.stderr, flush=True)
    order = rng.permutation(len(bolts))[:cycles]
    truth["cycles"] = len(order)      # fewer when fewer bolts can be shown
    for k in order:
        b = bolts[int(k)]
        target = np.array(b.position)
        if rng.random() < 0.2:  # hovers between two bolts first: nothing may be sent
            other = np.array(bolts[int(rng.integers(len(bolts)))].position)
            truth["bolt"] = None
            world.set_wrench(wrench_at(0.5 * (target + other), rng, length))
            await asyncio.sleep(0.6)
        pose = wrench_at(target + np.append(rng.normal(0, 0.3, 2), 0.0), rng, length)
        truth["bolt"] = b.bolt_id
        world.set_wrench(pose)
        leave = rng.random() < 0.1
        line: dict[str, Any] = {"bolt": b.bolt_id, "pset": b.parameters.pset, "result": None}
        if not await _tool_on(st, b.bolt_id):
            line["result"] = f"not selected ({_why_not(st)})"
        if st.last is not None and st.last.point_mm is not None:
            line["xy_error_mm"] = float(np.hypot(*(st.last.point_mm - pose.socket_v)[:2]))
        if line["result"] is None and leave:
            truth["bolt"] = None
            world.set_wrench(None)  # leaves before tightening: the tool must go off
            for _ in range(100):
                if not ctl.tool_enabled:
                    break
                await asyncio.sleep(0.05)
            line["result"] = "left before tightening; tool " + \
                ("disabled" if not ctl.tool_enabled else "STILL ENABLED")
        elif line["result"] is None:
            await _until_ok(st, b.bolt_id, line, nok_rng, truth["vin"])
        report.append(line)
        say(line)
        truth["bolt"] = None
        world.set_wrench(None)
        await asyncio.sleep(0.3)
    plc.lower_lift()
    await asyncio.sleep(0.5)


async def _tool_on(st: Station, bolt: str, tries: int = 600) -> bool:
    """Whether the tool comes on for ``bolt`` (up to ~30 s for selection, acknowledgement,
    confirmation)."""
    for _ in range(tries):
        if st.cycle.state is State.TIGHTENING and st.cycle.bolt == bolt \
                and simulators(st)[1].tool_enabled:
            return True
        await asyncio.sleep(0.05)
    return False


def _why_not(st: Station) -> str:
    """Why nothing was selected: the last localization's refusal, else the state's words."""
    seen = [e for e in st.bus.of(Localized) if isinstance(e, Localized)]
    last = seen[-1].reason if seen else None
    return reason_words(last) if last is not None else st.core.reason


async def _pull(st: Station, loosening: bool, nok: bool) -> tuple[Any, bool]:
    """The trigger pulled with the tool on: a loosening (it comes loose) or a tightening (NOK
    when ``nok``); the controller's result and whether the station recorded it."""
    ctl = simulators(st)[1]
    n_records = st.bus.count(ResultRecorded)
    ctl.nok_rate = 1.0 if nok and not loosening else 0.0
    shot = ctl.pull_trigger(result_type=2 if loosening else 1)
    for _ in range(100):
        if st.bus.count(ResultRecorded) > n_records:
            return shot, True
        await asyncio.sleep(0.05)
    return shot, False


async def _until_ok(st: Station, bolt: str, line: dict[str, Any],
                    nok_rng: np.random.Generator, vin: str) -> None:
    """The operator on ``bolt`` with the tool on, as the NOK policy has it: pull; after a NOK
    again (its loosen pset first where the policy says so); a locked bolt is released by the
    supervisor through the command path; until an OK tightening or :data:`MAX_RUNDOWNS`.
    ``line`` gets the last step as its ``result``, the earlier ones as ``before``, ``ok``
    and ``rundowns`` (the results the station must record)."""
    stubborn = nok_rng.random() < STUBBORN_P
    steps: list[str] = []
    line["rundowns"] = 0
    for _ in range(MAX_RUNDOWNS):
        sel = st.core.selection
        loosening = sel is not None and sel.loosen
        shot, _ = await _pull(st, loosening, stubborn or nok_rng.random() < NOK_P)
        if shot is None:
            steps.append("no result")
            line["unfinished"] = True
            break
        line["rundowns"] += 1
        word = "OK" if shot.ok else "NOK"
        steps.append(f"loosened (pset {shot.pset}) {word}" if loosening else
                     f"{word} {shot.torque_nm:.1f} Nm")
        if shot.ok and not loosening:
            break
        matcher = st.core.matcher
        if matcher is not None and bolt in matcher.locked:
            answer = await st.submit(ReleaseBolt(vin, bolt, "demo: joint checked"),
                                     SUPERVISOR)
            steps.append("locked, released by the supervisor" if answer.accepted else
                         f"locked, release refused ({answer.reason})")
            stubborn = False    # the supervisor had the thread seen to
        if not await _tool_on(st, bolt):
            steps.append(f"not selected again ({_why_not(st)})")
            line["unfinished"] = True
            break
    line["ok"] = bool(steps) and steps[-1].startswith("OK")
    line["result"], line["before"] = steps[-1], steps[:-1]


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
            await _operator(station, world, rng, cycles, report, say, truth, nok_rng)
            stop.set()
            await task
            if getattr(args, "hold", False) and screens.server is not None:
                await _hold(screens.server.url, report, int(truth.get("cycles", cycles)),
                            truth, args.json)
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
    """``--hold``: the run is over (station stopped, results recorded); the screens keep
    serving its results from the run's temporary database until SIGINT or SIGTERM, so they
    can be browsed (and exported) before the demo's folder is removed."""
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


def stand_ins(cfg: StationConfig) -> list[str]:
    """The real devices a station file names ("lift modbus-tcp://..."), which the demo
    replaces by its simulators; none for a simulated station's file.

    Why it runs rather than refuses: a commissioning engineer runs the demo on the station's
    own file to try its geometry (calibrations, registrations, bolt table) before the devices
    answer; what must never happen is a PASS that reads as if the lift, the controller and
    the cameras had been tried.  So the demo says, at its start and in its summary, that its
    simulators stood in for them and that its records went to a temporary database."""
    real = [f"camera {name} {url}" for name, url in cfg.cameras.items() if not _sim(url)]
    real += [f"{what} {url}" for what, url in (("lift", cfg.lift.url),
                                                ("wrench", cfg.wrench.url)) if not _sim(url)]
    return real


def _sim(url: str) -> bool:
    scheme = url.split("://", 1)[0].lower()
    return scheme == "sim" or scheme.startswith("sim+")


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
