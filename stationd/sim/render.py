"""Physically exact synthetic camera images: the ground truth of the accuracy benchmarks.

The detector is meant to find marker centres to ~0.01 px, so the images it is judged on must
be right to well below that: every pixel near a marker is ray-cast through the full camera
model (lens distortion included) onto the marker's plane and box-filtered with ``S x S``
samples where it straddles a colour boundary (see ``raycast``).  No rasteriser is involved: a
rasterised ellipse is exactly the modelling shortcut the benchmarks must not inherit.

Pipeline (linear 0-255, no gamma): reflectance (background with optional texture, distractors
and markers, far to near) x illumination field x colour cast -> Gaussian blur -> Gaussian noise
-> rounding and clipping -> salt-and-pepper.  The background, illumination, noise and
salt-and-pepper are all functions of *sensor* coordinates and the seed, so a window render is
the same region of the full frame; that lets benchmarks render only what the detector looks at.
"""

from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np

from stationd.geometry.camera import Camera
from stationd.sim.raycast import Bar, Chessboard, Disc, Patch, RingMarker, composite
from stationd.vision.marker import PURPLE_RGB, RGB, MarkerSpec

Window = tuple[int, int, int, int]
_STRIP = 512  # rows per block of a large render: bounds memory, multiple of _TILE
_TILE = 256  # noise tiles, seeded by their sensor position
_TEXTURE_STREAM, _NOISE_STREAM, _SP_STREAM = 1, 2, 3


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    A = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    c, s = math.cos(angle), math.sin(angle)
    return np.asarray(np.eye(3) * c + s * A + (1 - c) * np.outer(a, a))


@dataclass(frozen=True, eq=False)
class MarkerPose:
    """A plane pose in the camera frame (mm): centre, and rotation columns (x, y, normal).

    The normal points towards the camera (``normal . centre < 0``): that is the printed face.
    """

    centre_mm: np.ndarray
    rotation: np.ndarray

    def __post_init__(self) -> None:
        c = np.asarray(self.centre_mm, dtype=np.float64).reshape(3)
        R = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        if not (np.allclose(R.T @ R, np.eye(3), atol=1e-9) and np.linalg.det(R) > 0):
            raise ValueError("rotation must be a proper rotation matrix")
        if c[2] <= 0 or float(R[:, 2] @ c) >= 0:
            raise ValueError("the marker must be in front of the camera and face it")
        object.__setattr__(self, "centre_mm", c)
        object.__setattr__(self, "rotation", R)

    @property
    def normal(self) -> np.ndarray:
        return np.asarray(self.rotation[:, 2])

    @classmethod
    def look(cls, centre_mm: np.ndarray | tuple[float, float, float], tilt_deg: float = 0.0,
             tilt_azimuth_deg: float = 0.0, spin_deg: float = 0.0) -> MarkerPose:
        """A marker at ``centre_mm`` whose normal is tilted ``tilt_deg`` from the line of sight.

        Zero tilt: the normal points straight back at the camera centre.  The tilt is a rotation
        about an axis perpendicular to the line of sight at ``tilt_azimuth_deg`` (0 = the image
        +u direction, 90 = +v); ``spin_deg`` turns the marker about its own normal first.
        """
        if not 0.0 <= tilt_deg < 90.0:
            raise ValueError("tilt_deg must be in [0, 90)")
        c = np.asarray(centre_mm, dtype=np.float64).reshape(3)
        n0 = -c / np.linalg.norm(c)
        e1 = np.array([1.0, 0.0, 0.0]) - n0[0] * n0
        if np.linalg.norm(e1) < 1e-6:
            e1 = np.array([0.0, 1.0, 0.0]) - n0[1] * n0
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(e1, n0)  # close to +v for a marker ahead of the camera
        az, spin = math.radians(tilt_azimuth_deg), math.radians(spin_deg)
        tilt = _rodrigues(math.cos(az) * e1 + math.sin(az) * e2, math.radians(tilt_deg))
        n = tilt @ n0
        x = tilt @ (math.cos(spin) * e1 + math.sin(spin) * e2)
        return cls(centre_mm=c, rotation=np.column_stack([x, np.cross(n, x), n]))


