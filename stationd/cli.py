"""The ``stationd`` command: one entry point, one sub-command per job.

Exit codes are a contract: 0 success (marker found), 1 not found (the JSON still says why),
2 bad input, always with one readable line on stderr and never a traceback; 130 stopped by
Ctrl-C (SIGINT), 143 by SIGTERM, with one line too, whenever it comes (:func:`main`).

Why this module imports almost nothing at its top: ``.venv/bin/stationd`` imports it before
:func:`main` can take the signals over, and a Ctrl-C during an import of numpy or SQLAlchemy
there was a traceback; everything heavy is imported inside :func:`main` or a command.
"""

from __future__ import annotations

import argparse
import functools
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import Any, NoReturn

from stationd import stopping
from stationd.cliparse import EXIT_BAD_INPUT
from stationd.cliparse import Parser as _Parser
from stationd.errors import InputError, StationError, printable
from stationd.stopping import STOPPING, held

EXIT_OK, EXIT_NOT_FOUND = 0, 1
#: a command stopped by a signal: the shell's 128 + the signal's number, as if it had been
#: killed by it (a script tells Ctrl-C and systemd's stop apart as it would for any program)
EXIT_SIGINT, EXIT_SIGTERM = 128 + signal.SIGINT, 128 + signal.SIGTERM
#: each stopping signal's line and exit code
STOPPED_WORDS: dict[signal.Signals, tuple[str, int]] = {
    signal.SIGINT: ("stationd: interrupted (Ctrl-C)", EXIT_SIGINT),
    signal.SIGTERM: ("stationd: stopped by SIGTERM", EXIT_SIGTERM),
    signal.SIGHUP: ("stationd: stopped by SIGHUP (hang-up)", 128 + signal.SIGHUP)}
#: the reader of the output went away (``| head``) before the command finished: the code a
#: program killed by SIGPIPE exits with, never 0 (``status | true`` passed a station in fault)
EXIT_SIGPIPE = 128 + signal.SIGPIPE


def _reported() -> tuple[type[Exception], ...]:
    """What a command reports as one line (exit 2): the station's errors and those of the
    layers below it, which have their own roots (``db`` and ``drivers`` import nothing from
    stationd).  Imported when asked: ``db.errors`` loads SQLAlchemy's."""
    from db.errors import DbError
    from drivers.errors import DriverError

    return (StationError, DbError, DriverError)


def _emit(obj: dict[str, Any]) -> None:
    from stationd.jsonout import strict_json

    sys.stdout.write(strict_json(obj) + "\n")


def port_arg(text: str) -> int:
    """A TCP port to listen on: 0 (any free one) to 65535."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a port number") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"{value}: a port is 0-65535")
    return value


def unit_arg(text: str) -> int:
    """A Modbus unit id: 0-247."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a unit id") from None
    if not 0 <= value <= 247:
        raise argparse.ArgumentTypeError(f"{value}: a Modbus unit id is 0-247")
    return value


