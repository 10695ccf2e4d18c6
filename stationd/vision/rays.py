"""The ring found from its own structure: radial profiles from a hint of its centre.

Why not a global threshold: Otsu's threshold on the ROI falls between "white" and "the rest"
as soon as the purple is dark or saturated, the light dim or a highlight sits on the ring, and
the dark ring then merges with the field (or with a dark glove over it).  The marker's own
structure does not depend on any of that: along every ray from the centre the intensity
*falls* at the white disk's edge and *rises* again at the ring's outer edge, 1.5 times further
out (r_out / r_in = 15 / 10, kept under any tilt for rays from the centre, to first order).

So: cast rays from the hint, find on each ray the strongest falling/rising edge pair at that
radius ratio, keep the rays whose pair is clearly there (an occluder's ray has no such pair or
a weak one), fit rough ellipses to the inner and outer points with the Leitz fitter, recentre
on the inner ellipse and do it once more.  The result seeds the sub-pixel edge assignment
(``edges``); the contrasts measured on the rays set the Canny thresholds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from stationd.vision.ellipse import fit_ellipse
from stationd.vision.types import Ellipse, Refusal

N_RAYS = 72
STEP_PX = 0.5
RATIO_WINDOW = (1.36, 1.64)  # accepted r_out / r_in along a ray (nominal 1.5)
MIN_RAYS = 30  # rays that must show the ring's structure (over 40 %)
MIN_STEP = 3.0  # grey levels: weaker edges are noise, whatever the light
MIN_TINT = 0.5  # a ray's field chroma, relative to the median of the rays


@dataclass(frozen=True, eq=False)
class RayRing:
    """Rough ellipses of the two boundaries (ROI pixels) and the ring's measured contrasts."""

    inner: Ellipse
    outer: Ellipse
    white: float  # median grey level of the disk next to its edge
    ring: float  # median darkest level of the ring
    field: float  # median level just outside the ring
    rays: int  # rays that showed the structure
    tint: float = 0.0  # median field chroma just outside the ring (0 without chroma)


