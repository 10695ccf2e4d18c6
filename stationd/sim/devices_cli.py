"""``stationd sim plc`` and ``stationd sim controller``: the simulated lift PLC and tightening
controller on their real protocols, on TCP ports of their own, set up from a station file.

Why: to commission a station (or a third-party client: an HMI, an integrator's Open Protocol
library) against the devices the tests use, before the real ones answer.  The PLC serves the
station file's register map as the unit its lift URL names (``--unit`` another); the
controller runs the psets of its bolt table.  Both serve until SIGINT or SIGTERM.  The PLC
takes one command per line on its standard input (``raise``, ``lower``, ``vehicle CODE
[VIN]``, ``next``, ``fault``, ``clear``), or cycles vehicles on its own with ``--every
SECONDS``: a new VIN, the lift up for that long, down, and again.

    stationd sim plc --config station.yaml --port 5020 --every 60
    stationd sim controller --config station.yaml --port 4545 --trigger-every 2
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import TextIO

from drivers.errors import UrlError
from drivers.lift.base import RegisterMap
from drivers.lift.sim import SimulatedPlc, parse_sim_lift_url
from drivers.modbus_link import parse_modbus_url
from drivers.wrench.sim.cli import ListenError, behaviour, serve, troubles_words
from drivers.wrench.sim.controller import DEFAULT_PSETS, SimController, SimPset
from stationd.boltfile import load_bolts
from stationd.config import load_station_config
from stationd.errors import InputError, StationError
from stationd.sim.vin import make_vin
from stationd.station.policy import NokPolicy

HELP = "commands: raise | lower | vehicle CODE [VIN] | next | fault | clear | quit"


def psets_of(bolts_path: Path) -> dict[int, SimPset]:
    """The controller's programs: the psets of a bolt table."""
    table = load_bolts(bolts_path)
    out: dict[int, SimPset] = {}
    for p in [*table.psets, *(q for m in table.models for q in m.psets)]:
        t, a = p.torque, p.angle
        out[p.number] = SimPset(t.target, t.min, t.max, a.target if a else 0.0,
                                a.min if a else 0.0, a.max if a else 0.0)
    return out


def _stop_on_signals() -> threading.Event:
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    return stop


#: the controller's loosening program for a loosen pset: a joint that comes loose is OK
LOOSEN_PROGRAM = SimPset(40.0, 5.0, 150.0, 360.0, 90.0, 720.0, name="loosen")


def loosen_programs(policy: NokPolicy) -> dict[int, SimPset]:
    """The simulated controller's programs for the policy's loosen psets."""
    rules = [policy.default, *policy.psets.values(), *policy.bolts.values()]
    return {r.loosen_pset: LOOSEN_PROGRAM for r in rules if r.loosen_pset is not None}


def lift_unit(url: str) -> int:
    """The Modbus unit a station file's lift URL reads (``unit=``, 1 where it says none, and
    for a lift that is not on Modbus)."""
    try:
        if url.startswith("sim:"):
            return int(parse_sim_lift_url(url)["unit"])
        return parse_modbus_url(url)[0].unit
    except UrlError:
        return 1


def _station(path: str | None) -> tuple[RegisterMap, dict[int, SimPset] | None, int]:
    """The station file's lift registers, its controller's programs (the bolt table's psets
    and the NOK policy's loosen psets: a standalone controller without them refused every
    loosening the station asked for: a line engineer's trial) and its lift's Modbus unit
    (the simulated PLC served unit 1 whatever the file said: its daemon stayed in fault,
    "a unit id it does not serve")."""
    if path is None:
        return RegisterMap(), None, 1
    cfg = load_station_config(path)
    # a station whose tables are in its database only: the simulator's default programs
    psets = DEFAULT_PSETS if cfg.bolts_path is None else psets_of(cfg.bolts_path)
    return cfg.lift.registers, {**loosen_programs(cfg.nok), **psets}, lift_unit(cfg.lift.url)


def first_serial(now: float) -> int:
    """The serial number a simulated PLC's vehicles go on from: the clock's seconds, so a
    restarted simulator (or daemon, on the same database) does not bring the closed VINs of
    its last run back as reworks (its vehicles come at most one a second)."""
    return int(now) % 900_000


def plc_command(plc: SimulatedPlc, line: str, code: int, serial: list[int],
                say: Callable[[str], None]) -> bool:
    """One command typed to the PLC; False for ``quit``.  A bad command is said, not fatal."""
    words = line.split()
    if not words:
        return True
    cmd, args = words[0].lower(), words[1:]
    try:
        if cmd == "quit":
            return False
        if cmd == "raise":
            plc.raise_lift()
        elif cmd == "lower":
            plc.lower_lift()
        elif cmd == "fault":
            plc.set_fault(True)
        elif cmd == "clear":
            plc.set_fault(False)
        elif cmd == "next":
            serial[0] = serial[0] % 999_999 + 1
            plc.lower_lift()
            plc.set_vehicle(code, make_vin(serial[0]))
            plc.raise_lift()
        elif cmd == "vehicle" and 1 <= len(args) <= 2:
            if not args[0].isdigit():
                say(f"refused: the model code is a whole number, not {args[0]!r} "
                    "(vehicle CODE [VIN])")
                return True
            plc.set_vehicle(int(args[0]), args[1] if len(args) == 2 else None)
        else:
            say(f"not a command: {line.strip()!r}; {HELP}")
            return True
    except ValueError as exc:
        say(f"refused: {exc}")
        return True
    s = plc.state()
    say(f"lift {'at working height' if s.at_working_height else 'not at height'}, vehicle "
        f"{s.model_code} {s.vin or '-'}{', FAULT' if s.fault else ''}")
    return True


