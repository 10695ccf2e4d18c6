"""Edges of the two marker boundaries inside the ROI (paper 2.4, plus sub-pixel refinement).

Steps, all at full resolution but only inside the ROI:

1. ``intensity``: the V channel (max of B, G, R).  It is linear across both boundaries (the
   same channel dominates on each side), unlike the Retinex output, whose log would move the
   edge; enhancement is for finding the ROI, not for measuring in it.
2. ``remove_impulses``: a switching median.  Only pixels that are a local extremum *and*
   far from their 3x3 median are replaced, so salt-and-pepper points go while clean edges stay
   untouched (a plain median filter would bias curved edges).
3. ``canny_otsu``: Canny on the lightly smoothed ROI with thresholds from Otsu's method:
   ``high = t_otsu`` and ``low = high / 2``.  Otsu's threshold scales with the ROI's contrast,
   so the rule works at 10 % illumination as at full light.
4. ``ring_outline``: Otsu binarisation; the black ring is the dark region that has a hole (the
   white disk) with the area ratio of the marker, ``(r_in/r_out)^2`` (affine invariant), and
   the hole and outer contour give rough ellipses.
5. ``subpixel``: each Canny pixel is moved to the peak of the gradient magnitude along the
   dominant gradient axis (Devernay's correction), with a Gaussian (log-parabola) peak fit, which
   is exact for a blurred step edge.
6. ``assign``: edge points near each rough ellipse, with the right gradient polarity (inner
   boundary: brighter inside; outer boundary: purple brighter outside), linked into 8-connected
   contours; contours mostly off both ellipses are dropped as clutter.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from stationd.result import Refusal
from stationd.vision.ellipse import params_to_conic, sampson_distance
from stationd.vision.rays import MIN_TINT, RayRing, chroma, ring_from_rays
from stationd.vision.types import Ellipse

# Smoothing before the gradient (px).  Wide enough for a stable peak fit, narrow enough that
# the curvature bias (about sigma^2 / 2R, the same on both sides of the centre) stays ~0.01 px.
GRADIENT_SIGMA = 1.0
IMPULSE_THRESHOLD = 25.0
MIN_COS = 0.7  # an edge point's gradient within ~45 degrees of its boundary's normal


RotatedBox = tuple[tuple[float, float], tuple[float, float], float]


def _box(b: tuple[Sequence[float], Sequence[float], float]) -> RotatedBox:
    """cv2.fitEllipse's ((cx, cy), (w, h), angle) as plain floats."""
    return (float(b[0][0]), float(b[0][1])), (float(b[1][0]), float(b[1][1])), float(b[2])


@dataclass(frozen=True, eq=False)
class RingOutline:
    """Rough geometry of the black ring from the Otsu binarisation (ROI pixel coordinates)."""

    inner: RotatedBox  # cv2.fitEllipse box
    outer: RotatedBox
    area_ratio: float
    threshold: float


@dataclass(frozen=True, eq=False)
class BoundaryEdges:
    """Sub-pixel edge points (ROI pixel coordinates) of the two boundaries."""

    inner: np.ndarray  # (N, 2)
    outer: np.ndarray  # (M, 2)
    canny_low: float
    canny_high: float
    outline: RingOutline
    # edge points near the ring that neither boundary took (wrong direction, polarity or
    # colour beyond: an occluder's edge), for drawing what was rejected
    dropped: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))


def intensity(roi_bgr: np.ndarray) -> np.ndarray:
    """V = max(B, G, R) as float32.

    With OpenCV per channel: numpy's ``max(axis=2)`` over a strided 3-channel ROI costs
    ~2.5 ms on a 300x300 px ROI, twenty times more, the same values.
    """
    b, g, r = cv2.split(roi_bgr)
    return np.asarray(cv2.max(cv2.max(b, g), r), dtype=np.float32)