def _profiles(smooth: np.ndarray, centre: tuple[float, float], r_max: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ang = np.linspace(0.0, 2 * math.pi, N_RAYS, endpoint=False)
    r = np.arange(0.0, r_max, STEP_PX, dtype=np.float64)
    dirs = np.stack([np.cos(ang), np.sin(ang)], 1)
    mx = (centre[0] + dirs[:, 0:1] * r[None, :]).astype(np.float32)
    my = (centre[1] + dirs[:, 1:2] * r[None, :]).astype(np.float32)
    prof = cv2.remap(smooth, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                     borderValue=np.nan)
    return np.asarray(prof, np.float64), r, dirs


def _peak(d: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Sub-sample position of the extremum of d at idx (parabola through 3 samples)."""
    rows = np.arange(d.shape[0])
    i = np.clip(idx, 1, d.shape[1] - 2)
    a, b, c = d[rows, i - 1], d[rows, i], d[rows, i + 1]
    den = a - 2 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(np.abs(den) > 1e-12, 0.5 * (a - c) / den, 0.0)
    return np.asarray(i + np.clip(off, -0.5, 0.5))


def _pass(smooth: np.ndarray, chroma: np.ndarray | None, centre: tuple[float, float],
          radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | Refusal:
    """One round of rays: the (inner, outer) points of the rays that show the ring, and the
    per-ray (white, ring, field, field chroma) levels."""
    prof, r, dirs = _profiles(smooth, centre, 2.4 * radius + 4.0)
    prof = np.nan_to_num(prof, nan=0.0)
    chrom = None
    if chroma is not None:
        chrom = np.nan_to_num(_profiles(chroma, centre, 2.4 * radius + 4.0)[0], nan=0.0)
    d = np.diff(prof, axis=1)  # d[k] is the slope between samples k and k + 1
    m = d.shape[1]
    lo_i = max(1, int(0.12 * radius / STEP_PX))
    hi_i = min(m - 2, int(1.7 * radius / STEP_PX))
    best = np.full(N_RAYS, -np.inf)
    bi = np.zeros(N_RAYS, np.intp)
    bj = np.zeros(N_RAYS, np.intp)
    # running maximum of the rising slope over the window [1.36 i, 1.64 i] for each i
    for i in range(lo_i, hi_i):
        j0 = int(math.ceil(RATIO_WINDOW[0] * (i + 0.5) - 0.5))
        j1 = min(m - 1, int(RATIO_WINDOW[1] * (i + 0.5) - 0.5))
        if j1 <= j0:
            continue
        seg = d[:, j0:j1 + 1]
        jj = np.argmax(seg, axis=1)
        rise = seg[np.arange(N_RAYS), jj]
        score = np.minimum(-d[:, i], rise)
        better = score > best
        best[better] = score[better]
        bi[better] = i
        bj[better] = j0 + jj[better]
    ok = best > 0.0
    rows = np.arange(N_RAYS)
    white = np.array([prof[k, max(0, bi[k] - max(2, bi[k] // 3)):bi[k] + 1].max()
                      for k in rows])
    ring = np.array([prof[k, bi[k] + 1:bj[k] + 1].min() if bj[k] > bi[k] else np.inf
                     for k in rows])
    field = np.array([prof[k, bj[k]:min(m + 1, bj[k] + 2 + (bj[k] - bi[k]) // 2)].max()
                      for k in rows])
    step = np.minimum(white - ring, field - ring)
    ok &= step >= MIN_STEP
    # each edge must be the transition itself: the level crosses half-way between its two
    # sides within a few samples of it (a ring of other proportions has its rise elsewhere,
    # and only noise slopes where 10/15 expects it)
    delta = np.clip(((bj - bi) * 0.3).astype(np.intp), 2, 8)
    last = prof.shape[1] - 1
    half_in, half_out = 0.5 * (white + ring), 0.5 * (ring + field)
    ok &= prof[rows, np.maximum(bi - delta + 1, 0)] > half_in
    ok &= prof[rows, np.minimum(bi + delta, last)] < half_in
    ok &= prof[rows, np.maximum(bj - delta + 1, 0)] < half_out
    ok &= prof[rows, np.minimum(bj + delta, last)] > half_out
    if ok.sum() >= 3:  # an occluded ray's pair is far weaker than the ring's own
        ok &= step >= 0.35 * float(np.median(step[ok]))
    tint = np.zeros(N_RAYS)
    if chrom is not None:
        # the field beyond the ring has the field's colour; an occluder's edge (a grey
        # arm, a hand) can mimic the rise but not the colour: judged against the majority
        tint = np.array([np.median(chrom[k, min(last, bj[k] + delta[k]):
                                         min(last, bj[k] + delta[k] + max(2, (bj[k] - bi[k])
                                                                           // 2)) + 1])
                         for k in rows])
        if ok.sum() >= 3:
            ok &= tint >= MIN_TINT * float(np.median(tint[ok]))
    if ok.sum() < MIN_RAYS:
        return Refusal(f"no dark ring with the marker's proportions around the candidate: "
                       f"{int(ok.sum())} of {N_RAYS} rays show bright disk / dark ring / "
                       f"brighter field at 10/15 (< {MIN_RAYS})")
    ri = r[0] + (_peak(-d, bi) + 0.5) * STEP_PX
    ro = r[0] + (_peak(d, bj) + 0.5) * STEP_PX
    c = np.asarray(centre, np.float64)
    inner = c + dirs * ri[:, None]
    outer = c + dirs * ro[:, None]
    levels = np.stack([white, ring, field, tint], 1)
    return inner[ok], outer[ok], levels[ok]


def chroma(roi_bgr: np.ndarray) -> np.ndarray:
    """How purple a pixel is: ((R + B) / 2 - G) / (max + 1), smoothed like the intensity.

    High for any printed purple (R and B above G) whatever its darkness, near 0 for black,
    white, grey, metal and skin; a white-balance cast shifts it for all of them alike, which
    is why callers compare it to the field's own median, not to a constant.
    """
    f = roi_bgr.astype(np.float32)
    b, g, r = f[..., 0], f[..., 1], f[..., 2]
    c = (0.5 * (r + b) - g) / (np.maximum(np.maximum(r, g), b) + 1.0)
    return np.asarray(cv2.GaussianBlur(c, (0, 0), 1.0))


def ring_from_rays(smooth: np.ndarray, centre: tuple[float, float], radius: float,
                   tint: np.ndarray | None = None) -> RayRing | Refusal:
    """Rough inner/outer ellipses of the ring around ``centre`` (outer radius ~ ``radius``).

    ``smooth`` is the smoothed intensity of the ROI (float32), ``tint`` its :func:`chroma`
    (optional: rays whose "field" is not the field's colour are dropped); ROI pixels.
    Refuses, naming what was missing, when too few rays show the ring or a fit fails.
    """
    if not (radius > 1.0 and math.isfinite(radius)):
        return Refusal(f"no usable ring radius estimate ({radius})")
    cur, rad = (float(centre[0]), float(centre[1])), float(radius)
    result: RayRing | Refusal = Refusal("no ring")
    for _ in range(3):  # the last pass, from the inner ellipse's centre, decides
        got = _pass(smooth, tint, cur, rad)
        if isinstance(got, Refusal):
            return got
        pin, pout, levels = got
        e_in = fit_ellipse(pin)
        e_out = fit_ellipse(pout)
        if isinstance(e_in, Refusal):
            return Refusal(f"ring rays, inner boundary: {e_in.reason}")
        if isinstance(e_out, Refusal):
            return Refusal(f"ring rays, outer boundary: {e_out.reason}")
        med = np.median(levels, axis=0)
        result = RayRing(e_in, e_out, float(med[0]), float(med[1]), float(med[2]), len(pin),
                         float(med[3]))
        shift = math.hypot(e_in.centre[0] - cur[0], e_in.centre[1] - cur[1])
        cur = (float(e_in.centre[0]), float(e_in.centre[1]))
        rad = float(math.sqrt(e_out.axes[0] * e_out.axes[1]))
        if shift < 0.5:
            break
    return result