def _serve_plc(args: argparse.Namespace, stop: threading.Event, out: TextIO) -> int:
    registers, _, unit = _station(args.config)
    if args.unit is not None:
        unit = args.unit

    def say(text: str) -> None:
        print(text, file=out, flush=True)

    serial = [first_serial(time.time())]
    with SimulatedPlc(registers, unit=unit) as plc:
        try:
            port = plc.start_tcp(args.port)
        except (OSError, RuntimeError) as exc:   # pymodbus says a busy port as RuntimeError
            why = getattr(exc, "strerror", None) or "the port is in use or not allowed"
            raise InputError(f"cannot listen on 127.0.0.1:{args.port}: {why}") from None
        say(f"lift PLC listening on 127.0.0.1:{port} (Modbus TCP, unit {plc.unit})")
        if args.every > 0:
            while not stop.is_set():
                plc_command(plc, "next", args.model_code, serial, say)
                if stop.wait(args.every):
                    break
                plc_command(plc, "lower", args.model_code, serial, say)
                stop.wait(min(5.0, args.every / 3))
            return 0
        say(HELP)
        reader = threading.Thread(target=_read_commands, daemon=True,
                                  args=(plc, args.model_code, serial, say, stop))
        reader.start()
        # woken now and then: a SIGTERM taken by another thread (the PLC's server) sets the
        # main thread's flag without waking a wait with no end (a run in CI waited 60 s)
        while not stop.wait(0.5):
            pass
    return 0


def _read_commands(plc: SimulatedPlc, code: int, serial: list[int],
                   say: Callable[[str], None], stop: threading.Event) -> None:
    """Commands typed on stdin until ``quit``.  Where stdin ends (``</dev/null``, nohup, a
    service) the PLC serves on as it stands: it ended silently, and the station only saw
    "connection refused"."""
    for line in sys.stdin:
        if not plc_command(plc, line, code, serial, say):
            stop.set()
            return
    say("stdin closed: the PLC serves on as it stands until stopped (SIGTERM, Ctrl-C); "
        "--every N raises and lowers the lift by itself")


def _serve_controller(args: argparse.Namespace, stop: threading.Event, out: TextIO) -> int:
    _, psets, _ = _station(args.config)
    try:
        sim = SimController(psets, seed=args.seed,
                            nok_rate=args.nok_rate, link_ack=args.link_ack,
                            **behaviour(args))
    except ValueError as exc:
        print(f"stationd: error: {exc}", file=sys.stderr)
        return 2
    listed = ", ".join(str(p) for p in sorted(sim.psets))
    troubles = troubles_words(args)
    try:
        return serve(sim, args.host, args.port, args.trigger_every, stop,
                     lambda port: f"controller listening on {args.host}:{port} (Open "
                                  f"Protocol; psets {listed}{troubles})", out,
                     types=args.result_types)
    except ListenError as exc:   # a port in use: the station's words, exit 2
        raise InputError(str(exc)) from None


def _check_args(args: argparse.Namespace) -> None:
    """Numbers that cannot work refused at the start (one line, exit 2), not taken silently
    or refused at the first vehicle."""
    every = getattr(args, "every", None)
    if every is not None and not (math.isfinite(every) and every >= 0):
        raise InputError(f"--every {every:g}: seconds, 0 (commands typed on stdin) or more")
    code = getattr(args, "model_code", None)
    if code is not None and not 0 <= code <= 0xFFFF:
        raise InputError(f"--model-code {code}: the PLC's register holds 0-65535")
    trigger = getattr(args, "trigger_every", None)
    if trigger is not None and not (math.isfinite(trigger) and trigger >= 0):
        raise InputError(f"--trigger-every {trigger:g}: seconds, 0 (no automatic trigger) or more")
    share = getattr(args, "nok_rate", None)
    if share is not None and not 0.0 <= share <= 1.0:    # NaN too
        raise InputError(f"--nok-rate {share:g}: the share of NOK results, 0 to 1 (0.05: one "
                         "in twenty)")


def run(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """``stationd sim plc|controller`` (the arguments are ``stationd.cli``'s)."""
    _check_args(args)
    stop = _stop_on_signals()
    try:
        if args.sim_device == "plc":
            return _serve_plc(args, stop, out)
        return _serve_controller(args, stop, out)
    except StationError as exc:   # a station file that does not read, a port in use
        print(f"stationd: error: {exc}", file=sys.stderr)
        return 2


__all__ = ["LOOSEN_PROGRAM", "loosen_programs", "plc_command", "psets_of", "run"]
