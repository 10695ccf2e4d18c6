"""``stationd calibrate stereo``: calibrate the camera pair from board images.

Kept apart from ``stationd.cli`` so the calibration command can be wired in with one call
(:func:`add_calibrate_parser`) and tested without the rest of the command line.  Bad input is
an :class:`~stationd.errors.InputError` (``stationd`` turns it into one line and exit code 2).
"""

from __future__ import annotations

import argparse
import glob
import re
import sys
from pathlib import Path
from typing import Any

import yaml

from stationd.errors import InputError
from stationd.jsonout import strict_json

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


def cmd_calibrate_stereo(args: argparse.Namespace) -> int:
    """Detect the board in each pair, calibrate, print the report, write the pair YAML."""
    from stationd.geometry.calibration import calibrate_stereo, parse_board

    board = parse_board(args.board)
    left = expand_images(list(args.left), "--left")
    right = expand_images(list(args.right), "--right")
    report = calibrate_stereo(left, right, board)
    out = Path(args.out)
    header = (f"# stationd calibrate stereo: {board.describe()}\n"
              f"# {report.used} of {len(report.views)} image pairs used; RMS reprojection error "
              f"pair {report.rms_px:.3f} px, left {report.rms_left_px:.3f} px, right "
              f"{report.rms_right_px:.3f} px\n"
              "# x_right = R @ x_left + T, T in mm; dist in OpenCV order k1 k2 p1 p2 k3\n")
    text = header + yaml.safe_dump(report.pair.to_dict(), sort_keys=False,
                                   default_flow_style=None)
    try:
        out.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{out}: cannot write: {exc.strerror}") from None
    if getattr(args, "json", False):
        sys.stdout.write(strict_json({**report.to_json(), "out": str(out)}) + "\n")
    else:
        print(report.format())
        print(f"wrote {out}")
    return EXIT_OK


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
                    "and writes the pair YAML.")
    s.add_argument("--left", required=True, nargs="+", metavar="GLOB",
                   help="left images, e.g. 'L*.png' (quoted, or expanded by the shell)")
    s.add_argument("--right", required=True, nargs="+", metavar="GLOB", help="right images")
    s.add_argument("--board", required=True, metavar="SPEC",
                   help="chessboard:COLSxROWS:SQUARE_MM (inner corners, e.g. chessboard:9x6:25) "
                        "or charuco:COLSxROWS:SQUARE_MM:MARKER_MM:DICT (squares, e.g. "
                        "charuco:11x8:20:15:DICT_5X5_100)")
    s.add_argument("--out", default="pair.yaml", help="pair YAML to write (default pair.yaml)")
    s.add_argument("--json", action="store_true", help="print the report as one JSON object")
    s.set_defaults(func=cmd_calibrate_stereo)
    from stationd.geometry.vehicle_cli import add_vehicle_parser

    add_vehicle_parser(csub)
    return c
