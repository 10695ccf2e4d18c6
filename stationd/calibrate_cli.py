"""``stationd calibrate stereo|camera``: calibrate the camera pair, or one camera, from board
images.  ``stereo`` writes the pair file and each camera's own file (what ``detect --camera``
reads), so the calibration chain feeds itself; every file is written or none is.

Kept apart from ``stationd.cli`` so the calibration command can be wired in with one call
(:func:`add_calibrate_parser`) and tested without the rest of the command line.  Bad input is
an :class:`~stationd.errors.InputError` (``stationd`` turns it into one line and exit code 2).
"""

from __future__ import annotations

import argparse
import filecmp
import glob
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml

from stationd.errors import InputError
from stationd.jsonout import strict_json
from stationd.outfile import refuse_to_replace, write_all

if TYPE_CHECKING:
    from stationd.geometry.camera import StereoPair

EXIT_OK, EXIT_REFUSED = 0, 1
#: what each output may replace: its own kind of calibration (an earlier run's), nothing else
PAIR_FILE = ("a stereo pair calibration", ("pair",))
CAMERA_FILE = ("a camera calibration", ("camera",))


def _natural_key(path: str) -> list[Any]:
    """``L2.png`` before ``L10.png``: cameras number their frames without leading zeros."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path)]


def expand_images(patterns: list[str], option: str) -> list[str]:
    """Expand glob patterns (quoted, or already expanded by the shell) into a sorted list.
    Left and right images are paired by position, so the order must be reproducible."""
    found: list[str] = []
    for pattern in patterns:
        matches = glob.glob(pattern) if glob.has_magic(pattern) else (
            [pattern] if Path(pattern).exists() else [])
        if not matches:
            raise InputError(f"{option} {pattern!r}: matches no file")
        found.extend(sorted(matches, key=_natural_key))
    return found


def _side_file(out: Path, side: str) -> Path:
    """``pair.yaml`` -> ``pair.left.yaml``: the default name of one camera's file."""
    return out.with_name(f"{out.stem}.{side}{out.suffix or '.yaml'}")


def _check_outputs(outputs: list[tuple[Path, tuple[str, tuple[str, ...]]]]) -> None:
    """Before minutes of corner detection: every output's folder exists, no two coincide,
    none is a link, and each replaces nothing but an earlier calibration of its own kind
    (``calibrate camera --out pair.yaml`` overwrote a stereo pair calibration)."""
    paths = [p for p, _ in outputs]
    if len({p.resolve() for p in paths}) != len(paths):
        raise InputError("the output files must differ: " + ", ".join(map(str, paths)))
    for p, (writing, may_replace) in outputs:
        if not p.parent.is_dir():
            raise InputError(f"{p}: no such folder {p.parent}")
        refuse_to_replace(p, writing, may_replace)


def _refuse_same_images(left: list[str], right: list[str]) -> None:
    """The i-th left and right images must be two files with two contents: the same images
    for both cameras calibrate a pair with no baseline (3.5e-9 mm), which triangulates
    nothing."""
    if len(left) != len(right):
        return    # calibrate_stereo says so, with the counts
    same = [(lp, rp) for lp, rp in zip(left, right, strict=True)
            if filecmp.cmp(lp, rp, shallow=False)]
    if same:
        lp, rp = same[0]
        which = "all" if len(same) == len(left) else f"{len(same)} of {len(left)}"
        raise InputError(f"--left and --right give the same images ({which} pairs, e.g. {lp} "
                         f"and {rp}): each pair needs the left camera's image and the right "
                         "camera's, taken at one instant")


def _implausible_baseline(baseline_mm: float) -> str | None:
    """Why a calibrated pair's baseline cannot be a station's (the bounds the station file
    checks a pair calibration against), None when it can."""
    from stationd.deviceconfig import BASELINE_MM

    lo, hi = BASELINE_MM
    if lo <= baseline_mm <= hi:
        return None
    cause = ("the left and right images show the board from one place: the same camera "
             "twice, or copies of one image?" if baseline_mm < lo else
             "left and right images of different moments, or a wrong --board square size?")
    return (f"the calibrated baseline is {baseline_mm:.3g} mm, not a plausible stereo "
            f"baseline ({lo:g}-{hi:g} mm): {cause}")


def _swapped(pair: StereoPair) -> str | None:
    """Why the pair looks calibrated from swapped images (``--left`` given the right
    camera's), with what to do; None when it does not."""
    why = pair.swapped()
    return None if why is None else (f"{why} (--left must be the images of the camera on the "
                                     "left, seen as the cameras look; give them the other way "
                                     "round)")


def _yaml(header: str, data: dict[str, Any]) -> str:
    return header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None)


