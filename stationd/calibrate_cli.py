"""``stationd calibrate stereo|camera``: calibrate the camera pair, or one camera, from board
images.  ``stereo`` writes the pair file and each camera's own file (what ``detect --camera``
reads), so the calibration chain feeds itself; every file is written or none is.

Kept apart from ``stationd.cli`` so the calibration command can be wired in with one call
(:func:`add_calibrate_parser`) and tested without the rest of the command line.  Bad input is
an :class:`~stationd.errors.InputError` (``stationd`` turns it into one line and exit code 2).
"""

from __future__ import annotations

import argparse
import glob
import os
import re
import sys
import tempfile
from pathlib import Path
from typing import Any

import yaml

from stationd.errors import InputError
from stationd.jsonout import strict_json
from stationd.outfile import refuse_to_replace

EXIT_OK = 0


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


def write_all(files: list[tuple[Path, str]]) -> None:
    """Write every file or none: each goes to a temporary file beside it first, and the
    renames happen only once all are written (a full disk or a missing folder leaves no
    half-written calibration behind)."""
    temps: list[tuple[str, Path]] = []
    try:
        for path, text in files:
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent or ".")
            temps.append((tmp, path))
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
        for tmp, path in temps:
            os.replace(tmp, path)
    except OSError as exc:
        for tmp, _ in temps:
            Path(tmp).unlink(missing_ok=True)
        where = exc.filename or (files[len(temps) - 1][0] if temps else files[0][0])
        raise InputError(f"{where}: cannot write: {exc.strerror}") from None


def _check_outputs(paths: list[Path]) -> None:
    """Before minutes of corner detection: every output's folder exists, no two coincide."""
    if len({p.resolve() for p in paths}) != len(paths):
        raise InputError("the output files must differ: " + ", ".join(map(str, paths)))
    for p in paths:
        if not p.parent.is_dir():
            raise InputError(f"{p}: no such folder {p.parent}")
        if p.is_dir():
            raise InputError(f"{p}: is a folder, expected a file name")
        # an earlier calibration may be replaced; a station file, a database, ... may not
        refuse_to_replace(p, "a calibration", ("yaml",))


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
    _check_outputs([out, out_left, out_right])
    left = expand_images(list(args.left), "--left")
    right = expand_images(list(args.right), "--right")
    report = calibrate_stereo(left, right, board)
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
    _check_outputs([out])
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
                    "PAIR.right.yaml beside it unless --out-left / --out-right say otherwise).")
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
                    "that detect --camera reads.")
    m.add_argument("images", nargs="+", metavar="GLOB",
                   help="board images, e.g. 'cam*.png' (quoted, or expanded by the shell)")
    m.add_argument("--board", required=True, metavar="SPEC", help=BOARD_HELP)
    m.add_argument("--out", default="camera.yaml",
                   help="camera YAML to write (default camera.yaml)")
    m.add_argument("--json", action="store_true", help="print the report as one JSON object")
    m.set_defaults(func=cmd_calibrate_camera)
    from stationd.vehicle_cli import add_vehicle_parser

    add_vehicle_parser(csub)
    return c
