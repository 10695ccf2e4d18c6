"""The ``stationd`` command: one entry point, one sub-command per job.

Exit codes are a contract: 0 success (marker found), 1 not found (the JSON still says why),
2 bad input, always with one readable line on stderr and never a traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from stationd.errors import InputError, StationError

EXIT_OK, EXIT_NOT_FOUND, EXIT_BAD_INPUT = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line and exit code 2."""

    def error(self, message: str) -> NoReturn:
        sys.stderr.write(f"{self.prog}: error: {message} (see --help)\n")
        raise SystemExit(EXIT_BAD_INPUT)


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    return "[" + ", ".join(f"{x:.3f}" for x in v) + "]"


# -- detect -------------------------------------------------------------------------------
def cmd_detect(args: argparse.Namespace) -> int:
    from stationd.config import load_station_config
    from stationd.geometry.camera import Camera
    from stationd.imageio import read_image
    from stationd.vision.detect import detect

    cfg = load_station_config(args.config)
    camera = Camera.load(args.camera)
    image = read_image(args.image)
    det = detect(image, camera, cfg.vision, cfg.marker)
    if args.json:
        _emit(det.to_json())
    elif det.found:
        print(f"found: centre {_fmt(det.centre_px)} px (ellipse centre "
              f"{_fmt(det.ellipse_centre_px)}), normal {_fmt(det.normal)}, "
              f"{det.timings_ms.get('total', 0):.1f} ms")
    else:
        print(f"not found: {det.reason}")
    return EXIT_OK if det.found else EXIT_NOT_FOUND


# -- localize -----------------------------------------------------------------------------
def cmd_localize(args: argparse.Namespace) -> int:
    from stationd.config import load_station_config
    from stationd.geometry.camera import StereoPair
    from stationd.geometry.stereo import localize
    from stationd.imageio import read_image

    if args.repeat < 1:
        raise InputError("--repeat must be at least 1")
    cfg = load_station_config(args.config)
    pair = StereoPair.load(args.pair)
    left, right = read_image(args.left), read_image(args.right)
    times: list[float] = []
    res = None
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        res = localize(pair, left, right, cfg.vision, cfg.marker)
        times.append((time.perf_counter() - t0) * 1e3)
    assert res is not None  # noqa: S101 - repeat >= 1
    out = res.to_json()
    if args.repeat > 1:
        out["repeat"] = {"n": args.repeat, "median_ms": float(np.median(times)),
                         "min_ms": float(np.min(times)), "max_ms": float(np.max(times))}
    if args.json:
        _emit(out)
    elif res.found:
        print(f"found: point {_fmt(res.point_mm)} mm, normal {_fmt(res.normal)}, epipolar "
              f"{res.epipolar_px:.3f} px, {res.timings_ms.get('total', 0):.1f} ms")
    else:
        print(f"not found: {res.reason}")
    return EXIT_OK if res.found else EXIT_NOT_FOUND