def cmd_calibrate_stereo(args: argparse.Namespace) -> int:
    """Detect the board in each pair, calibrate, print the report, write the pair YAML and
    the two camera YAMLs."""
    from stationd.geometry.calibration import calibrate_stereo, parse_board

    board = parse_board(args.board)
    out = Path(args.out)
    out_left = Path(args.out_left) if args.out_left else _side_file(out, "left")
    out_right = Path(args.out_right) if args.out_right else _side_file(out, "right")
    _check_outputs([(out, PAIR_FILE), (out_left, CAMERA_FILE), (out_right, CAMERA_FILE)])
    left = expand_images(list(args.left), "--left")
    right = expand_images(list(args.right), "--right")
    _refuse_same_images(left, right)
    report = calibrate_stereo(left, right, board)
    refused = _implausible_baseline(report.pair.baseline_mm) or _swapped(report.pair)
    if refused is not None:
        if getattr(args, "json", False):
            sys.stdout.write(strict_json({**report.to_json(), "refused": refused}) + "\n")
        else:
            print(report.format())
        sys.stderr.write(f"stationd: calibrate stereo: {refused}; nothing written\n")
        return EXIT_REFUSED
    header = (f"# stationd calibrate stereo: {board.describe()}\n"
              f"# {report.used} of {len(report.views)} image pairs used; RMS reprojection error "
              f"pair {report.rms_px:.3f} px, left {report.rms_left_px:.3f} px, right "
              f"{report.rms_right_px:.3f} px\n")
    pair = report.pair
    write_all([
        (out, _yaml(header + "# x_right = R @ x_left + T, T in mm; dist in OpenCV order k1 k2 "
                             "p1 p2 k3\n", pair.to_dict())),
        (out_left, _yaml(header + f"# the left camera of {out.name}; dist in OpenCV order k1 "
                                  "k2 p1 p2 k3\n", pair.left.to_dict())),
        (out_right, _yaml(header + f"# the right camera of {out.name}; dist in OpenCV order "
                                   "k1 k2 p1 p2 k3\n", pair.right.to_dict())),
    ])
    if getattr(args, "json", False):
        sys.stdout.write(strict_json({**report.to_json(), "out": str(out),
                                      "out_left": str(out_left),
                                      "out_right": str(out_right)}) + "\n")
    else:
        print(report.format())
        print(f"wrote {out}, {out_left}, {out_right}")
    return EXIT_OK


def cmd_calibrate_camera(args: argparse.Namespace) -> int:
    """Detect the board in each image, calibrate one camera, print the report, write the
    camera YAML (``K``, ``dist``, ``size``: what ``detect --camera`` reads)."""
    from stationd.geometry.calibration import calibrate_camera, parse_board

    board = parse_board(args.board)
    out = Path(args.out)
    _check_outputs([(out, CAMERA_FILE)])
    images = expand_images(list(args.images), "images")
    report = calibrate_camera(images, board)
    header = (f"# stationd calibrate camera: {board.describe()}\n"
              f"# {report.used} of {len(report.views)} images used; RMS reprojection error "
              f"{report.rms_px:.3f} px; dist in OpenCV order k1 k2 p1 p2 k3\n")
    write_all([(out, _yaml(header, report.camera.to_dict()))])
    if getattr(args, "json", False):
        sys.stdout.write(strict_json({**report.to_json(), "out": str(out)}) + "\n")
    else:
        print(report.format())
        print(f"wrote {out}")
    return EXIT_OK


BOARD_HELP = ("chessboard:COLSxROWS:SQUARE_MM (inner corners, e.g. chessboard:9x6:25) or "
              "charuco:COLSxROWS:SQUARE_MM:MARKER_MM:DICT (squares, e.g. "
              "charuco:11x8:20:15:DICT_5X5_100)")


def add_calibrate_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``calibrate`` (with its ``stereo`` sub-command) to the ``stationd`` sub-parsers."""
    c: argparse.ArgumentParser = subparsers.add_parser(
        "calibrate", help="calibrate cameras from board images")
    # the nested sub-parsers use the parent's parser class (one-line usage errors, exit 2)
    csub = c.add_subparsers(dest="calibrate", required=True, parser_class=type(c))
    s = csub.add_parser(
        "stereo", help="calibrate the stereo pair (K, dist of each camera; R, T in mm)",
        description="Pairs the i-th left image with the i-th right image (sorted by name, "
                    "numbers in natural order), finds the board in both, calibrates each camera "
                    "and the pair, rejects views whose error is an outlier, prints a report "
                    "and writes the pair YAML and each camera's YAML (PAIR.left.yaml, "
                    "PAIR.right.yaml beside it unless --out-left / --out-right say otherwise). "
                    "A pair whose baseline is not 20-2000 mm, or whose right camera is to the "
                    "left of its left one (left and right swapped), is refused (exit 1, "
                    "nothing written), as are the same images for both cameras (exit 2). An "
                    "output replaces only an earlier calibration of its own kind, never "
                    "another file or a link.")
    s.add_argument("--left", required=True, nargs="+", metavar="GLOB",
                   help="left images, e.g. 'L*.png' (quoted, or expanded by the shell)")
    s.add_argument("--right", required=True, nargs="+", metavar="GLOB", help="right images")
    s.add_argument("--board", required=True, metavar="SPEC", help=BOARD_HELP)
    s.add_argument("--out", default="pair.yaml", help="pair YAML to write (default pair.yaml)")
    s.add_argument("--out-left", metavar="FILE",
                   help="the left camera's YAML (default: OUT with .left before the suffix)")
    s.add_argument("--out-right", metavar="FILE",
                   help="the right camera's YAML (default: OUT with .right before the suffix)")
    s.add_argument("--json", action="store_true", help="print the report as one JSON object")
    s.set_defaults(func=cmd_calibrate_stereo)
    m = csub.add_parser(
        "camera", help="calibrate one camera (K, dist) from board images",
        description="Finds the board in each image, calibrates the camera, rejects views "
                    "whose error is an outlier, prints a report and writes the camera YAML "
                    "that detect --camera reads. --out replaces only an earlier camera "
                    "calibration, never another file (a pair calibration, a station file) "
                    "or a link.")
    m.add_argument("images", nargs="+", metavar="GLOB",
                   help="board images, e.g. 'cam*.png' (quoted, or expanded by the shell)")
    m.add_argument("--board", required=True, metavar="SPEC", help=BOARD_HELP)
    m.add_argument("--out", default="camera.yaml",
                   help="camera YAML to write (default camera.yaml)")
    m.add_argument("--json", action="store_true", help="print the report as one JSON object")
    m.set_defaults(func=cmd_calibrate_camera)
    from stationd.refcheck_cli import add_check_parser
    from stationd.vehicle_cli import add_vehicle_parser

    add_vehicle_parser(csub)
    add_check_parser(csub)
    return c