def remove_impulses(v: np.ndarray, threshold: float = IMPULSE_THRESHOLD) -> np.ndarray:
    """Replace isolated impulse pixels by their 3x3 median; other pixels are left unchanged."""
    med = cv2.medianBlur(np.clip(v, 0, 255).astype(np.uint8), 3).astype(np.float32)
    kernel = np.ones((3, 3), np.uint8)
    kernel[1, 1] = 0
    nb_max = cv2.dilate(v, kernel)
    nb_min = cv2.erode(v, kernel)
    # ">=" rather than ">": two impulses side by side (common at 400 points in 120x75 px)
    # are each other's neighbour maximum; the 3x3 median still ignores them.
    salt = (v >= nb_max) & (v - med > threshold)
    pepper = (v <= nb_min) & (med - v > threshold)
    bad = salt | pepper
    if not bad.any():
        return v
    out = v.copy()
    out[bad] = med[bad]
    return out


def otsu_threshold(v: np.ndarray) -> float:
    """Otsu's threshold of an intensity image (0-255 scale)."""
    u8 = np.clip(np.rint(v), 0, 255).astype(np.uint8)
    t, _ = cv2.threshold(u8, 0, 255, cv2.THRESH_BINARY | cv2.THRESH_OTSU)
    return float(t)


def ring_outline(smooth: np.ndarray, threshold: float, ratio_sq: float,
                 hint: tuple[float, float] | None = None) -> RingOutline | Refusal:
    """Find the black ring: a dark region with one hole whose area ratio matches the marker."""
    dark = (smooth < threshold).astype(np.uint8)
    contours, hierarchy = cv2.findContours(dark, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE)
    if hierarchy is None:
        return Refusal("no dark ring in the ROI")
    hier = hierarchy.reshape(-1, 4)
    rows, cols = smooth.shape
    best: tuple[float, RingOutline] | None = None
    for i, h in enumerate(hier):
        if h[3] != -1 or h[2] == -1 or len(contours[i]) < 12:
            continue  # not a top-level region with a hole
        bx, by, bw, bh = cv2.boundingRect(contours[i])
        if bx == 0 or by == 0 or bx + bw >= cols or by + bh >= rows:
            continue  # the ring lies inside the purple field; the dark background does not
        outer_area = cv2.contourArea(contours[i])
        # the largest hole of this region
        child, hole, hole_area = h[2], -1, 0.0
        while child != -1:
            a = cv2.contourArea(contours[child])
            if a > hole_area:
                hole, hole_area = child, a
            child = hier[child][0]
        if hole < 0 or len(contours[hole]) < 8 or outer_area <= 0:
            continue
        ratio = hole_area / outer_area
        # pixel contours run through dark pixel centres: the hole looks larger and the
        # outside smaller by about half a pixel each, hence a loose window here; the
        # concentric-pencil check after the fit is the tight one.
        if not 0.5 * ratio_sq < ratio < 1.6 * ratio_sq:
            continue
        inner_box = _box(cv2.fitEllipse(contours[hole]))
        outer_box = _box(cv2.fitEllipse(contours[i]))
        score = abs(np.log(ratio / ratio_sq))
        if hint is not None:
            d = np.hypot(inner_box[0][0] - hint[0], inner_box[0][1] - hint[1])
            score += d / max(outer_box[1][0], 1.0)
        outline = RingOutline(inner_box, outer_box, ratio, threshold)
        if best is None or score < best[0]:
            best = (score, outline)
    if best is None:
        return Refusal("no dark ring with the marker's proportions in the ROI")
    return best[1]


def _box_conic(box: RotatedBox) -> np.ndarray:
    """The conic of a cv2.fitEllipse box ((cx, cy), (width, height), degrees)."""
    (cx, cy), (w, h), ang = box
    return params_to_conic((cx, cy), (max(w / 2.0, 0.5), max(h / 2.0, 0.5)), np.radians(ang))


