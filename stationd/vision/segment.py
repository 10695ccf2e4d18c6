"""Colour segmentation of the purple marker field on the reduced image (paper 2.1, 2.3).

Why a two-stage search: the marker covers well under 1 % of a 20 MP frame and every
full-resolution filter costs hundreds of ms, so the detector looks for it on a 1/8 image and
only then works at full resolution inside a ROI.  This module is that first stage: HSV
threshold (after the optional Retinex enhancement) -> purple regions -> keep the ones that
*enclose a hole* (the white disk and black ring are not purple) whose brightness profile is
bright centre / dark ring / brighter outside.  A purple bar, a purple part of the car or a
purple glove has no such hole and is not returned; two markers give two candidates.

Nothing here assumes the field is a square or the exact radius ratios: other renderers and
other print sizes only need "purple around a dark ring around a bright centre".
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import cv2
import numpy as np

from stationd.vision.enhance import EnhanceParams, enhance_hsv
from stationd.yamlio import YamlNode

__all__ = ["DEFAULT_HSV", "Candidate", "HsvRange", "find_candidates", "purple_mask"]

Pair = tuple[int, int]


@dataclass(frozen=True)
class HsvRange:
    """Accepted box in OpenCV uint8 HSV units: H 0-179 (degrees / 2), S and V 0-255.

    ``h`` may wrap (``lo > hi`` means ``h >= lo or h <= hi``), for reds.  The defaults are for
    the *enhanced* image and were derived by enumeration (``tests/vision/test_segment.py``
    re-does it): printed purples of hue 265-295 deg, saturation >= 45 %, value 40-100 %, under
    independent R, G, B gains in [0.85, 1.15] and 10-100 % light, rounded to 8 bits.

    * H 118-168 (236-336 deg): the cast moves those hues to 238-336 deg (the extremes are the
      least saturated purples, e.g. 265 deg with R x 0.85, G x 1.15, which *is* a grey-blue).
    * S >= 50 (20 %): the least saturated case falls to S = 59 after 8-bit rounding at 10 %
      light; the bounded S stretch of ``enhance`` can take at most ~3 of that away.
    * V >= 45: Retinex puts the purple at ~100-200 whatever the light and black print at
      ~0-30; without enhancement it also drops raw pixels too dark to have a reliable hue.

    Known overlap (a box cannot do better): pure 240 deg blue, and grey or white under a cast
    of more than ~8 % towards purple (G low, R and B high), are accepted.  The ring/hole test
    of :func:`find_candidates` rejects such things; ``tune-color`` narrows the box per station.
    """

    h: Pair = (118, 168)
    s: Pair = (50, 255)
    v: Pair = (45, 255)

    def __post_init__(self) -> None:
        for name, (lo, hi), top in (("h", self.h, 179), ("s", self.s, 255), ("v", self.v, 255)):
            if not (0 <= lo <= top and 0 <= hi <= top):
                raise ValueError(f"{name} bounds must be integers in [0, {top}]")
            if name != "h" and lo > hi:
                raise ValueError(f"{name}: lo must be <= hi (only h may wrap around)")

    @classmethod
    def from_node(cls, node: YamlNode) -> HsvRange:
        """Read ``{h: [lo, hi], s: [lo, hi], v: [lo, hi]}`` (all three required)."""
        kw: dict[str, Pair] = {}
        for key, child in node.mapping(("h", "s", "v"), required=("h", "s", "v")).items():
            items = child.items()
            if len(items) != 2:
                raise child.error("expected [lo, hi]")
            top = 179 if key == "h" else 255
            lo, hi = (e.integer(lo=0, hi=top) for e in items)
            kw[key] = (lo, hi)
        try:
            return cls(**kw)
        except ValueError as exc:
            raise node.error(str(exc)) from None

    def to_dict(self) -> dict[str, list[int]]:
        return {"h": list(self.h), "s": list(self.s), "v": list(self.v)}

    def accepts(self, hsv: np.ndarray) -> np.ndarray:
        """Boolean array: which HSV triples (any leading shape, last axis 3) are in the box."""
        h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
        lo, hi = self.h
        in_h = (h >= lo) & (h <= hi) if lo <= hi else (h >= lo) | (h <= hi)
        return np.asarray(in_h & (s >= self.s[0]) & (s <= self.s[1])
                          & (v >= self.v[0]) & (v <= self.v[1]))


DEFAULT_HSV = HsvRange()

MIN_HOLE_RADIUS_PX = 2.0  # reduced px: smaller holes are noise pinholes, not a ring
MIN_CONTRAST = 0.15  # (bright - dark) / (bright + dark) for centre/ring and outside/ring
ROI_MARGIN_PX = 2  # reduced px; one is lost to INTER_LINEAR sampling only 2x2 of 8x8


def purple_mask(hsv: np.ndarray, ranges: HsvRange, *, clean: bool = True) -> np.ndarray:
    """uint8 0/255 mask of in-range pixels, cleaned by a 3x3 rank rule.

    Cleaning: a purple pixel with fewer than 2 purple 8-neighbours is dropped (salt from
    sensor noise in the dark) and a non-purple pixel with at least 7 is filled (pepper in the
    purple field).  Not a morphological opening/closing: at the detection limit the purple
    frame around the ring is 1-2 px wide on the reduced image and an opening would erase the
    very marker it should keep, while a closing would shrink or fill its hole.  A 1-px line
    survives, a hole of radius 2 px is not filled.
    """
    lo, hi = ranges.h
    if lo <= hi:
        mask = cv2.inRange(hsv, (lo, ranges.s[0], ranges.v[0]), (hi, ranges.s[1], ranges.v[1]))
    else:  # wrap-around hue: in S and V, and not in the excluded hue gap (hi, lo)
        in_sv = cv2.inRange(hsv, (0, ranges.s[0], ranges.v[0]), (179, ranges.s[1], ranges.v[1]))
        gap = cv2.inRange(hsv, (hi + 1, 0, 0), (lo - 1, 255, 255))
        mask = cv2.bitwise_and(in_sv, cv2.bitwise_not(gap))
    if clean:
        count = cv2.boxFilter(mask // 255, cv2.CV_8U, (3, 3), normalize=False,
                              borderType=cv2.BORDER_CONSTANT)  # includes the pixel itself
        mask[(mask > 0) & (count < 3)] = 0
        mask[count >= 7] = 255
    return np.asarray(mask)


@dataclass(frozen=True)
class Candidate:
    """A purple region around a ring-like hole, in full-resolution pixels.

    ``roi`` = (x, y, w, h): the purple region's bounding box plus a margin (10 %, at least 2
    reduced pixels), clipped to the image; only the part of the region within 3 major
    semi-axes of the hole counts, so a purple car body around a marker does not blow it up.
    ``hole_centre`` / ``hole_radius``: centroid and equivalent radius of the hole (~ the ring's
    outer edge).  ``at_border``: that region touches the image border, so the field may be cut;
    the caller refuses it but can say why.  (A hole cut by the border is no hole: nothing is
    returned for it.)  ``score`` in [0, 1]: how ellipse-like the hole is times ``contrast``,
    the weaker of centre/ring and outside/ring brightness contrasts.
    """

    roi: tuple[int, int, int, int]
    hole_centre: tuple[float, float]
    hole_radius: float
    score: float
    at_border: bool
    contrast: float


def _hole_shape(hole: np.ndarray) -> tuple[float, float, np.ndarray, float, float] | None:
    """Centre, 2x2 map of the unit circle onto the hole, equivalent radius, ellipse fit.

    From the moments of the hole's *outer* contour, so purple specks inside it (noise on the
    ring, a white disk turned purple by a cast) do not count.  A filled ellipse with
    semi-axes (a, b) has covariance diag(a^2, b^2) / 4, so ``fit`` = area / (4 pi sqrt(det))
    is 1 for an ellipse and smaller for ragged shapes.  The contour runs through the centres
    of the hole's edge pixels, ~0.5 px inside its edge: the radii are corrected for that.
    """
    contours, _ = cv2.findContours(hole, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    m = cv2.moments(max(contours, key=len))
    area = m["m00"]
    if area <= 0:
        return None
    cov = np.array([[m["mu20"], m["mu11"]], [m["mu11"], m["mu02"]]]) / area
    evals, evecs = np.linalg.eigh(cov)
    if evals[0] <= 1e-6:
        return None
    fit = area / (4.0 * math.pi * math.sqrt(evals[0] * evals[1]))
    axes = 2.0 * np.sqrt(evals) + 0.5
    radius = math.sqrt(area / math.pi) + 0.5
    return m["m10"] / area, m["m01"] / area, evecs * axes, radius, fit


_T = np.array([0.0, 0.2, 0.4, 0.6, 0.7, 0.8, 0.9, 1.0, 1.15, 1.3, 1.45], dtype=np.float32)
_ANG = np.linspace(0, 2 * math.pi, 16, endpoint=False, dtype=np.float32)
_UNIT = np.stack([np.cos(_ANG), np.sin(_ANG)])


def _ring_contrast(v: np.ndarray, cx: float, cy: float, a: np.ndarray) -> float:
    """min(centre vs ring, outside vs ring) contrast of the median V on ellipses around a hole.

    Radii are in units of the hole (t = 1 at its edge): bright centre t <= 0.4, darkest ring
    0.6 <= t <= 1, brightest outside 1 < t < 1.5.  Medians over 16 directions, so a noise
    pixel or a partial occlusion does not decide.
    """
    pts = a.astype(np.float32) @ _UNIT  # 2 x 16: the hole's edge, relative to its centre
    mx = np.ascontiguousarray(cx + _T[:, None] * pts[0][None, :], dtype=np.float32)
    my = np.ascontiguousarray(cy + _T[:, None] * pts[1][None, :], dtype=np.float32)
    prof = np.median(cv2.remap(v, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE),
                     axis=1)
    centre = float(prof[_T <= 0.4].max())
    ring = float(prof[(_T >= 0.6) & (_T <= 1.0)].min())
    outside = float(prof[_T > 1.0].max())
    return min((centre - ring) / (centre + ring + 1.0), (outside - ring) / (outside + ring + 1.0))


def find_candidates(small_bgr: np.ndarray, scale: int, ranges: HsvRange = DEFAULT_HSV, *,
                    enhance: EnhanceParams | None, full_size: tuple[int, int],
                    min_hole_radius_px: float = MIN_HOLE_RADIUS_PX) -> list[Candidate]:
    """Plausible marker ROIs in a reduced BGR image, best first (possibly none).

    ``small_bgr`` is the full frame reduced by ``scale`` (cv2.resize INTER_LINEAR), ``full_size``
    the full frame's (w, h); ``enhance`` None skips the Retinex/stretch step.  Holes are the
    4-connected non-purple components that do not touch the image border (connected
    components, not contours: a noisy dark frame has thousands of specks and contour tracing
    of all of them costs 10x more).
    """
    return search_candidates(small_bgr, scale, ranges, enhance=enhance, full_size=full_size,
                             min_hole_radius_px=min_hole_radius_px)[0]


def search_candidates(small_bgr: np.ndarray, scale: int, ranges: HsvRange = DEFAULT_HSV, *,
                      enhance: EnhanceParams | None, full_size: tuple[int, int],
                      min_hole_radius_px: float = MIN_HOLE_RADIUS_PX,
                      timings: dict[str, float] | None = None
                      ) -> tuple[list[Candidate], int]:
    """:func:`find_candidates`, and the area (reduced px) of the largest purple region not
    on the frame's border: the detector retries at a finer scale only when that region is
    small enough to be a marker too small for this scale.  No purple, a large region with
    no ring in it, or only regions on the frame's edge (a marker cut by it) would be
    searched again for nothing, at four to twenty times the cost.

    The area is only needed when nothing was found, so it is 0 whenever candidates are
    returned: labelling every purple region of the frame costs ~2 ms, while a candidate's
    own region is flood-filled from its hole (:func:`_region_box`).  ``timings``, when
    given, accumulates the milliseconds of the enhancement (``"retinex"``, a part of the
    search) for the speed benchmark."""
    if small_bgr.dtype != np.uint8 or small_bgr.ndim != 3 or small_bgr.shape[2] != 3:
        raise ValueError(f"expected a uint8 HxWx3 BGR image, got {small_bgr.dtype} "
                         f"{small_bgr.shape}")
    sh, sw = small_bgr.shape[:2]
    fw, fh = full_size
    if scale < 1 or abs(sw * scale - fw) >= scale or abs(sh * scale - fh) >= scale:
        raise ValueError(f"image {sw}x{sh} at 1/{scale} does not match full size {fw}x{fh}")
    hsv = cv2.cvtColor(small_bgr, cv2.COLOR_BGR2HSV)
    t0 = time.perf_counter()
    seg = hsv if enhance is None else enhance_hsv(hsv, enhance, float(scale))
    if timings is not None:
        timings["retinex"] = timings.get("retinex", 0.0) + (time.perf_counter() - t0) * 1e3
    mask = purple_mask(seg, ranges)
    holes, boxes = _enclosed_holes(mask, 0.9 * math.pi * min_hole_radius_px ** 2)
    v = cv2.extractChannel(hsv, 2).astype(np.float32)  # raw V: no model in the check
    if not boxes:
        return _no_enclosed_ring(v, mask, scale, full_size, min_hole_radius_px)
    found: list[tuple[Candidate, float, float, float]] = []
    for k, (x0, y0, x1, y1) in boxes:
        hole = (holes[y0 - 1:y1 + 1, x0 - 1:x1 + 1] == k).astype(np.uint8)
        shape = _hole_shape(hole)
        if shape is None or shape[3] < min_hole_radius_px:
            continue
        hx, hy, a, radius, fit = shape
        cx, cy = hx + x0 - 1, hy + y0 - 1
        contrast = _ring_contrast(v, cx, cy, a)
        if contrast < MIN_CONTRAST:
            continue
        # The enclosing purple region (above the hole's top row), seen within ~3 major
        # semi-axes of the hole: a marker field fits, a purple car body does not blow the ROI.
        top = int(np.argmax(holes[y0, x0:x1] == k)) + x0
        reach = 3.0 * float(np.linalg.norm(a, axis=0).max()) + 1.0
        wx0, wy0 = max(0, math.floor(cx - reach)), max(0, math.floor(cy - reach))
        wx1, wy1 = min(sw, math.ceil(cx + reach) + 1), min(sh, math.ceil(cy + reach) + 1)
        rx0, ry0, rx1, ry1 = _region_box(mask, (top, y0 - 1), (wx0, wy0, wx1, wy1))
        at_border = rx0 == 0 or ry0 == 0 or rx1 == sw or ry1 == sh
        m = max(ROI_MARGIN_PX, 0.1 * max(rx1 - rx0, ry1 - ry0))
        fx0, fy0 = max(0, math.floor((rx0 - m) * scale)), max(0, math.floor((ry0 - m) * scale))
        fx1 = min(fw, math.ceil((rx1 + m) * scale))
        fy1 = min(fh, math.ceil((ry1 + m) * scale))
        score = min(fit, 1.0 / fit) * min(max(contrast, 0.0), 1.0)
        centre = ((cx + 0.5) * scale - 0.5, (cy + 0.5) * scale - 0.5)
        cand = Candidate((fx0, fy0, fx1 - fx0, fy1 - fy0), centre, radius * scale, score,
                         at_border, contrast)
        found.append((cand, cx, cy, radius))
    if not found:
        return _no_enclosed_ring(v, mask, scale, full_size, min_hole_radius_px)
    found.sort(key=lambda t: -t[0].score)
    kept: list[tuple[Candidate, float, float, float]] = []
    for c in found:  # one marker whose hole is split by noise must not give two candidates
        if all(math.hypot(c[1] - k[1], c[2] - k[2]) > max(c[3], k[3]) for k in kept):
            kept.append(c)
    return [c[0] for c in kept], 0


MAX_BOXED_HOLES = 4  # holes boxed one by one; more (a cluttered frame) are labelled with stats


def _enclosed_holes(mask: np.ndarray, min_area: float
                    ) -> tuple[np.ndarray, list[tuple[int, tuple[int, int, int, int]]]]:
    """The 4-connected non-purple components (labels image) and, in label order, those not
    touching the border, of at least ``min_area`` px and 2 px in both directions, with
    their boxes (x0, y0, x1, y1), exclusive ends.

    Why not ``connectedComponentsWithStats``: its statistics cost twice the labelling itself
    (~1.5 ms of ~2.3 on the 1/8 frame), and only the few large enclosed holes need a box:
    areas by ``bincount``, border contact from the border rows, boxes of the survivors from
    their pixels.  A frame with many such holes falls back to the statistics, so the cost
    stays bounded; both give the same labels and boxes.
    """
    inv = cv2.bitwise_not(mask)
    n, holes = cv2.connectedComponents(inv, connectivity=4)
    area = np.bincount(holes.ravel(), minlength=n)
    keep = area >= min_area
    keep[0] = False  # label 0 is the purple itself
    for edge in (holes[0], holes[-1], holes[:, 0], holes[:, -1]):
        keep[edge] = False
    labels = np.flatnonzero(keep)
    if labels.size > MAX_BOXED_HOLES:
        _, holes, stats, _ = cv2.connectedComponentsWithStats(inv, connectivity=4)
        x, y, w, h = (stats[labels, i] for i in range(4))
        spans = [(int(a), int(b), int(a + c), int(b + d)) for a, b, c, d in zip(x, y, w, h,
                                                                              strict=True)]
    else:
        spans = []
        for k in labels:
            ys, xs = np.nonzero(holes == k)
            spans.append((int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1))
    boxes = [(int(k), b) for k, b in zip(labels, spans, strict=True)
             if min(b[2] - b[0], b[3] - b[1]) >= 2]
    return holes, boxes


def _region_box(mask: np.ndarray, seed: tuple[int, int], window: tuple[int, int, int, int]
                ) -> tuple[int, int, int, int]:
    """Bounding box (x0, y0, x1, y1), exclusive ends, of the part inside ``window`` of the
    8-connected purple region through ``seed`` (a purple pixel).

    A flood fill of the whole region (it may leave the window and come back), so the box is
    the one a labelling of every region would give, at the cost of this region only.
    """
    sh, sw = mask.shape
    fill = np.zeros((sh + 2, sw + 2), np.uint8)
    cv2.floodFill(mask, fill, seed, 255, 0, 0, 8 | cv2.FLOODFILL_MASK_ONLY | (1 << 8))
    wx0, wy0, wx1, wy1 = window
    ys, xs = np.nonzero(fill[wy0 + 1:wy1 + 1, wx0 + 1:wx1 + 1])
    return (int(xs.min()) + wx0, int(ys.min()) + wy0, int(xs.max()) + wx0 + 1,
            int(ys.max()) + wy0 + 1)


def _largest_region(mask: np.ndarray) -> int:
    """Area (px) of the largest 8-connected purple region that does not touch the frame's
    border, 0 without one (labelling and ``bincount``: the statistics of
    ``connectedComponentsWithStats`` cost more than both).

    Why not a region on the border: the finer retry is for a marker too small for this
    scale, and a small purple region on the frame's edge is, at a station, a marker leaving
    the frame with its ring cut (seen whole by another pair).  Searching it again at twice
    the resolution cost four times the first search for nothing: 70 ms of a 110 ms cycle
    in ``bench station``.  A marker both too small for the search and with its field cut
    by the edge is the price (its ring would be within a few mm of the edge)."""
    if not cv2.countNonZero(mask):
        return 0
    n, labels = cv2.connectedComponents(mask, connectivity=8)
    if n <= 1:
        return 0
    area = np.bincount(labels.ravel(), minlength=n)
    for edge in (labels[0], labels[-1], labels[:, 0], labels[:, -1]):
        area[edge] = 0
    return int(area[1:].max())


def _no_enclosed_ring(v: np.ndarray, mask: np.ndarray, scale: int, full_size: tuple[int, int],
                      min_hole_radius_px: float) -> tuple[list[Candidate], int]:
    """The disk seeds when no purple region encloses a ring, and the largest area of a
    region off the frame's border when there are none either (the finer retry needs it)."""
    seeds = _disk_seeds(v, mask, scale, full_size, min_hole_radius_px)
    return seeds, 0 if seeds else _largest_region(mask)


