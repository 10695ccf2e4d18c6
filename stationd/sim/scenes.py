"""Rendered test scenes for the benchmarks, the demo and the tests: stereo rigs, marker poses,
windowed renders, and the simulated station's four pairs (:func:`build_station`).

Renders are windows around the marker (the detector runs on them with the cropped camera),
so that thousands of accuracy samples stay cheap; the speed benchmark renders whole frames.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from stationd.geometry.camera import Camera, StereoPair
from stationd.geometry.frames import Transform
from stationd.sim.render import (
    MarkerPose,
    Scene,
    crop_camera,
    default_camera,
    marker_truth,
    render,
)
from stationd.vision.marker import MarkerSpec

Window = tuple[int, int, int, int]


def look_at_pair(camera: Camera, target_mm: np.ndarray, baseline_mm: float) -> StereoPair:
    """A pair whose right camera sits ``baseline_mm`` to the right and aims at the target."""
    c_right = np.array([baseline_mm, 0.0, 0.0])
    z = np.asarray(target_mm, dtype=np.float64) - c_right
    z /= np.linalg.norm(z)
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.vstack([x, y, z])  # rows: right camera axes in the left frame
    return StereoPair(camera, camera, R, -R @ c_right)


def station_pair(baseline_mm: float = 400.0, converge_mm: float = 1300.0) -> StereoPair:
    """The station's pair: two 20 MP cameras converging on the working height."""
    return look_at_pair(default_camera(), np.array([0.0, 0.0, converge_mm]), baseline_mm)


def to_right(pair: StereoPair, pose: MarkerPose) -> MarkerPose:
    """The same marker pose in the right camera's frame."""
    return MarkerPose(pair.R @ pose.centre_mm + pair.T, pair.R @ pose.rotation)


def marker_window(camera: Camera, pose: MarkerPose, spec: MarkerSpec,
                  margin_px: float = 48.0, *, clip: bool = False) -> Window | None:
    """Sensor window around the marker's purple field (None when it leaves the sensor).

    ``clip``: a marker partly out of the sensor gets the part of its window on the sensor
    (what a frame can show of it; a window render equals that region of the whole frame),
    None only when nothing of it is on the sensor or a corner is not in front of the camera
    (its projection means nothing: the caller renders the whole frame)."""
    f = spec.field_mm
    corners = np.array([[-f, -f, 0], [f, -f, 0], [f, f, 0], [-f, f, 0]], dtype=np.float64)
    pts_mm = pose.centre_mm + corners @ pose.rotation.T
    if clip and np.any(pts_mm[:, 2] <= 1e-6):
        return None
    pts = camera.project(pts_mm)
    lo = np.floor(pts.min(axis=0) - margin_px)
    hi = np.ceil(pts.max(axis=0) + margin_px)
    w, h = camera.size
    if clip:
        lo, hi = np.maximum(lo, 0.0), np.minimum(hi, [w - 1.0, h - 1.0])
        if lo[0] > hi[0] or lo[1] > hi[1]:
            return None
    elif lo[0] < 0 or lo[1] < 0 or hi[0] > w - 1 or hi[1] > h - 1:
        return None
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)


@dataclass(frozen=True, eq=False)
class View:
    """One windowed render: the image, the camera cropped to it, the truth in its pixels."""

    image: np.ndarray
    camera: Camera
    window: Window
    centre_px: np.ndarray
    field_bbox: Window  # in window pixels


def render_view(camera: Camera, pose: MarkerPose, spec: MarkerSpec, seed: int,
                **scene_kw: Any) -> View | None:
    """Render one marker through ``camera`` in a window around it (None if out of view).

    ``scene_kw`` are :class:`Scene` fields; ``salt_pepper_in_field`` (int) puts that many
    salt-and-pepper points inside the field's bounding box, as in the paper's section 4.1;
    ``dirt`` (int) paints that many grey spots of 1-2.5 px radius on the ring's boundaries
    after rendering: clutter that survives the impulse filter and gives the edge outliers the
    Leitz criterion is for (the marker's geometry, the truth, is untouched).
    """
    win = marker_window(camera, pose, spec)
    if win is None:
        return None
    sp = int(scene_kw.pop("salt_pepper_in_field", 0))
    dirt = int(scene_kw.pop("dirt", 0))
    scene = Scene(markers=[(pose, spec)], **scene_kw)
    if sp:
        # the field's box is the marker's truth, which the render computes from the geometry
        # alone: no render needed to know it
        bx, by, bw, bh = marker_truth(camera, pose, spec, win).bbox
        scene = replace(scene, salt_pepper=sp, salt_pepper_roi=(win[0] + bx, win[1] + by, bw, bh))
    out = render(camera, scene, window=win, seed=seed)
    t = out.truth[0]
    image = _dirty(out.image, camera, pose, spec, win, dirt, seed) if dirt else out.image
    return View(image, crop_camera(camera, win), win, t.centre_px, t.bbox)


