"""``stationd bench vision``: the paper's experiments on rendered images, with our figures.

Sections (``--only``): radii (Table 1), centre (Tables 2-3), rod (reference rod), saltpepper
(section 4.1), lowlight (enhancement), speed (per stage, per image, per pair, vs AprilTag 3),
robustness (purples, casts, dim light, Bayer, blur, defocus, glare, occlusion, phantoms).
Every number printed is measured in this run; the paper's figures are quoted beside them.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from stationd import progress
from stationd.geometry.camera import Camera
from stationd.jsonout import finite
from stationd.localize.stereo import localize_detections, triangulate
from stationd.outfile import write_atomic
from stationd.sim import scenes as sc
from stationd.sim.render import MarkerPose, default_camera
from stationd.vision.detect import Detection, detect
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import Gates, VisionParams

SPEC = MarkerSpec()
NOISE: dict[str, Any] = {"blur_sigma": 0.8, "noise_sigma": 2.0}
ROD_LENGTHS = (882.546, 882.753, 882.473, 882.902)
Result = dict[str, Any]


def _stats(errors: list[float]) -> dict[str, float]:
    a = np.abs(np.asarray(errors, dtype=np.float64))
    if a.size == 0:
        return {"n": 0}
    return {"n": int(a.size), "mean": float(a.mean()), "median": float(np.median(a)),
            "p95": float(np.percentile(a, 95)), "max": float(a.max()), "min": float(a.min())}


def _err(d: Detection, truth: np.ndarray, attr: str = "centre_px") -> float:
    v = getattr(d, attr)
    return float(np.hypot(*(v - truth)))


def _stereo_views(pair: Any, pose: MarkerPose, seed: int, **kw: Any) -> tuple[Any, Any] | None:
    left = sc.render_view(pair.left, pose, SPEC, seed, **dict(kw))
    right = sc.render_view(pair.right, sc.to_right(pair, pose), SPEC, seed + 1, **dict(kw))
    if left is None or right is None:
        return None
    return left, right


# -- Tables 2-3: centre error over distance and tilt ----------------------------------------
def bench_centre(rng: np.random.Generator, quick: bool) -> Result:
    """Centre error against the true projection: ellipse centre, concentric pencil, the
    paper's correction with the normal chosen in one image (paper_mono: by the concentric
    split, else the pencil's centre) and in stereo (paper: Eq. 16, normals fused); each
    sample is a stereo pair converging on the marker."""
    cam = default_camera()
    distances = [400, 700, 1000, 1500, 2000]
    tilts = [0, 15, 30, 45, 55, 65]
    reps = 1 if quick else 3
    conc = VisionParams(centre_method="concentric")
    paper = VisionParams(centre_method="paper")
    methods = ("ellipse", "concentric", "paper_mono", "paper")
    errs: dict[str, list[float]] = {m: [] for m in methods}
    per_cell: dict[str, dict[str, float]] = {}
    failures: list[str] = []
    samples = 0
    for dist in distances:
        for tilt in tilts:
            cell: dict[str, list[float]] = {m: [] for m in methods}
            for _ in range(reps):
                pose = sc.random_pose(rng, cam, dist, tilt, spread=0.5)
                pair = sc.look_at_pair(cam, pose.centre_mm, 0.3 * dist)
                seed = int(rng.integers(1 << 30))
                views = _stereo_views(pair, pose, seed, **NOISE)
                if views is None:
                    continue
                samples += 1
                lv, rv = views
                dl = detect(lv.image, lv.camera, conc, SPEC)
                dr = detect(rv.image, rv.camera, conc, SPEC)
                pl = detect(lv.image, lv.camera, paper, SPEC)
                pr = detect(rv.image, rv.camera, paper, SPEC)
                if not (dl.found and dr.found and pl.found and pr.found):
                    side = "left" if not (dl.found and pl.found) else "right"
                    view_pose = pose if side == "left" else sc.to_right(pair, pose)
                    view_tilt = sc.tilt_of(view_pose.normal, view_pose.centre_mm)
                    failures.append(f"{dist} mm {tilt} deg, {side} view at {view_tilt:.0f} deg: "
                                    f"{dl.reason or dr.reason or pl.reason or pr.reason}")
                    continue
                st = localize_detections(sc.crop_pair(pair, lv, rv), pl, pr, paper)
                for d, p, v, ds in ((dl, pl, lv, st.left), (dr, pr, rv, st.right)):
                    cell["ellipse"].append(_err(d, v.centre_px, "ellipse_centre_px"))
                    cell["concentric"].append(_err(d, v.centre_px))
                    cell["paper_mono"].append(_err(p, v.centre_px))
                    if st.found:
                        cell["paper"].append(_err(ds, v.centre_px))
                if not st.found:
                    failures.append(f"{dist} mm {tilt} deg (paper, stereo): {st.reason}")
            for k, v in cell.items():
                errs[k] += v
            per_cell[f"{dist}mm/{tilt}deg"] = {k: float(np.median(v)) if v else math.nan
                                               for k, v in cell.items()}
    return {"samples": samples, "images": 2 * samples,
            "methods": {k: _stats(v) for k, v in errs.items()},
            "per_cell_median": per_cell, "failures": failures[:20],
            "failure_count": len(failures)}


# -- Table 1: 3D radii with and without the Leitz criterion ---------------------------------
def bench_radii(rng: np.random.Generator, quick: bool) -> Result:
    pair = sc.station_pair()
    n = 10 if quick else 30
    out: Result = {}
    poses = [sc.pose_in_pair(rng, pair, (1100, 1500), (0, 40)) for _ in range(n)]
    seeds = [int(rng.integers(1 << 30)) for _ in range(n)]
    # dirt on the ring's boundaries gives the edge outliers the criterion is for
    views = [_stereo_views(pair, pose, seed, dirt=12, **NOISE)
             for pose, seed in zip(poses, seeds, strict=True)]
    # The residual and split gates would refuse most plain fits here (that is their job); to
    # compare the fits themselves they are off in this section, and what they would have
    # refused is counted.
    open_gates = Gates(max_rms_px=math.inf, max_centre_split_px=math.inf)
    variants = {"leitz": VisionParams(gates=open_gates),
                "leitz_centre_residual": VisionParams(residual="centre", gates=open_gates),
                "plain": VisionParams(leitz=False, gates=open_gates)}
    limit = Gates().max_rms_px
    for key, params in variants.items():
        radii: dict[str, list[float]] = {"inner": [], "outer": []}
        centre: list[float] = []
        gated = 0
        for vw in views:
            if vw is None:
                continue
            lv, rv = vw
            dl = detect(lv.image, lv.camera, params, SPEC)
            dr = detect(rv.image, rv.camera, params, SPEC)
            st = localize_detections(sc.crop_pair(pair, lv, rv), dl, dr, params)
            if st.found:
                radii["inner"].append(st.radii_mm["inner"])
                radii["outer"].append(st.radii_mm["outer"])
                centre += [_err(st.left, lv.centre_px), _err(st.right, rv.centre_px)]
                rms = [e.rms for d in (dl, dr) for e in (d.inner, d.outer) if e is not None]
                gated += max(rms) > limit
        out[key] = {"centre_px": _stats(centre), "pairs": sum(v is not None for v in views),
                    "refused_by_default_gates": gated}
        for name, true_r in (("inner", SPEC.inner_mm), ("outer", SPEC.outer_mm)):
            r = np.asarray(radii[name])
            e = np.abs(r - true_r)
            out[key][name] = {"n": int(r.size), "std": float(r.std()) if r.size else math.nan,
                              "mean_error": float(e.mean()) if r.size else math.nan,
                              "max_error": float(e.max()) if r.size else math.nan,
                              "min_error": float(e.min()) if r.size else math.nan}
    return out


# -- the reference rod -----------------------------------------------------------------------
def bench_rod(rng: np.random.Generator, quick: bool) -> Result:
    """Lengths between two marker centres triangulated with the exact calibration."""
    pair = sc.station_pair()
    placements = 4 if quick else 10
    errs: dict[str, list[float]] = {"corrected": [], "ellipse": []}
    refused = 0
    for _ in range(placements):
        for length in ROD_LENGTHS:
            ends = _rod_ends(rng, pair, length)
            pts: dict[str, list[np.ndarray]] = {"corrected": [], "ellipse": []}
            for pose in ends:
                views = _stereo_views(pair, pose, int(rng.integers(1 << 30)), **NOISE)
                if views is None:
                    break
                lv, rv = views
                dl = detect(lv.image, lv.camera, VisionParams(), SPEC)
                dr = detect(rv.image, rv.camera, VisionParams(), SPEC)
                cp = sc.crop_pair(pair, lv, rv)
                st = localize_detections(cp, dl, dr)
                if not st.found or st.point_mm is None:
                    break
                assert dl.inner is not None and dr.inner is not None  # noqa: S101
                # window pixels and the cropped pair triangulate the same 3D point
                pts["corrected"].append(st.point_mm)
                pts["ellipse"].append(triangulate(cp, np.array(dl.inner.centre),
                                                  np.array(dr.inner.centre)))
            if len(pts["corrected"]) != 2:
                refused += 1
                continue
            for k in errs:
                errs[k].append(float(np.linalg.norm(pts[k][0] - pts[k][1])) - length)
    return {"placements": placements, "segments": len(ROD_LENGTHS), "refused": refused,
            "corrected": _stats(errs["corrected"]), "ellipse": _stats(errs["ellipse"])}


def _rod_ends(rng: np.random.Generator, pair: Any, length: float) -> list[MarkerPose]:
    for _ in range(200):
        mid = np.array([rng.uniform(-50, 250), rng.uniform(-150, 150), rng.uniform(1150, 1450)])
        ang = rng.uniform(-0.35, 0.35)
        d = np.array([math.cos(ang), math.sin(ang), rng.uniform(-0.15, 0.15)])
        d /= np.linalg.norm(d)
        # both markers on the rod, facing down at the cameras with a common tilt
        normal = np.array([rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), -1.0])
        normal /= np.linalg.norm(normal)
        rot = sc.rotation_towards(normal, rng)
        ends = [MarkerPose(mid + s * 0.5 * length * d, rot) for s in (-1.0, 1.0)]
        if all(sc.marker_window(pair.left, p, SPEC) and sc.marker_window(
                pair.right, sc.to_right(pair, p), SPEC) for p in ends):
            return ends
    raise RuntimeError("no rod placement in view")


# -- section 4.1: salt-and-pepper in a 120x75 px ROI ----------------------------------------
def bench_saltpepper(rng: np.random.Generator, quick: bool) -> Result:
    pair = sc.station_pair(baseline_mm=500.0, converge_mm=2050.0)
    n = 10 if quick else 50
    out: Result = {}
    poses: list[MarkerPose] = []
    while len(poses) < n:
        # ~2.05 m and ~50 deg: the field's box is about 120 x 75 px, as in the paper
        c = np.array([rng.uniform(-150, 650), rng.uniform(-350, 350), rng.uniform(1950, 2150)])
        pose = MarkerPose.look(c, float(rng.uniform(45, 55)), float(rng.choice([0.0, 180.0])),
                               0.0)
        if sc.marker_window(pair.left, pose, SPEC) and sc.marker_window(
                pair.right, sc.to_right(pair, pose), SPEC):
            poses.append(pose)
    for count in (200, 300, 400):
        found = 0
        centre: list[float] = []
        rin: list[float] = []
        rout: list[float] = []
        boxes: list[tuple[int, int]] = []
        reasons: list[str] = []
        for pose in poses:
            views = _stereo_views(pair, pose, int(rng.integers(1 << 30)),
                                  salt_pepper_in_field=count, **NOISE)
            if views is None:
                continue
            lv, rv = views
            boxes.append((lv.field_bbox[2], lv.field_bbox[3]))
            dl = detect(lv.image, lv.camera, VisionParams(), SPEC)
            dr = detect(rv.image, rv.camera, VisionParams(), SPEC)
            st = localize_detections(sc.crop_pair(pair, lv, rv), dl, dr)
            if not st.found:
                reasons.append(str(st.reason))
                continue
            found += 1
            centre += [_err(dl, lv.centre_px), _err(dr, rv.centre_px)]
            rin.append(st.radii_mm["inner"] - SPEC.inner_mm)
            rout.append(st.radii_mm["outer"] - SPEC.outer_mm)
        bw = np.median([b[0] for b in boxes]) if boxes else math.nan
        bh = np.median([b[1] for b in boxes]) if boxes else math.nan
        out[str(count)] = {"pairs": len(poses), "detection_rate": found / len(poses),
                           "roi_median_px": [float(bw), float(bh)],
                           "centre_px": _stats(centre), "inner_radius_mm": _stats(rin),
                           "outer_radius_mm": _stats(rout), "refusals": reasons}
    return out


# -- low light --------------------------------------------------------------------------------
def bench_lowlight(rng: np.random.Generator, quick: bool) -> Result:
    cam = default_camera()
    n = 20 if quick else 100
    levels = [1.0, 0.5, 0.25, 0.1]
    poses = [sc.random_pose(rng, cam, float(rng.uniform(500, 2000)), float(rng.uniform(0, 50)))
             for _ in range(n)]
    seeds = [int(rng.integers(1 << 30)) for _ in range(n)]
    out: Result = {}
    for level in levels:
        row: Result = {}
        views = [sc.render_view(cam, p, SPEC, s, illumination=level, vignetting=0.3,
                                gradient=0.3, gradient_deg=float(s % 360), **NOISE)
                 for p, s in zip(poses, seeds, strict=True)]
        for enhance in (True, False):
            params = VisionParams(enhance=enhance)
            found, errs, reasons = 0, [], []
            for v in views:
                if v is None:
                    continue
                d = detect(v.image, v.camera, params, SPEC)
                if d.found:
                    found += 1
                    errs.append(_err(d, v.centre_px))
                else:
                    reasons.append(str(d.reason))
            total = sum(v is not None for v in views)
            row["enhanced" if enhance else "plain"] = {
                "images": total, "detection_rate": found / max(total, 1),
                "centre_px": _stats(errs), "refusals": reasons[:10]}
        out[f"{int(level * 100)}%"] = row
    return out


# -- speed ------------------------------------------------------------------------------------
SPEED_TARGET_PAIR_MS = 30.0  # issue 10: a 20 MP stereo pair on 2 cores, median
STAGES = ("reduce", "segment", "retinex", "rays", "edges", "undistort", "fit", "centre")


def bench_speed(rng: np.random.Generator, quick: bool, *, camera: Camera | None = None,
                apriltag: bool = True) -> Result:
    """Where the time of one localization goes, on the station's pair (20 MP by default).

    Per image (``detect`` alone, one after the other): the stages of the detector, wall
    clock, median over the runs (``retinex`` is a part of ``segment``; ``rays`` is the ring
    search inside the ROI, ``edges`` the rest of the ROI's work).  Per pair (``localize``,
    both images on two threads): wall clock, process CPU (both cores: the wall time is what
    the station waits for, the CPU what the machine pays) and the stereo step.  A frame with
    no marker in it (most frames of most pairs) is timed too: it must cost one reduced
    search.  ``camera`` replaces the 20 MP camera (the tests use a smaller one).
    """
    from stationd.localize.stereo import localize
    from stationd.sim.render import Scene, render

    pair = sc.station_pair() if camera is None else sc.look_at_pair(
        camera, np.array([0.0, 0.0, 1300.0]), 400.0)
    pose = sc.pose_in_pair(rng, pair, (1200, 1300), (10, 30))
    scene_l = Scene(markers=[(pose, SPEC)], texture=0.15, vignetting=0.3, **NOISE)
    scene_r = replace(scene_l, markers=[(sc.to_right(pair, pose), SPEC)])
    left = render(pair.left, scene_l, seed=1).image
    right = render(pair.right, scene_r, seed=2).image
    empty = render(pair.left, replace(scene_l, markers=[]), seed=3).image
    runs = 5 if quick else 21
    params = VisionParams()
    res = localize(pair, left, right, params, SPEC)  # warm-up (imports, thread pool, caches)
    pair_ms, pair_cpu, stereo_ms, image_ms, image_cpu, empty_ms, empty_cpu = (
        [] for _ in range(7))
    stages: dict[str, list[float]] = {}
    within: list[bool] = []
    empty_det = detect(empty, pair.left, params, SPEC)
    for _ in range(runs):
        c0, t0 = time.process_time(), time.perf_counter()
        res = localize(pair, left, right, params, SPEC)
        pair_ms.append((time.perf_counter() - t0) * 1e3)
        pair_cpu.append((time.process_time() - c0) * 1e3)
        stereo_ms.append(res.timings_ms["stereo"])
        c0, t0 = time.process_time(), time.perf_counter()
        d = detect(left, pair.left, params, SPEC)
        image_ms.append((time.perf_counter() - t0) * 1e3)
        image_cpu.append((time.process_time() - c0) * 1e3)
        for k, v in d.timings_ms.items():
            stages.setdefault(k, []).append(v)
        # each run's stages add up to no more than its total (Retinex is part of segment);
        # checked per run: medians of parts need not add up under the median of the whole
        parts = sum(v for k, v in d.timings_ms.items() if k in STAGES and k != "retinex")
        within.append(parts <= d.timings_ms.get("total", float("inf")) + 1e-9)
        c0, t0 = time.process_time(), time.perf_counter()
        empty_det = detect(empty, pair.left, params, SPEC)
        empty_ms.append((time.perf_counter() - t0) * 1e3)
        empty_cpu.append((time.process_time() - c0) * 1e3)

    def med(v: list[float]) -> float:
        return float(np.median(v))

    out: Result = {
        "frame": list(pair.left.size), "runs": runs, "found": res.found,
        "pair_ms_median": med(pair_ms), "pair_ms_min": float(min(pair_ms)),
        "pair_cpu_ms_median": med(pair_cpu), "stereo_ms_median": med(stereo_ms),
        "image_ms_median": med(image_ms), "image_cpu_ms_median": med(image_cpu),
        "stage_ms_median": {k: med(stages[k]) for k in (*STAGES, "total") if k in stages},
        "stages_within_total": all(within),
        "no_marker": {"ms_median": med(empty_ms), "cpu_ms_median": med(empty_cpu),
                      "found": empty_det.found, "reason": empty_det.reason,
                      "stage_ms": {k: round(v, 3) for k, v in empty_det.timings_ms.items()}},
        "target_pair_ms": SPEED_TARGET_PAIR_MS,
        "target_met": med(pair_ms) <= SPEED_TARGET_PAIR_MS}
    if apriltag:
        out["apriltag"] = _apriltag_peer(left, right, pair, pose, runs)
    return out


def _apriltag_peer(left: np.ndarray, right: np.ndarray, pair: Any, pose: MarkerPose,
                   runs: int) -> Result:
    """AprilTag 3 (pupil-apriltags, quad_decimate=2, 2 threads) on the same frames, with a
    tag36h11 of the marker's field size pasted beside the marker so it has one to find."""
    try:
        import cv2
        from pupil_apriltags import Detector
    except ImportError:
        return {"skipped": "pupil-apriltags not installed (pip install -e '.[bench]')"}
    tag = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(
        cv2.aruco.DICT_APRILTAG_36h11), 0, 200)
    tag = np.pad(tag, 20, constant_values=255)
    frames = []
    for img, cam, p in ((left, pair.left, pose), (right, pair.right, sc.to_right(pair, pose))):
        f = SPEC.field_mm
        offset = p.rotation[:, 0] * 3 * f  # beside the marker, in its plane
        corners = np.array([[-f, -f, 0], [f, -f, 0], [f, f, 0], [-f, f, 0]], dtype=np.float64)
        dst = cam.project(p.centre_mm + offset + corners @ p.rotation.T).astype(np.float32)
        src = np.array([[0, 0], [240, 0], [240, 240], [0, 240]], dtype=np.float32)
        H = cv2.getPerspectiveTransform(src, dst)
        warped = cv2.warpPerspective(tag, H, (img.shape[1], img.shape[0]), flags=cv2.INTER_AREA,
                                     borderValue=0)
        mask = cv2.warpPerspective(np.full_like(tag, 255), H, (img.shape[1], img.shape[0])) > 0
        grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        grey[mask] = warped[mask]
        frames.append(grey)
    det = Detector(families="tag36h11", nthreads=2, quad_decimate=2.0)
    found = len(det.detect(frames[0]))
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        for g in frames:
            det.detect(g)
        times.append((time.perf_counter() - t0) * 1e3)
    return {"pair_ms_median": float(np.median(times)), "tags_found_left": found,
            "settings": "tag36h11, quad_decimate=2, nthreads=2, grey input"}