# -- marker -------------------------------------------------------------------------------
def cmd_marker(args: argparse.Namespace) -> int:
    from stationd.config import load_station_config
    from stationd.vision.printable import marker_svg

    cfg = load_station_config(args.config)
    out = Path(args.out)
    try:
        out.write_text(marker_svg(cfg.marker), encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{out}: cannot write: {exc.strerror}") from None
    m = cfg.marker
    print(f"wrote {out}: white r={m.inner_mm:g} mm, black ring to r={m.outer_mm:g} mm, purple "
          f"field {2 * m.field_mm:g} mm square; print at 100 % scale")
    return EXIT_OK


# -- tune-color ---------------------------------------------------------------------------
def _results_file(text: str) -> str:
    """A benchmark's ``--out``: checked before a run of minutes, not after it (a file that
    cannot be written would otherwise lose the run)."""
    import os

    folder = Path(text).parent
    if not folder.is_dir() or not os.access(folder, os.W_OK):
        raise argparse.ArgumentTypeError(f"{text}: folder {folder} does not exist or is not "
                                         "writable")
    return text


def _parse_roi(text: str) -> tuple[int, int, int, int]:
    parts = text.split(",")
    try:
        x, y, w, h = (int(p) for p in parts)
    except ValueError:
        raise InputError(f"--roi {text!r}: expected x,y,w,h (four integers)") from None
    if w <= 0 or h <= 0 or x < 0 or y < 0:
        raise InputError(f"--roi {text!r}: x, y must be >= 0 and w, h > 0")
    return x, y, w, h


def cmd_tune_color(args: argparse.Namespace) -> int:
    from stationd.imageio import read_image
    from stationd.vision.color import tune_hsv, write_hsv_yaml

    image = read_image(args.reference)
    roi = _parse_roi(args.roi) if args.roi else None
    if roi is not None:
        h, w = image.shape[:2]
        x, y, rw, rh = roi
        if x + rw > w or y + rh > h:
            raise InputError(f"--roi {args.roi}: outside the {w}x{h} image")
    ranges = tune_hsv(image, roi)
    out = Path(args.out)
    write_hsv_yaml(out, ranges, source=str(args.reference), roi=roi)
    print(f"wrote {out}: h {list(ranges.h)}, s {list(ranges.s)}, v {list(ranges.v)}; "
          f"use it with 'vision: {{hsv: {out.name}}}' in the station config")
    return EXIT_OK


# -- bench / demo -------------------------------------------------------------------------
def cmd_bench(args: argparse.Namespace) -> int:
    from stationd.bench.vision import run_vision_bench

    return run_vision_bench(args)


def cmd_bench_station(args: argparse.Namespace) -> int:
    from stationd.bench.station import run_station_bench

    return run_station_bench(args)


def cmd_bench_chain(args: argparse.Namespace) -> int:
    from stationd.bench.chain import run_chain_bench

    return run_chain_bench(args)


def cmd_run(args: argparse.Namespace) -> int:
    from stationd.station.run import run_daemon

    return run_daemon(args)


def cmd_bench_soak(args: argparse.Namespace) -> int:
    from stationd.bench.soak import run_soak

    return run_soak(args)


def cmd_demo(args: argparse.Namespace) -> int:
    if args.vision:
        from stationd.demo import run_demo

        return int(run_demo(args))
    from stationd.station.demo import run_station_demo

    return run_station_demo(args)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="stationd", description="Vision-guided bolt-tightening station.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    d = sub.add_parser("detect", help="localize the marker in one image")
    d.add_argument("image")
    d.add_argument("--camera", required=True, help="camera YAML (K, dist, size)")
    d.add_argument("--config", help="station YAML (marker, vision)")
    d.add_argument("--json", action="store_true", help="print one JSON object")
    d.set_defaults(func=cmd_detect)

    lo = sub.add_parser("localize", help="localize the marker in a stereo pair (mm)")
    lo.add_argument("left")
    lo.add_argument("right")
    lo.add_argument("--pair", required=True, help="pair YAML (left, right, R, T)")
    lo.add_argument("--config", help="station YAML (marker, vision)")
    lo.add_argument("--json", action="store_true")
    lo.add_argument("--repeat", type=int, default=1,
                    help="localize N times on the loaded images and report timings")
    lo.set_defaults(func=cmd_localize)

    mk = sub.add_parser("marker", help="write a printable marker (SVG, true scale)")
    mk.add_argument("--out", default="marker.svg")
    mk.add_argument("--config", help="station YAML (marker sizes)")
    mk.set_defaults(func=cmd_marker)

    tc = sub.add_parser("tune-color", help="derive HSV ranges from a well-lit reference image")
    tc.add_argument("reference")
    tc.add_argument("--roi", help="x,y,w,h of the marker's purple field in the image")
    tc.add_argument("--out", default="hsv.yaml",
                    help="HSV file to write (the station config reads it as vision.hsv)")
    tc.set_defaults(func=cmd_tune_color)

    b = sub.add_parser("bench", help="benchmarks that print figures")
    bsub = b.add_subparsers(dest="bench", required=True, parser_class=_Parser)
    bv = bsub.add_parser("vision", help="the paper's experiments on rendered images")
    bv.add_argument("--out", default="bench-vision.json", type=_results_file,
                    help="JSON results file")
    bv.add_argument("--quick", action="store_true", help="fewer samples (a smoke run)")
    bv.add_argument("--only", help="comma-separated sections: "
                    "radii,centre,rod,saltpepper,lowlight,speed")
    bv.add_argument("--seed", type=int, default=1)
    bv.set_defaults(func=cmd_bench)
    bc = bsub.add_parser("chain", help="the whole chain: calibration, vehicle frame, rod, bolts")
    bc.add_argument("--out", default="bench-chain.json", type=_results_file,
                    help="JSON results file")
    bc.add_argument("--quick", action="store_true", help="2 pairs, fewer samples")
    bc.add_argument("--seed", type=int, default=1)
    bc.set_defaults(func=cmd_bench_chain)
    bs = bsub.add_parser("station", help="the daemon on the simulated station: latency from "
                         "frame exposure to acknowledged parameters, memory")
    bs.add_argument("--out", default="bench-station.json", type=_results_file,
                    help="JSON results file")
    bs.add_argument("--cycles", type=int, default=20, help="bolts to select and tighten")
    bs.add_argument("--seed", type=int, default=1)
    bs.add_argument("--json", action="store_true", help="print one summary object")
    bs.set_defaults(func=cmd_bench_station)
    bk = bsub.add_parser("soak", help="the daemon through a long shift: outages, reworks, load")
    bk.add_argument("--bolts", type=int, default=100, help="bolts to tighten in all")
    bk.add_argument("--per-vehicle", type=int, default=10, help="bolts per vehicle")
    bk.add_argument("--faults", action="store_true", help="random device outages and reworks")
    bk.add_argument("--load", type=int, default=0, help="busy processes during the run")
    bk.add_argument("--seed", type=int, default=1)
    bk.add_argument("--json", action="store_true", help="print one summary object")
    bk.set_defaults(func=cmd_bench_soak)

    from stationd.db_cli import add_config_parser, add_db_parser
    from stationd.geometry.calibrate_cli import add_calibrate_parser
    from stationd.probe import add_probe_parser

    add_calibrate_parser(sub)
    add_probe_parser(sub)
    add_db_parser(sub)
    add_config_parser(sub)

    rn = sub.add_parser("run", help="the station daemon (as systemd runs it)")
    rn.add_argument("--config", required=True, help="station YAML")
    rn.set_defaults(func=cmd_run)

    dm = sub.add_parser("demo", help="the main job: a simulated run")
    dm.add_argument("--seed", type=int, default=7)
    dm.add_argument("--cycles", type=int, default=10, help="bolts to tighten (with --vision: "
                    "marker placements to localize)")
    dm.add_argument("--config", help="station YAML (default: config/sim/station.yaml)")
    dm.add_argument("--vision", action="store_true",
                    help="only the vision demo: render stereo pairs, localize, print errors")
    dm.add_argument("--save", help="with --vision: also write the images and pair.yaml here")
    dm.add_argument("--json", action="store_true", help="print one summary object")
    dm.set_defaults(func=cmd_demo)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except StationError as exc:
        sys.stderr.write(f"stationd: error: {exc}\n")
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        sys.stderr.write("stationd: interrupted\n")
        return 130