@dataclass(frozen=True, eq=False)
class Distractor:
    """A purple patch with no ring (a disc, or a bar of half-length ``size_mm``) on a plane."""

    pose: MarkerPose
    kind: Literal["disc", "bar"] = "disc"
    size_mm: float = 15.0  # disc radius, or half-length of the bar along the pose's x axis
    half_width_mm: float = 4.0  # bar only
    rgb: RGB = PURPLE_RGB


@dataclass(eq=False)
class Scene:
    """Everything in front of the lens and everything the sensor adds.

    Illumination field: ``illumination * clip(vignette * gradient, light_min, 1)``, with the
    vignette falling quadratically from 1 at the principal point to ``1 - vignetting`` at the
    farthest sensor corner, and the gradient falling linearly from 1 to ``1 - gradient`` across
    the sensor towards ``gradient_deg`` (0 = +u, 90 = +v).  ``cast`` are RGB channel gains.
    ``salt_pepper`` distinct pixels, uniform inside ``salt_pepper_roi`` (sensor x, y, w, h; None
    = the whole sensor), are set to 0 or 255 in all channels after quantisation.
    """

    markers: list[tuple[MarkerPose, MarkerSpec]] = field(default_factory=list)
    background_rgb: tuple[float, float, float] = (70.0, 75.0, 80.0)
    texture: float = 0.0  # relative amplitude of the background's blotchy texture
    texture_cell_px: int = 32
    distractors: list[Distractor] = field(default_factory=list)
    boards: list[tuple[MarkerPose, Chessboard]] = field(default_factory=list)
    illumination: float = 1.0
    vignetting: float = 0.0
    gradient: float = 0.0
    gradient_deg: float = 0.0
    light_min: float = 0.0
    cast: tuple[float, float, float] = (1.0, 1.0, 1.0)
    blur_sigma: float = 0.0
    noise_sigma: float = 0.0
    salt_pepper: int = 0
    salt_pepper_roi: Window | None = None

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """Reject parameters outside their physical range (Scene is mutable: render re-checks)."""
        if not (self.illumination >= 0 and 0 <= self.vignetting < 1 and 0 <= self.gradient < 1
                and 0 <= self.light_min <= 1 and min(self.cast) > 0):
            raise ValueError("illumination parameters out of range")
        if min(self.blur_sigma, self.noise_sigma, self.texture, self.salt_pepper) < 0:
            raise ValueError("blur, noise, texture and salt-and-pepper must be >= 0")
        if int(self.texture_cell_px) != self.texture_cell_px or self.texture_cell_px < 4:
            raise ValueError("texture_cell_px must be an integer >= 4")


@dataclass(frozen=True, eq=False)
class MarkerTruth:
    """Ground truth of one marker; pixel quantities are in the rendered window's coordinates.

    ``tilt_deg`` is measured from the line of sight (as in ``MarkerPose.look``);
    ``axis_tilt_deg`` from the optical axis (0 = parallel to the image plane, where the
    ellipse centre is unbiased).  ``bbox`` (x, y, w, h) covers the purple field's footprint,
    clipped to the window; ``visible`` says the whole field is inside the window.
    """

    centre_px: np.ndarray
    centre_undist_px: np.ndarray
    normal: np.ndarray
    centre_mm: np.ndarray
    tilt_deg: float
    distance_mm: float
    bbox: Window
    visible: bool
    axis_tilt_deg: float


@dataclass(frozen=True, eq=False)
class Rendered:
    """A uint8 BGR image (OpenCV order), its markers' truth, and the sensor window it shows."""

    image: np.ndarray
    truth: list[MarkerTruth]
    window: Window


def default_camera() -> Camera:
    """The station's Hikvision MV-CS200-10UC (20 MP, 2.4 um pixels) with its 12 mm lens."""
    K = np.array([[5000.0, 0.0, 2735.5], [0.0, 5000.0, 1823.5], [0.0, 0.0, 1.0]])
    return Camera(K=K, dist=np.array([-0.08, 0.12, 2e-4, -1e-4, 0.0]), size=(5472, 3648))


def crop_camera(camera: Camera, window: Window) -> Camera:
    """The camera seen through a window: same lens, principal point in window coordinates."""
    x0, y0, w, h = _check_window(window, camera.size)
    K = camera.K.copy()
    K[0, 2] -= x0
    K[1, 2] -= y0
    return Camera(K=K, dist=camera.dist.copy(), size=(w, h))