def _dirty(image: np.ndarray, camera: Camera, pose: MarkerPose, spec: MarkerSpec, win: Window,
           count: int, seed: int) -> np.ndarray:
    import cv2

    rng = np.random.default_rng(seed + 7919)
    r = rng.choice([spec.inner_mm, spec.outer_mm], count) + rng.uniform(-0.6, 0.6, count)
    phi = rng.uniform(0, 2 * math.pi, count)
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.zeros(count)], axis=1)
    px = camera.project(pose.centre_mm + local @ pose.rotation.T) - np.array(win[:2])
    out = image.copy()
    shift = 4  # sub-pixel drawing precision (1/16 px)
    for (u, v), rad, grey in zip(px, rng.uniform(1.0, 2.5, count),
                                 rng.uniform(40, 200, count), strict=True):
        cv2.circle(out, (round(u * 16), round(v * 16)), round(rad * 16), (grey, grey, grey),
                   -1, cv2.LINE_AA, shift)
    return out


def crop_pair(pair: StereoPair, left: View, right: View) -> StereoPair:
    """The pair with each camera cropped to its view's window."""
    return StereoPair(left.camera, right.camera, pair.R, pair.T)


def random_pose(rng: np.random.Generator, camera: Camera, distance_mm: float, tilt_deg: float,
                spread: float = 0.6) -> MarkerPose:
    """A marker at ``distance_mm`` along a random ray within ``spread`` of the half-field,
    its normal tilted ``tilt_deg`` from the line of sight at a random azimuth and spin."""
    w, h = camera.size
    u = w / 2 + rng.uniform(-spread, spread) * w / 2
    v = h / 2 + rng.uniform(-spread, spread) * h / 2
    ray = np.append(camera.pixels_to_normalized(np.array([[u, v]]))[0], 1.0)
    centre = distance_mm * ray / np.linalg.norm(ray)
    return MarkerPose.look(centre, tilt_deg, float(rng.uniform(0, 360)),
                           float(rng.uniform(0, 360)))


def pose_in_pair(rng: np.random.Generator, pair: StereoPair,
                 depth: tuple[float, float] = (1150.0, 1450.0),
                 tilt: tuple[float, float] = (5.0, 35.0),
                 spec: MarkerSpec | None = None) -> MarkerPose:
    """A marker under the chassis (left frame), in full view of both cameras of the pair."""
    spec = spec or MarkerSpec()
    for _ in range(200):
        c = np.array([rng.uniform(-350, 550), rng.uniform(-300, 300), rng.uniform(*depth)])
        pose = MarkerPose.look(c, float(rng.uniform(*tilt)), float(rng.uniform(0, 360)),
                               float(rng.uniform(0, 360)))
        if marker_window(pair.left, pose, spec) and marker_window(
                pair.right, to_right(pair, pose), spec):
            return pose
    raise RuntimeError("no marker pose in view of both cameras")


def rotation_towards(normal: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A rotation whose third column is ``normal`` and whose in-plane spin is random."""
    n = normal / np.linalg.norm(normal)
    a = rng.normal(size=3)
    x = a - (a @ n) * n
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(n, x), n])


def tilt_of(normal: np.ndarray, centre: np.ndarray) -> float:
    """Angle (deg) between a normal and the line of sight back to the camera."""
    return math.degrees(math.acos(float(np.clip(-normal @ centre / np.linalg.norm(centre),
                                                 -1, 1))))


# -- the simulated station: four pairs under the chassis ------------------------------------
@dataclass(frozen=True, eq=False)
class StationPair:
    """One pair as built (the truth, for rendering) and as commissioned (for measuring)."""

    name: str
    true_pair: StereoPair
    R_vc: np.ndarray  # left camera axes in the vehicle frame (columns)
    c_v: np.ndarray   # left camera centre in the vehicle frame
    calibrated: StereoPair | None = None
    to_vehicle: Transform | None = None

    def to_camera(self, p_v: np.ndarray, rot_v: np.ndarray) -> MarkerPose:
        return MarkerPose(self.R_vc.T @ (p_v - self.c_v), self.R_vc.T @ rot_v)


def _camera(rng: np.random.Generator) -> Camera:
    """A real camera of the station's model: focal length, centre and lens vary a little."""
    base = default_camera()
    K = base.K.copy()
    K[0, 0] *= 1 + rng.normal(0, 0.005)
    K[1, 1] = K[0, 0] * (1 + rng.normal(0, 1e-4))
    K[0, 2] += rng.normal(0, 10)
    K[1, 2] += rng.normal(0, 10)
    dist = base.dist + rng.normal(0, 0.005, base.dist.size) * np.array([1, 1, 0.02, 0.02, 0])
    return Camera(K, dist, base.size)


def build_station(rng: np.random.Generator, count: int) -> list[StationPair]:
    """Pairs on the floor 1.3 m under the chassis, two on each side, looking up and inwards."""
    spots = [(900.0, -750.0), (900.0, 750.0), (2500.0, -750.0), (2500.0, 750.0)][:count]
    out = []
    for k, (x, y) in enumerate(spots):
        c = np.array([x, y, -1300.0])
        target = np.array([x + 250.0, 0.35 * y, 0.0])
        z = (target - c) / np.linalg.norm(target - c)
        xa = np.array([1.0, 0.0, 0.0]) - z[0] * z
        xa /= np.linalg.norm(xa)
        R_vc = np.column_stack([xa, np.cross(z, xa), z])
        left, right = _camera(rng), _camera(rng)
        looking = look_at_pair(left, R_vc.T @ (target - c), 400.0)
        out.append(StationPair(f"pair{k + 1}", StereoPair(left, right, looking.R, looking.T),
                               R_vc, c))
    return out
