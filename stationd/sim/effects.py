"""Physical image effects beyond the renderer: what a real station adds to a clean marker.

Why a separate module: ``render`` is the exact ground truth (ray-cast, box-filtered); the
robustness benchmark needs the things that make real frames hard, applied to a noise-free
render in the order light meets them:

1. things in front of the marker (``paint_planar``): occluders (an arm, a socket, a chassis
   member, a glove) and the phantom shapes (washers, rings on purple), painted as polygons in a
   plane through the marker's pose and anti-aliased by 4x4 supersampling;
2. a clipped specular highlight (``highlight``): a bright lobe added before the sensor clips;
3. optics and motion (``motion_blur``, ``defocus``): centred line and disk kernels, so the
   blur moves no centre (a real exposure is centred on the mid-exposure pose);
4. sensor: noise, then Bayer sampling (``bayer_mosaic``) and the driver's demosaicing with
   OpenCV (``demosaic``), which puts colour fringes on the black/white edges.

Every parameter is a physical quantity (px of blur, mm of occluder, gains), so a benchmark
draws them from ranges, not from values tuned to the detector.
"""

from __future__ import annotations

import colorsys
import math

import cv2
import numpy as np

from stationd.geometry.camera import Camera

__all__ = ["BAYER_PATTERNS", "DEMOSAIC_METHODS", "OCCLUDER_COLOURS", "OCCLUDER_SHAPES",
           "bayer_mosaic", "circle_polygon", "defocus", "demosaic", "highlight",
           "motion_blur", "occluder_polygon", "outer_coverage", "outer_coverage_all",
           "paint_planar", "purple_rgb"]

# Occluder reflectances (linear 0-255, RGB): dark glove/rubber, skin, grey plastic, bare metal.
OCCLUDER_COLOURS: dict[str, tuple[float, float, float]] = {
    "dark": (28.0, 28.0, 30.0), "skin": (205.0, 150.0, 120.0), "grey": (120.0, 120.0, 125.0),
    "metal": (190.0, 195.0, 200.0)}
OCCLUDER_SHAPES = ("disk", "edge", "finger", "hand", "frame")
BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
DEMOSAIC_METHODS = ("bilinear", "vng", "ea")

# OpenCV names a Bayer pattern by the 2nd row's 2nd and 3rd pixels; these are the codes whose
# output matches the pattern named by its top-left 2x2 block (checked in tests/sim).
_CV_CODE = {"RGGB": "BayerBG", "BGGR": "BayerRG", "GRBG": "BayerGB", "GBRG": "BayerGR"}
_METHOD_SUFFIX = {"bilinear": "2BGR", "vng": "2BGR_VNG", "ea": "2BGR_EA"}
_SS = 4  # supersampling of painted polygons (per axis)


def purple_rgb(hue_deg: float, sat: float, val: float) -> tuple[int, int, int]:
    """sRGB 0-255 of an HSV print colour (hue in degrees, saturation and value 0-1)."""
    r, g, b = colorsys.hsv_to_rgb((hue_deg % 360.0) / 360.0, sat, val)
    return round(r * 255), round(g * 255), round(b * 255)


def circle_polygon(radius_mm: float, centre: tuple[float, float] = (0.0, 0.0),
                   n: int = 256) -> np.ndarray:
    """(n, 2) vertices of a circle in the plane (mm)."""
    t = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return np.stack([centre[0] + radius_mm * np.cos(t), centre[1] + radius_mm * np.sin(t)], 1)


