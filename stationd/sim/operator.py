"""The simulated operator: signs in at the station (so every rundown is recorded with their
name), raises the lift with a vehicle, takes the wrench to its bolts and tightens them as the
station's NOK policy has it; a simulated supervisor releases a locked bolt through the command
path the screens use (``Station.submit``).  Without one (``supervisor=None``: ``stationd demo
--no-sim-supervisor``, ``stationd run --sim-operator --no-sim-supervisor``) every supervisor
decision is left to people: the first bolt of each vehicle is a stubborn joint, so a lock is
met; the locked (or held) bolt waits, the operator tightens the other bolts, then waits with the
vehicle on the lift until a person releases it (the screens' Release form, ``stationd
release``) and tightens it.  The lift goes down only when no bolt of the vehicle is locked or
held: one held after the operator went on (its push lost, found by the next result; a result
fetched after a reload) is released (by the simulated supervisor, else by a person) and
tightened again first.  Why: training and commissioning need the Locked panel and a
person's release, which a simulated supervisor answering within a second never let anyone see.

Why here, below the demo: one operator for ``stationd demo`` (a vehicle, then a verdict) and
for ``stationd run --sim-operator`` (vehicle after vehicle in the daemon, :mod:`stationd.sim.
daemon`): the two exercise the same rounds, so what the demo passes the daemon shows.
"""

from __future__ import annotations

import asyncio
import shlex
import signal
import sys
import threading
from collections.abc import Callable, Collection, Iterator, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from db.kinds import LOOSENED, NOK, TO_LOOSEN
from db.repository import BoltInfo
from drivers.counting import counted
from drivers.devices import Kind, simulated
from drivers.lift.sim import SimLift, SimulatedPlc
from drivers.wrench.base import ResultKind, ResultType, Status, result_kind
from drivers.wrench.sim.controller import SimController, SimTightening, SimWrench
from stationd.config import StationConfig
from stationd.errors import InputError
from stationd.shell.daemon import Station
from stationd.sim.devices_cli import LOOSEN_PROGRAM, loosen_programs
from stationd.sim.world import World, wrench_at
from stationd.station.commands import Issuer, ReleaseBolt, Right, SignIn
from stationd.station.events import BoltReleased, BoltSkipped, Localized, ResultRecorded, State
from stationd.station.state import CoreStatus
from stationd.words import reason_words, result_type_words, skip_words, state_words

#: a tightening fails now and then; a stubborn joint (a damaged thread) fails until its bolt
#: locks and the supervisor released it; a loosening always comes loose
NOK_P, STUBBORN_P = 0.1, 0.1
#: rundowns the simulated operator makes on one bolt before giving up on it
MAX_RUNDOWNS = 10
#: a bolt open again after a person's command is tightened again at most this often in a round
MAX_AGAIN = 3
#: who releases a locked bolt (the command path is the screens')
SUPERVISOR = Issuer("supervisor", frozenset({Right.RELEASE}), "demo")
#: who holds the wrench: signed in at the station through the command path (no right needed)
OPERATOR = Issuer("operator", frozenset(), "demo")


def stand_ins(cfg: StationConfig) -> list[str]:
    """The real devices a station file names ("lift modbus-tcp://..."); none for a simulated
    station's file.  The demo runs its simulators instead of them (and says so); ``stationd run
    --sim-operator`` refuses such a station (its operator would drive real devices).  Which
    devices are simulated twins is their drivers' to say (``drivers.devices.simulated``)."""
    real = [f"camera {name} {url}" for name, url in cfg.cameras.items()
            if not simulated(Kind.CAMERA, url)]
    real += [f"{kind} {url}" for kind, url in ((Kind.LIFT, cfg.lift.url),
                                                (Kind.WRENCH, cfg.wrench.url))
             if not simulated(kind, url)]
    return real


def undriven(cfg: StationConfig) -> list[str]:
    """The simulated devices the scripted operator cannot drive ("wrench sim+modbus://..."):
    it raises the simulated PLC's lift and pulls the simulated Open Protocol controller's
    trigger in this process (``sim://lift``, ``sim://wrench``: :func:`simulators`); another
    twin (``sim+modbus://wrench``, a register-driven controller) it cannot reach.  Asked at
    the start (a technician's trial: the daemon started, then its operator failed every 3 s
    for good)."""
    return [f"{kind} {url}" for kind, url in ((Kind.LIFT, cfg.lift.url),
                                              (Kind.WRENCH, cfg.wrench.url))
            if simulated(kind, url) and urlsplit(str(url)).scheme != "sim"]


def releasers(cfg: StationConfig) -> list[str]:
    """The station file's users whose role has the release right (who can release a lock)."""
    return cfg.access.users_with(Right.RELEASE)


def supervisor_of(cfg: StationConfig, source: str) -> Issuer:
    """Whom the simulated supervisor releases locks as: the first user (by name) of the
    station file whose role has the release right, with that role's rights; where none has,
    the simulator's own ``supervisor``.  Why: releases were recorded by ``supervisor``, no
    user of a file that names its supervisors (a new user's trial), where the operator
    already signs in as the file's own operator."""
    names = releasers(cfg)
    if not names:
        return Issuer(SUPERVISOR.user, SUPERVISOR.rights, source)
    role = cfg.access.users[names[0]].role
    return Issuer(names[0], cfg.access.roles.get(role, frozenset()), source)


