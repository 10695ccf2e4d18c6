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

from stationd.result import Refusal
from stationd.vision.ellipse import fit_trimmed, params_to_conic
from stationd.vision.types import Ellipse

N_RAYS = 72
STEP_PX = 0.5
OUTER_OVER_INNER = 1.5  # r_out / r_in of the marker (15 / 10)
RATIO_WINDOW = (1.36, 1.64)  # accepted r_out / r_in along a ray (nominal 1.5)
MIN_RAYS = 30  # rays that must show the ring's structure (over 40 %)
MIN_STEP = 3.0  # grey levels: weaker edges are noise, whatever the light
PEAKS = 4  # strongest falling / rising edges per ray considered for the pair
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


def _top_peaks(x: np.ndarray, lo: int, hi: int, k: int) -> np.ndarray:
    """Column indices of the ``k`` highest local maxima of each row of ``x`` in [lo, hi)."""
    v = np.full(x.shape, -np.inf)
    core = x[:, lo:hi]
    left = x[:, lo - 1:hi - 1]
    right = x[:, lo + 1:hi + 1] if hi + 1 <= x.shape[1] else np.pad(
        x[:, lo + 1:], ((0, 0), (0, 1)), constant_values=-np.inf)
    v[:, lo:hi] = np.where((core >= left) & (core > right) & (core > 0), core, -np.inf)
    k = min(k, hi - lo)
    return np.asarray(np.argpartition(-v, k - 1, axis=1)[:, :k])


def _pass(smooth: np.ndarray, chroma: np.ndarray | None, centre: tuple[float, float],
          radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | Refusal:
    """One round of rays: the (inner, outer) points of the rays that show the ring, and the
    per-ray (white, ring, field, field chroma) levels.

    On each ray only the strongest few falling and rising edges are candidates (a ring, a
    field border, an occluder's edges: few per ray); of their pairs at the 10/15 ratio the
    one with the strongest weaker edge wins.
    """
    prof, r, dirs = _profiles(smooth, centre, 2.4 * radius + 4.0)
    prof = np.nan_to_num(prof, nan=0.0)
    d = np.diff(prof, axis=1)  # d[k] is the slope between samples k and k + 1
    m = d.shape[1]
    lo_i = max(1, int(0.12 * radius / STEP_PX))
    hi_i = min(m - 2, int(1.7 * radius / STEP_PX))
    lo_j = int(RATIO_WINDOW[0] * lo_i)
    if hi_i <= lo_i or m - 1 <= lo_j + 1:
        return Refusal("candidate ring too small for radial profiles")
    rows = np.arange(N_RAYS)
    fi = _top_peaks(-d, lo_i, hi_i, PEAKS)  # (rays, K) falling edges
    rj = _top_peaks(d, lo_j, m - 1, PEAKS)  # (rays, K) rising edges
    fall = -d[rows[:, None], fi]
    rise = d[rows[:, None], rj]
    ratio = (rj[:, None, :] + 0.5) / (fi[:, :, None] + 0.5)
    score = np.minimum(fall[:, :, None], rise[:, None, :])
    score = np.where((ratio >= RATIO_WINDOW[0]) & (ratio <= RATIO_WINDOW[1]), score, -np.inf)
    flat = score.reshape(N_RAYS, -1)
    pick = np.argmax(flat, axis=1)
    best = flat[rows, pick]
    bi = fi[rows, pick // fi.shape[1]]
    bj = rj[rows, pick % rj.shape[1]]
    ok = np.isfinite(best) & (best > 0.0)
    bj = np.where(ok, bj, np.minimum(bi + 2, m - 1))
    idx = np.arange(prof.shape[1])[None, :]
    bi_, bj_ = bi[:, None], bj[:, None]
    white = np.where((idx >= np.maximum(0, bi_ - np.maximum(2, bi_ // 3))) & (idx <= bi_),
                     prof, -np.inf).max(axis=1)
    ring = np.where((idx > bi_) & (idx <= bj_), prof, np.inf).min(axis=1)
    field = np.where((idx >= bj_) & (idx < bj_ + 2 + (bj_ - bi_) // 2), prof,
                     -np.inf).max(axis=1)
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
    if chroma is not None:
        # the field beyond the ring has the field's colour; an occluder's edge (a grey
        # arm, a hand) can mimic the rise but not the colour: judged against the majority
        at = r[0] + (bj + delta + np.maximum(1, (bj - bi) // 4)) * STEP_PX
        px = (centre[0] + dirs[:, 0] * at).astype(np.float32)[:, None]
        py = (centre[1] + dirs[:, 1] * at).astype(np.float32)[:, None]
        tint = cv2.remap(chroma, px, py, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0.0)[:, 0].astype(np.float64)
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


def _robust(pts: np.ndarray) -> Ellipse | Refusal:
    got = fit_trimmed(pts, floor_px=1.0)
    return got if isinstance(got, Refusal) else got[1]


def _scaled(e: Ellipse, k: float) -> Ellipse:
    axes = (e.axes[0] * k, e.axes[1] * k)
    return Ellipse(conic=params_to_conic(e.centre, axes, e.angle), centre=e.centre, axes=axes,
                   angle=e.angle)


def _concentric(inner: Ellipse, outer: Ellipse) -> bool:
    """The two rough ellipses look like this marker's circles: nearly concentric, radii
    about 15/10 (perspective moves the centres apart by a few percent of the radius)."""
    r_in = math.sqrt(inner.axes[0] * inner.axes[1])
    r_out = math.sqrt(outer.axes[0] * outer.axes[1])
    shift = math.hypot(outer.centre[0] - inner.centre[0], outer.centre[1] - inner.centre[1])
    return shift <= 0.08 * r_out and abs(r_out / r_in / OUTER_OVER_INNER - 1.0) <= 0.12


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
        e_in = _robust(pin)
        if isinstance(e_in, Refusal):
            return Refusal(f"ring rays, inner boundary: {e_in.reason}")
        e_out = _robust(pout)
        if isinstance(e_out, Refusal) or not _concentric(e_in, e_out):
            # occluders ahead of most rays: the inner circle (never occluded) scaled by
            # r_out / r_in is the rough outer boundary; the fine fit corrects perspective
            e_out = _scaled(e_in, OUTER_OVER_INNER)
        med = np.median(levels, axis=0)
        result = RayRing(e_in, e_out, float(med[0]), float(med[1]), float(med[2]), len(pin),
                         float(med[3]))
        shift = math.hypot(e_in.centre[0] - cur[0], e_in.centre[1] - cur[1])
        cur = (float(e_in.centre[0]), float(e_in.centre[1]))
        rad = float(math.sqrt(e_out.axes[0] * e_out.axes[1]))
        # the edge points do not depend on where the rays start, only the 10/15 window
        # does: a hint this close needs no second pass
        if shift < max(0.5, 0.04 * rad):
            break
    return result
