"""``stationd probe``: commissioning checks of one device, over its real protocol.

Connects, prints the device's identity and state, and exits 0 on success, 1 when the device
refuses or nothing arrives in time, 2 for a bad URL or option, always with one readable line.
A device a running daemon drives is refused (exit 2) before it is touched: the probe takes
the daemon's device lock (``stationd.lock.probing``) for as long as it talks to the device.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
from typing import Any

from drivers.errors import DeviceError, UrlError
from drivers.lift import FORMS as LIFT_FORMS
from drivers.wrench import FORMS as WRENCH_FORMS
from stationd.jsonout import strict_json
from stationd.probelock import locked

EXIT_OK, EXIT_NO_ANSWER = 0, 1


def seconds(text: str) -> float:
    """A time option (``--timeout``, ``--wait-result``): a finite number of seconds > 0.
    NaN would make every wait return at once, a negative one never start."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of seconds") from None
    if not (math.isfinite(value) and 0 < value <= 86400):
        raise argparse.ArgumentTypeError(f"{text}: expected seconds, > 0 and at most a day")
    return value


def _emit(args: argparse.Namespace, obj: dict[str, Any], text: str) -> None:
    if args.json:
        sys.stdout.write(strict_json(obj) + "\n")
    else:
        print(text)


def _failed(args: argparse.Namespace, kind: str, exc: DeviceError) -> int:
    """A device that refuses or does not answer: exit 1, one line (and the JSON if asked)."""
    if isinstance(exc, UrlError):
        raise exc  # bad input: exit 2 through the CLI's error path
    if args.json:
        sys.stdout.write(strict_json({"device": args.url, "kind": kind, "ok": False,
                                     "error": str(exc)}) + "\n")
    sys.stderr.write(f"stationd: {kind}: {exc}\n")
    return EXIT_NO_ANSWER


def probe_lift(args: argparse.Namespace) -> int:
    from drivers.devices import Kind, open_device
    from stationd.config import load_station_config

    cfg = load_station_config(args.config)
    try:
        with locked(args, "lift"), \
                open_device(Kind.LIFT, args.url, register_map=cfg.lift.registers,
                            timeout=args.timeout) as lift:
            ident = lift.identity()
            state = lift.read_state(timeout=args.timeout)
    except DeviceError as exc:
        return _failed(args, "lift", exc)
    st = dataclasses.asdict(state)
    _emit(args, {"device": args.url, "kind": "lift", "ok": True, "identity": ident,
                 "state": {**st, "ready": state.ready}},
          f"{ident}\n  height {state.height_mm:.1f} mm, at working height "
          f"{'yes' if state.at_working_height else 'no'}, moving "
          f"{'yes' if state.moving else 'no'}, fault {'YES' if state.fault else 'no'}, "
          f"vehicle model {state.model_code}, VIN {state.vin or '-'}")
    return EXIT_OK


def _result_json(r: Any) -> dict[str, Any]:
    from stationd.station.results import type_code
    from stationd.words import result_type_words

    code = type_code(r)
    return {"torque_nm": r.torque_nm, "angle_deg": r.angle_deg, "ok": r.ok,
            "torque_status": r.torque_status.name, "angle_status": r.angle_status.name,
            "tightening_id": r.tightening_id, "pset": r.pset, "vin": r.vin,
            "result_type": code, "what": result_type_words(code) if code is not None
            else "result without a type (its revision carries none)"}


def _wait_tightening(w: Any, seconds: float) -> tuple[Any, list[dict[str, Any]]]:
    """The first tightening within ``seconds`` (None: none), and what else came before it:
    a loosening, a batch increment, a type the station does not know or a message that
    could not be read is said as what it is, never as a tightening (the station closes no
    bolt with one), and the wait goes on."""
    import time

    from drivers.wrench import ResultKind, UnreadableResult, result_kind
    from stationd.station.results import type_code

    others: list[dict[str, Any]] = []
    deadline = time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        r = w.wait_result(left)
        if r is None:
            break
        if isinstance(r, UnreadableResult):
            others.append({"what": "a result that could not be read", "error": r.error,
                           "tightening_id": r.tightening_id, "pset": r.pset})
        elif result_kind(type_code(r)) is ResultKind.TIGHTENING:
            return r, others
        else:
            others.append(_result_json(r))
    return None, others


def clock_words(offset: float | None) -> str:
    """A controller's clock against this machine's, as ``probe wrench`` says it (in whole
    seconds as the daemon's journal says them)."""
    from drivers.wrench.base import CLOCK_FAR_S, clock_seconds

    if offset is None:
        return "not known (it did not say its time, or keeps none)"
    whole = clock_seconds(offset)
    if whole == 0:
        return "agrees with this machine's (within 1 s)"
    return f"{whole:+d} s from this machine's" + (
        ": set the controller's clock" if abs(offset) >= CLOCK_FAR_S else "")