def check_people(cfg: StationConfig) -> None:
    """``--no-sim-supervisor`` (``stationd demo``, ``stationd run --sim-operator``) leaves each
    lock to a person's release: the station file needs a user whose role has the release
    right.  Why: on config/sim (no ``access:``) the operator waited for a release through
    ``stationd release`` or the screens' Release form, where every login was refused ("no
    users are configured"), until Ctrl-C; one check for both commands, said at the start."""
    if not releasers(cfg):
        raise InputError(f"--no-sim-supervisor needs access.users in {cfg.path} with a user "
                         "holding the release right (a supervisor), or nobody could release "
                         "a lock: give --config a station file with one (stationd user hash "
                         "makes a password's hash)")


@dataclass(frozen=True)
class Plan:
    """The operator's bolts on a vehicle as the station has it now: those to go to, in the
    plan's order; those locked or held, left for a person's release (tightened once
    released); those done or skipped already, left out."""

    visit: tuple[str, ...]
    waiting: tuple[str, ...]
    finished: tuple[str, ...]


def plan_of(planned: Sequence[str], finished: Collection[str],
            stopped_now: Collection[str]) -> Plan:
    """The vehicle's ``planned`` bolts (the operator's order) against what the station says:
    ``finished`` (done or skipped) and ``stopped_now`` (locked or held).  Why from the station
    and not from the operator's memory: a reload starts a new round of the operator on the
    same vehicle, and the round's own list started again: it hovered half a minute on each
    bolt already done ("not selected: already done") and went past a lock it had been
    waiting on.  The station (its database, reopened by the new station) is what a person
    reads too."""
    visit = tuple(b for b in planned if b not in finished and b not in stopped_now)
    waiting = tuple(b for b in planned if b in stopped_now and b not in finished)
    return Plan(visit, waiting, tuple(b for b in planned if b in finished))