def seed_arg(text: str) -> int:
    """``--seed``: a non-negative integer (numpy's generators refuse negative seeds, after the
    command has started)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value}: a seed must be >= 0")
    return value


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

    if args.draw:
        _check_drawing(args.draw)
    cfg = load_station_config(args.config)
    camera = _detect_camera(args, Camera.load)
    image = read_image(args.image)
    det = detect(image, camera, cfg.vision, cfg.marker)
    if args.draw:
        _write_drawing(Path(args.draw), image, camera, det, cfg)
    if args.json:
        _emit(det.to_json())
    elif det.found:
        print(f"found: centre {_fmt(det.centre_px)} px (ellipse centre "
              f"{_fmt(det.ellipse_centre_px)}), normal {_fmt(det.normal)}, "
              f"{det.timings_ms.get('total', 0):.1f} ms")
    else:
        print(f"not found: {det.reason}")
    return EXIT_OK if det.found else EXIT_NOT_FOUND


#: ``detect --draw``: what the drawing may replace (the outputs' rule, stationd.outfile)
DRAW_HELP = ("write what the detector saw: ROI with edge points used/rejected, ellipses, "
             "centres, reason; and an overview (PNG).  An existing file is replaced only when "
             "it is an earlier drawing of detect --draw; any other file, and a link, is "
             "refused")


def _check_drawing(path: str) -> None:
    """``--draw`` before any work: a ``.png`` name (a PNG in ``out.txt`` would mislead whoever
    opens it), not a link, nothing there but an earlier drawing (``--draw link.png``,
    ``link.png`` pointing at the station file, replaced the station file with a PNG)."""
    from stationd.outfile import refuse_to_replace

    if not path.lower().endswith(".png"):
        raise InputError(f"--draw {path}: the drawing is a PNG; name the file .png")
    out = Path(path)
    if not out.parent.is_dir():
        raise InputError(f"--draw {path}: no such folder {out.parent}")
    refuse_to_replace(out, "the drawing", ("drawing",), option="--draw")


def _write_drawing(path: Path, image: Any, camera: Any, det: Any, cfg: Any) -> None:
    """The drawing as a PNG stamped as ``detect --draw``'s own (so the next run may replace
    it), written whole (a temporary file renamed over it), never through a link."""
    import cv2

    from stationd.outfile import DRAWING_STAMP, stamp_png, write_atomic
    from stationd.vision.draw import draw, explain

    picture = draw(image, camera, explain(image, camera, det, cfg.vision, cfg.marker))
    ok, buf = cv2.imencode(".png", picture)
    if not ok:
        raise InputError(f"--draw {path}: PNG encoding failed")
    write_atomic(path, stamp_png(buf.tobytes(), DRAWING_STAMP))


def _detect_camera(args: argparse.Namespace, load_camera: Callable[[str], Any]) -> Any:
    """The camera of ``detect``: its own file (``--camera``), or one side of a pair file
    (``--pair PAIR.yaml --side left``), so the output of ``calibrate stereo`` is used as is."""
    from stationd.geometry.camera import StereoPair

    if (args.camera is None) == (args.pair is None):
        raise InputError("give either --camera CAMERA.yaml or --pair PAIR.yaml [--side "
                         "left|right]")
    if args.camera is not None:
        if args.side is not None:
            raise InputError("--side goes with --pair (a camera file has one camera)")
        return load_camera(args.camera)
    pair = StereoPair.load(args.pair)
    return pair.right if args.side == "right" else pair.left


# -- localize -----------------------------------------------------------------------------
def cmd_localize(args: argparse.Namespace) -> int:
    import numpy as np

    from stationd.config import load_station_config
    from stationd.geometry.camera import StereoPair
    from stationd.imageio import read_image
    from stationd.localize.stereo import localize

    if args.repeat < 1:
        raise InputError("--repeat must be at least 1")
    cfg = load_station_config(args.config)
    pair = StereoPair.load(args.pair)
    baseline = float(np.linalg.norm(pair.T))
    if not np.isfinite(baseline) or baseline < 1e-6:
        raise InputError(f"{args.pair}: T: the baseline is {baseline:g} mm; two cameras at "
                         "one place cannot triangulate (is T in mm, from calibrate stereo?)")
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
        print(f"not found: {res.said}")
    return EXIT_OK if res.found else EXIT_NOT_FOUND


# -- marker -------------------------------------------------------------------------------
def cmd_marker(args: argparse.Namespace) -> int:
    from stationd.config import load_station_config
    from stationd.vision.printable import marker_svg

    out = Path(args.out)
    if out.suffix.lower() != ".svg":   # the print is SVG: a .png of SVG text opens nowhere
        raise InputError(f"{out}: the marker is written as SVG: give a .svg file name")
    from stationd.outfile import refuse_to_replace, write_atomic

    refuse_to_replace(out, "the marker", ("svg",))   # through a symlink too: its target
    cfg = load_station_config(args.config)
    write_atomic(out, marker_svg(cfg.marker))        # replaces a link, never writes through
    m = cfg.marker
    print(f"wrote {out}: white r={m.inner_mm:g} mm, black ring to r={m.outer_mm:g} mm, purple "
          f"field {2 * m.field_mm:g} mm square; print at 100 % scale")
    return EXIT_OK


# -- tune-color ---------------------------------------------------------------------------
def _results_file(text: str) -> str:
    """A benchmark's ``--out``: checked before a run of minutes, not after it (a file that
    cannot be written would otherwise lose the run)."""
    import os

    if Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text}: is a folder; give a file name")
    if Path(text).exists() and not os.access(text, os.W_OK):
        raise argparse.ArgumentTypeError(f"{text}: exists and is not writable")
    from stationd.outfile import refuse_to_replace
    try:   # an earlier benchmark's JSON may be replaced, nothing else
        refuse_to_replace(Path(text), "benchmark results", ("json",))
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
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
    from stationd.outfile import refuse_to_replace
    from stationd.vision.color import tune_hsv, verify_marker, write_hsv_yaml

    refuse_to_replace(Path(args.out), "HSV ranges", ("hsv",))
    image = read_image(args.reference)
    roi = _parse_roi(args.roi) if args.roi else None
    if roi is not None:
        h, w = image.shape[:2]
        x, y, rw, rh = roi
        if x + rw > w or y + rh > h:
            raise InputError(f"--roi {args.roi}: outside the {w}x{h} image")
    # Only a verified marker's purple is measured, and the tuned box must still find it:
    # otherwise nothing is written (exit 1, the reason on stderr).
    reason = verify_marker(image, roi=roi)
    if reason is None:
        ranges = tune_hsv(image, roi)
        lost = verify_marker(image, ranges, roi)
        reason = None if lost is None else f"the tuned ranges would lose the marker ({lost})"
    if reason is not None:
        sys.stderr.write(f"stationd: tune-color: {args.reference}: {reason}; nothing "
                         "written\n")
        return EXIT_NOT_FOUND
    out = Path(args.out)
    write_hsv_yaml(out, ranges, source=str(args.reference), roi=roi)
    print(f"wrote {out}: h {list(ranges.h)}, s {list(ranges.s)}, v {list(ranges.v)}; "
          f"use it with 'vision: {{hsv: {out.name}}}' in the station config")
    return EXIT_OK


# -- bench / demo / sim -------------------------------------------------------------------
def cmd_sim(args: argparse.Namespace) -> int:
    from stationd.sim.devices_cli import run

    return run(args)


# -- bench / demo -------------------------------------------------------------------------
def cmd_bench(args: argparse.Namespace) -> int:
    from stationd.bench.vision import run_vision_bench

    return run_vision_bench(args)


def _nice(text: str) -> int | str:
    """``--browser-nice``: a niceness step (an integer), or ``idle`` (SCHED_IDLE)."""
    if text == "idle":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: a number or idle") from None


def cmd_bench_station(args: argparse.Namespace) -> int:
    from stationd.bench.station import run_station_bench

    return run_station_bench(args)


def cmd_bench_chain(args: argparse.Namespace) -> int:
    from stationd.bench.chain import run_chain_bench

    return run_chain_bench(args)


def cmd_bench_linkcut(args: argparse.Namespace) -> int:
    from stationd.bench.linkcut import run_linkcut_bench

    return run_linkcut_bench(args)


def cmd_bench_line(args: argparse.Namespace) -> int:
    from stationd.bench.line import run_line_bench

    return run_line_bench(args)


def cmd_run(args: argparse.Namespace) -> int:
    """``stationd run``; on a station with ``sim://`` devices, with the simulated world (and,
    with ``--sim-operator``, its operator) inside the daemon, beside each station it runs."""
    from stationd.stopping import take_reloads

    take_reloads()   # a SIGHUP while the files are read is a reload, not the daemon's end
    from stationd.shell.serve import run_daemon
    from stationd.stationcheck import validate_station

    if args.no_sim_supervisor and not args.sim_operator:
        raise InputError("--no-sim-supervisor goes with --sim-operator (without it no "
                         "simulated supervisor runs: every decision is people's already)")
    cfg = validate_station(args.config)   # before a simulated world is built around it
    if not args.sim_operator and not _simulated(cfg):
        return run_daemon(args)
    # the simulator, loaded by the command line alone (never by the runtime)
    from stationd.sim.in_daemon import SimulatedStation

    sim = SimulatedStation(cfg, operator=args.sim_operator,
                           supervisor=not args.no_sim_supervisor)
    try:
        return run_daemon(args, beside=sim.beside)
    finally:
        sim.close()


def _simulated(cfg: Any, cameras_only: bool = False) -> bool:
    """Whether a station has a simulated device (its driver says): asked here, so that a
    station of real devices never loads the simulator."""
    from drivers.devices import Kind, simulated

    urls = [*((Kind.CAMERA, u) for u in cfg.cameras.values()),
            *(() if cameras_only else ((Kind.LIFT, cfg.lift.url), (Kind.WRENCH, cfg.wrench.url)))]
    return any(simulated(kind, str(url)) for kind, url in urls)


def cmd_calibrate_check(args: argparse.Namespace) -> int:
    """``stationd calibrate check``, with the simulated world in this process when the
    station's cameras are ``sim://`` (checked here, they would find none)."""
    from drivers.camera.sim import registered_worlds
    from stationd.config import load_station_config
    from stationd.refcheck_cli import cmd_calibrate_check as check

    cfg = load_station_config(args.config, station=True)
    if not _simulated(cfg, cameras_only=True) or set(cfg.pairs) <= set(registered_worlds()):
        return check(args)     # real cameras, or a world this process has already (a test's)
    from stationd.sim.world import World

    world = World(cfg, seed=0)
    try:
        return check(args)
    finally:
        world.close()


