"""``stationd bench vision --only robustness``: recall, precision and safety under real effects.

Why: the accuracy sections judge the detector on clean renders; a station sees other print
purples, white-balance casts, dim light, a colour (Bayer) camera, motion blur, defocus, glare
and hands or chassis members in front of the marker.  Each condition draws its parameters
from physical ranges (``stationd.sim.effects``), renders small windows around the marker
(not 20 MP frames) and counts found / centre error / wrong (> 2 px) / phantom.  The phantom
sets hold no marker at all: purple patches and disks, washers, rings on purple.  AprilTag 3
is run on the same occlusion set with a tag of the marker's field size.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal

import cv2
import numpy as np

from stationd.geometry.camera import Camera
from stationd.sim import effects as fx
from stationd.sim import scenes as sc
from stationd.sim.render import Distractor, MarkerPose, Scene, crop_camera, default_camera, render
from stationd.vision.detect import detect
from stationd.vision.marker import PURPLE_RGB, MarkerSpec
from stationd.vision.params import VisionParams

SPEC = MarkerSpec()
WRONG_PX = 2.0
Result = dict[str, Any]


@dataclass
class Setup:
    """What one sample draws: every effect off unless a condition turns it on."""

    purple: tuple[int, int, int] = PURPLE_RGB
    cast: tuple[float, float, float] = (1.0, 1.0, 1.0)
    illumination: float = 1.0
    noise: float = 2.0
    blur: float = 0.8
    motion: tuple[float, float] = (0.0, 0.0)  # length px, angle deg
    defocus: float = 0.0
    glare: tuple[float, float, float] | None = None  # ring radius mm, angle, peak
    occluder: tuple[str, str, float, float] | None = None  # shape, colour, fraction, angle
    bayer: tuple[str, str] | None = None  # pattern, method
    phantom: str | None = None  # no marker: what is there instead
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class Sample:
    image: np.ndarray
    camera: Camera
    truth: np.ndarray | None  # marker centre (window px); None for a phantom set
    covered: float  # fraction of the outer ring the occluder hides
    tag_image: np.ndarray | None = None
    tag_truth: np.ndarray | None = None


def _any_purple(rng: np.random.Generator) -> tuple[int, int, int]:
    return fx.purple_rgb(rng.uniform(265, 295), rng.uniform(0.40, 0.90), rng.uniform(0.35, 0.85))


def _cast(rng: np.random.Generator) -> tuple[float, float, float]:
    r, g, b = rng.uniform(0.85, 1.15, 3)
    return float(r), float(g), float(b)


def _pose(rng: np.random.Generator, cam: Camera) -> MarkerPose:
    while True:
        pose = sc.random_pose(rng, cam, float(rng.uniform(900, 1600)), float(rng.uniform(0, 45)),
                              spread=0.5)
        if sc.marker_window(cam, pose, SPEC) is not None:
            return pose


def _finish(img: np.ndarray, s: Setup, rng: np.random.Generator) -> np.ndarray:
    """Optics, motion, sensor: blur kernels, noise, clipping, Bayer + demosaicing."""
    img = fx.motion_blur(img, *s.motion)
    img = fx.defocus(img, s.defocus)
    if s.blur > 0:
        img = np.asarray(cv2.GaussianBlur(img, (0, 0), s.blur))
    img = img + rng.normal(0.0, s.noise, img.shape).astype(np.float32)
    out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if s.bayer is not None:
        out = fx.demosaic(fx.bayer_mosaic(out, s.bayer[0]), *s.bayer)
    return np.asarray(out)


def _gain(s: Setup) -> np.ndarray:
    return np.asarray(s.cast[::-1], np.float32) * np.float32(s.illumination)


def _tag_base(scene: Scene, cam: Camera, win: tuple[int, int, int, int],
              pose: MarkerPose, s: Setup) -> tuple[np.ndarray, np.ndarray]:
    """The same window with an AprilTag (tag36h11, black border = 5/6 of the field) instead."""
    bg = render(cam, Scene(background_rgb=scene.background_rgb, cast=s.cast,
                           illumination=s.illumination), window=win, supersample=1)
    tag = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(
        cv2.aruco.DICT_APRILTAG_36h11), 0, 200)
    tag = np.pad(tag, 20, constant_values=255).astype(np.float32)
    f = SPEC.field_mm
    # the printed face looks at the camera: its y axis runs opposite to the image's
    corners = np.array([[-f, f, 0], [f, f, 0], [f, -f, 0], [-f, -f, 0]], dtype=np.float64)
    dst = (cam.project(pose.centre_mm + corners @ pose.rotation.T) - np.array(win[:2])
           ).astype(np.float32)
    src = np.array([[-0.5, -0.5], [239.5, -0.5], [239.5, 239.5], [-0.5, 239.5]], np.float32)
    H = cv2.getPerspectiveTransform(src, dst)
    size = (win[2], win[3])
    warped = cv2.warpPerspective(tag, H, size, flags=cv2.INTER_AREA)
    cover = cv2.warpPerspective(np.ones_like(tag), H, size, flags=cv2.INTER_AREA)
    img = bg.image.astype(np.float32) * (1 - cover[..., None])
    img += (warped * cover)[..., None] * (_gain(s) * 235.0 / 255.0)
    truth = cam.project(pose.centre_mm)[0] - np.array(win[:2], np.float64)
    return img, truth


def make_sample(setup: Setup, rng: np.random.Generator, with_tag: bool = False) -> Sample:
    """Render one window: marker (or phantom), occluder, glare, then optics and sensor."""
    cam = default_camera()
    pose = _pose(rng, cam)
    win = sc.marker_window(cam, pose, SPEC)
    assert win is not None  # noqa: S101 - _pose guarantees it
    bg = tuple(float(v) for v in rng.uniform(40, 110, 3))
    spec = MarkerSpec(purple_rgb=setup.purple)
    markers = [] if setup.phantom else [(pose, spec)]
    scene = Scene(markers=markers, background_rgb=bg, cast=setup.cast,  # type: ignore[arg-type]
                  illumination=setup.illumination, texture=0.1)
    if setup.phantom in ("patch", "disk"):
        kind: Literal["disc", "bar"] = "bar" if setup.phantom == "patch" else "disc"
        scene.distractors = [Distractor(pose, kind, float(rng.uniform(12, 25)),
                                        float(rng.uniform(5, 12)), setup.purple)]
    seed = int(rng.integers(1 << 30))
    img = render(cam, scene, window=win, seed=seed).image.astype(np.float32)
    local = crop_camera(cam, win)
    gain = _gain(setup)
    origin = (0, 0)

    def paint(polys: list[np.ndarray], rgb: tuple[float, ...], target: np.ndarray) -> None:
        for p in polys:
            fx.paint_planar(target, local, origin, pose.centre_mm, pose.rotation, p,
                            np.asarray(rgb[::-1], np.float32) * gain)

    if setup.phantom == "washer":  # bare metal washer (and its dark bolt hole) on the chassis
        paint([fx.circle_polygon(float(rng.uniform(12, 16)))], fx.OCCLUDER_COLOURS["metal"], img)
        paint([fx.circle_polygon(float(rng.uniform(5, 8)))], (25.0, 25.0, 25.0), img)
    elif setup.phantom == "ring":  # rings on purple: a black O-ring, or a ring of other ratio
        r_out = float(rng.uniform(12, 18))
        paint([fx.circle_polygon(24.0)], setup.purple, img)
        paint([fx.circle_polygon(r_out)], (22.0, 22.0, 24.0), img)
        if rng.random() < 0.5:
            paint([fx.circle_polygon(r_out * float(rng.uniform(0.75, 0.85)))], setup.purple, img)
        else:  # white centre, but not this marker's 10/15 proportions
            ratio = float(rng.choice([rng.uniform(0.35, 0.55), rng.uniform(0.8, 0.9)]))
            paint([fx.circle_polygon(r_out * ratio)], (245.0, 245.0, 245.0), img)
    tag = tag_truth = None
    if with_tag:
        tag, tag_truth = _tag_base(scene, cam, win, pose, setup)
    covered = 0.0
    if setup.occluder is not None and setup.occluder[2] > 0:
        shape, colour, frac, ang = setup.occluder
        polys, covered = fx.occluder_polygon(shape, frac, ang, SPEC.inner_mm, SPEC.outer_mm)
        paint(polys, fx.OCCLUDER_COLOURS[colour], img)
        if tag is not None:
            paint(polys, fx.OCCLUDER_COLOURS[colour], tag)
    if setup.glare is not None:
        r, ang, peak = setup.glare
        p = pose.centre_mm + pose.rotation[:, :2] @ np.array([r * math.cos(ang),
                                                              r * math.sin(ang)])
        uv = local.project(p)[0]
        width = float(np.hypot(*(local.project(pose.centre_mm + pose.rotation[:, 0] * 2.5)[0]
                                 - local.project(pose.centre_mm)[0])))
        fx.highlight(img, (float(uv[0]), float(uv[1])), width, peak)
    image = _finish(img, setup, rng)
    truth = None if setup.phantom else cam.project(pose.centre_mm)[0] - np.array(win[:2])
    tag_img = None
    if tag is not None:
        tag_img = cv2.cvtColor(_finish(tag, setup, rng), cv2.COLOR_BGR2GRAY)
    return Sample(image, local, truth, covered, tag_img, tag_truth)


# -- conditions: each draws a Setup from ranges ------------------------------------------------
Draw = Callable[[np.random.Generator], Setup]


def _base(rng: np.random.Generator) -> Setup:
    return Setup(illumination=float(rng.uniform(0.6, 1.0)))


def _purples(rng: np.random.Generator) -> Setup:
    return Setup(purple=_any_purple(rng), cast=_cast(rng),
                 illumination=float(rng.uniform(0.6, 1.0)))


def _dim(rng: np.random.Generator) -> Setup:
    return Setup(purple=_any_purple(rng), cast=_cast(rng),
                 illumination=float(rng.uniform(0.08, 0.15)))


def _bayer(rng: np.random.Generator) -> Setup:
    s = _purples(rng)
    s.bayer = (str(rng.choice(fx.BAYER_PATTERNS)), str(rng.choice(fx.DEMOSAIC_METHODS)))
    return s


def _motion(rng: np.random.Generator) -> Setup:
    s = _purples(rng)
    s.motion = (float(rng.uniform(1.0, 6.0)), float(rng.uniform(0, 180)))
    return s


def _defocus(rng: np.random.Generator) -> Setup:
    s = _purples(rng)
    s.defocus = float(rng.uniform(0.5, 2.5))
    return s


def _glare(rng: np.random.Generator) -> Setup:
    s = _purples(rng)
    s.glare = (float(rng.uniform(9.0, 16.0)), float(rng.uniform(0, 2 * math.pi)),
               float(rng.uniform(150.0, 500.0)))
    return s


def _occluded(lo: float, hi: float, shapes: tuple[str, ...]) -> Draw:
    def draw(rng: np.random.Generator) -> Setup:
        s = _purples(rng)
        s.occluder = (str(rng.choice(shapes)), str(rng.choice(list(fx.OCCLUDER_COLOURS))),
                      float(rng.uniform(lo, hi)), float(rng.uniform(0, 2 * math.pi)))
        return s
    return draw


def _combined(rng: np.random.Generator) -> Setup:
    s = _occluded(0.0, 0.2, fx.OCCLUDER_SHAPES)(rng)
    s.bayer = (str(rng.choice(fx.BAYER_PATTERNS)), "bilinear")
    s.motion = (float(rng.uniform(0.0, 3.0)), float(rng.uniform(0, 180)))
    return s


def _phantom(kind: str) -> Draw:
    def draw(rng: np.random.Generator) -> Setup:
        s = _purples(rng)
        s.phantom = kind
        return s
    return draw


CONDITIONS: dict[str, tuple[Draw, bool]] = {  # name: (draw, run AprilTag on it too)
    "clean": (_base, False),
    "purple range + cast": (_purples, False),
    "light 8-15 %": (_dim, False),
    "bayer demosaiced": (_bayer, False),
    "motion blur 1-6 px": (_motion, False),
    "defocus 0.5-2.5 px": (_defocus, False),
    "glare on ring": (_glare, False),
    "occluded 0-20 %": (_occluded(0.0, 0.2, fx.OCCLUDER_SHAPES), True),
    "occluded 20-40 %": (_occluded(0.2, 0.4, ("hand", "frame")), True),
    "combined": (_combined, False),
    "phantom: purple bar": (_phantom("patch"), False),
    "phantom: purple disk": (_phantom("disk"), False),
    "phantom: washer": (_phantom("washer"), False),
    "phantom: ring on purple": (_phantom("ring"), False),
}


def _apriltag(samples: list[Sample]) -> Result:
    try:
        from pupil_apriltags import Detector
    except ImportError:
        return {"skipped": "pupil-apriltags not installed"}
    det = Detector(families="tag36h11", nthreads=1, quad_decimate=1.0)
    errs: list[float] = []
    for s in samples:
        if s.tag_image is None or s.tag_truth is None:
            continue
        hits = [d for d in det.detect(s.tag_image) if d.tag_id == 0]
        if hits:
            # AprilTag puts the origin at the corner of pixel (0, 0), OpenCV at its centre
            errs.append(float(np.hypot(*(np.asarray(hits[0].center) - 0.5 - s.tag_truth))))
    return {"images": len(samples), "found": len(errs), **_stats(errs),
            "wrong": sum(e > WRONG_PX for e in errs)}


def _stats(errs: list[float]) -> dict[str, float]:
    if not errs:
        return {}
    a = np.asarray(errs)
    return {"median": float(np.median(a)), "p95": float(np.percentile(a, 95)),
            "max": float(a.max())}


def bench_robustness(rng: np.random.Generator, quick: bool,
                     only: tuple[str, ...] | None = None, n: int | None = None) -> Result:
    """Every condition (or ``only`` those), ``n`` seeded images each (default 4 with
    ``quick``, a smoke run of under a minute of CPU; 30 otherwise)."""
    n = n or (4 if quick else 30)
    seed = int(rng.integers(1 << 30))
    params = VisionParams()
    out: Result = {"per_condition": n}
    for k, (name, (draw, tag)) in enumerate(CONDITIONS.items()):
        if only is not None and name not in only:
            continue
        found, errs, wrong, reasons, visible = 0, [], 0, [], []
        samples = []
        for i in range(n):
            r = np.random.default_rng([seed, k, i])
            s = make_sample(draw(r), r, with_tag=tag)
            if tag:
                samples.append(s)
            d = detect(s.image, s.camera, params, SPEC)
            if not d.found:
                reasons.append(str(d.reason))
                continue
            found += 1
            if s.truth is not None and d.centre_px is not None:
                e = float(np.hypot(*(d.centre_px - s.truth)))
                errs.append(e)
                wrong += e > WRONG_PX
                visible.append(float(getattr(d, "outer_visible", math.nan)))
        phantom = name.startswith("phantom")
        row: Result = {"images": n, "found": 0 if phantom else found,
                       "phantom": found if phantom else 0, "wrong": wrong, **_stats(errs),
                       "refusals": sorted(set(reasons))[:6]}
        if visible:
            row["visible_min"] = float(np.nanmin(visible)) if np.isfinite(visible).any() else None
        if tag:
            row["apriltag"] = _apriltag(samples)
        out[name] = row
    return out


def print_table(res: Result) -> None:
    """condition | found | centre error median / p95 / max | wrong | phantom."""
    def f(v: Any) -> str:
        return "-" if v is None else f"{v:.4f}"

    head = ["condition", "found", "median px", "p95 px", "max px", "wrong", "phantom"]
    rows = []
    for name, r in res.items():
        if not isinstance(r, dict):
            continue
        found = "-" if name.startswith("phantom") else f"{r['found']}/{r['images']}"
        rows.append([name, found, f(r.get("median")), f(r.get("p95")), f(r.get("max")),
                     str(r["wrong"]), f"{r['phantom']}/{r['images']}"
                     if name.startswith("phantom") else "-"])
        a = r.get("apriltag")
        if a and "found" in a:
            rows.append([f"  AprilTag 3, {name}", f"{a['found']}/{a['images']}",
                         f(a.get("median")), f(a.get("p95")), f(a.get("max")), str(a["wrong"]),
                         "-"])
    widths = [max(len(x[i]) for x in [head, *rows]) for i in range(len(head))]
    print(f"\nRobustness ({res.get('per_condition')} seeded images per condition, small "
          f"windows of the 20 MP camera, 0.9-1.6 m, tilt 0-45 deg)")
    for r in [head, ["-" * w for w in widths], *rows]:
        print("  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in
                        enumerate(zip(r, widths, strict=True))))
    for name, r in res.items():
        if isinstance(r, dict) and r.get("refusals") and not name.startswith("phantom"):
            print(f"  {name} refused: {' | '.join(r['refusals'][:3])}")