def _inside(poly: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Even-odd point-in-polygon test, vectorised over points."""
    x, y = pts[:, 0][:, None], pts[:, 1][:, None]
    x0, y0 = poly[:, 0][None, :], poly[:, 1][None, :]
    x1, y1 = np.roll(poly[:, 0], -1)[None, :], np.roll(poly[:, 1], -1)[None, :]
    cross = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return np.asarray((cross & (x < xi)).sum(axis=1) % 2 == 1)


def outer_coverage(poly: np.ndarray, outer_mm: float, n: int = 720) -> float:
    """Fraction of the marker's outer circle (radius ``outer_mm``) that ``poly`` covers."""
    return float(_inside(poly, circle_polygon(outer_mm, n=n)).mean())


def _one(kind: str, size: float, angle: float, inner_mm: float, outer_mm: float,
         width_mm: float) -> np.ndarray:
    """One convex-ish occluder of ``kind`` whose reach into the ring grows with ``size``."""
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    clear = inner_mm + 0.6  # never touches the white disk (nor its edge's blur)
    d = clear + (1.0 - size) * (outer_mm - clear + 0.2)  # closest approach to the centre
    if kind == "disk":  # a socket or a knuckle: a big round thing from outside
        rho = 2.0 * outer_mm
        pts = circle_polygon(rho, (d + rho, 0.0), 128)
    elif kind == "edge":  # a chassis member or an arm: a straight edge across the field
        pts = np.array([[d, -4 * outer_mm], [6 * outer_mm, -4 * outer_mm],
                        [6 * outer_mm, 4 * outer_mm], [d, 4 * outer_mm]])
    else:  # a finger or a tool tip reaching radially into the ring, round-ended
        w = width_mm * (0.3 + 0.7 * size)
        t = np.linspace(math.pi / 2, 3 * math.pi / 2, 24)
        tip = np.stack([d + w + w * np.cos(t), w * np.sin(t)], 1)
        pts = np.vstack([[[6 * outer_mm, w]], tip, [[6 * outer_mm, -w]]])
    return np.asarray(pts @ rot.T)


def _shapes(kind: str, size: float, angle: float, inner_mm: float, outer_mm: float,
            width_mm: float) -> list[np.ndarray]:
    """The occluder as polygons: one thing, or several (fingers of a hand, two members)."""
    if kind in ("disk", "edge", "finger"):
        return [_one(kind, size, angle, inner_mm, outer_mm, width_mm)]
    if kind == "hand":  # three fingers 55 degrees apart
        return [_one("finger", size, angle + k * math.radians(55), inner_mm, outer_mm,
                     width_mm) for k in (-1, 0, 1)]
    if kind == "frame":  # the wrench seen between two chassis members
        return [_one("edge", size, angle + k * math.pi, inner_mm, outer_mm, width_mm)
                for k in (0, 1)]
    raise ValueError(f"occluder shape must be one of {OCCLUDER_SHAPES}, got {kind!r}")


def outer_coverage_all(polys: list[np.ndarray], outer_mm: float, n: int = 720) -> float:
    """Fraction of the outer circle covered by the union of ``polys``."""
    ring = circle_polygon(outer_mm, n=n)
    hit = np.zeros(n, bool)
    for p in polys:
        hit |= _inside(p, ring)
    return float(hit.mean())


def occluder_polygon(kind: str, fraction: float, angle: float, inner_mm: float,
                     outer_mm: float, width_mm: float = 6.0) -> tuple[list[np.ndarray], float]:
    """An occluder (marker-plane mm polygons) covering about ``fraction`` of the outer circle.

    It never reaches within 0.6 mm of the white disk, so one convex thing covers at most
    acos(r_in/r_out)/pi of the outer circle (25 % for this marker); "hand" and "frame" reach
    40 %.  The fraction actually achieved is returned beside the polygons.
    """
    if not 0.0 <= fraction <= 1.0:
        raise ValueError("fraction must be in [0, 1]")
    lo, hi = 0.0, 1.0
    for _ in range(16):  # bisection on the size: coverage grows with it
        mid = 0.5 * (lo + hi)
        if outer_coverage_all(_shapes(kind, mid, angle, inner_mm, outer_mm, width_mm),
                              outer_mm) < fraction:
            lo = mid
        else:
            hi = mid
    polys = _shapes(kind, hi, angle, inner_mm, outer_mm, width_mm)
    return polys, outer_coverage_all(polys, outer_mm)


def paint_planar(image: np.ndarray, camera: Camera, window_xy: tuple[int, int],
                 centre_mm: np.ndarray, rotation: np.ndarray, poly_mm: np.ndarray,
                 bgr: np.ndarray | tuple[float, float, float]) -> None:
    """Paint a polygon lying in the plane (centre, rotation) onto a float32 BGR image.

    The polygon is projected through the full camera (distortion included) at dense vertices
    and filled at 4x4 supersampling, so its edge is anti-aliased like a real one.
    """
    poly = np.asarray(poly_mm, dtype=np.float64)
    # densify edges so the lens distortion bends them as it would a real straight edge
    nxt = np.roll(poly, -1, axis=0)
    seg = np.linalg.norm(nxt - poly, axis=1)
    pts = [poly[i] + (nxt[i] - poly[i]) * t for i in range(len(poly))
           for t in np.linspace(0, 1, max(1, int(seg[i] / 0.5)), endpoint=False)]
    local = np.column_stack([np.asarray(pts), np.zeros(len(pts))])
    uv = camera.project(centre_mm + local @ rotation.T) - np.asarray(window_xy, np.float64)
    h, w = image.shape[:2]
    mask = np.zeros((h * _SS, w * _SS), np.uint8)
    fx = np.rint((uv + 0.5) * _SS - 0.5).astype(np.int32)
    cv2.fillPoly(mask, [fx.reshape(-1, 1, 2)], 255)
    cover = cv2.resize(mask.astype(np.float32) / 255.0, (w, h), interpolation=cv2.INTER_AREA)
    colour = np.asarray(bgr, dtype=np.float32)
    image *= (1.0 - cover)[..., None]
    image += cover[..., None] * colour


def highlight(image: np.ndarray, centre_px: tuple[float, float], sigma_px: float,
              peak: float) -> None:
    """Add a Gaussian specular lobe (linear units, may exceed 255: the sensor clips later)."""
    h, w = image.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    r2 = (xx - centre_px[0]) ** 2 + (yy - centre_px[1]) ** 2
    image += (peak * np.exp(-r2 / (2.0 * sigma_px ** 2)))[..., None]


def motion_blur(image: np.ndarray, length_px: float, angle_deg: float) -> np.ndarray:
    """Convolve with a centred line kernel of ``length_px`` (box in time, anti-aliased ends)."""
    if length_px <= 0.0:
        return image
    half = math.ceil(length_px / 2.0) + 1
    ss = 8
    n = 2 * half + 1
    k = np.zeros((n * ss, n * ss), np.float32)
    t = np.linspace(-length_px / 2.0, length_px / 2.0, 64 * max(1, math.ceil(length_px)))
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    xs = np.clip(((half + t * c + 0.5) * ss).astype(int), 0, n * ss - 1)
    ys = np.clip(((half + t * s + 0.5) * ss).astype(int), 0, n * ss - 1)
    np.add.at(k, (ys, xs), 1.0)
    kern = np.asarray(cv2.resize(k, (n, n), interpolation=cv2.INTER_AREA), np.float32)
    kern /= kern.sum()
    return np.asarray(cv2.filter2D(image, -1, kern, borderType=cv2.BORDER_REFLECT))


def defocus(image: np.ndarray, radius_px: float) -> np.ndarray:
    """Convolve with a uniform disk of ``radius_px`` (geometric-optics defocus), anti-aliased."""
    if radius_px <= 0.0:
        return image
    half = math.ceil(radius_px) + 1
    ss = 8
    n = 2 * half + 1
    yy, xx = np.mgrid[0:n * ss, 0:n * ss].astype(np.float32)
    cx = (n * ss - 1) / 2.0
    disk = ((xx - cx) ** 2 + (yy - cx) ** 2 <= (radius_px * ss) ** 2).astype(np.float32)
    kern = cv2.resize(disk, (n, n), interpolation=cv2.INTER_AREA)
    kern /= kern.sum()
    return np.asarray(cv2.filter2D(image, -1, kern, borderType=cv2.BORDER_REFLECT))


def bayer_mosaic(image_bgr: np.ndarray, pattern: str) -> np.ndarray:
    """One sensor channel per pixel, the colour filter array named by its top-left 2x2."""
    if pattern not in BAYER_PATTERNS:
        raise ValueError(f"pattern must be one of {BAYER_PATTERNS}, got {pattern!r}")
    idx = {"B": 0, "G": 1, "R": 2}
    raw = np.empty(image_bgr.shape[:2], dtype=image_bgr.dtype)
    for k, ch in enumerate(pattern):
        dy, dx = divmod(k, 2)
        raw[dy::2, dx::2] = image_bgr[dy::2, dx::2, idx[ch]]
    return raw


def demosaic(raw: np.ndarray, pattern: str, method: str = "bilinear") -> np.ndarray:
    """The driver's demosaicing (OpenCV): uint8 raw -> uint8 BGR."""
    if pattern not in BAYER_PATTERNS or method not in DEMOSAIC_METHODS:
        raise ValueError(f"pattern in {BAYER_PATTERNS} and method in {DEMOSAIC_METHODS}")
    code = getattr(cv2, f"COLOR_{_CV_CODE[pattern]}{_METHOD_SUFFIX[method]}")
    return np.asarray(cv2.cvtColor(raw, code))
