"""``stationd calibrate vehicle``: register a stereo pair into the vehicle frame.

The points file lists reference points with known vehicle coordinates and, per pair, where the
marker (or a fixture) was localized on them: either a left/right image pair, localized here
with the station's vision, or the pair-frame point itself::

    kind: rigid                 # rigid (default, 6 dof) or affine (the paper's, 12 dof)
    points:
      - name: R1
        vehicle_mm: [1200.0, -350.0, 0.0]
        seen_by:
          pair1: {left: r1_l.png, right: r1_r.png}
          pair2: {pair_mm: [101.2, -20.4, 1310.8]}

The fitted transform goes to the pair's ``to_vehicle`` file (never into the hand-written
station config).  Points also seen by pairs registered earlier are compared in the vehicle
frame: one vehicle frame for all pairs, or an error.

Refused, with nothing written: two reference points of one name (exit 2), and a fit that is
not plausible (exit 1, the residuals printed first, :func:`~stationd.geometry.frames.
implausible`): point sets in two units (pair points typed in metres fitted with an RMS of
70.6 mm and were written), points of a mirrored frame (one axis's sign flipped), one point
off by more than :data:`~stationd.geometry.frames.MAX_POINT_MM` (named, with the coordinate
that looks mistyped) or an RMS residual above :data:`~stationd.geometry.frames.MAX_RMS_MM`.
The ``to_vehicle`` file replaces only an earlier registration, never another file or a link.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from stationd import progress
from stationd.errors import InputError
from stationd.filekind import expect
from stationd.geometry.frames import (
    KINDS,
    MAX_POINT_MM,
    MAX_RMS_MM,
    Transform,
    fit_transform,
    implausible,
)
from stationd.outfile import refuse_to_replace, write_atomic
from stationd.yamlio import YamlNode

if TYPE_CHECKING:   # the configuration (every component's schema) is read when the command runs
    from stationd.config import StationConfig
    from stationd.deviceconfig import PairConfig

EXIT_OK, EXIT_DISAGREE, EXIT_REFUSED = 0, 1, 1
#: the points file, as ``calibrate vehicle --help`` shows it (and the README)
POINTS_FORMAT = """\
the points file (YAML; image paths relative to it):

  kind: rigid                 # rigid (default, 6 dof) or affine (the paper's, 12 dof)
  points:
    - name: R1                # each point its own name
      vehicle_mm: [1200.0, -350.0, 0.0]      # the point in the vehicle frame, mm
      seen_by:                # per pair: where it was localized
        pair1: {left: r1_l.png, right: r1_r.png}     # a stereo image pair, or
        pair2: {pair_mm: [101.2, -20.4, 1310.8]}     # the point in the pair's frame, mm
    - name: R2
      ...