def probe_wrench(args: argparse.Namespace) -> int:
    """Session start, optionally a pset selection (acknowledged or refused with the
    controller's code) and one tightening result (the tool is enabled for it, and disabled
    again before the probe ends)."""
    from drivers.devices import Kind, open_device
    from drivers.errors import RefusedError

    if args.pset is not None and not 0 <= args.pset <= 999:
        raise UrlError(f"--pset {args.pset}: Open Protocol psets are 0-999")
    out: dict[str, Any] = {"device": args.url, "kind": "wrench", "identity": None,
                           "acknowledged": False, "pset": args.pset, "error": None,
                           "result": None}
    code = EXIT_OK
    try:
        with locked(args, "wrench"), open_device(Kind.WRENCH, args.url,
                                                               timeout=args.timeout) as w:
            out["identity"] = w.identity()
            # its clock as the session measured it (a technician checking a controller
            # swapped in could not see it): None, not said or no clock
            out["clock_offset_s"] = w.clock_offset_s
            out["acknowledged"] = args.pset is None  # the session itself was accepted
            if args.pset is not None:
                try:
                    w.select_pset(args.pset, timeout=args.timeout)
                    out["acknowledged"] = True
                except RefusedError as exc:
                    out["error"] = {"code": exc.code, "text": str(exc)}
                    code = EXIT_NO_ANSWER
            if code == EXIT_OK and args.wait_result:
                w.enable_tool()
                try:
                    r, out["not_tightenings"] = _wait_tightening(w, args.wait_result)
                finally:
                    w.disable_tool()
                if r is None:
                    out["error"] = {"code": None, "text": f"no tightening result within "
                                                        f"{args.wait_result:g} s"}
                    code = EXIT_NO_ANSWER
                else:
                    out["result"] = _result_json(r)
    except DeviceError as exc:
        return _failed(args, "wrench", exc)
    out["ok"] = code == EXIT_OK     # as the lift's and every failure's object has it
    if args.json:
        sys.stdout.write(strict_json(out) + "\n")
    else:
        print(out["identity"])
        print(f"  clock: {clock_words(out.get('clock_offset_s'))}")
        if args.pset is not None:   # why it was refused: the one line on stderr below
            print(f"  pset {args.pset}: " + ("acknowledged" if out["acknowledged"] else
                                             "REFUSED"))
        for o in out.get("not_tightenings") or ():
            said = f": {o['error']}" if "error" in o else \
                f", {'OK' if o['ok'] else 'NOK'} torque {o['torque_nm']:.2f} Nm"
            print(f"  not a tightening: {o['what']}{said} (id {o['tightening_id']}); "
                  "still waiting for a tightening")
        if out["result"]:
            r = out["result"]
            print(f"  result: {r['what']} {'OK' if r['ok'] else 'NOK'} torque "
                  f"{r['torque_nm']:.2f} Nm ({r['torque_status']}), angle "
                  f"{r['angle_deg']:.0f} deg ({r['angle_status']}), id {r['tightening_id']}")
    if code and not args.json:
        sys.stderr.write(f"stationd: wrench: {out['error']['text']}\n")
    return code


def add_probe_parser(sub: Any) -> None:
    p = sub.add_parser("probe", help="connect to one device and show its identity and state")
    psub = p.add_subparsers(dest="device", required=True, parser_class=type(p))
    lift = psub.add_parser("lift", aliases=["plc"], help="read the lift PLC once (also: probe "
                                                          "plc)")
    lift.add_argument("url", help=LIFT_FORMS)     # the drivers' own list
    lift.add_argument("--config", help="station YAML (its lift register map)")
    lift.add_argument("--timeout", type=seconds, default=2.0, help="seconds (default 2)")
    lift.add_argument("--json", action="store_true", help="print one JSON object")
    lift.set_defaults(func=probe_lift, device="lift")
    w = psub.add_parser("wrench", aliases=["controller"],
                        help="start a session, select a pset, wait for a result (also: probe "
                             "controller)")
    w.add_argument("url", help=WRENCH_FORMS)
    w.add_argument("--pset", type=int, help="select this pset and wait for the acknowledgement")
    w.add_argument("--wait-result", type=seconds, metavar="SECONDS",
                   help="enable the tool and wait this long for one tightening result")
    w.add_argument("--timeout", type=seconds, default=2.0, help="seconds (default 2)")
    w.add_argument("--json", action="store_true", help="print one JSON object")
    w.set_defaults(func=probe_wrench, device="wrench")
    from stationd.probe_camera import add_camera_probe

    add_camera_probe(psub)