def subpixel(mag: np.ndarray, gx: np.ndarray, gy: np.ndarray,
             ys: np.ndarray, xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel edge positions by a Gaussian peak fit along the dominant gradient axis.

    Returns the refined (x, y) points and a mask of the pixels that are a true local maximum
    with a well-defined peak (others are dropped rather than guessed).
    """
    h, w = mag.shape
    inside = (xs >= 1) & (ys >= 1) & (xs < w - 1) & (ys < h - 1)
    xs, ys = xs[inside], ys[inside]
    horiz = np.abs(gx[ys, xs]) >= np.abs(gy[ys, xs])
    dx = horiz.astype(np.intp)
    dy = 1 - dx
    a = mag[ys - dy, xs - dx].astype(np.float64)
    b = mag[ys, xs].astype(np.float64)
    c = mag[ys + dy, xs + dx].astype(np.float64)
    ok = (b >= a) & (b >= c) & (a > 0) & (c > 0) & (b > 0)
    la = np.log(np.where(ok, a, 1.0))
    lb = np.log(np.where(ok, b, 1.0))
    lc = np.log(np.where(ok, c, 1.0))
    denom = la - 2.0 * lb + lc
    ok &= denom < -1e-9
    offset = np.where(ok, 0.5 * (la - lc) / np.where(ok, denom, -1.0), 0.0)
    ok &= np.abs(offset) <= 0.6
    px = xs + offset * dx
    py = ys + offset * dy
    pts = np.stack([px, py], axis=1).astype(np.float64)
    mask = np.zeros(inside.shape, bool)
    mask[np.flatnonzero(inside)[ok]] = True
    return pts[ok], mask


def _outline_from_rays(rr: RayRing, ratio_sq: float) -> RingOutline:
    def box(e: Ellipse) -> RotatedBox:
        return ((e.centre[0], e.centre[1]), (2.0 * e.axes[0], 2.0 * e.axes[1]),
                float(np.degrees(e.angle)))

    area = (rr.inner.axes[0] * rr.inner.axes[1]) / max(rr.outer.axes[0] * rr.outer.axes[1],
                                                      1e-9)
    return RingOutline(box(rr.inner), box(rr.outer), float(area), 0.5 * (rr.ring + rr.field))


def boundary_edges(roi_bgr: np.ndarray, ratio_sq: float,
                   hint: tuple[float, float] | None = None,
                   radius: float | None = None,
                   timings: dict[str, float] | None = None) -> BoundaryEdges | Refusal:
    """Sub-pixel edge points of the white/black and black/purple boundaries in a ROI.

    With a ``radius`` (the candidate's estimate of the ring's outer radius, ROI pixels) the
    ring is found from its own structure by radial profiles (``rays``); the Otsu outline is
    the fallback, and the only method without one.  Edge points are kept when they lie near
    a rough ellipse *and* their gradient crosses it the right way (inner: brighter inside;
    outer: brighter outside, within ~45 degrees of its normal): an occluder's edge meets the
    ring at an angle or with the wrong polarity, and what survives is left to the fitter.
    ``timings``, when given, receives the milliseconds spent on the rays (``"rays"``), for
    the speed benchmark's breakdown.
    """
    v = remove_impulses(intensity(roi_bgr))
    smooth = cv2.GaussianBlur(v, (0, 0), GRADIENT_SIGMA)
    outline: RingOutline | Refusal = Refusal("no candidate ring")
    step = 0.0
    tint = chroma(roi_bgr)
    field_tint = 0.0
    if hint is not None and radius is not None:
        t0 = time.perf_counter()
        rr = ring_from_rays(smooth, hint, radius, tint)
        if timings is not None:
            timings["rays"] = (time.perf_counter() - t0) * 1e3
        if not isinstance(rr, Refusal):
            outline = _outline_from_rays(rr, ratio_sq)
            step = min(rr.white - rr.ring, rr.field - rr.ring)
            field_tint = rr.tint
        else:
            outline = rr
    if isinstance(outline, Refusal):
        t = otsu_threshold(smooth)
        if t <= 1.0:
            return Refusal("ROI has no contrast")
        otsu = ring_outline(smooth, t, ratio_sq, hint)
        if isinstance(otsu, Refusal):
            return outline if radius is not None else otsu
        outline = otsu
        high, low = t, t / 2.0
    else:
        high, low = max(0.8 * step, 2.0), max(0.4 * step, 1.0)
    edges = cv2.Canny(np.clip(np.rint(smooth), 0, 255).astype(np.uint8), low, high,
                      L2gradient=True)
    gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3)
    mag = cv2.magnitude(gx, gy)
    ys, xs = np.nonzero(edges)
    if xs.size < 12:
        return Refusal("too few edge pixels in the ROI")
    pts, kept = subpixel(mag, gx, gy, ys, xs)
    ys_k, xs_k = ys[kept], xs[kept]
    gxk, gyk = gx[ys_k, xs_k].astype(np.float64), gy[ys_k, xs_k].astype(np.float64)
    gnorm = np.maximum(np.hypot(gxk, gyk), 1e-9)
    inner_c, outer_c = _box_conic(outline.inner), _box_conic(outline.outer)
    d_in = sampson_distance(inner_c, pts)
    d_out = sampson_distance(outer_c, pts)
    ring_w = 0.5 * (min(outline.outer[1]) - min(outline.inner[1]))
    tol = float(np.clip(0.35 * ring_w, 1.5, 4.0))
    # cosine between the gradient (dark -> bright) and each conic's outward normal
    cos_in = _normal_cos(inner_c, pts, gxk, gyk, gnorm)
    cos_out = _normal_cos(outer_c, pts, gxk, gyk, gnorm)
    is_in = (np.abs(d_in) < tol) & (np.abs(d_in) <= np.abs(d_out)) & (cos_in < -MIN_COS)
    is_out = (np.abs(d_out) < tol) & (np.abs(d_out) < np.abs(d_in)) & (cos_out > MIN_COS)
    if field_tint > 0.0:
        # outer points must have the field's colour just beyond them (3 px along the
        # gradient): the ring's edge against an arm or a glove has the edge but not the colour
        probe = pts + 3.0 * np.stack([gxk, gyk], 1) / gnorm[:, None]
        beyond = cv2.remap(tint, probe[:, 0:1].astype(np.float32),
                           probe[:, 1:2].astype(np.float32), cv2.INTER_LINEAR,
                           borderMode=cv2.BORDER_REPLICATE)[:, 0]
        is_out &= beyond >= MIN_TINT * field_tint
    near = (np.abs(d_in) < 3.0 * tol) | (np.abs(d_out) < 3.0 * tol)
    keep = _linked(edges, ys_k, xs_k, is_in | is_out, near)
    taken = (is_in | is_out) & keep
    return BoundaryEdges(inner=pts[is_in & keep], outer=pts[is_out & keep], canny_low=low,
                         canny_high=high, outline=outline,
                         dropped=pts[near & ~taken & (np.minimum(np.abs(d_in), np.abs(d_out))
                                                      < tol)])


def _normal_cos(C: np.ndarray, pts: np.ndarray, gx: np.ndarray, gy: np.ndarray,
                gnorm: np.ndarray) -> np.ndarray:
    n = pts @ C[:2, :2].T + C[:2, 2]  # half the conic's gradient: outward (inside negative)
    nn = np.maximum(np.hypot(n[:, 0], n[:, 1]), 1e-12)
    return np.asarray((gx * n[:, 0] + gy * n[:, 1]) / (gnorm * nn))


def _linked(edges: np.ndarray, ys: np.ndarray, xs: np.ndarray, on: np.ndarray,
            near: np.ndarray) -> np.ndarray:
    """Link edge pixels into 8-connected contours; keep contours mostly on a boundary.

    "Mostly" counts only the contour's pixels near the ring: a ring edge that runs on into a
    long occluder edge (a glove's outline across the field) is one contour, and the part
    far from the ring must not outvote the arc on it.
    """
    n, labels = cv2.connectedComponents(edges, connectivity=8)
    lab = labels[ys, xs]
    total = np.bincount(lab, weights=near.astype(np.float64), minlength=n)
    good = np.bincount(lab, weights=on.astype(np.float64), minlength=n)
    frac = good / np.maximum(total, 1)
    return np.asarray(frac[lab] >= 0.5)