the pair must see at least 3 points (affine: 4, not in one plane); more show the
residuals; a point seen by several pairs compares their registrations in the vehicle frame"""


@dataclass(frozen=True)
class Observation:
    name: str
    vehicle_mm: np.ndarray
    pair_mm: dict[str, np.ndarray]  # pair name -> point in that pair's left camera frame


def _observe(node: YamlNode, pair: PairConfig, cfg: StationConfig, base: Path) -> np.ndarray:
    from stationd.imageio import read_image
    from stationd.localize.stereo import localize

    m = node.mapping(("left", "right", "pair_mm"))
    if "pair_mm" in m:
        if "left" in m or "right" in m:
            raise node.error("give either pair_mm or left and right images, not both")
        return m["pair_mm"].vector([3])
    if "left" not in m or "right" not in m:
        raise node.error("expected pair_mm, or left and right images")
    left = read_image(base / m["left"].text())
    right = read_image(base / m["right"].text())
    res = localize(pair.calibration, left, right, cfg.vision, cfg.marker)
    if not res.found or res.point_mm is None:
        raise node.error(f"marker not localized: {res.said}")
    return res.point_mm


def read_points(path: Path, cfg: StationConfig) -> tuple[str, list[Observation]]:
    node = YamlNode.load(path)
    expect(node, "points", ("kind", "points"))   # a station file given here is said so
    root = node.mapping(("kind", "points"), required=("points",))
    kind = root["kind"].text(KINDS) if "kind" in root else "rigid"
    out: list[Observation] = []
    items = root["points"].items()
    named: dict[str, YamlNode] = {}
    for item in items:   # before any image is localized
        m = item.mapping(("name", "vehicle_mm", "seen_by"), required=("vehicle_mm", "seen_by"))
        if "name" in m:
            name = m["name"].text()
            if name in named:
                raise m["name"].error(f"two reference points are named {name!r} (the first "
                                      f"at line {named[name].line}): each point needs its "
                                      "own name")
            named[name] = m["name"]
    for i, item in enumerate(progress.track(items, "reference points", total=len(items),
                                            unit="point")):
        m = item.mapping(("name", "vehicle_mm", "seen_by"), required=("vehicle_mm", "seen_by"))
        name = m["name"].text() if "name" in m else f"#{i + 1}"
        seen: dict[str, np.ndarray] = {}
        seen_by = m["seen_by"]
        names = seen_by.value()
        if not isinstance(names, dict):
            raise seen_by.error("expected a mapping of pair names")
        for pname, obs in seen_by.mapping(tuple(str(k) for k in names)).items():
            if pname not in cfg.pairs:
                raise obs.error(f"no pair {pname!r} in the station config "
                                f"(pairs: {', '.join(cfg.pairs) or 'none'})")
            seen[pname] = _observe(obs, cfg.pairs[pname], cfg, path.parent)
        out.append(Observation(name, m["vehicle_mm"].vector([3]), seen))
    return kind, out


def cmd_calibrate_vehicle(args: argparse.Namespace) -> int:
    if not args.config:
        raise InputError("--config STATION.yaml is needed: it names the pairs")
    from stationd.config import load_station_config

    # this pair's registration is the one being written: a broken one is replaced, not read
    cfg = load_station_config(args.config, unregistered=args.pair)
    if args.pair not in cfg.pairs:
        raise InputError(f"--pair {args.pair}: not in {args.config} "
                         f"(pairs: {', '.join(cfg.pairs) or 'none'})")
    target = cfg.pairs[args.pair].to_vehicle_path
    if not target.parent.is_dir():
        raise InputError(f"{target}: cannot write: no such folder {target.parent}")
    refuse_to_replace(target, "a vehicle registration", ("registration",),
                      option=f"pairs.{args.pair}.to_vehicle")
    kind, points = read_points(Path(args.points), cfg)
    kind = args.kind or kind
    mine = [p for p in points if args.pair in p.pair_mm]
    src = np.array([p.pair_mm[args.pair] for p in mine]).reshape(-1, 3)
    dst = np.array([p.vehicle_mm for p in mine]).reshape(-1, 3)
    fit = fit_transform(src, dst, kind)
    if not isinstance(fit, Transform):
        raise InputError(f"{args.points}: pair {args.pair}: {fit.reason}")
    assert fit.residuals_mm is not None  # noqa: S101 - a fit always carries them
    print(f"pair {args.pair}: {kind} fit to {len(mine)} points, RMS {fit.rms_mm:.3f} mm")
    for p, r in zip(mine, fit.residuals_mm, strict=True):
        print(f"  {p.name}: residual {r:.3f} mm")
    if len(mine) == 3:
        print("  note: 3 points fit exactly up to noise; 4 or more let the residuals show a "
              "bad point")
    refused = implausible(fit, src, dst, [p.name for p in mine])
    if refused is not None:
        sys.stderr.write(f"stationd: calibrate vehicle: {args.points}: pair {args.pair}: "
                         f"{refused.reason}; {target} not written\n")
        return EXIT_REFUSED
    header = (f"# {args.pair} -> vehicle frame, {kind} fit to {len(mine)} points from "
              f"{args.points}; RMS {fit.rms_mm:.3f} mm\n# x_vehicle = A x_pair + t (mm)\n")
    write_atomic(target, header + yaml.safe_dump(fit.to_dict(), sort_keys=False,
                                                 default_flow_style=None))
    print(f"wrote {target}; a running daemon reads it at its next reload (systemctl reload "
          "stationd), then check the pair (stationd calibrate check)")
    return _cross_check(cfg, args.pair, fit, points)


def _cross_check(cfg: StationConfig, pair: str, fit: Transform,
                 points: list[Observation]) -> int:
    """Points seen by this pair and by pairs registered earlier must agree in the vehicle
    frame within the fits' residuals: 3 RMS for each fit, and at least 0.5 mm.  The earlier
    pair's residuals are not stored with its transform, so this fit's RMS stands for both."""
    worst = EXIT_OK
    for p in points:
        if pair not in p.pair_mm:
            continue
        here = fit.apply(p.pair_mm[pair])
        for other, x in p.pair_mm.items():
            tv = cfg.pairs[other].to_vehicle
            if other == pair or tv is None:
                continue
            d = float(np.linalg.norm(tv.apply(x) - here))
            allowed = max(0.5, 6.0 * fit.rms_mm)
            flag = "ok" if d <= allowed else "DISAGREE"
            print(f"  {p.name}: {pair} and {other} agree to {d:.3f} mm ({flag}, allowed "
                  f"{allowed:.2f} mm)")
            if d > allowed:
                worst = EXIT_DISAGREE
    return worst


def add_vehicle_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    v = sub.add_parser(
        "vehicle", help="register a stereo pair into the vehicle frame",
        formatter_class=argparse.RawDescriptionHelpFormatter, epilog=POINTS_FORMAT,
        description=textwrap.fill(
            "Fits the pair's frame to the vehicle frame from reference points and writes the "
            "pair's to_vehicle file. Refused, nothing written: two points of one name (exit "
            "2); point sets in two units, e.g. pair points in metres, points of a mirrored "
            f"frame (one axis's sign flipped), one point off by more than {MAX_POINT_MM:g} mm "
            f"(a typo: named) or an RMS residual above {MAX_RMS_MM:g} mm (exit 1). The file "
            "replaces only an earlier registration, never another file or a link.", 88))
    v.add_argument("--pair", required=True, help="pair name in the station config")
    v.add_argument("--points", required=True, help="reference points YAML")
    v.add_argument("--config", help="station YAML (pairs, vision)")
    v.add_argument("--kind", choices=KINDS, help="override the points file's kind")
    v.set_defaults(func=cmd_calibrate_vehicle)