def cmd_bench_soak(args: argparse.Namespace) -> int:
    from stationd.bench.soak import run_soak

    return run_soak(args)


def cmd_demo(args: argparse.Namespace) -> int:
    # options that contradict each other or do nothing here: said, not silently dropped
    if args.no_http and args.http is not None:
        raise InputError("--no-http with --http: one or the other")
    if args.no_opcua and args.opcua is not None:
        raise InputError("--no-opcua with --opcua: one or the other")
    if args.hold and args.no_http and args.no_opcua:
        raise InputError("--hold with --no-http and --no-opcua: --hold keeps serving the "
                         "screens or the OPC UA endpoint, and neither is served")
    if args.save is not None and not args.vision:
        raise InputError("--save writes the vision demo's images: it goes with --vision")
    if args.vision and (args.http is not None or args.hold):
        raise InputError("--http and --hold serve the station demo's screens, not --vision's")
    if args.vision and (args.opcua is not None or args.line_db is not None
                        or args.stations != 1 or args.no_sim_supervisor):
        raise InputError("--opcua, --line-db, --stations and --no-sim-supervisor go with the "
                         "station demo, not --vision")
    if args.no_sim_supervisor and args.stations != 1:
        raise InputError("--no-sim-supervisor with --stations: a person releases the locks at "
                         "the first station's screens; the others have none, and their locks "
                         "would wait for good")
    if args.vision:
        from stationd.demo.vision import run_demo

        return int(run_demo(args))
    from stationd.demo.station import run_station_demo

    return run_station_demo(args)


@functools.cache
def _parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of ``command`` (see :func:`build_parser`), built once per process and
    command: parsing never changes it, and a process that runs many commands (the tests run
    thousands) pays it once."""
    return build_parser(command)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The command line's parser: every command, or ``command``'s group alone.

    Why the one group: each group's module imports what its commands need (the core's words,
    numpy, the simulated controller), 0.3 s of every run when all are built, paid again by
    every command a script or the suite starts; ``stationd status`` needs none of the vision's.
    A run names its command first, so the others are never asked for; help on the command line
    itself (``stationd -h``, a command not known) builds them all and lists them all."""
    from stationd.release import release

    p = _Parser(prog="stationd", description="Vision-guided bolt-tightening station.")
    p.add_argument("--version", action="version", version=f"stationd {release()}")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bars (they are also off when stderr is not a terminal)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for names, add in _GROUPS:
        if command is None or command in names:
            add(sub)
    _quiet_everywhere(p)
    return p


