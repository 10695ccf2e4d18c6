"""``stationd bench chain``: the whole chain on rendered data (paper sections 3.4 and 4.2).

Nothing is taken from the true geometry except to render: each of the station's four pairs is
calibrated from rendered chessboard images, registered into the vehicle frame from rendered
markers on reference points, and then measures a reference rod and 50 bolts under the chassis,
with the wrench tilted up to 5 degrees.  The bolt ends are compared with the truth, with the
tool-axis compensation and with the paper's perpendicular-wrench rule on the same placements.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from stationd import progress
from stationd.bench.vision import NOISE, ROD_LENGTHS, SPEC, _stats
from stationd.geometry.calibration import ViewPair, calibrate_views, detect_corners, parse_board
from stationd.geometry.camera import StereoPair
from stationd.geometry.frames import Transform, fit_rigid
from stationd.geometry.tool import BoltEnd, ToolGeometry, bolt_end, fuse
from stationd.jsonout import finite
from stationd.localize.stereo import localize_detections
from stationd.outfile import write_atomic
from stationd.result import Refusal
from stationd.sim import scenes as sc
from stationd.sim.raycast import Chessboard
from stationd.sim.render import MarkerPose, Scene, crop_camera, render
from stationd.sim.scenes import StationPair, build_station
from stationd.vision.detect import detect
from stationd.vision.params import VisionParams

BOARD = Chessboard(9, 6, 60.0)
BOARD_SPEC = "chessboard:9x6:60"
TOOL = ToolGeometry(length_mm=300.0, max_tilt_deg=10.0)
Result = dict[str, Any]


# -- commissioning ---------------------------------------------------------------------------
def _board_poses(rng: np.random.Generator, pair: StereoPair, n: int) -> list[MarkerPose]:
    poses: list[MarkerPose] = []
    hx, hy = 0.5 * (BOARD.cols + 3) * BOARD.square, 0.5 * (BOARD.rows + 3) * BOARD.square
    card = np.array([[-hx, -hy, 0], [hx, -hy, 0], [hx, hy, 0], [-hx, hy, 0]])
    while len(poses) < n:
        c = np.array([rng.uniform(-450, 450), rng.uniform(-300, 300), rng.uniform(900, 1600)])
        p = MarkerPose.look(c, float(rng.uniform(0, 35)), float(rng.uniform(0, 360)),
                            float(rng.uniform(-20, 20)))
        corners = p.centre_mm + card @ p.rotation.T
        right = corners @ pair.R.T + pair.T
        if pair.left.contains(pair.left.project(corners), 20).all() and \
                pair.right.contains(pair.right.project(right), 20).all():
            poses.append(p)
    return poses


def calibrate_pair(rng: np.random.Generator, sp: StationPair, views: int) -> tuple[StereoPair,
                                                                                    Result]:
    board = parse_board(BOARD_SPEC)
    tp = sp.true_pair
    found = []
    for i, p in enumerate(_board_poses(rng, tp, views)):
        imgs = []
        for cam, pose in ((tp.left, p), (tp.right, sc.to_right(tp, p))):
            scene = Scene(boards=[(pose, BOARD)], texture=0.1, vignetting=0.2, **NOISE)
            imgs.append(cv2.cvtColor(render(cam, scene, seed=int(rng.integers(1 << 30)),
                                            supersample=4).image, cv2.COLOR_BGR2GRAY))
        found.append(ViewPair(f"L{i}", f"R{i}", detect_corners(imgs[0], board),
                              detect_corners(imgs[1], board)))
    rep = calibrate_views(found, board, tp.left.size, tp.right.size)
    cal = rep.pair
    return cal, {"views": views, "used": rep.used, "rms_px": rep.rms_px,
                 "baseline_error_mm": abs(cal.baseline_mm - tp.baseline_mm),
                 "focal_error_px": float(abs(cal.left.K[0, 0] - tp.left.K[0, 0]))}


def _localize_marker(sp: StationPair, pair: StereoPair, pose_l: MarkerPose,
                     seed: int) -> tuple[np.ndarray, np.ndarray] | str:
    """Render the marker through the true pair, measure it with ``pair`` (calibrated)."""
    tp = sp.true_pair
    lv = sc.render_view(tp.left, pose_l, SPEC, seed, **NOISE)
    rv = sc.render_view(tp.right, sc.to_right(tp, pose_l), SPEC, seed + 1, **NOISE)
    if lv is None or rv is None:
        return "out of view"
    cam_l, cam_r = crop_camera(pair.left, lv.window), crop_camera(pair.right, rv.window)
    params = VisionParams()
    dl, dr = detect(lv.image, cam_l, params, SPEC), detect(rv.image, cam_r, params, SPEC)
    res = localize_detections(StereoPair(cam_l, cam_r, pair.R, pair.T), dl, dr, params)
    if not res.found or res.point_mm is None or res.normal is None:
        return str(res.reason)
    return res.point_mm, res.normal


def _marker_rotation(normal_down: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return sc.rotation_towards(normal_down, rng)


def register_pair(rng: np.random.Generator, sp: StationPair, n: int) -> tuple[Transform, Result]:
    """Markers on ``n`` reference points of the chassis (fixtures, known vehicle coordinates)."""
    assert sp.calibrated is not None  # noqa: S101 - calibrated first
    src: list[np.ndarray] = []
    dst: list[np.ndarray] = []
    while len(dst) < n:
        x0 = sp.c_v[0] + 250.0
        p = np.array([rng.uniform(x0 - 450, x0 + 450), rng.uniform(-350, 350) + 0.35 * sp.c_v[1],
                      rng.uniform(-60, 30)])
        down = np.array([rng.normal(0, 0.1), rng.normal(0, 0.1), -1.0])
        pose = sp.to_camera(p, _marker_rotation(down / np.linalg.norm(down), rng))
        got = _localize_marker(sp, sp.calibrated, pose, int(rng.integers(1 << 30)))
        if isinstance(got, str):
            continue
        src.append(got[0])
        dst.append(p)
    fit = fit_rigid(np.array(src), np.array(dst))
    if not isinstance(fit, Transform):
        raise RuntimeError(fit.reason)
    return fit, {"points": n, "rms_mm": fit.rms_mm}


# -- measurements ----------------------------------------------------------------------------
def bench_rod(rng: np.random.Generator, sp: StationPair, placements: int) -> Result:
    assert sp.calibrated is not None  # noqa: S101
    errs: list[float] = []
    for _ in range(placements):
        for length in ROD_LENGTHS:
            for _ in range(100):
                mid = np.array([rng.uniform(-150, 150), rng.uniform(-150, 150),
                                rng.uniform(1150, 1400)])
                d = np.array([1.0, rng.uniform(-0.3, 0.3), rng.uniform(-0.1, 0.1)])
                d /= np.linalg.norm(d)
                rot = _marker_rotation(np.array([rng.uniform(-.3, .3), rng.uniform(-.3, .3),
                                                 -1.0]), rng)
                ends = [MarkerPose(mid + s * 0.5 * length * d, rot) for s in (-1.0, 1.0)]
                got = [_localize_marker(sp, sp.calibrated, e, int(rng.integers(1 << 30)))
                       for e in ends]
                if not any(isinstance(g, str) for g in got):
                    break
            else:
                continue
            a, b = (g[0] for g in got if not isinstance(g, str))
            errs.append(float(np.linalg.norm(a - b)) - length)
    return {"pair": sp.name, **_stats(errs)}


def bench_bolts(rng: np.random.Generator, station: list[StationPair], n: int) -> Result:
    err_axis: dict[str, list[float]] = {"x": [], "y": []}
    err_perp: dict[str, list[float]] = {"x": [], "y": []}
    tilts: list[float] = []
    refusals: list[str] = []
    multi = 0
    while len(tilts) < n:
        sp0 = station[len(tilts) % len(station)]
        bolt = np.array([sp0.c_v[0] + 250 + rng.uniform(-400, 400),
                         0.35 * sp0.c_v[1] + rng.uniform(-300, 300), rng.uniform(-80, 40)])
        tilt, az = math.radians(rng.uniform(0, 5)), rng.uniform(0, 2 * math.pi)
        axis = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az),
                         math.cos(tilt)])
        centre = bolt - TOOL.length_mm * axis
        rot = _marker_rotation(-axis, rng)
        ends: list[BoltEnd] = []
        perp: list[np.ndarray] = []
        sigmas: list[float] = []
        for sp in station:
            pose = sp.to_camera(centre, rot)
            if sc.marker_window(sp.true_pair.left, pose, SPEC) is None:
                continue
            got = _localize_marker(sp, sp.calibrated or sp.true_pair, pose,
                                   int(rng.integers(1 << 30)))
            if isinstance(got, str) or sp.to_vehicle is None:
                continue
            c_v = sp.to_vehicle.apply(got[0])
            n_v = sp.to_vehicle.apply_direction(got[1])
            e = bolt_end(c_v, n_v, TOOL)
            p = bolt_end(c_v, n_v, replace(TOOL, rule="perpendicular"))
            if isinstance(e, BoltEnd) and isinstance(p, BoltEnd):
                ends.append(e)
                perp.append(p.point_mm)
                z = float(np.linalg.norm(got[0]))
                sigmas.append(0.05 * (z / 1000.0) ** 2)  # stereo depth noise grows with Z^2
        if not ends:
            refusals.append("no pair localized the marker")
            continue
        multi += len(ends) > 1
        f = fuse([e.point_mm for e in ends], sigmas, max_spread_mm=2.0)
        if isinstance(f, Refusal):
            refusals.append(f.reason)
            continue
        est = f.point_mm
        pp = np.mean(perp, axis=0)
        tilts.append(math.degrees(tilt))
        for k, i in (("x", 0), ("y", 1)):
            err_axis[k].append(float(est[i] - bolt[i]))
            err_perp[k].append(float(pp[i] - bolt[i]))

    def signed(v: list[float]) -> dict[str, float]:
        a = np.asarray(v)
        return {"min": float(a.min()), "max": float(a.max()), "mean_abs": float(np.abs(a).mean()),
                "variance": float(a.var()), "max_abs": float(np.abs(a).max())}

    return {"bolts": n, "seen_by_two_or_more": multi, "max_tilt_deg": float(max(tilts)),
            "axis": {k: signed(v) for k, v in err_axis.items()},
            "perpendicular": {k: signed(v) for k, v in err_perp.items()},
            "refusals": refusals[:10]}


def run_chain_bench(args: argparse.Namespace) -> int:
    quick = bool(args.quick)
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    station = build_station(rng, 2 if quick else 4)
    res: Result = {"quick": quick, "seed": args.seed, "pairs": {}}
    for i, sp in enumerate(progress.track(station, "bench chain: pairs", unit="pair")):
        print(f"[bench chain] calibrating and registering {sp.name} ...", flush=True)
        cal, crep = calibrate_pair(rng, sp, 8 if quick else 12)
        sp = replace(sp, calibrated=cal)
        tv, rrep = register_pair(rng, sp, 6)
        station[i] = replace(sp, to_vehicle=tv)
        res["pairs"][sp.name] = {"calibration": crep, "registration": rrep}
    print("[bench chain] reference rod ...", flush=True)
    res["rod"] = bench_rod(rng, station[0], 3 if quick else 10)
    print("[bench chain] bolts ...", flush=True)
    res["bolts"] = bench_bolts(rng, station, 12 if quick else 50)
    res["seconds"] = round(time.perf_counter() - t0, 1)
    _print(res)
    # whole or not at all: a Ctrl-C or a full disk while writing left half a JSON
    write_atomic(Path(args.out), json.dumps(finite(res), indent=1, allow_nan=False) + "\n")
    print(f"[bench chain] wrote {args.out}")
    return 0


def _print(res: Result) -> None:
    print("\nCommissioning (from rendered boards and reference points)")
    for name, p in res["pairs"].items():
        c, r = p["calibration"], p["registration"]
        print(f"  {name}: {c['used']}/{c['views']} board views, RMS {c['rms_px']:.3f} px, "
              f"baseline error {c['baseline_error_mm']:.3f} mm, focal error "
              f"{c['focal_error_px']:.2f} px; vehicle registration RMS {r['rms_mm']:.3f} mm "
              f"({r['points']} points)")
    rod = res["rod"]
    print(f"\nReference rod ({rod['pair']}, calibrated from boards): |length error| mean "
          f"{rod.get('mean', math.nan):.4f} mm, max {rod.get('max', math.nan):.4f} mm over "
          f"{rod.get('n', 0)} lengths   (paper 0.176 mm mean; target <= 0.15 mm)")
    b = res["bolts"]
    print(f"\nBolt ends, {b['bolts']} bolts, wrench tilt up to {b['max_tilt_deg']:.1f} deg "
          f"({b['seen_by_two_or_more']} seen by two pairs, fused)")
    print("  method          axis  min      max      mean|e|  variance  max|e|   (mm)")
    for meth in ("axis", "perpendicular"):
        for k in ("x", "y"):
            s = b[meth][k]
            print(f"  {meth:14s}  {k}     {s['min']:+7.3f}  {s['max']:+7.3f}  "
                  f"{s['mean_abs']:7.3f}  {s['variance']:8.3f}  {s['max_abs']:7.3f}")
    print("  paper: X -3.642..3.545 mean 1.884, Y -3.225..3.834 mean 1.844; "
          "target: max <= 1.0 mm with the axis rule")