MAX_DISK_SEEDS = 24  # bright blobs examined when no purple region encloses a ring
MIN_PURPLE_AROUND = 0.4  # fraction of directions with purple just outside the ring


def _purple_around(mask: np.ndarray, cx: float, cy: float, a: np.ndarray) -> float:
    """Fraction of 16 directions in which the field just outside the ring (t 1.2-1.6) is
    purple: an occluder may hide part of the field, not all of it."""
    pts = a.astype(np.float32) @ _UNIT
    t = np.array([1.2, 1.4, 1.6], np.float32)
    mx = np.ascontiguousarray(cx + t[:, None] * pts[0][None, :], dtype=np.float32)
    my = np.ascontiguousarray(cy + t[:, None] * pts[1][None, :], dtype=np.float32)
    hit = cv2.remap(mask, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=0)
    return float((hit > 0).any(axis=0).mean())


def _disk_seeds(v: np.ndarray, mask: np.ndarray, scale: int, full_size: tuple[int, int],
                min_hole_radius_px: float) -> list[Candidate]:
    """Candidates from the white disk when no purple region encloses a ring.

    Why: an arm, a socket or a chassis member across the purple field or the ring joins the
    ring's "hole" to the outside, and the enclosed-hole search sees nothing.  The white disk
    itself is never occluded (if it were, there would be nothing safe to measure): a bright,
    not purple, elliptical blob brighter than the field, whose surroundings pass the same
    bright centre / dark ring / brighter outside test at the 10/15 ratio, with purple in
    enough directions around it.  Only run when there is purple and no enclosed ring, so a
    frame without a marker still costs one reduced search.
    """
    purple_v = v[mask > 0]
    if purple_v.size == 0:
        return []
    out: list[Candidate] = []
    notp = mask == 0
    level = float(np.median(purple_v))
    # the white print is a small part of the frame: the brightest level, not a percentile
    # (which would be the occluder's or the chassis' level)
    top = float(v.max())
    # A bright occluder (metal, skin) reaching close to the disk merges with it at 1/8
    # scale; the white print is the brightest thing there, so higher levels split it off.
    # At those levels the purple mask is not asked: white under a white-balance cast of
    # more than ~8 % towards purple is inside the HSV box (see HsvRange), but it is still
    # far brighter than any printed purple (V <= 85 %).
    for t in (0.0, 0.45, 0.75):
        above = v > level + t * max(top - level, 0.0)
        bright = ((notp | (t > 0.0)) & above).astype(np.uint8)
        for cand in _bright_blobs(v, mask, bright, scale, full_size, min_hole_radius_px):
            if all(math.hypot(cand.hole_centre[0] - c.hole_centre[0],
                              cand.hole_centre[1] - c.hole_centre[1]) > c.hole_radius
                   for c in out):
                out.append(cand)
        if out:
            break
    out.sort(key=lambda c: -c.score)
    return out