def command_word(argv: Sequence[str]) -> str | None:
    """The command ``argv`` names, when one it can parse alone: its first word not an option
    (the top-level options take no value), a known command, with no help or version asked
    before it (they list every command).  None: build every command."""
    for word in argv:
        if word in ("-h", "--help", "--version"):
            return None
        if not word.startswith("-"):
            return word if any(word in names for names, _ in _GROUPS) else None
    return None


def _add_calibrate(sub: Any) -> None:
    from stationd.calibrate_cli import add_calibrate_parser

    add_calibrate_parser(sub)
    _subcommand(sub, "calibrate", "check").set_defaults(func=cmd_calibrate_check)


def _add_probe(sub: Any) -> None:
    from stationd.probe import add_probe_parser

    add_probe_parser(sub)


def _add_db_and_config(sub: Any) -> None:
    from stationd.db_cli import add_config_parser, add_db_parser

    add_db_parser(sub)
    add_config_parser(sub)


def _add_commands(sub: Any) -> None:
    from stationd.command_cli import add_command_parsers

    add_command_parsers(sub)


def _add_teach(sub: Any) -> None:
    from stationd.teach_cli import add_teach_parser

    add_teach_parser(sub)


def _add_line(sub: Any) -> None:
    from stationd.line_cli import add_line_parser

    add_line_parser(sub)


def _add_vision_parsers(sub: Any) -> None:
    """The vision's commands on images: detect, localize, marker, tune-color."""
    d = sub.add_parser("detect", help="localize the marker in one image")
    d.add_argument("image", help="the image (PNG, TIFF, ...; `stationd demo --vision --save DIR` "
                   "renders some)")
    d.add_argument("--camera", help="camera YAML (K, dist, size)")
    d.add_argument("--pair", help="pair YAML (from calibrate stereo): use one of its cameras")
    d.add_argument("--side", choices=("left", "right"),
                   help="with --pair: which camera took the image (default left)")
    d.add_argument("--config", help="station YAML (marker, vision)")
    d.add_argument("--json", action="store_true", help="print one JSON object")
    d.add_argument("--draw", metavar="OUT.png", help=DRAW_HELP)
    d.set_defaults(func=cmd_detect)

    lo = sub.add_parser("localize", help="localize the marker in a stereo pair (mm)")
    lo.add_argument("left", help="the left camera's image")
    lo.add_argument("right", help="the right camera's image, taken at the same instant")
    lo.add_argument("--pair", required=True, help="pair YAML (left, right, R, T)")
    lo.add_argument("--config", help="station YAML (marker, vision)")
    lo.add_argument("--json", action="store_true", help="print one JSON object")
    lo.add_argument("--repeat", type=int, default=1,
                    help="localize N times on the loaded images and report timings")
    lo.set_defaults(func=cmd_localize)

    mk = sub.add_parser("marker", help="write a printable marker (SVG, true scale)")
    mk.add_argument("--out", default="marker.svg", help="SVG file to write (default: "
                    "%(default)s); print it at 100 %% scale")
    mk.add_argument("--config", help="station YAML (marker sizes)")
    mk.set_defaults(func=cmd_marker)

    tc = sub.add_parser("tune-color", help="derive HSV ranges from a well-lit reference image")
    tc.add_argument("reference", help="an image of the marker under the station's light")
    tc.add_argument("--roi", help="x,y,w,h of the marker's purple field in the image")
    tc.add_argument("--out", default="hsv.yaml",
                    help="HSV file to write (the station config reads it as vision.hsv)")
    tc.set_defaults(func=cmd_tune_color)


