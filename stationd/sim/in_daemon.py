"""``stationd run`` on a simulated station: the simulated world inside the daemon.

Why: the ``sim://`` cameras render the world registered in their process
(:func:`drivers.camera.sim.register_world`), so a daemon on ``config/sim`` without one looked
healthy until a vehicle came, then every pair faulted.  With this, ``stationd run --config
config/sim/station.yaml`` serves a station that works without hardware, so the service, the
screens and people's commands can be tried; ``--sim-operator`` adds the demo's operator
(:mod:`stationd.sim.operator`), vehicle after vehicle.

The runtime never imports the simulator (an import-linter contract): ``stationd.cli`` builds a
:class:`SimulatedStation` and hands the serve loop its :meth:`SimulatedStation.beside`, which
the loop runs beside every station it starts (the first and each reload's).  A reload that
changes the geometry (pairs, calibrations, registrations, references, the marker) gets a new
world; the controller gets the bolt table's psets (and the NOK policy's loosen programs).

Without ``--sim-operator`` the operator is idle: the lift stays down, said once in the
journal, and the simulated PLC takes ``stationd sim plc``'s commands (``next``, ``raise``,
``lower``, ``vehicle CODE [VIN]``, ``fault``, ``clear``) on the daemon's standard input.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import pickle
import sys
import threading
import time
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from sqlalchemy.exc import SQLAlchemyError

from db.errors import DbError
from db.repository import Repository
from drivers.counting import counted
from drivers.devices import Kind, simulated
from drivers.lift.base import LiftState
from drivers.lift.sim import SimLift, SimulatedPlc
from drivers.wrench.sim.controller import SimController, SimWrench
from stationd.boltfile import load_bolts
from stationd.config import StationConfig
from stationd.errors import InputError, StationError
from stationd.lock import lock_path
from stationd.shell.daemon import Station
from stationd.sim.devices_cli import HELP, first_serial, plc_command, psets_of
from stationd.sim.operator import (
    check_people,
    loosen_programs,
    operate,
    releasers,
    stand_ins,
    supervisor_of,
    undriven,
)
from stationd.sim.vin import make_vin
from stationd.sim.world import World
from stationd.station.commands import Issuer, Right

log = logging.getLogger("stationd")
#: bolts the scripted operator visits on each vehicle, and the wait between two vehicles, s
BOLTS_PER_VEHICLE, BETWEEN_VEHICLES_S = 5, 3.0
#: who releases a bolt the scripted operator's NOKs locked (the source says it was simulated)
SIM_SUPERVISOR = Issuer("supervisor", frozenset({Right.RELEASE}), "sim operator")
#: the scripted operator's own name, for a station file without a user of the operator role
#: (:func:`sim_operator`): signed in at the station, its rundowns carry the name
SIM_OPERATOR = Issuer("operator", frozenset(), "sim operator")
#: the role whose users hold the tool: the scripted operator signs in as one of them
OPERATOR_ROLE = "operator"
#: the journal's line for an idle simulated lift (said once per daemon)
IDLE_LINE = ("simulated lift: {now}; raise it with 'next' (a new vehicle at "
             "working height) on the daemon's standard input ({help}), or run stationd run "
             "with --sim-operator for a scripted operator")


def sim_pairs(cfg: StationConfig) -> list[str]:
    """The pairs whose two cameras are simulated (the world renders theirs; a pair on real or
    ``file://`` cameras shows its own frames)."""
    return [name for name, pc in cfg.pairs.items()
            if pc.left and pc.right and all(simulated(Kind.CAMERA, cfg.cameras.get(cam, ""))
                                            for cam in (pc.left, pc.right))]


def needs_world(cfg: StationConfig) -> bool:
    """Whether a camera of the station is simulated (``sim://PAIR/SIDE``: its driver says)."""
    return any(simulated(Kind.CAMERA, url) for url in cfg.cameras.values())


def sim_operator(cfg: StationConfig) -> tuple[Issuer | None, str | None]:
    """Whom the scripted operator signs in as, and what the journal says of it once (None:
    nothing).  The first user (by name) of ``access.users`` whose role is ``operator``: the
    rundowns are recorded by a person the station knows, as a trainer who set up the file
    expects (and as its operator screen and ``stationd db report`` then show).  Without one,
    said once: on a station that does not require sign-in, the simulator's own name
    ``operator`` (:data:`SIM_OPERATOR`), as before (config/sim has no ``access:``); on one that
    requires it (``operator_required: true``) nobody: the operator waits, the vehicle on
    the lift, for a person to sign in.  Why not another user of the file there: a
    supervisor's name on the simulator's rundowns is what requiring sign-in is to prevent,
    and a name the file does not give would work around the rule being trained."""
    access = cfg.access
    users = sorted(name for name, u in access.users.items() if u.role == OPERATOR_ROLE)
    if users:
        return Issuer(users[0], access.roles.get(OPERATOR_ROLE, frozenset()),
                      "sim operator"), None
    if not access.operator_required:
        return SIM_OPERATOR, (f"no user of {cfg.path} has the {OPERATOR_ROLE} role: the "
                              f"operator signs in as '{SIM_OPERATOR.user}', a name the file "
                              "does not give (give a user that role in access.users to "
                              "have the rundowns recorded by them)")
    return None, (f"{cfg.path} requires a signed-in operator (access.operator_required) and "
                  f"no user of it has the {OPERATOR_ROLE} role: the operator waits, the "
                  "vehicle on the lift, for a person to sign in (the operator screen, "
                  "stationd operator sign-in)")


def _geometry(cfg: StationConfig) -> bytes:
    """What the world is made of: a reload that changes it gets a new world."""
    return pickle.dumps((cfg.pairs, cfg.marker, cfg.references, cfg.cameras))


def left_by_the_last_run(cfg: StationConfig) -> tuple[str | None, int | None]:
    """What the last daemon left, as the station's database says: the vehicle at the station,
    not closed (its lift still up: a real PLC keeps it), and the newest controller tightening
    id recorded (a real controller's count goes on); None each where there is none or the
    database cannot say (not there yet, not readable: a simulation starts empty then)."""
    try:
        with Repository.open(cfg.database_url, read_only=True) as repo:
            return repo.at_station(), repo.last_tightening_id()
    except (DbError, StationError, SQLAlchemyError, OSError) as exc:
        log.debug("nothing of a last run read from %s: %s", cfg.database_url, exc)
        return None, None


def controller_memory(cfg: StationConfig) -> Path | None:
    """The file the simulated controller keeps its results in (for MID 0064), in the
    station's own folder: beside its lock (by its SQLite database, or in the records folder
    of a database server), ``<database>.sim-wrench.jsonl``; None where the station keeps no
    file (a database in memory, or on a server without a records folder).  The controller's
    own file, never the station's database: it stands for a device of its own, whose results
    outlive the station's restart whatever the station recorded."""
    held = lock_path(cfg.database_url, cfg.records.images_dir)
    return None if held is None else held.with_suffix(".sim-wrench.jsonl")


def _model_code(cfg: StationConfig) -> int:
    """The lift code of the bolt table's first model with bolts (1 without one)."""
    if cfg.bolts_path is None:
        return 1
    codes = [m.code for m in load_bolts(cfg.bolts_path).models if m.code is not None and m.bolts]
    return codes[0] if codes else 1


class SimulatedStation:
    """The simulated world (and operator) of a daemon whose station names ``sim://`` devices.

    ``operator``: the scripted operator (refused for a station with real devices: it would
    raise a real lift); ``stdin``: where an idle station's PLC commands come from;
    ``supervisor`` False: no simulated supervisor, locks wait for a person's release."""

    def __init__(self, cfg: StationConfig, *, operator: bool = False, seed: int = 7,
                 stdin: TextIO | None = None, supervisor: bool = True) -> None:
        if operator:
            real = stand_ins(cfg)
            if real:
                raise InputError(f"{cfg.path}: --sim-operator drives simulated devices only; "
                                 f"this station names real ones ({', '.join(real)}): run it "
                                 "without --sim-operator")
            twins = undriven(cfg)
            if twins:
                raise InputError(f"{cfg.path}: --sim-operator drives the simulated lift and "
                                 "Open Protocol controller (sim://lift, sim://wrench) only; "
                                 f"this station names {', '.join(twins)}: name sim://wrench, "
                                 "or run it without --sim-operator")
            if not supervisor:
                check_people(cfg)     # before the world is built: one line, at the start
        self.operator, self.seed = operator, seed
        #: False (``--no-sim-supervisor``): locks are left to people (the operator waits)
        self.supervisor = supervisor
        self.world: World | None = None
        self._key: bytes | None = None
        self._stdin = stdin if stdin is not None else sys.stdin
        self._plc: SimulatedPlc | None = None     # the idle station's, for typed commands
        self._code = 1
        self._told = False
        self._reader: threading.Thread | None = None
        self._serial = [first_serial(time.time())]
        self._noted: set[str] = set()
        self._new_world = False    # said in the journal once the daemon's journal is set up
        #: the simulated lift as the last station left it (a reload): height, fault, vehicle
        self._lift: LiftState | None = None
        self._staying: str | None = None    # its VIN, at working height: the operator goes on
        #: the vehicle the last daemon left at height (its database says): the first
        #: station's lift starts with it, as a real PLC keeps it through a restart
        self._left_up, self._last_id = left_by_the_last_run(cfg)
        self._across = "reload"     # what the vehicle staying stayed across
        #: the last station's simulated controller: the next one goes on from it
        self._controller: SimController | None = None
        #: whom the scripted operator signs in as (:func:`sim_operator`)
        self._signer: Issuer | None = SIM_OPERATOR
        #: the simulator's own name, signed in as the last station closed, and since when:
        #: it stays signed in across a reload as a person of the file does
        self._signed: tuple[str, float] | None = None
        #: the vehicle the operator works on (its VIN and plan: ``operate``'s truth), kept
        #: across a reload: a vehicle that stays keeps its plan
        self._truth: dict[str, Any] | None = None
        #: the operator's draws (placement, hovering, NOKs), one stream a daemon: a reload
        #: goes on with it rather than drawing the first vehicle's again
        self._rng = np.random.default_rng(seed)
        self._nok_rng = np.random.default_rng([seed, 21])
        self.follow(cfg)

    def follow(self, cfg: StationConfig) -> None:
        """The world for ``cfg``: built when its cameras are simulated and its geometry is new,
        closed when none is."""
        key = _geometry(cfg) if needs_world(cfg) else None
        if key == self._key:
            return
        self.close()
        self._key = key
        if key is not None:
            self.world = World(cfg, seed=self.seed)
            self._new_world = True

    def close(self) -> None:
        if self.world is not None:
            self.world.close()
        self.world, self._key = None, None

    async def beside(self, cfg: StationConfig, station: Station, stop: asyncio.Event) -> None:
        """Beside one station of the serve loop, until ``stop``: the world follows its
        configuration, the simulated controller gets its psets, then the operator works
        (``--sim-operator``) or waits (the lift down, raised from standard input)."""
        self.follow(cfg)
        self._program(cfg, station)
        self._restore(station)      # before the station's loop first reads the lift
        try:
            self._code = _model_code(cfg)
        except StationError as exc:    # validated before: never, but the daemon stays up
            log.error("simulated operator: %s", exc)
        scripted = self.operator and self.world is not None and not stand_ins(cfg)
        if self.operator and not scripted:
            log.error("simulated operator: %s names real devices (%s): the operator stays "
                      "idle", cfg.path, ", ".join(stand_ins(cfg)) or "no sim:// camera")
        if scripted:
            self._sign_in_as(cfg, station)     # before the station's loop starts
        if not scripted:
            self._idle(station)      # before the journal's lines: typed commands find its PLC
        elif not self.supervisor and not releasers(cfg):     # a reload took them away
            log.error("simulated operator: no user of %s holds the release right: a lock "
                      "waits until the station file gives one a role with it (and the "
                      "station is reloaded)", cfg.path)
        if self._new_world:
            self._new_world = False
            who = "idle" if not scripted else "scripted" if self.supervisor else \
                "scripted, no simulated supervisor: locks wait for a person's release"
            log.info("simulated world: the sim:// cameras of %s render it (operator: %s)",
                     counted(len(sim_pairs(cfg)), "pair"), who)
        if not scripted and self._plc is not None and not self._told:
            self._told = True
            up = self._plc.state()
            # (a vehicle the last run left at height is up: not said "down" after it, a trial)
            now = f"vehicle {up.vin} at working height" if up.at_working_height and up.vin \
                else "down, no vehicle"
            log.info(IDLE_LINE.format(now=now, help=HELP.removeprefix("commands: ")
                                      .removesuffix(" | quit")))
        try:
            if scripted:
                await self._operate(station, stop)
            else:
                await stop.wait()
        finally:
            if not scripted:    # the scripted operator's keeps it before its round ends
                self._keep(station)
            self._plc = None
            if self.world is not None:
                self.world.set_wrench(None)

    # -- the lift across a reload ---------------------------------------------------------
    def _keep(self, station: Station) -> None:
        """The simulated lift as this station leaves it (before the scripted operator's round
        is cancelled, which lowers it): the next station's lift starts so, as a real PLC goes
        on through a daemon's reload.  And the simulator's own name if it is signed in: the
        station keeps only the file's users signed in (:meth:`Station.open`)."""
        lift = station.lift
        self._lift = lift.plc.state() if isinstance(lift, SimLift) else None
        who = station.core.status().operator
        self._signed = (who, time.time()) if who is not None and who == SIM_OPERATOR.user \
            and who not in station.cfg.access.users else None

    def _sign_in_as(self, cfg: StationConfig, station: Station) -> None:
        """Whom the operator signs in as on this station (said once a daemon when not a user
        of the file); the simulator's own name, signed in before the reload, stays signed in
        when the new file still has nobody of the operator role (one sign-in a daemon, not
        one a reload)."""
        self._signer, said = sim_operator(cfg)
        if said is not None:
            self._note(said)
        signed, self._signed = self._signed, None
        if signed is not None and self._signer == SIM_OPERATOR:
            station.still_signed_in(*signed)

    def _restore(self, station: Station) -> None:
        """The new station's simulated lift as the last one was left: the vehicle on the
        lift stays (the station reopens it from its database, with what was done).  Why: each
        station's ``sim://lift`` starts a new PLC, down and empty, so a reload that changed
        only ``stable_frames`` dropped the vehicle ("lift not at working height")."""
        kept, self._lift = self._lift, None
        left_up, self._left_up = self._left_up, None
        lift = station.lift
        if not isinstance(lift, SimLift):
            return
        plc = lift.plc
        if kept is None and left_up is not None:
            try:
                plc.set_vehicle(_model_code(station.cfg), left_up)
            except (ValueError, StationError) as exc:
                log.warning("the simulated vehicle %s left at height by the last run does not "
                            "come back: %s", left_up, exc)
                return
            plc.raise_lift()
            self._staying, self._across = left_up, "restart"
            log.info("simulated lift: vehicle %s still at height from the last run (a PLC "
                     "keeps it through the station's restart)", left_up)
            return
        if kept is None:
            return
        try:
            plc.set_vehicle(kept.model_code, kept.vin)
        except ValueError as exc:     # the new register map cannot hold it
            log.warning("reload: the simulated vehicle %s leaves the lift: the lift's new "
                        "registers cannot hold it (%s)", kept.vin, exc)
            return
        try:
            plc.set_height(kept.height_mm)
        except ValueError:
            plc.raise_lift() if kept.at_working_height else plc.lower_lift()
        if kept.fault:
            plc.set_fault(True)
        if kept.vin is not None and kept.at_working_height:
            self._staying, self._across = kept.vin, "reload"

    def _program(self, cfg: StationConfig, station: Station) -> None:
        """The simulated controller goes on from the last station's (its tightening ids, its
        stored results, its scatter: :meth:`SimController.go_on_from`), keeps its results in
        a file of its own (:func:`controller_memory`: after a restart it has those the last
        daemon's made, as a real controller has), and runs the bolt table's psets (and the
        NOK policy's loosen psets), as ``stationd sim controller --config`` does.

        Why carried: each station opens its own ``sim://wrench``, a new simulator whose ids
        started at 1 again with the same seed, so after a reload it sent the same (id,
        torque, angle) results again, which a real controller never does.  Carrying its state
        (rather than numbering after the newest id in the database) is what a real
        controller does through a daemon's reload: it is not reset, its ids and its stored
        results go on whatever the station recorded.  Taken from the last simulator once the
        last station has closed it (its final state: a result made while it stopped is
        counted too), before this station's loop starts."""
        wrench = station.wrench
        if not isinstance(wrench, SimWrench):
            return
        before, self._controller = self._controller, wrench.controller
        if before is not None and before is not wrench.controller:
            wrench.controller.go_on_from(before)
        elif before is None and self._last_id is not None:    # the daemon's first station
            wrench.controller.go_on_after(self._last_id, self.seed)
        self._last_id = None
        memory, said = controller_memory(cfg), len(wrench.controller.errors)
        if memory is not None:
            wrench.controller.keep_results_in(memory)
        for problem in wrench.controller.errors[said:]:     # its file: the results in memory
            log.warning("simulated controller: %s", problem)
        if cfg.bolts_path is None:
            return
        try:
            wrench.controller.psets = {**loosen_programs(cfg.nok), **psets_of(cfg.bolts_path)}
        except StationError as exc:
            log.error("simulated controller: its psets: %s", exc)

    # -- idle: the lift down, commands on standard input ----------------------------------
    def _idle(self, station: Station) -> None:
        lift = station.lift
        if not isinstance(lift, SimLift):
            return     # a real lift: the vehicles come from the line
        self._plc = lift.plc
        if self._reader is None:
            self._reader = threading.Thread(target=self._read, name="sim-plc-stdin",
                                            daemon=True)
            self._reader.start()

    def _read(self) -> None:
        """The PLC commands typed on standard input, to the running station's PLC."""
        try:
            for line in self._stdin:
                plc = self._plc
                if plc is None:
                    log.warning("simulated lift: no idle simulated station (starting, "
                                "reloading or operated): %r ignored", line.strip()[:80])
                elif not plc_command(plc, line, self._code, self._serial, _said):
                    log.info("simulated lift: quit is not a command of the daemon (stop it "
                             "with Ctrl-C or SIGTERM)")
        except (OSError, ValueError):    # standard input closed or not text: no commands
            return

    # -- the scripted operator --------------------------------------------------------------
    async def _operate(self, station: Station, stop: asyncio.Event) -> None:
        task = asyncio.create_task(self._vehicles(station))
        try:
            await stop.wait()
        finally:
            self._keep(station)     # before the cancelled round lowers the lift
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def _vehicles(self, station: Station) -> None:
        """Vehicle after vehicle: a new VIN raised, a few of its bolts tightened (NOK now and
        then, as the demo), the lift lowered; a round that fails is journaled, never fatal."""
        assert self.world is not None  # noqa: S101 - checked by the caller
        rng, nok_rng = self._rng, self._nok_rng
        while True:
            staying, self._staying = self._staying, None
            if staying is None:
                self._serial[0] = self._serial[0] % 999_999 + 1
            kept = self._truth if staying is not None and self._truth is not None \
                and self._truth["vin"] == staying else None
            truth: dict[str, Any] = {"bolt": None, "model_code": self._code,
                                     "vin": staying or make_vin(self._serial[0]),
                                     "plan": None if kept is None else kept.get("plan")}
            self._truth = truth
            if staying is not None:
                log.info("simulated operator: vehicle %s stays on the lift across the %s; "
                         "its bolts go on", staying, self._across)
            else:
                log.info("simulated operator: vehicle %s (lift code %d) arrives",
                         truth["vin"], self._code)
            try:
                await operate(station, self.world, rng, BOLTS_PER_VEHICLE, [], _bolt_said,
                              truth, nok_rng, note=self._note,
                              supervisor=supervisor_of(station.cfg, SIM_SUPERVISOR.source)
                              if self.supervisor else None,
                              operator=self._signer)
            except InputError as exc:
                log.warning("simulated operator: %s", exc)
            except (StationError, RuntimeError, OSError) as exc:
                log.error("simulated operator: %s: %s", type(exc).__name__, exc)
            finally:
                self.world.set_wrench(None)
                lift = station.lift
                if isinstance(lift, SimLift):
                    lift.plc.lower_lift()
            await asyncio.sleep(BETWEEN_VEHICLES_S)

    def _note(self, text: str) -> None:
        """The operator's notes (bolts no pair sees), each once a daemon, not per vehicle."""
        if text not in self._noted:
            self._noted.add(text)
            log.info("simulated operator: %s", text)


def _said(text: str) -> None:
    log.info("simulated lift: %s", text)


def _bolt_said(line: dict[str, Any]) -> None:
    before = f" (first: {'; '.join(line['before'])})" if line.get("before") else ""
    log.info("simulated operator: %s: pset %s, %s%s", line["bolt"], line["pset"],
             line["result"], before)


__all__ = ["BOLTS_PER_VEHICLE", "SimulatedStation", "controller_memory", "needs_world"]