def _stderr(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def simulators(st: Station) -> tuple[SimulatedPlc, SimController]:
    """The simulated PLC and controller behind a simulated station's lift and wrench."""
    lift, wrench = st.lift, st.wrench
    if not isinstance(lift, SimLift) or not isinstance(wrench, SimWrench):
        raise RuntimeError("the simulated operator needs the simulated lift and controller")
    return lift.plc, wrench.controller


async def operate(st: Station, world: World, rng: np.random.Generator, cycles: int,
                  report: list[dict[str, Any]], say: Callable[[dict[str, Any]], None],
                  truth: dict[str, Any], nok_rng: np.random.Generator,
                  note: Callable[[str], None] | None = None,
                  supervisor: Issuer | None = SUPERVISOR, operator: Issuer | None = OPERATOR,
                  share: tuple[int, int] = (1, 1), interruptible: bool = False) -> None:
    """One vehicle: ``truth['vin']`` (lift code ``truth['model_code']``) raised, up to
    ``cycles`` of its bolts in view visited in the ``rng``'s order (each line to ``say`` and
    ``report``), tightened as the NOK policy has it (:func:`until_ok`), the lift lowered.
    ``truth['bolt']`` is where the wrench really is, at every moment (the demo checks each
    parameter send against it).  InputError when the vehicle is not opened or no bolt of it
    is in view.  ``truth['plan']``: the bolts planned for this vehicle, in order (drawn from
    the ``rng`` when absent, and set); the bolts the station says are done or skipped are
    left out and those it says are locked wait for a release (:func:`plan_of`): a round on a
    vehicle that stays across a reload goes on where the last one was.  ``operator`` signs
    in at the station first unless someone is signed in (a person who signed in at the
    screens stays signed in, across a reload too: the rundowns are theirs); None: nobody
    signs in, and on a station that requires sign-in the operator waits, the vehicle on the
    lift, until a person has signed in.
    ``share`` (k, n): this station is the k-th of a line of n, and its bolts are the k-th of
    n shares of the bolts in view (:func:`share_of`); ``truth['share']`` gets them.
    ``supervisor`` None: locks are left to people (:func:`wait_for_people`);
    ``interruptible``: Ctrl-C or SIGTERM during that wait ends it (the demo's, a command's:
    not the daemon's, which stops in order): the bolts left locked are said as such
    (``unfinished``), the vehicle lowered, and ``truth['interrupted']`` names the signal and
    the bolts."""
    r = _Round(st, world, rng, nok_rng, truth, report, say, note, supervisor, interruptible)
    await r.arrive(operator)
    bolts, infos = r.bolts_in_view(share)
    r.by_id = {b.bolt_id: b for b in bolts}
    if truth.get("plan") is None:
        truth["plan"] = [bolts[int(k)].bolt_id for k in rng.permutation(len(bolts))[:cycles]]
    planned = [bolt for bolt in truth["plan"] if bolt in r.by_id]
    truth["cycles"] = len(planned)      # fewer when fewer bolts can be shown
    now = st.core.status()
    plan = plan_of(planned, now.done | now.skipped, now.locked | now.held)
    if plan.finished:
        r.tell_note(f"{truth['vin']}: {', '.join(plan.finished)} done already (the station "
                    f"says so): the operator goes on with "
                    f"{', '.join([*plan.visit, *plan.waiting]) or 'none'}")
    # the plan's first bolt is the stubborn joint that locks for people (once released, it
    # has been seen to)
    r.stubborn = planned[0] if supervisor is None and planned else None
    waiting = r.left_to_people(plan.waiting) if supervisor is None else {}
    for bolt_id in plan.visit if supervisor is None else \
            [b for b in planned if b in plan.visit or b in plan.waiting]:
        await r.visit(r.by_id[bolt_id], bolts, waiting)
    for bolt_id, (b, line) in waiting.items():
        # held (its result not known) or locked (its NOKs), as the station has it (a new
        # user's trial: a held bolt's line said "locked, released by sam")
        await r.for_people(bolt_id, b, line,
                           "held" if bolt_id in r.st.core.status().held else "locked")
        r.tell(line)
        await r.away()
    # the lift goes down only when no bolt of the vehicle waits for a supervisor (README:
    # the vehicle waits on the lift for the release): a bolt held after its visit (its push
    # lost, found when the next result skipped its id; a result fetched after a reload), or
    # locked or held and in no wait above, was gone past and the lift lowered under it (a
    # supervisor's trial).  Released (by the simulated supervisor, else by a person), it is
    # tightened again; its line goes on from the one said
    released: dict[str, int] = {}
    # the bolts that waited for a person this round, planned or not: one locked before a
    # restart (the new process's plan is drawn anew) and released while the operator was at
    # other bolts is open again all the same (a supervisor's trial: never tightened again,
    # the vehicle closed with it ending NOK)
    waited = left_over(now, [b.bolt_id for b in bolts])
    while "interrupted" not in truth:
        again = open_again(st, [*planned, *(b for b in waited if b not in planned)])
        if late := waiting_now(st, infos):
            waited += [b for b in late if b not in waited and b in r.by_id]
            released[late[0]] = released.get(late[0], 0) + 1
            await r.late(late[0], released[late[0]])
        elif again and released.get(again[0], 0) < MAX_AGAIN:
            # released or entered by a person meanwhile, still to be run down (its result
            # not known, its last rundown a NOK, to be loosened): tightened before the lift
            # goes down (a new user's trial: a hold released while the operator waited on
            # another bolt, an entered NOK, were left and the vehicle closed with them)
            released[again[0]] = released.get(again[0], 0) + 1
            await r.again(again[0])
        else:
            break
    r.plc.lower_lift()
    await asyncio.sleep(0.5)


class _Round:
    """One vehicle's round of :func:`operate`: what its steps share (the station, the
    world, the draws, what is said), each step a method of its own."""

    def __init__(self, st: Station, world: World, rng: np.random.Generator,
                 nok_rng: np.random.Generator, truth: dict[str, Any],
                 report: list[dict[str, Any]], say: Callable[[dict[str, Any]], None],
                 note: Callable[[str], None] | None, supervisor: Issuer | None,
                 interruptible: bool) -> None:
        self.st, self.world, self.rng, self.nok_rng = st, world, rng, nok_rng
        self.truth, self.report, self.say, self.note = truth, report, say, note
        self.tell_note: Callable[[str], None] = note or _stderr
        self.supervisor, self.interruptible = supervisor, interruptible
        self.plc, self.ctl = simulators(st)
        self.length = st.cfg.tool.length_mm
        self.by_id: dict[str, BoltInfo] = {}
        self.stubborn: str | None = None
        self.said: dict[str, dict[str, Any]] = {}    # the bolts' lines said in this round

    async def arrive(self, operator: Issuer | None) -> None:
        """The operator signs in (unless someone is), the vehicle raised and opened; on a
        station that requires sign-in without a simulated operator, a person signs in."""
        st, truth = self.st, self.truth
        if operator is not None and st.core.status().operator is None:
            answer = await st.submit(SignIn(f"{operator.source}: the simulated operator"),
                                     operator)
            if not answer.accepted:
                self.tell_note(f"note: the simulated operator did not sign in: "
                               f"{reason_words(answer.reason) if answer.reason else '?'}")
        self.plc.set_vehicle(truth["model_code"], truth["vin"])
        self.plc.raise_lift()
        for _ in range(200):
            if st.vin is not None and st.core.status().model is not None:
                break
            await asyncio.sleep(0.05)
        else:
            raise InputError("the simulated vehicle was not opened: "
                             f"{state_words(st.core.status().reason)}")
        while operator is None and st.cfg.access.operator_required \
                and st.core.status().operator is None:   # a person signs in (told once before)
            await asyncio.sleep(0.2)

    def bolts_in_view(self, share: tuple[int, int]) -> tuple[list[BoltInfo], list[BoltInfo]]:
        """The vehicle's bolts some pair sees (of this station's ``share`` of a line; said
        where some are left out), and all of them."""
        st, truth = self.st, self.truth
        bolts: list[BoltInfo] = []
        unseen: list[BoltInfo] = []
        model = st.core.status().model
        assert st.repo is not None and model is not None  # noqa: S101 - opened before
        infos = st.repo.bolts_for_model(model)   # the simulation's truth, from the table
        for b in infos:   # a bolt no pair sees cannot be demonstrated: say so
            pairs = self.world.seen_by(wrench_at(np.array(b.position), np.random.default_rng(0),
                                                 self.length, max_tilt_deg=0.0))
            (bolts if pairs else unseen).append(b)
        if not bolts:
            raise InputError(f"no bolt of the vehicle (lift code {truth['model_code']}) is in "
                             "view of any pair of this station (check the pairs' to_vehicle "
                             "transforms and the bolt positions)")
        if unseen:
            self.tell_note(f"note: {len(unseen)} of {len(infos)} bolts are in view of no pair "
                           f"and are left out: {', '.join(b.bolt_id for b in unseen[:8])}"
                           f"{' ...' if len(unseen) > 8 else ''}")
        if share != (1, 1):
            mine = share_of([b.bolt_id for b in bolts], *share)
            if not mine:
                raise InputError(f"station {share[0]} of {share[1]} has no bolt of its own: "
                                 f"{counted(len(bolts), 'bolt')} in view for {share[1]} "
                                 "stations")
            # said after the station's id ("DEMO-1 tightens its own bolts, 25 of the 50 in
            # view: ..."; it read "DEMO-1 its own bolts: 25 of the 50")
            self.tell_note(f"{'' if self.note else 'this station '}tightens its own bolts, "
                           f"{len(mine)} of the {len(bolts)} in view: "
                           f"{', '.join(mine[:12])}{' ...' if len(mine) > 12 else ''}")
            bolts = [b for b in bolts if b.bolt_id in mine]
        truth["share"] = [b.bolt_id for b in bolts]
        return bolts, infos

    def left_to_people(self, bolts: Sequence[str]
                       ) -> dict[str, tuple[BoltInfo, dict[str, Any]]]:
        """The ``bolts`` locked before this round, left to people: their lines, waiting.  A
        bolt locked before a reload: its NOKs were the last round's, said in its line all
        the same (its line began with the release, the NOKs that locked it left out)."""
        assert self.st.repo is not None  # noqa: S101 - opened before
        streaks = self.st.repo.nok_streaks(self.truth["vin"]) if bolts else {}
        return {bolt: (self.by_id[bolt], {
            "bolt": bolt, "pset": self.by_id[bolt].parameters.pset, "result": LEFT_FOR_PEOPLE,
            "waits": True, "rundowns": 0, "before": noks_before(streaks.get(bolt, 0))})
            for bolt in bolts}

    async def visit(self, b: BoltInfo, bolts: list[BoltInfo],
                    waiting: dict[str, tuple[BoltInfo, dict[str, Any]]]) -> None:
        """The wrench to ``b`` (now and then hovering between two bolts first, or leaving
        before tightening), tightened as the NOK policy has it; its line said, or kept in
        ``waiting`` where it waits for a person."""
        st, rng, truth, world = self.st, self.rng, self.truth, self.world
        target = np.array(b.position)
        if rng.random() < 0.2:  # hovers between two bolts first: nothing may be sent
            other = np.array(bolts[int(rng.integers(len(bolts)))].position)
            truth["bolt"] = None
            world.set_wrench(wrench_at(0.5 * (target + other), rng, self.length))
            await asyncio.sleep(0.6)
        pose = wrench_at(target + np.append(rng.normal(0, 0.3, 2), 0.0), rng, self.length)
        truth["bolt"] = b.bolt_id
        world.set_wrench(pose)
        # drawn always (the seed's stream); the bolt that locks for people is never left
        leave = rng.random() < 0.1 and b.bolt_id != self.stubborn
        line: dict[str, Any] = {"bolt": b.bolt_id, "pset": b.parameters.pset, "result": None}
        supervisor = self.supervisor
        if supervisor is not None and stopped(st, b.bolt_id):   # locked before (a reload)
            assert st.repo is not None  # noqa: S101 - opened before
            noks = noks_before(st.repo.nok_streaks(truth["vin"]).get(b.bolt_id, 0))
            what = stopped_words(st, b.bolt_id)
            answer = await st.submit(ReleaseBolt(truth["vin"], b.bolt_id,
                                                 f"{supervisor.source}: joint checked"),
                                     supervisor)
            line["before"] = [*noks, f"{what}, released by the supervisor" if answer.accepted
                              else f"{what}, release refused ({answer.reason})"]
        if not await _tool_on(st, b.bolt_id):
            line["result"] = f"not selected ({_why_not(st)})"
        if st.last is not None and st.last.point_mm is not None:
            line["xy_error_mm"] = float(np.hypot(*(st.last.point_mm - pose.socket_v)[:2]))
        if line["result"] is None and leave:
            truth["bolt"] = None
            world.set_wrench(None)  # leaves before tightening: the tool must go off
            for _ in range(100):
                if not self.ctl.tool_enabled:
                    break
                await asyncio.sleep(0.05)
            line["result"] = "left before tightening; tool " + \
                ("disabled" if not self.ctl.tool_enabled else "STILL ENABLED")
        elif line["result"] is None:
            first = line.pop("before", [])
            await until_ok(st, b.bolt_id, line, self.nok_rng, truth["vin"], supervisor,
                           stubborn=True if b.bolt_id == self.stubborn else None)
            line["before"] = [*first, *line["before"]]
        if line.get("waits"):
            waiting[b.bolt_id] = (b, line)      # its line is said once a person released it
        else:
            self.report.append(line)
            self.said[b.bolt_id] = line
            self.say(line)
        await self.away()

    async def away(self) -> None:
        """The wrench out of view between two bolts."""
        self.truth["bolt"] = None
        self.world.set_wrench(None)
        await asyncio.sleep(0.3)

    def _pose(self, b: BoltInfo) -> Any:
        """The wrench on ``b``, a little off its centre (drawn from the round's stream)."""
        return wrench_at(np.array(b.position) + np.append(self.rng.normal(0, 0.3, 2), 0.0),
                         self.rng, self.length)

    async def for_people(self, bolt_id: str, b: BoltInfo | None, line: dict[str, Any],
                         what: str = "locked") -> None:
        """``bolt_id`` waits for a person's release (``line['waits']``), then is tightened
        again (``b`` None: not a bolt of the operator's, left as released; ``what``: why it
        waits, "locked" or "held")."""
        st, truth = self.st, self.truth
        while line.get("waits") and "interrupted" not in truth:
            try:
                who = await wait_for_people(st, bolt_id, truth["vin"], self.tell_note,
                                            self.interruptible, truth.get("screens"))
            except WaitEnded as ended:
                truth["interrupted"] = {"signal": ended.signal, "bolts": []}
                break
            skip = _skipped_by(st, bolt_id)
            if skip is not None:     # skipped by a person who may release: the station's
                line.pop("waits")    # part done (locked, then a person's decision)
                line["before"] = [*line.get("before", []), "locked"]
                line["result"] = f"skipped ({skip})"
                break
            entered = entered_outcomes(st, bolt_id)
            if who is None and entered and bolt_id in st.core.status().done:
                # its outcome entered OK (a held bolt): done, not released (a supervisor's
                # trial: "held, released" in its line, then the done bolt tried again)
                line.pop("waits")
                line["before"] = [*line.get("before", []), what]
                line["result"] = f"OK entered by {entered[-1][0]}"
                line["ok"] = True
                break
            # its history says who released it, not that it was left to people
            before = [*line.get("before", []), released_words(who, what)
                      if line["result"] == LEFT_FOR_PEOPLE else line["result"]]
            line.pop("waits")
            if b is None:
                line["before"], line["result"] = before, "not a bolt the operator tightens"
                break
            rundowns = int(line.get("rundowns", 0))
            pose = self._pose(b)
            truth["bolt"] = bolt_id
            self.world.set_wrench(pose)
            if not await _tool_on(st, bolt_id):
                line["result"] = f"not selected after the release ({_why_not(st)})"
                line["before"], line["unfinished"] = before, True
            else:   # a person had the joint seen to: it is no longer stubborn
                await until_ok(st, bolt_id, line, self.nok_rng, truth["vin"], None,
                               stubborn=False)
                line["before"] = [*before, *line["before"]]
                line["rundowns"] = rundowns + int(line["rundowns"])
        if line.get("waits"):   # the wait ended by a signal: still locked, not released
            line.pop("waits")
            line["result"] = (f"locked, not released: the wait for a person's release ended "
                              f"by {ended_words(truth)}")
            line["unfinished"] = True
            truth["interrupted"]["bolts"].append(bolt_id)

    def tell(self, line: dict[str, Any]) -> None:
        """``line`` said (added to the report once)."""
        if line["bolt"] not in self.said:
            self.said[line["bolt"]] = line
            self.report.append(line)
        self.say(line)

    async def again(self, bolt_id: str) -> None:
        """``bolt_id`` open again after a person's release or entered outcome (its result not
        known, or a NOK): tightened as the NOK policy has it; its line goes on from the one
        said."""
        info = self.by_id[bolt_id]
        released = any(v.bolt == bolt_id and v.check_first
                       for v in self.st.core.status().bolts)
        what = "released from a hold" if released else "open again after a person's command"
        line: dict[str, Any] = {"bolt": bolt_id, "pset": info.parameters.pset,
                                "result": "", "rundowns": 0, "before": [what]}
        await self._tighten_again(info, line, "again")
        self._said_on(bolt_id, line)
        await self.away()

    async def _tighten_again(self, info: BoltInfo, line: dict[str, Any], when: str) -> None:
        """The wrench back on ``info``'s bolt, tightened as the NOK policy has it, its steps
        after ``line``'s; not selected (``when``: after what): said, unfinished."""
        bolt_id = info.bolt_id
        self.truth["bolt"] = bolt_id
        self.world.set_wrench(self._pose(info))
        if not await _tool_on(self.st, bolt_id):
            line["result"] = f"not selected {when} ({_why_not(self.st)})"
            line["unfinished"] = True
            return
        first = line["before"]
        await until_ok(self.st, bolt_id, line, self.nok_rng, self.truth["vin"],
                       self.supervisor, stubborn=False)
        line["before"] = [*first, *line["before"]]

    def _said_on(self, bolt_id: str, line: dict[str, Any]) -> None:
        """``line`` said, going on from ``bolt_id``'s line said before (its steps, its
        rundowns added)."""
        before = self.said.get(bolt_id)
        if before is not None:      # its line as said, then what came after
            line["before"] = [*before.get("before", []), before["result"], *line["before"]]
            line["rundowns"] = int(before.get("rundowns", 0)) + int(line["rundowns"])
            kept = {k: before[k] for k in ("xy_error_mm",) if k in before}
            before.clear()
            before.update(line, **kept)
            line = before
        self.tell(line)

    async def late(self, bolt_id: str, times: int) -> None:
        """``bolt_id`` locked or held after its visit (``times`` so far in this round):
        released by the simulated supervisor (up to MAX_RUNDOWNS times) and tightened
        again, else left to people; its line goes on from the one said."""
        st, truth, supervisor = self.st, self.truth, self.supervisor
        info = self.by_id.get(bolt_id)
        now = st.core.status()
        what = "held" if bolt_id in now.held else "locked"
        line: dict[str, Any] = {
            "bolt": bolt_id, "pset": None if info is None else info.parameters.pset,
            "result": LEFT_FOR_PEOPLE, "waits": True, "rundowns": 0,
            "before": [f"{what} after its visit" if bolt_id in self.said else what]}
        if supervisor is not None and times <= MAX_RUNDOWNS:
            answer = await st.submit(ReleaseBolt(truth["vin"], bolt_id,
                                                 f"{supervisor.source}: joint checked"),
                                     supervisor)
            if answer.accepted:
                line["before"].append("released by the supervisor")
                line.pop("waits")
                if info is None:
                    line["result"] = "not a bolt the operator tightens"
                else:
                    await self._tighten_again(info, line, "after the release")
            else:
                line["before"].append(f"release refused ({answer.reason})")
        await self.for_people(bolt_id, info, line, what)   # nothing to wait for where released
        self._said_on(bolt_id, line)
        await self.away()


def share_of(bolts: list[str], k: int, n: int) -> list[str]:
    """The k-th (1-based) of ``n`` shares of ``bolts``: consecutive runs of the table's
    order, as a line's stations each have their own section of the vehicle, sizes differing
    by at most one; no bolt is in two shares."""
    base, extra = divmod(len(bolts), n)
    start = (k - 1) * base + min(k - 1, extra)
    return bolts[start:start + base + (1 if k <= extra else 0)]


async def _tool_on(st: Station, bolt: str, tries: int = 600) -> bool:
    """Whether the tool comes on for ``bolt`` (up to ~30 s for selection, acknowledgement,
    confirmation)."""
    for _ in range(tries):
        if st.core.status().state is State.TIGHTENING and st.core.status().bolt == bolt \
                and simulators(st)[1].tool_enabled:
            return True
        await asyncio.sleep(0.05)
    return False


def _why_not(st: Station, window_s: float = 30.0) -> str:
    """Why nothing was selected: the last localization's refusal, else the state's words with
    how many localizations came in the operator's wait ("tracking the wrench" alone left a
    loaded machine's few frames unsaid: a line engineer's trial)."""
    seen = [e for e in st.bus.of(Localized) if isinstance(e, Localized)]
    last = seen[-1].reason if seen else None
    if last is not None:
        return reason_words(last)
    recent = sum(1 for e in seen if e.t >= seen[-1].t - window_s) if seen else 0
    return (f"{state_words(st.core.status().reason)}; {recent} localizations in the last "
            f"{window_s:g} s, the last without a refusal: a machine too busy for the frames "
            "a selection needs?")


async def _pull(st: Station, loosening: bool, nok: bool) -> tuple[Any, bool]:
    """The trigger pulled with the tool on: a loosening (it comes loose) or a tightening (NOK
    when ``nok``); the controller's result and whether the station recorded it."""
    ctl = simulators(st)[1]
    n_records = st.bus.count(ResultRecorded)
    ctl.nok_rate = 1.0 if nok and not loosening else 0.0
    # a tightening as the controller's schedule makes it (its troubles, where its URL asks
    # for some: other result types, bodies that do not read, pushes lost)
    shot = ctl.pull_trigger(result_type=2 if loosening else None)
    for _ in range(100):
        if st.bus.count(ResultRecorded) > n_records:
            return shot, True
        await asyncio.sleep(0.05)
    return shot, False


def shot_words(shot: SimTightening) -> str:
    """A result in the demo's words: a tightening "OK 25.3 Nm, 31 deg"; a NOK names every
    quantity that failed with the limit it crossed ("NOK: angle 94 deg > 90 max; torque 50.1
    Nm").  Why: the line showed the torque alone, so an angle NOK read as a NOK at a good
    torque.  A result that is no tightening says its type: a loosening "loosening OK 36.0 Nm,
    446 deg", a controller event "batch increment (result type 3): no rundown" (it read "OK
    0.0 Nm, 0 deg", as if a bolt were tightened: a supervisor's trial), a type the
    specification does not name by its code before its values."""
    code = shot.record.result_type if shot.record is not None else ResultType.TIGHTENING
    kind = result_kind(code)
    if kind is ResultKind.TIGHTENING:
        return _rundown_words(shot)
    if kind is ResultKind.EVENT:
        return f"{result_type_words(code)} (result type {code}): no rundown"
    return f"{result_type_words(code)}{':' if kind is ResultKind.UNKNOWN else ''} " \
        + _rundown_words(shot)


def _rundown_words(shot: SimTightening) -> str:
    """A rundown's result and values (:func:`shot_words`)."""
    rec = shot.record
    torque, angle = f"torque {shot.torque_nm:.1f} Nm", f"angle {shot.angle_deg:.0f} deg"
    if shot.ok:
        return f"OK {shot.torque_nm:.1f} Nm, {shot.angle_deg:.0f} deg"
    failed, passed = [], []
    for words, status, lo, hi, fmt in (
            (torque, shot.torque_status, None if rec is None else rec.torque_min / 100,
             None if rec is None else rec.torque_max / 100, ".1f"),
            (angle, shot.angle_status, None if rec is None else rec.angle_min,
             None if rec is None else rec.angle_max, ".0f")):
        if status == Status.LOW:
            failed.append(words + ("" if lo is None else f" < {lo:{fmt}} min"))
        elif status == Status.HIGH:
            failed.append(words + ("" if hi is None else f" > {hi:{fmt}} max"))
        else:
            passed.append(words)
    if not failed:     # the controller said NOK with both within limits
        failed.append("the controller's verdict")
    return f"NOK: {'; '.join(failed)}" + (f" ({', '.join(passed)} within limits)"
                                           if passed else "")


def stopped(st: Station, bolt: str) -> bool:
    """Whether ``bolt`` waits for a supervisor: locked after NOKs in a row, or held (its
    result could not be read)."""
    now = st.core.status()
    return bolt in now.locked or bolt in now.held


def stopped_words(st: Station, bolt: str) -> str:
    """What ``bolt`` waits for a supervisor as: "held" (its result not known), else
    "locked" (a quality trial: a held bolt's line said "locked, released by the
    supervisor", and the records had no lock)."""
    return "held" if bolt in st.core.status().held else "locked"


#: a bolt's step while it waits for a person's release (``until_ok``), and once released
LEFT_FOR_PEOPLE = "locked: left for a person's release"


def noks_before(n: int) -> list[str]:
    """A bolt's NOKs in a row from before a reload, as its line's first step."""
    return [f"{n} NOK before the reload"] if n else []


def waiting_now(st: Station, infos: Sequence[BoltInfo]) -> list[str]:
    """The vehicle's bolts waiting for a supervisor now (locked after NOKs in a row, or held:
    their result not known), in the bolt table's order."""
    now = st.core.status()
    return [b.bolt_id for b in infos if b.bolt_id in now.locked or b.bolt_id in now.held]


def open_again(st: Station, planned: Sequence[str]) -> list[str]:
    """The planned bolts the station holds open though the operator went past them: released
    from a hold (their result not known), their last rundown a NOK (an outcome a person
    entered), to be loosened first or loosened last; neither locked nor held (those wait for
    a person: :func:`waiting_now`), in the plan's order."""
    return open_in(st.core.status(), planned)


def open_in(now: CoreStatus, bolts: Sequence[str]) -> list[str]:
    """:func:`open_again` of the station's status ``now``, of ``bolts``."""
    views = {v.bolt: v for v in now.bolts}
    return [b for b in bolts if (v := views.get(b)) is not None and v.locked is None
            and v.held is None and (v.check_first or v.status in (NOK, TO_LOOSEN, LOOSENED))]


def left_over(now: CoreStatus, in_view: Sequence[str]) -> list[str]:
    """The bolts of ``in_view`` a round finds waiting for a person (locked, held) or open
    again (:func:`open_in`) as it begins: left by the round before a restart, whose new plan
    is drawn anew and may not name them.  Each is run down before the lift goes down (a
    quality trial: B02, released and loosened before a restart, never tightened again, the
    vehicle closed with "1 to tighten again")."""
    waiting = [b for b in in_view if b in now.locked or b in now.held]
    return waiting + [b for b in open_in(now, in_view) if b not in waiting]


def released_words(user: str | None, what: str = "locked") -> str:
    """The step of a bolt a person released: "locked, released by sam" (``what``: "held"
    for a bolt held for its result)."""
    return f"{what}, released" + (f" by {user}" if user else "")


def _releases(st: Station, bolt: str) -> list[str]:
    """Who released ``bolt``, oldest first (the station's BoltReleased events)."""
    return [e.user for e in st.bus.of(BoltReleased) if isinstance(e, BoltReleased)
            and e.bolt == bolt]


def entered_outcomes(st: Station, bolt: str) -> list[tuple[str, bool]]:
    """The outcomes people entered for ``bolt`` (who, OK), oldest first (the station's
    ResultRecorded events of entered results)."""
    return [(e.entered_by, e.ok) for e in st.bus.of(ResultRecorded)
            if isinstance(e, ResultRecorded) and e.bolt == bolt and e.entered_by is not None]


def _skipped_by(st: Station, bolt: str) -> str | None:
    """Why ``bolt`` is skipped, in the station's words (``sam's command (to rework)``), or
    None: not skipped (a person with the release right may skip a locked bolt instead)."""
    if bolt not in st.core.status().skipped:
        return None
    skips = [e.skip for e in st.bus.of(BoltSkipped)
             if isinstance(e, BoltSkipped) and e.bolt == bolt and e.skip is not None]
    return skip_words(skips[-1]) if skips else "skipped"


class WaitEnded(Exception):  # noqa: N818 - a wait ended, not an error
    """A signal (Ctrl-C, SIGTERM) ended the wait for a person's release."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signal = signal.Signals(signum).name


def ended_words(truth: dict[str, Any]) -> str:
    """"Ctrl-C" or "SIGTERM": what ended the people's wait."""
    got = (truth.get("interrupted") or {}).get("signal")
    return "Ctrl-C" if got == "SIGINT" else str(got)


@contextmanager
def _signals_end(ended: asyncio.Event, got: list[int]) -> Iterator[None]:
    """While in the body, SIGINT and SIGTERM set ``ended`` (and are put in ``got``) instead
    of stopping the process; the handlers before are put back after (an ignored signal stays
    ignored).  In the main thread only: signals reach no other."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    loop = asyncio.get_running_loop()

    def on_signal(signum: int, frame: object) -> None:
        got.append(signum)
        loop.call_soon_threadsafe(ended.set)

    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    for s, handler in before.items():
        if handler is not signal.SIG_IGN:
            signal.signal(s, on_signal)
    try:
        yield
    finally:
        for s, handler in before.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)


async def wait_for_people(st: Station, bolt: str, vin: str, note: Callable[[str], None],
                          interruptible: bool = False, url: str | None = None) -> str | None:
    """The operator waits, the vehicle on the lift, until a person releases ``bolt`` (the
    screens' Release form, ``stationd release``): said once, and again when released.  Who
    released it (None: not heard within 2 s of the release).  ``interruptible``: Ctrl-C or
    SIGTERM ends the wait (:class:`WaitEnded`), so the demo can still say what was done.
    ``url``: the screens the station serves: the release command is said with it (without,
    with the station's file: ``stationd release`` alone asks the default station's).
    Why: Ctrl-C there printed "stationd: interrupted (Ctrl-C)" alone, no summary, although
    bolts had been tightened."""
    before, entered_before = len(_releases(st, bolt)), len(entered_outcomes(st, bolt))
    path = getattr(st.cfg, "path", None)   # absolute: pasted in another folder it works
    where = f" --url {url}" if url else \
        f" --config {shlex.quote(str(Path(path).resolve()))}" if path else ""
    # with the reason a release needs (a supervisor's trial: pasted as said, it was refused)
    command = f"stationd release {vin} {bolt}{where} --comment TEXT --user NAME"
    # held (its result not read or not known) or locked (its NOKs): as the station has it
    # (an MES integrator's trial: a held bolt was said locked)
    what = "held" if bolt in st.core.status().held else "locked"
    note(f"{bolt} of {vin} {what}: the operator waits, the vehicle on the lift, for a "
         f"person's release (the screens' Release form, or {command})"
         + ("; Ctrl-C ends the wait and the run" if interruptible else ""))
    ended, got = asyncio.Event(), list[int]()
    with _signals_end(ended, got) if interruptible else nullcontext():
        while stopped(st, bolt):
            if ended.is_set():
                raise WaitEnded(got[0])
            try:
                await asyncio.wait_for(ended.wait(), 0.2)
            except TimeoutError:
                pass
    skip = _skipped_by(st, bolt)
    if skip is not None:    # a person with the release right skipped it instead
        note(f"{bolt} of {vin} skipped ({skip}): the operator leaves it")
        return None
    # the release's event, or the record of an outcome entered (a held bolt), follows the
    # lock's end (the core's act): waited for once, either
    for _ in range(40):
        entered = entered_outcomes(st, bolt)[entered_before:]
        after = _releases(st, bolt)[before:]
        if entered or after:
            break
        await asyncio.sleep(0.05)
    if entered and bolt in st.core.status().done:
        # an OK entered: done, nothing to tighten (a supervisor's trial: said "released",
        # then the operator tried the done bolt for 30 s)
        note(f"{bolt} of {vin}: its outcome entered by {entered[-1][0]} (OK): done, the "
             "operator leaves it")
        return None
    who = after[-1] if after else None
    note(f"{bolt} of {vin} released: the operator tightens it again")
    return who


async def until_ok(st: Station, bolt: str, line: dict[str, Any],
                   nok_rng: np.random.Generator, vin: str,
                   supervisor: Issuer | None = SUPERVISOR, *,
                   stubborn: bool | None = None) -> None:
    """The operator on ``bolt`` with the tool on, as the NOK policy has it: pull; after a NOK
    again (its loosen pset first where the policy says so); a locked bolt is released by the
    supervisor through the command path; until an OK tightening or :data:`MAX_RUNDOWNS`.
    ``line`` gets the last step as its ``result``, the earlier ones as ``before``, ``ok``
    and ``rundowns`` (the results the station must record).  ``supervisor`` None: a locked
    bolt is left for people (``line['waits']``); ``stubborn``: the joint fails until it locks
    (True) or has been seen to (False; None: drawn)."""
    line.pop("waits", None)
    drawn = nok_rng.random() < STUBBORN_P     # drawn always: the seed's stream stays the same
    stubborn = drawn if stubborn is None else stubborn
    steps: list[str] = []
    line["rundowns"] = 0
    for _ in range(MAX_RUNDOWNS):
        loosening = st.core.status().loosen
        shot, _ = await _pull(st, loosening, stubborn or nok_rng.random() < NOK_P)
        if shot is None:
            steps.append("no result")
            line["unfinished"] = True
            break
        line["rundowns"] += 1
        word = "OK" if shot.ok else "NOK"
        steps.append(f"loosened (pset {shot.pset}) {word}" if loosening else
                     shot_words(shot))
        if shot.ok and not loosening:
            break
        if stopped(st, bolt) and supervisor is None:
            steps.append(LEFT_FOR_PEOPLE)
            line["waits"] = True
            break
        if stopped(st, bolt) and supervisor is not None:
            what = stopped_words(st, bolt)
            answer = await st.submit(ReleaseBolt(vin, bolt, f"{supervisor.source}: joint "
                                                 "checked"), supervisor)
            steps.append(f"{what}, released by the supervisor" if answer.accepted else
                         f"{what}, release refused ({answer.reason})")
            stubborn = False    # the supervisor had the thread seen to
        if not await _tool_on(st, bolt):
            steps.append(f"not selected again ({_why_not(st)})")
            line["unfinished"] = True
            break
    line["ok"] = bool(steps) and steps[-1].startswith("OK")
    line["result"], line["before"] = steps[-1], steps[:-1]


__all__ = [
    "LOOSEN_PROGRAM",
    "MAX_RUNDOWNS",
    "NOK_P",
    "OPERATOR",
    "STUBBORN_P",
    "SUPERVISOR",
    "Plan",
    "WaitEnded",
    "ended_words",
    "loosen_programs",
    "operate",
    "plan_of",
    "share_of",
    "shot_words",
    "simulators",
    "stand_ins",
    "stopped",
    "supervisor_of",
    "until_ok",
    "wait_for_people",
    "waiting_now",
]