def _bright_blobs(v: np.ndarray, mask: np.ndarray, bright: np.ndarray, scale: int,
                  full_size: tuple[int, int], min_hole_radius_px: float) -> list[Candidate]:
    """The elliptical bright blobs of one level that pass the ring and purple tests."""
    sh, sw = v.shape
    fw, fh = full_size
    _, labels, stats, _ = cv2.connectedComponentsWithStats(bright, connectivity=4)
    x, y, w, h, area = (stats[:, i] for i in range(5))
    r_disk = min_hole_radius_px / 1.5
    ok = ((x > 0) & (y > 0) & (x + w < sw) & (y + h < sh) & (np.minimum(w, h) >= 2)
          & (area >= 0.9 * math.pi * r_disk ** 2))
    ok[0] = False
    order = np.flatnonzero(ok)
    order = order[np.argsort(-area[order])][:MAX_DISK_SEEDS]
    out: list[Candidate] = []
    for k in order:
        x0, y0, x1, y1 = int(x[k]), int(y[k]), int(x[k] + w[k]), int(y[k] + h[k])
        blob = (labels[y0 - 1:y1 + 1, x0 - 1:x1 + 1] == k).astype(np.uint8)
        shape = _hole_shape(blob)
        if shape is None or shape[4] < 0.7:
            continue
        hx, hy, a, radius, fit = shape
        cx, cy = hx + x0 - 1, hy + y0 - 1
        ring = a * 1.5  # the ring's outer edge, in the hole convention of _ring_contrast
        contrast = _ring_contrast(v, cx, cy, ring)
        if contrast < MIN_CONTRAST or _purple_around(mask, cx, cy, ring) < MIN_PURPLE_AROUND:
            continue
        reach = 2.6 * float(np.linalg.norm(ring, axis=0).max()) + ROI_MARGIN_PX
        fx0, fy0 = max(0, math.floor((cx - reach) * scale)), max(0, math.floor((cy - reach)
                                                                                * scale))
        fx1 = min(fw, math.ceil((cx + reach + 1) * scale))
        fy1 = min(fh, math.ceil((cy + reach + 1) * scale))
        centre = ((cx + 0.5) * scale - 0.5, (cy + 0.5) * scale - 0.5)
        score = 0.5 * min(fit, 1.0 / fit) * min(contrast, 1.0)
        out.append(Candidate((fx0, fy0, fx1 - fx0, fy1 - fy0), centre, 1.5 * radius * scale,
                             score, False, contrast))
    return out