def bench_robustness(rng: np.random.Generator, quick: bool) -> Result:
    """Recall, precision and safety under real effects (``stationd.bench.robustness``)."""
    from stationd.bench.robustness import bench_robustness as run

    return run(rng, quick)


SECTIONS: dict[str, Callable[[np.random.Generator, bool], Result]] = {
    "radii": bench_radii, "centre": bench_centre, "rod": bench_rod,
    "saltpepper": bench_saltpepper, "lowlight": bench_lowlight, "speed": bench_speed,
    "robustness": bench_robustness,
}


def run_vision_bench(args: argparse.Namespace) -> int:
    from drivers.counting import noun
    from stationd.bench.report import print_report
    from stationd.errors import InputError

    names = list(SECTIONS) if args.only is None else [s.strip() for s in args.only.split(",")]
    unknown = [n or "''" for n in names if n not in SECTIONS]   # "" is no section, not all
    if unknown:
        raise InputError(f"--only: unknown {noun(len(unknown), 'section')} {', '.join(unknown)} "
                         f"(accepted: {', '.join(SECTIONS)})")
    results: Result = {"machine": {"cpus": __import__("os").cpu_count(),
                                   "python": platform.python_version()},
                       "quick": bool(args.quick), "seed": args.seed}
    for name in progress.track(names, "bench vision: sections", unit="section"):
        t0 = time.perf_counter()
        print(f"[bench vision] {name} ...", flush=True)
        results[name] = SECTIONS[name](np.random.default_rng(args.seed), args.quick)
        results.setdefault("seconds", {})[name] = round(time.perf_counter() - t0, 1)
    print_report(results)
    if "robustness" in results:
        from stationd.bench.robustness import print_table

        print_table(results["robustness"])
    # whole or not at all: a Ctrl-C or a full disk while writing left half a JSON
    write_atomic(Path(args.out), json.dumps(finite(results), indent=1, allow_nan=False) + "\n")
    print(f"[bench vision] wrote {args.out}")
    return 0
