"""``stationd demo``: the main job.  Until the daemon exists, a vision demo.

It renders stereo pairs of the marker at full resolution (5472x3648) through the station's
pair, as the wrench visits a few places under the chassis, localizes each with the same code
the station runs, and prints the result beside the rendering's ground truth.  ``--save DIR``
also writes the images and the calibration, so ``stationd detect`` / ``localize`` can be tried
on them.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import cv2
import numpy as np
import yaml

from stationd import progress
from stationd.errors import InputError
from stationd.jsonout import strict_json
from stationd.localize.stereo import localize
from stationd.outfile import DEMO_IMAGE_STAMP, refuse_to_replace, stamp_png, write_atomic
from stationd.sim import scenes as sc
from stationd.sim.render import MarkerPose, Scene, render
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams


def _placements(rng: np.random.Generator, count: int) -> list[MarkerPose]:
    pair = sc.station_pair()
    return [sc.pose_in_pair(rng, pair, (1100.0, 1500.0), (0.0, 35.0)) for _ in range(count)]


def _save_dir(text: str) -> Path:
    """The ``--save`` folder, checked before minutes of rendering: an existing file, or a
    folder that cannot be made or written, is refused in one line."""
    save = Path(text)
    if save.exists() and not save.is_dir():
        raise InputError(f"--save {save}: exists and is not a folder (images and pair.yaml "
                         "are written into a folder)")
    try:
        save.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--save {save}: cannot create the folder: {exc.strerror}") from None
    if not os.access(save, os.W_OK | os.X_OK):
        raise InputError(f"--save {save}: the folder is not writable")
    return save


def _outputs(save: Path, count: int) -> list[Path]:
    """The files ``--save`` writes, each checked by the one output rule before minutes of
    rendering: never through a link, never over a file of another kind (an image of the
    demo's own, a pair calibration for pair.yaml)."""
    refuse_to_replace(save / "pair.yaml", "the demo's pair calibration", ("pair",),
                      option="--save")
    images = [save / f"{side}_{k}.png" for k in range(count) for side in ("left", "right")]
    for path in images:
        refuse_to_replace(path, "the demo's image", ("demo-image",), option="--save")
    return images


def _write_image(path: Path, image: np.ndarray) -> None:
    """A rendered image as a PNG stamped as the demo's own, written whole."""
    ok, buf = cv2.imencode(".png", image)
    if not ok:
        raise InputError(f"--save {path.parent}: {path.name} could not be encoded")
    write_atomic(path, stamp_png(buf.tobytes(), DEMO_IMAGE_STAMP))


def run_demo(args: argparse.Namespace) -> int:
    count = int(getattr(args, "cycles", 3))  # 0 is refused, not taken for the default
    if count < 1:
        raise InputError("--cycles must be at least 1")
    rng = np.random.default_rng(args.seed)
    pair = sc.station_pair()
    spec = MarkerSpec()
    params = VisionParams()
    save = _save_dir(args.save) if getattr(args, "save", None) else None
    if save is not None:
        _outputs(save, count)
        write_atomic(save / "pair.yaml", yaml.safe_dump(pair.to_dict(), sort_keys=False))
    errors, latencies, found = [], [], 0
    for k, pose in enumerate(progress.track(_placements(rng, count), "demo: placements",
                                            total=count, unit="pair")):
        scene = Scene(markers=[(pose, spec)], texture=0.15, vignetting=0.3, gradient=0.3,
                      gradient_deg=float(rng.uniform(0, 360)), blur_sigma=0.8, noise_sigma=2.0)
        left = render(pair.left, scene, seed=2 * k + 1)
        right = render(pair.right, Scene(**{**scene.__dict__,
                                           "markers": [(sc.to_right(pair, pose), spec)]}),
                       seed=2 * k + 2)
        if save is not None:
            for name, img in ((f"left_{k}.png", left.image), (f"right_{k}.png", right.image)):
                _write_image(save / name, img)
        res = localize(pair, left.image, right.image, params, spec)
        latencies.append(res.timings_ms["total"])
        if not args.json:
            head = f"placement {k + 1}: marker at {np.round(pose.centre_mm, 1).tolist()} mm, " \
                   f"tilt {left.truth[0].tilt_deg:.1f} deg"
        if res.found and res.point_mm is not None and res.left.centre_px is not None:
            found += 1
            err_mm = float(np.linalg.norm(res.point_mm - pose.centre_mm))
            err_px = float(np.hypot(*(res.left.centre_px - left.truth[0].centre_px)))
            errors.append(err_mm)
            if not args.json:
                print(f"{head}\n  localized {np.round(res.point_mm, 3).tolist()} mm: 3D error "
                      f"{err_mm:.3f} mm, left centre error {err_px:.4f} px, "
                      f"{res.timings_ms['total']:.1f} ms")
        elif not args.json:
            print(f"{head}\n  refused: {res.said}")
    err_mean = float(np.mean(errors)) if errors else float("nan")
    err_max = float(np.max(errors)) if errors else float("nan")
    p50 = float(np.percentile(latencies, 50))
    summary = {"placements": count, "found": found,
               "error_mm": {"mean": err_mean if errors else None,
                            "max": err_max if errors else None},
               "latency_ms": {"p50": p50, "max": float(np.max(latencies))}}
    if args.json:
        sys.stdout.write(strict_json(summary) + "\n")
    else:
        print(f"summary: {found}/{count} localized; 3D error mean {err_mean:.3f} mm, max "
              f"{err_max:.3f} mm; localization p50 {p50:.1f} ms per 20 MP stereo pair")
        if save is not None:
            print(f"images and pair.yaml written to {save}/; try: stationd localize "
                  f"{save}/left_0.png {save}/right_0.png --pair {save}/pair.yaml --json")
    return 0 if found == count else 1