def _add_bench_parser(sub: Any) -> None:
    """``stationd bench``: the benchmarks that print figures."""
    b = sub.add_parser("bench", help="benchmarks that print figures")
    bsub = b.add_subparsers(dest="bench", required=True, parser_class=_Parser)
    bv = bsub.add_parser("vision", help="the paper's experiments on rendered images")
    bv.add_argument("--out", default="bench-vision.json", type=_results_file,
                    help="JSON results file")
    bv.add_argument("--quick", action="store_true", help="fewer samples (a smoke run)")
    bv.add_argument("--only", help="comma-separated sections: "
                    "radii,centre,rod,saltpepper,lowlight,speed,robustness")
    bv.add_argument("--seed", type=seed_arg, default=1, help="(default: %(default)s)")
    bv.set_defaults(func=cmd_bench)
    bc = bsub.add_parser("chain", help="the whole chain: calibration, vehicle frame, rod, bolts")
    bc.add_argument("--out", default="bench-chain.json", type=_results_file,
                    help="JSON results file")
    bc.add_argument("--quick", action="store_true", help="2 pairs, fewer samples")
    bc.add_argument("--seed", type=seed_arg, default=1, help="(default: %(default)s)")
    bc.set_defaults(func=cmd_bench_chain)
    bs = bsub.add_parser("station", help="the daemon on the simulated station: latency from "
                         "frame exposure to acknowledged parameters, memory")
    bs.add_argument("--out", default="bench-station.json", type=_results_file,
                    help="JSON results file")
    bs.add_argument("--cycles", type=int, default=20, help="bolts to select and tighten")
    bs.add_argument("--seed", type=seed_arg, default=1, help="(default: %(default)s)")
    bs.add_argument("--json", action="store_true", help="print one summary object")
    bs.add_argument("--browsers", type=int, default=0, metavar="N",
                    help="run the plan again with the screens served and N headless Chromium "
                    "windows on / and /cameras; print latency and the daemon's CPU with and "
                    "without")
    bs.add_argument("--clients", choices=("chromium", "sse"), default="chromium",
                    help="with --browsers: real headless Chromium on this machine's cores "
                    "(default), or SSE readers and frame loaders in a process of their own "
                    "making the same requests, as browsers on the panel PCs would (the "
                    "daemon's own cost, without browsers rendering beside it)")
    bs.add_argument("--passes", type=int, default=1, metavar="K",
                    help="with --browsers (or --opcua, --line): alternate K passes with the "
                    "screens (the services) and K without (after a first without), pooled "
                    "(default: %(default)s)")
    bs.add_argument("--opcua", action="store_true",
                    help="run the plan again with the OPC UA server and an MES subscribed in "
                    "its own process: each result event's delay after the result was stored, "
                    "and the latency with and without")
    bs.add_argument("--line", action="store_true",
                    help="run the plan again forwarding to a throw-away line PostgreSQL (with "
                    "--opcua: both); the latency with and without")
    bs.add_argument("--paired", action="store_true",
                    help="with --browsers: within each pass with the screens, hold the "
                    "clients (SIGSTOP) on every other bolt and compare the bolts with them "
                    "running against those with them held (the same machine, the same pass)")
    bs.add_argument("--browser-nice", type=_nice, default=5, metavar="N|idle",
                    help="with --browsers: run Chromium N steps below the daemon's priority, "
                    "as on a station PC where the unit's Nice=-5 puts the daemon above a "
                    "kiosk browser at 0 (default: %(default)s; 0: the same priority); idle: "
                    "under SCHED_IDLE, as a kiosk unit with CPUSchedulingPolicy=idle (it "
                    "runs only on a core the daemon leaves free)")
    bs.set_defaults(func=cmd_bench_station)
    bx = bsub.add_parser("linkcut", help="the daemon with its controller on Open Protocol: "
                         "a link cut during a run of tightenings (none lost), and the cost of "
                         "curves on the latency")
    bx.add_argument("--out", default="bench-linkcut.json", type=_results_file,
                    help="JSON results file")
    bx.add_argument("--cycles", type=int, default=30,
                    help="placements of the wrench in each pass (default: %(default)s)")
    bx.add_argument("--cut-s", type=float, default=10.0, metavar="S",
                    help="how long the link is cut (default: %(default)s)")
    bx.add_argument("--pace-s", type=float, default=1.0, metavar="S",
                    help="seconds per placement while the link is down (default: "
                    "%(default)s)")
    bx.add_argument("--passes", type=int, default=1, metavar="K",
                    help="passes without and with curves, alternating (default: %(default)s)")
    bx.add_argument("--seed", type=seed_arg, default=1, help="(default: %(default)s)")
    bx.add_argument("--json", action="store_true", help="print one summary object")
    bx.set_defaults(func=cmd_bench_linkcut)
    bk = bsub.add_parser("soak", help="the daemon through a long shift: outages, reworks, load")
    bk.add_argument("--bolts", type=int, default=100,
                    help="bolts to tighten in all (default: %(default)s)")
    bk.add_argument("--per-vehicle", type=int, default=10,
                    help="bolts per vehicle (default: %(default)s)")
    bk.add_argument("--faults", action="store_true", help="device outages (lift, controller, "
                    "also mid-tightening, camera pairs), reloads (valid, refused, lift down) "
                    "and reworks")
    bk.add_argument("--load", type=int, default=0, help="busy processes during the run")
    bk.add_argument("--seed", type=int, default=1, help="(default: %(default)s)")
    bk.add_argument("--json", action="store_true", help="print one summary object")
    bk.set_defaults(func=cmd_bench_soak)
    bl = bsub.add_parser("line", help="a line's stations forwarding to one PostgreSQL: "
                         "throughput, lag, a backlog drained")
    bl.add_argument("--stations", type=int, default=30, help="(default: %(default)s)")
    bl.add_argument("--rundowns", type=int, default=20, metavar="N",
                    help="rundowns per station under normal load (default: %(default)s)")
    bl.add_argument("--interval", type=float, default=2.0, metavar="S",
                    help="seconds between a station's rundowns (default: %(default)s)")
    bl.add_argument("--backlog", type=int, default=10_000, metavar="N",
                    help="rundowns recorded by the stations between them while the line "
                    "database is away, drained after (0: none; default: %(default)s)")
    bl.add_argument("--station-backlog", type=int, default=10_000, metavar="N",
                    help="then the same for one station alone, its own forwarder draining "
                    "while it records (0: none; default: %(default)s)")
    bl.add_argument("--pg", metavar="URL", help="the line database (postgresql+psycopg://...; "
                    "default: a throw-away server started for the run); its tables keep the "
                    "benchmark's rows (station ids BENCH-NN, new database ids)")
    bl.add_argument("--seed", type=seed_arg, default=1, help="(default: %(default)s)")
    bl.add_argument("--json", action="store_true", help="print one summary object")
    bl.set_defaults(func=cmd_bench_line)


