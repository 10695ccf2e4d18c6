"""``stationd probe``: commissioning checks of one device, over its real protocol.

Connects, prints the device's identity and state, and exits 0 on success, 1 when the device
refuses or nothing arrives in time, 2 for a bad URL or option, always with one readable line.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from typing import Any

from drivers.errors import DeviceError, UrlError

EXIT_OK, EXIT_NO_ANSWER = 0, 1


def _emit(args: argparse.Namespace, obj: dict[str, Any], text: str) -> None:
    if args.json:
        sys.stdout.write(json.dumps(obj) + "\n")
    else:
        print(text)


def _failed(args: argparse.Namespace, kind: str, exc: DeviceError) -> int:
    """A device that refuses or does not answer: exit 1, one line (and the JSON if asked)."""
    if isinstance(exc, UrlError):
        raise exc  # bad input: exit 2 through the CLI's error path
    if args.json:
        sys.stdout.write(json.dumps({"device": args.url, "kind": kind, "ok": False,
                                     "error": str(exc)}) + "\n")
    sys.stderr.write(f"stationd: {kind}: {exc}\n")
    return EXIT_NO_ANSWER


def probe_lift(args: argparse.Namespace) -> int:
    from drivers.lift import open_lift
    from stationd.config import load_station_config

    cfg = load_station_config(args.config)
    try:
        with open_lift(args.url, cfg.lift.registers, timeout=args.timeout) as lift:
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


def add_probe_parser(sub: Any) -> None:
    p = sub.add_parser("probe", help="connect to one device and show its identity and state")
    psub = p.add_subparsers(dest="device", required=True, parser_class=type(p))
    lift = psub.add_parser("lift", help="read the lift PLC once")
    lift.add_argument("url", help="modbus-tcp://HOST:PORT?unit=N | modbus-rtu:///dev/ttyUSB0?"
                                  "baud=19200&parity=E&unit=N | sim://lift")
    lift.add_argument("--config", help="station YAML (its lift register map)")
    lift.add_argument("--timeout", type=float, default=2.0, help="seconds (default 2)")
    lift.add_argument("--json", action="store_true", help="print one JSON object")
    lift.set_defaults(func=probe_lift)