def roi_around(camera: Camera, centre_mm: np.ndarray | tuple[float, float, float],
               size: tuple[int, int] = (120, 75)) -> Window:
    """A sensor rectangle of ``size`` centred on a 3D point's image (for ``salt_pepper_roi``)."""
    u, v = camera.project(np.asarray(centre_mm, dtype=np.float64))[0]
    return round(u - size[0] / 2), round(v - size[1] / 2), size[0], size[1]


def render(camera: Camera, scene: Scene, *, window: Window | None = None, seed: int = 0,
           supersample: int = 16) -> Rendered:
    """Render ``scene`` as ``camera`` sees it, in ``window`` (x0, y0, w, h) of the sensor.

    Deterministic in ``seed``; pixel (0, 0) of the image is sensor pixel (x0, y0), and a window
    render equals that region of the full frame (up to float rounding before quantisation).
    """
    scene.check()
    if supersample < 1 or seed < 0:
        raise ValueError("supersample must be >= 1 and seed >= 0")
    win = _check_window(window or (0, 0, *camera.size), camera.size)
    x0, y0, w, h = win
    gain = _gain(scene).astype(np.float64)
    patches = [_marker_patch(p, s, gain) for p, s in scene.markers]
    patches += [_distractor_patch(d, gain) for d in scene.distractors]
    card = np.array([[235.0, 235.0, 235.0], [25.0, 25.0, 25.0]]) * gain  # white, black (BGR)
    patches += [Patch(b, card, p.centre_mm, p.rotation) for p, b in scene.boards]
    patches.sort(key=lambda p: -float(np.linalg.norm(p.centre)))  # painter's order: far first
    texture = _texture_octaves(scene, camera.size, seed)
    image = np.empty((h, w, 3), dtype=np.uint8)
    rows = [y0, *range((y0 // _STRIP + 1) * _STRIP, y0 + h, _STRIP), y0 + h]

    def block(ya: int, yb: int) -> None:
        image[ya - y0 : yb - y0] = _render_block(camera, scene, patches, texture,
                                                 (x0, ya, w, yb - ya), seed, supersample)

    # Blocks are independent and NumPy / OpenCV release the GIL in bulk work: use the cores.
    with ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
        list(pool.map(block, rows[:-1], rows[1:]))
    _salt_pepper(image, scene, camera.size, win, seed)
    truth = [marker_truth(camera, pose, spec, win) for pose, spec in scene.markers]
    return Rendered(image=image, truth=truth, window=win)


def marker_truth(camera: Camera, pose: MarkerPose, spec: MarkerSpec,
                 window: Window | None = None) -> MarkerTruth:
    """The truth ``render`` reports for this marker in ``window``: geometry only, no pixels."""
    return _truth(camera, pose, spec, _check_window(window or (0, 0, *camera.size),
                                                    camera.size))


# -- internals ------------------------------------------------------------------------------
def _check_window(window: Window, size: tuple[int, int]) -> Window:
    x0, y0, w, h = (int(v) for v in window)
    if not (x0 >= 0 and y0 >= 0 and w >= 1 and h >= 1 and x0 + w <= size[0]
            and y0 + h <= size[1]):
        raise ValueError(f"window {window} does not fit the {size[0]}x{size[1]} sensor")
    return x0, y0, w, h


def _marker_patch(pose: MarkerPose, spec: MarkerSpec, gain: np.ndarray | None = None) -> Patch:
    """The marker as a ray-castable patch; ``gain`` (BGR) turns its colours into lit BGR."""
    colours = np.array([spec.white_rgb, spec.black_rgb, spec.purple_rgb], dtype=np.float64)
    colours = colours[:, ::-1] * (1.0 if gain is None else gain)
    shape = RingMarker(spec.inner_mm, spec.outer_mm, spec.field_mm)
    return Patch(shape, colours, pose.centre_mm, pose.rotation)


def _distractor_patch(d: Distractor, gain: np.ndarray) -> Patch:
    if d.size_mm <= 0 or d.half_width_mm <= 0 or d.kind not in ("disc", "bar"):
        raise ValueError("a distractor is a 'disc' or a 'bar' with sizes > 0")
    shape = Disc(d.size_mm) if d.kind == "disc" else Bar(d.size_mm, d.half_width_mm)
    colours = np.array([d.rgb[::-1]], dtype=np.float64) * gain
    return Patch(shape, colours, d.pose.centre_mm, d.pose.rotation)


def _truth(camera: Camera, pose: MarkerPose, spec: MarkerSpec, win: Window) -> MarkerTruth:
    x0, y0, w, h = win
    off = np.array([x0, y0], dtype=np.float64)
    c, n = pose.centre_mm, pose.normal
    dist = float(np.linalg.norm(c))
    umin, umax, vmin, vmax = _marker_patch(pose, spec).footprint(camera)
    umin, umax, vmin, vmax = umin - x0, umax - x0, vmin - y0, vmax - y0
    bx0, by0 = max(math.floor(umin + 0.5), 0), max(math.floor(vmin + 0.5), 0)
    bx1, by1 = min(math.ceil(umax - 0.5), w - 1), min(math.ceil(vmax - 0.5), h - 1)
    return MarkerTruth(
        centre_px=camera.project(c)[0] - off,
        centre_undist_px=(camera.K @ (c / c[2]))[:2] - off,
        normal=n.copy(),
        centre_mm=c.copy(),
        tilt_deg=math.degrees(math.acos(min(1.0, float(-n @ c) / dist))),
        distance_mm=dist,
        bbox=(bx0, by0, max(bx1 - bx0 + 1, 0), max(by1 - by0 + 1, 0)),
        visible=bool(umin >= -0.5 and vmin >= -0.5 and umax <= w - 0.5 and vmax <= h - 0.5),
        axis_tilt_deg=math.degrees(math.acos(min(1.0, float(-n[2])))),
    )


def _render_block(camera: Camera, scene: Scene, patches: list[Patch],
                  texture: list[tuple[np.ndarray, int]], block: Window, seed: int,
                  supersample: int) -> np.ndarray:
    """One block of rows (BGR throughout), shaded with a blur margin so blocks join seamlessly."""
    x0, y0, w, h = block
    sw, sh = camera.size
    m = math.ceil(4 * scene.blur_sigma) if scene.blur_sigma > 0 else 0
    ex0, ey0 = max(0, x0 - m), max(0, y0 - m)
    ext = (ex0, ey0, min(sw, x0 + w + m) - ex0, min(sh, y0 + h + m) - ey0)
    light = _light_field(scene, camera, ext)
    shade = light
    for grid, cell in texture:
        octave = _texture_octave(grid, cell, ext)
        shade = octave if shade is None else shade * octave
    base = np.asarray(scene.background_rgb[::-1], dtype=np.float32) * _gain(scene)
    img = np.empty((ext[3], ext[2], 3), dtype=np.float32)
    if shade is None:
        img[:] = base
    else:
        np.multiply(shade[..., None], base, out=img)
    for patch in patches:
        composite(camera, patch, img, ex0, ey0, supersample, light=light)
    if m:
        img = np.asarray(cv2.GaussianBlur(img, (2 * m + 1, 2 * m + 1), scene.blur_sigma,
                                          borderType=cv2.BORDER_REFLECT))
    img = np.ascontiguousarray(img[y0 - ey0 : y0 - ey0 + h, x0 - ex0 : x0 - ex0 + w])
    if scene.noise_sigma > 0:
        _add_noise(img, scene.noise_sigma, seed, x0, y0)
    np.maximum(img, 0, out=img)
    return np.asarray(cv2.convertScaleAbs(img))  # rounds half to even, saturates at 255


def _gain(scene: Scene) -> np.ndarray:
    """Overall illumination times the colour cast, in BGR order."""
    return np.asarray(scene.cast[::-1], dtype=np.float32) * np.float32(scene.illumination)


def _texture_octaves(scene: Scene, size: tuple[int, int],
                     seed: int) -> list[tuple[np.ndarray, int]]:
    """Random node grids over the whole sensor: coarse blotches, then grain at half strength.

    Each grid holds ``1 + texture * N(0, 1)`` values (clipped at 0) and is seeded once per
    render, so every window sees the same chassis.
    """
    if scene.texture <= 0:
        return []
    rng = np.random.default_rng([seed, _TEXTURE_STREAM])
    octaves = []
    for cell, amp in ((scene.texture_cell_px, scene.texture),
                      (max(2, scene.texture_cell_px // 4), scene.texture / 2)):
        nodes = rng.standard_normal((size[1] // cell + 5, size[0] // cell + 5))
        octaves.append((np.maximum(1 + amp * nodes, 0).astype(np.float32), cell))
    return octaves


def _texture_octave(grid: np.ndarray, cell: int, block: Window) -> np.ndarray:
    """Bilinear interpolation of ``grid`` (node k at sensor ``(k - 2) * cell + (cell - 1) / 2``).

    That is ``cv2.resize``'s sampling convention for an exact ``cell`` x upscale; resizing the
    nodes around the block with one spare node each side keeps its border handling out of
    the crop, so the result is independent of the block and cheap.
    """
    x0, y0, w, h = block
    kx, ky = x0 // cell + 1, y0 // cell + 1
    nx, ny = -(-(x0 + w) // cell) + 3 - kx, -(-(y0 + h) // cell) + 3 - ky
    up = cv2.resize(grid[ky : ky + ny, kx : kx + nx], (nx * cell, ny * cell),
                    interpolation=cv2.INTER_LINEAR)
    jx, jy = x0 - (kx - 2) * cell, y0 - (ky - 2) * cell
    return np.asarray(up[jy : jy + h, jx : jx + w])


def _light_field(scene: Scene, camera: Camera, block: Window) -> np.ndarray | None:
    """``clip(vignette * gradient, light_min, 1)`` over the block (None where it is all 1)."""
    if scene.vignetting == 0 and scene.gradient == 0:
        return None
    x0, y0, w, h = block
    sw, sh = camera.size
    cx, cy = camera.K[0, 2], camera.K[1, 2]
    u, v = np.arange(x0, x0 + w, dtype=np.float64), np.arange(y0, y0 + h, dtype=np.float64)
    cu, cv = np.array([0, sw - 1, 0, sw - 1]), np.array([0, 0, sh - 1, sh - 1])
    k = scene.vignetting / float(np.max((cu - cx) ** 2 + (cv - cy) ** 2))
    th = math.radians(scene.gradient_deg)
    pc = cu * math.cos(th) + cv * math.sin(th)
    g = scene.gradient / max(float(pc.max() - pc.min()), 1e-9)
    vig = (1 - k * (v - cy) ** 2).astype(np.float32)[:, None] - (k * (u - cx) ** 2).astype(
        np.float32)
    vig *= (1 - g * (v * math.sin(th) - pc.min())).astype(np.float32)[:, None] - (
        g * u * math.cos(th)).astype(np.float32)
    return np.asarray(np.clip(vig, scene.light_min, 1.0, out=vig))


def _add_noise(img: np.ndarray, sigma: float, seed: int, x0: int, y0: int) -> None:
    """Add Gaussian noise from 256x256 tiles seeded by their sensor position (window-stable)."""
    h, w = img.shape[:2]
    s = np.float32(sigma)
    for ty in range(y0 // _TILE, (y0 + h - 1) // _TILE + 1):
        for tx in range(x0 // _TILE, (x0 + w - 1) // _TILE + 1):
            gen = np.random.Generator(np.random.SFC64([seed, _NOISE_STREAM, ty, tx]))
            tile = gen.standard_normal((_TILE, _TILE, 3), dtype=np.float32)
            ya, yb = max(y0, ty * _TILE), min(y0 + h, (ty + 1) * _TILE)
            xa, xb = max(x0, tx * _TILE), min(x0 + w, (tx + 1) * _TILE)
            part = tile[ya - ty * _TILE : yb - ty * _TILE, xa - tx * _TILE : xb - tx * _TILE]
            img[ya - y0 : yb - y0, xa - x0 : xb - x0] += s * part


def _salt_pepper(image: np.ndarray, scene: Scene, size: tuple[int, int], win: Window,
                 seed: int) -> None:
    """Set ``scene.salt_pepper`` distinct ROI pixels (sensor coordinates) to 0 or 255."""
    if scene.salt_pepper == 0:
        return
    rx, ry, rw, rh = scene.salt_pepper_roi or (0, 0, *size)
    if rw <= 0 or rh <= 0 or scene.salt_pepper > rw * rh:
        raise ValueError("salt_pepper_roi is empty or smaller than the salt-and-pepper count")
    rng = np.random.default_rng([seed, _SP_STREAM])
    idx = rng.choice(rw * rh, size=scene.salt_pepper, replace=False)
    values = (rng.integers(0, 2, size=scene.salt_pepper) * 255).astype(np.uint8)
    x0, y0, w, h = win
    u, v = rx + idx % rw - x0, ry + idx // rw - y0
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    image[v[inside], u[inside]] = values[inside, None]