def _add_run_and_sim_parsers(sub: Any) -> None:
    """``stationd run`` (the daemon) and ``stationd sim`` (a simulated device on its real
    protocol)."""
    rn = sub.add_parser("run", help="the station daemon (as systemd runs it)")
    rn.add_argument("--config", required=True, help="station YAML")
    rn.add_argument("--sim-operator", action="store_true",
                    help="a simulated station (sim:// lift, controller and cameras) with a "
                    "scripted operator: vehicles arrive, the wrench visits bolts, the "
                    "controller tightens (now and then NOK); without it the simulated lift "
                    "stays down (commands on standard input: next, raise, lower, ...)")
    rn.add_argument("--no-sim-supervisor", action="store_true",
                    help="with --sim-operator: no simulated supervisor; locks (and every "
                    "supervisor decision) are left to people: the first bolt of each vehicle "
                    "locks, the operator tightens the others and waits, the vehicle on the "
                    "lift, until a person releases it (the screens' Release form, stationd "
                    "release)")
    rn.set_defaults(func=cmd_run)

    sm = sub.add_parser("sim", help="the simulated lift PLC or tightening controller on its "
                        "real protocol, to commission a station or a client against")
    sim_sub = sm.add_subparsers(dest="sim_device", required=True)
    plc = sim_sub.add_parser("plc", aliases=["lift"],
                             help="the lift PLC, Modbus TCP on 127.0.0.1 (also: sim lift)")
    plc.add_argument("--config", help="station file: its lift register map (else defaults)")
    plc.add_argument("--port", type=port_arg, default=5020, help="TCP port (%(default)s)")
    plc.add_argument("--unit", type=unit_arg, metavar="N",
                     help="the Modbus unit id it serves (default: the station file's lift "
                          "URL's unit=, else 1)")
    plc.add_argument("--model-code", type=int, default=1,
                     help="the vehicles' model code (%(default)s)")
    plc.add_argument("--every", type=float, default=0.0, metavar="SECONDS",
                     help="cycle vehicles, each at working height this long (default: "
                          "commands on standard input)")
    plc.set_defaults(sim_device="plc")
    ctl = sim_sub.add_parser("controller", aliases=["wrench"],
                             help="the tightening controller, Open Protocol (also: sim wrench)")
    ctl.set_defaults(sim_device="controller")
    ctl.add_argument("--config", help="station file: the psets of its bolt table")
    ctl.add_argument("--host", default="127.0.0.1", help="address to listen on (%(default)s)")
    ctl.add_argument("--port", type=port_arg, default=4545, help="TCP port (%(default)s)")
    ctl.add_argument("--seed", type=seed_arg, default=0, help="result scatter (%(default)s)")
    ctl.add_argument("--nok-rate", type=float, default=0.05,
                     help="share of NOKs (%(default)s)")
    ctl.add_argument("--link-ack", action="store_true",
                     help="acknowledge at link level (MID 9997/9998)")
    ctl.add_argument("--trigger-every", type=float, default=0.0, metavar="SECONDS",
                     help="pull the trigger at this interval when the tool may run (off)")
    from drivers.wrench.sim.cli import add_behaviour_options  # result types, mislabel, clock

    add_behaviour_options(ctl)
    sm.set_defaults(func=cmd_sim)


def _add_demo_parser(sub: Any) -> None:
    """``stationd demo``: the main job, a simulated run."""
    dm = sub.add_parser("demo", help="the main job: a simulated run")
    dm.add_argument("--seed", type=seed_arg, default=7, help="(default: %(default)s)")
    dm.add_argument("--cycles", type=int, default=10, help="bolts to tighten (with --vision: "
                    "marker placements to localize; default: %(default)s)")
    dm.add_argument("--config", help="station YAML (default: config/sim/station.yaml)")
    dm.add_argument("--vision", action="store_true",
                    help="only the vision demo: render stereo pairs, localize, print errors")
    dm.add_argument("--save", help="with --vision: also write the images and pair.yaml here")
    dm.add_argument("--json", action="store_true", help="print one summary object")
    dm.add_argument("--http", metavar="HOST:PORT", help="serve the screens here (default: the "
                    "station file's http.listen, else 127.0.0.1:8080)")
    dm.add_argument("--no-http", action="store_true", help="do not serve the screens")
    dm.add_argument("--hold", action="store_true", help="after the run, keep serving the "
                    "screens (results, export) and the OPC UA endpoint until Ctrl-C")
    dm.add_argument("--opcua", metavar="HOST:PORT", help="serve the station's OPC UA endpoint "
                    "here (default: 127.0.0.1:4840, or the next free port; port 0: any free "
                    "one); security none, anonymous read and subscribe")
    dm.add_argument("--no-opcua", action="store_true", help="do not serve OPC UA")
    dm.add_argument("--line-db", metavar="URL", help="forward the station's records to this "
                    "line database (postgresql+psycopg://USER@HOST:PORT/DB)")
    dm.add_argument("--stations", type=int, default=1, metavar="N",
                    help="N simulated stations of one line (after the first, light ones, one "
                    "after another), forwarding to --line-db or, without it, a throw-away "
                    "PostgreSQL (default: %(default)s)")
    dm.add_argument("--no-sim-supervisor", action="store_true",
                    help="no simulated supervisor: locks (and every supervisor decision) are "
                    "left to people: the first bolt locks, the operator tightens the others "
                    "and waits until a person releases it (the screens' Release form, "
                    "stationd release); Ctrl-C ends the wait")
    dm.add_argument("--load", type=int, default=0, metavar="N",
                    help="N busy processes beside the station for the run (CPU load)")
    dm.set_defaults(func=cmd_demo)


#: the top-level commands by the function adding them, in the order help lists them (a
#: test checks the names against what each function adds)
_GROUPS: tuple[tuple[tuple[str, ...], Callable[[Any], None]], ...] = (
    (("detect", "localize", "marker", "tune-color"), _add_vision_parsers),
    (("bench",), _add_bench_parser),
    (("calibrate",), _add_calibrate),
    (("probe",), _add_probe),
    (("db", "config"), _add_db_and_config),
    (("skip", "reopen", "release", "loosen", "enter-outcome", "operator", "feed", "user",
      "status"), _add_commands),
    (("teach",), _add_teach),
    (("line",), _add_line),
    (("run", "sim"), _add_run_and_sim_parsers),
    (("demo",), _add_demo_parser),
)


def _subcommand(sub: Any, *names: str) -> argparse.ArgumentParser:
    """The parser of ``stationd NAME SUBNAME ...`` (to set what it runs from here)."""
    parser: argparse.ArgumentParser = sub.choices[names[0]]
    for name in names[1:]:
        action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = action.choices[name]
    return parser


def _quiet_everywhere(parser: argparse.ArgumentParser) -> None:
    """``--quiet`` is accepted after the sub-command too (``stationd demo --quiet``), where
    a user types it; SUPPRESS keeps a leaf from resetting the top-level flag."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in action.choices.values():
                if not any(a.dest == "quiet" for a in child._actions):
                    child.add_argument("-q", "--quiet", action="store_true",
                                       default=argparse.SUPPRESS, help=argparse.SUPPRESS)
                _quiet_everywhere(child)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command of ``argv`` (the process's own arguments when None) and return its
    exit code.

    Why the signals are taken here, once, rather than by each command: a Ctrl-C or a SIGTERM
    may come at any moment, while a module loads, while the parser is built, while a command
    waits on a server that does not answer, while a demo starts its simulators; one place
    turns either into one line and 130 (143) wherever it lands.  Both raise a
    KeyboardInterrupt in the main thread (an asyncio command's tasks are cancelled by
    ``asyncio.run`` for either), and whatever a library makes of it on its way up (numpy
    turns one that lands in its C import into an ImportError) is taken for the signal it
    was.  A command that takes the signals itself (``stationd run`` stops its station in
    order, ``demo --hold`` ends its hold, ``demo --no-sim-supervisor`` the people's wait) does
    so inside."""
    outfile = sys.modules.get("stationd.outfile")
    if outfile is not None:
        outfile.forget_written()
    with _signals(restore=argv is not None) as stopped:
        try:
            if stopped.signal is not None:   # came as the handlers were put in
                raise KeyboardInterrupt
            code = _main(argv, stopped)
            if stopped.signal is None:
                return code
            raise KeyboardInterrupt   # one deferred and not raised before the command ended
        except SystemExit:
            raise
        except BaseException:
            if stopped.signal is None:
                raise
            code = _stopped(stopped)
            if argv is None:   # the process's own command: it ends here (see _end)
                _end(code)
            return code


def _end(code: int) -> NoReturn:
    """End the process now with ``code``, its line said and its files whole or removed.

    Why not by returning it: a KeyboardInterrupt (our signals' way up) that passed through C
    code running Python code (an extension's import at the demo's start) leaves CPython's
    "unhandled KeyboardInterrupt" flag set although the command handled it, and the
    interpreter then ends itself by SIGINT (-2 to the parent, 130 from a shell) whatever code
    was returned: a SIGTERM read as a Ctrl-C, 1 start in 5.  What is buffered is flushed
    first; the command's own cleanup (``finally`` blocks, its temporary folder) has run."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass   # closed: the code still says it
    logging.shutdown()
    os._exit(code)


class _Stopped:
    """The signal that stopped the command (None: none came)."""

    signal: int | None = None


#: a signal that lands in the import machinery's own code is asked again this much later,
#: at most this many times in a row (then raised wherever it lands)
DEFER_S, DEFER_TIMES = 0.02, 50


@contextmanager
def _signals(restore: bool) -> Iterator[_Stopped]:
    """SIGINT and SIGTERM raise a KeyboardInterrupt in the main thread, remembered in the
    yielded :class:`_Stopped` (a SIGINT ignored from the start, a background job's, stays
    ignored).  ``restore``: put the previous handlers back at the end (a caller that goes on,
    such as a test calling :func:`main`).  Otherwise the process ends after this: both
    signals get their defaults, so one that comes while the interpreter exits (its output
    said, its files written or removed) ends it by the signal itself, the shell's 130 or 143,
    silently, instead of a traceback from ``threading._shutdown`` or a module's finalizer."""
    stopped = _Stopped()
    if threading.current_thread() is not threading.main_thread():
        yield stopped     # signals reach the main thread only: nothing to take over here
        return

    deferred: list[int] = [0]
    pending: list[threading.Timer] = []      # the one signal asked again, if any

    def again(signum: int) -> None:
        if signal.getsignal(signum) is on_signal:   # not after the handlers were put back
            os.kill(os.getpid(), signum)

    def later(signum: int) -> None:
        """Ask for ``signum`` again a moment later (a bounded number of times in a row)."""
        deferred[0] += 1
        timer = threading.Timer(DEFER_S, again, (signum,))
        timer.daemon = True
        pending.append(timer)
        timer.start()

    unraisable = sys.unraisablehook

    def on_unraisable(u: Any) -> None:
        # raised by on_signal in a callback whose exceptions Python ignores (a weakref's,
        # a finalizer's: SQLAlchemy's registry as the demo started, under load), the
        # interrupt would be printed as "Exception ignored" and lost: asked again instead
        if isinstance(u.exc_value, KeyboardInterrupt) and stopped.signal is not None \
                and deferred[0] < DEFER_TIMES:
            later(stopped.signal)
            return
        unraisable(u)

    def on_signal(signum: int, frame: FrameType | None) -> None:
        if stopped.signal is None:
            stopped.signal = signum
        if stopping.deferred(signum):
            return   # a step that must be whole (stopping.held): raised again at its end
        for timer in pending:
            timer.cancel()
        pending.clear()
        if _importing(frame) and deferred[0] < DEFER_TIMES:
            # raised here (a module lock's weakref callback) the interrupt would be printed
            # as "Exception ignored" with its traceback and lost: asked again a moment later
            later(signum)
            return
        raise KeyboardInterrupt

    before = {s: signal.getsignal(s) for s in STOPPING}
    for _ in STOPPING:
        try:
            for s in STOPPING:
                if before[s] is not signal.SIG_IGN and signal.getsignal(s) is not on_signal:
                    signal.signal(s, on_signal)
            break
        except KeyboardInterrupt:
            # the signal came as the handlers were being put in (raised by this handler, in
            # place already, or by Python's own for a Ctrl-C just before): remembered, the
            # rest put in, and raised where the command begins (main): a traceback from
            # signal.signal under load, before main's own handling (the suite, once)
            if stopped.signal is None:
                stopped.signal = signal.SIGINT
    sys.unraisablehook = on_unraisable
    try:
        yield stopped
    finally:
        sys.unraisablehook = unraisable
        for timer in pending:   # a signal deferred and not raised: main() says it
            timer.cancel()
        signal.pthread_sigmask(signal.SIG_BLOCK, STOPPING)   # no signal while they change
        try:
            for s, handler in before.items():
                if not restore and handler is not signal.SIG_IGN:
                    handler = signal.SIG_DFL
                # a handler installed outside Python reads as None: the default then
                signal.signal(s, signal.SIG_DFL if handler is None else handler)
        finally:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, STOPPING)


def _importing(frame: FrameType | None) -> bool:
    """Whether ``frame``, the one a signal interrupted, is the import machinery's own code,
    where an exception from a signal handler can land in a callback that prints it and goes
    on (``_get_module_lock``'s weakref callback).  Only the innermost frame: a module's own
    code run by an import (seconds, or hung) is interrupted at once."""
    return frame is not None and frame.f_code.co_filename.startswith("<frozen importlib")


def _stopped(stopped: _Stopped) -> int:
    """The one line and the code of a command stopped by a signal.  From here on, a second
    signal ends the process at once (the defaults), silently: the line is said, the files the
    command was writing are either whole or removed (written beside and renamed,
    :func:`stationd.outfile.write_all`), and the line names those already in place."""
    for s in STOPPING:
        if signal.getsignal(s) is not signal.SIG_IGN:
            signal.signal(s, signal.SIG_DFL)
    line, code = STOPPED_WORDS.get(signal.Signals(stopped.signal or signal.SIGINT),
                                   STOPPED_WORDS[signal.SIGINT])
    try:
        sys.stderr.write(f"{line}{_after_writing()}\n")
        sys.stderr.flush()
    except (OSError, ValueError):
        pass   # stderr closed (a terminal that hung up): the code still says it
    return code


def _after_writing() -> str:
    """What a stopped command had already put in place, for its stop line: a file written
    whole just before the signal (the rename done, "wrote" not said yet) is there, and the
    line says so rather than leaving the user to think nothing was written."""
    outfile = sys.modules.get("stationd.outfile")   # not loaded: nothing was written
    files = outfile.written() if outfile is not None else ()
    if not files:
        return ""
    if len(files) <= 3:
        return " after writing " + ", ".join(printable(str(f)) for f in files)
    return f" after writing {len(files)} files, the last {printable(str(files[-1]))}"


def _main(argv: Sequence[str] | None, stopped: _Stopped) -> int:
    with held():   # a signal in a C extension's import: numpy's PyCapsule_Import makes it
                   # an ImportError, or a module is left half made
        from stationd import progress
        from stationd.logsetup import quiet_opencv

        quiet_opencv()   # OpenCV's own warnings are no lines of ours (before it loads)
        words = list(sys.argv[1:] if argv is None else argv)
        parser = _parser(command_word(words))
        reported = _reported()
    _Parser.argv = words
    args = parser.parse_args(words)
    func: Callable[[argparse.Namespace], int] = args.func
    progress.configure(quiet=bool(getattr(args, "quiet", False)))
    try:
        code = func(args)
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit
        return code
    except reported as exc:
        if stopped.signal is not None:   # a library's words for the interruption
            raise
        from stationd.logsetup import error_mark

        sys.stderr.write(f"{error_mark()}stationd: error: "
                         f"{printable(str(exc), keep=chr(10))}\n")
        return EXIT_BAD_INPUT
    except BrokenPipeError:
        # ``stationd db report VIN | head``: the reader has all it wanted, quietly; but the
        # command's own answer was not given, so no success either.  Point stdout at
        # /dev/null so the interpreter's final flush does not fail a second time.
        _silence_stdout()
        return EXIT_SIGPIPE


def _silence_stdout() -> None:
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass  # stdout is not a real file (a test's capture): nothing to flush
