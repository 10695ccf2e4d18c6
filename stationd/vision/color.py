"""``tune-color``: HSV ranges of the marker's purple from a well-lit reference image (paper 2.1).

The paper adjusts the ranges by hand in MATLAB on a well-lit image; here the same image gives
them by rule, so a station with a different print or lamp is re-tuned in one command and the
result is reproducible:

1. The purple pixels: inside the ROI if one is given, else the dominant, most saturated
   purple-ish region (hue 220-350 deg): of the purple-ish pixels, those with at least 60 % of
   the 99th-percentile saturation, largest 8-connected component; eroded by 1 px so no pixel
   mixed with the ring or the background votes.  None -> :class:`InputError`.
2. H and S: every sampled pixel is re-imaged under every white-balance cast with channel
   gains in {0.85, 1, 1.15} (27 combinations, the 8 corners included) and at 100/50/25/10 %
   light with 8-bit rounding; H = [0.5th, 99.5th percentile] of all that, widened by 1 unit;
   S >= the 0.5th percentile, lowered by what the bounded S stretch of ``enhance`` can take
   away, minus 3.  So the range holds the reference colour under the +-15 % cast and in the
   10 % corner by construction rather than by a guessed margin.
3. V (after enhancement, as the detector sees it on its reduced image): half the 10th
   percentile of the enhanced V of the purple pixels, between 20 and the default 45 -- Retinex
   keeps the purple at about the same enhanced V in the dark, so V only has to reject black.
4. The result never accepts more than the default box (:data:`DEFAULT_HSV`): tuning is for
   rejecting what a station's print and lamp make look purple, and a box wider than the one
   derived for every printed purple would only let more of the car in.  So V is the default's.

Which image is a reference: :func:`verify_marker` runs the detector's ring check (a purple field
around a dark ring around a bright centre) on it; ``stationd tune-color`` refuses an image
where it finds no marker, and a tuned box that would lose the marker it was tuned on.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import cv2
import numpy as np

from stationd.errors import ImageError, InputError
from stationd.vision.enhance import EnhanceParams, enhance_hsv
from stationd.vision.segment import DEFAULT_HSV, HsvRange, purple_mask
from stationd.yamlio import YamlNode

__all__ = ["PURPLISH", "read_hsv_yaml", "tune_hsv", "verify_marker", "write_hsv_yaml"]

Roi = tuple[int, int, int, int]
PURPLISH = HsvRange(h=(110, 175), s=(40, 255), v=(30, 255))  # the net "purple-ish" casts
MIN_PIXELS = 30
WORK_MAX_SIDE = 1400  # the searched area is reduced to this for the statistics
GAINS = (0.85, 1.0, 1.15)
LIGHTS = (1.0, 0.5, 0.25, 0.1)
MAX_SAMPLES = 2000


def _select(bgr: np.ndarray) -> np.ndarray:
    """Mask of the chosen purple region in ``bgr`` (rule 1 of the module docstring)."""
    hsv = cv2.cvtColor(bgr, cv2.COLOR_BGR2HSV)
    net = purple_mask(hsv, PURPLISH) > 0
    if np.count_nonzero(net) < MIN_PIXELS:
        raise InputError("no purple-ish pixels (hue 220-350 deg, saturation >= 16 %) found; "
                         "is the marker in view and lit, or is --roi on it?")
    s = hsv[..., 1]
    strong = (net & (s >= 0.6 * np.percentile(s[net], 99))).astype(np.uint8)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(strong, connectivity=8)
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    if stats[best, cv2.CC_STAT_AREA] < MIN_PIXELS:
        raise InputError(f"the purple region has only {stats[best, cv2.CC_STAT_AREA]} pixels "
                         f"(< {MIN_PIXELS}); give a larger --roi or a closer reference image")
    region = (labels == best).astype(np.uint8)
    eroded = cv2.erode(region, np.ones((3, 3), np.uint8))
    return (eroded if np.count_nonzero(eroded) >= MIN_PIXELS else region) > 0


def _reimaged(samples: np.ndarray) -> np.ndarray:
    """HSV of ``samples`` (N x 3 BGR) under every cast and light level, 8-bit rounded."""
    gains = np.array(list(itertools.product(GAINS, repeat=3)), dtype=np.float64)  # B, G, R
    x = (samples[None, None, :, :].astype(np.float64) * gains[:, None, None, :]
         * np.array(LIGHTS)[None, :, None, None])
    x8 = np.clip(np.round(x), 0, 255).astype(np.uint8).reshape(-1, 1, 3)
    return np.asarray(cv2.cvtColor(x8, cv2.COLOR_BGR2HSV).reshape(-1, 3))


def tune_hsv(bgr: np.ndarray, roi: Roi | None = None, *,
             enhance: EnhanceParams | None = None, search_scale: int = 8) -> HsvRange:
    """HSV range for the purple of a well-lit reference image (rules in the module docstring).

    ``roi`` (x, y, w, h) in image pixels: where the purple field is; ``None`` searches the
    whole image.  ``enhance`` and ``search_scale`` are the detector's (defaults: the station's).
    Raises :class:`InputError` when there is nothing purple to measure.
    """
    if not isinstance(bgr, np.ndarray) or bgr.dtype != np.uint8 or bgr.ndim != 3 \
            or bgr.shape[2] != 3:
        raise ImageError("the reference must be an 8-bit BGR image")
    enhance = enhance or EnhanceParams()
    ih, iw = bgr.shape[:2]
    x, y, w, h = roi if roi is not None else (0, 0, iw, ih)
    if w <= 0 or h <= 0 or x < 0 or y < 0 or x + w > iw or y + h > ih:
        raise InputError(f"ROI {roi} is not inside the {iw}x{ih} image")
    f = max(1, math.ceil(max(w, h) / WORK_MAX_SIDE))
    area = bgr[y:y + h, x:x + w]
    work = area if f == 1 else cv2.resize(area, (max(1, w // f), max(1, h // f)),
                                          interpolation=cv2.INTER_AREA)
    sel = _select(work)
    pix = work[sel]
    pix = pix[np.linspace(0, len(pix) - 1, min(len(pix), MAX_SAMPLES)).astype(np.intp)]
    sim = _reimaged(pix)
    h_lo, h_hi = np.percentile(sim[:, 0], (0.5, 99.5))
    h_range = (max(PURPLISH.h[0], math.floor(h_lo) - 1), min(PURPLISH.h[1], math.ceil(h_hi) + 1))
    s_min = float(np.percentile(sim[:, 1], 0.5))
    s_min = (s_min - enhance.s_max_lo) * 255.0 / (255.0 - enhance.s_max_lo) - 3.0
    s_lo = int(np.clip(math.floor(s_min), 25, 200))
    # V as the detector sees it: the whole frame reduced and enhanced.
    sc = max(1, search_scale)
    small = cv2.resize(bgr, (max(1, iw // sc), max(1, ih // sc)), interpolation=cv2.INTER_LINEAR)
    v_enh = enhance_hsv(cv2.cvtColor(small, cv2.COLOR_BGR2HSV), enhance, float(sc))[..., 2]
    ys, xs = np.nonzero(sel)
    fx, fy = x + (xs + 0.5) * f - 0.5, y + (ys + 0.5) * f - 0.5  # full-resolution pixels
    sx = np.clip(np.round((fx + 0.5) / sc - 0.5).astype(np.intp), 0, small.shape[1] - 1)
    sy = np.clip(np.round((fy + 0.5) / sc - 0.5).astype(np.intp), 0, small.shape[0] - 1)
    v_lo = int(np.clip(round(0.5 * float(np.percentile(v_enh[sy, sx], 10))), 20,
                       DEFAULT_HSV.v[0]))
    return _within_default(HsvRange(h=h_range, s=(s_lo, 255), v=(v_lo, 255)))


def _within_default(r: HsvRange) -> HsvRange:
    """Rule 4: the tuned box cut to the default box (never wider, on any bound)."""
    d = DEFAULT_HSV
    h = (max(r.h[0], d.h[0]), min(r.h[1], d.h[1]))
    if h[0] > h[1]:
        raise InputError(f"the reference's purple (H {r.h[0]}-{r.h[1]}) lies outside the "
                         f"hues the detector accepts (H {d.h[0]}-{d.h[1]}); is it the marker?")
    return HsvRange(h=h, s=(max(r.s[0], d.s[0]), min(r.s[1], d.s[1])),
                    v=(max(r.v[0], d.v[0]), min(r.v[1], d.v[1])))


def verify_marker(bgr: np.ndarray, ranges: HsvRange = DEFAULT_HSV, roi: Roi | None = None, *,
                  enhance: EnhanceParams | None = None, search_scale: int = 8) -> str | None:
    """``None`` when the detector's ring check finds a marker with ``ranges`` (its centre
    inside ``roi`` when one is given), else the reason there is none.  Why: the statistics of
    :func:`tune_hsv` are only the marker's purple if the purple measured is a marker's."""
    from stationd.vision.detect import check_image, reduce
    from stationd.vision.segment import search_candidates

    check_image(bgr)
    enhance = enhance or EnhanceParams()
    ih, iw = bgr.shape[:2]
    scale = max(1, search_scale)
    while True:
        cands, _ = search_candidates(reduce(bgr, scale), scale, ranges, enhance=enhance,
                                     full_size=(iw, ih))
        if roi is not None:
            x, y, w, h = roi
            cands = [c for c in cands
                     if x <= c.hole_centre[0] < x + w and y <= c.hole_centre[1] < y + h]
        if cands:
            return None
        if scale <= 2:
            break
        scale //= 2
    where = "in the image" if roi is None else "inside --roi"
    return (f"no marker {where} passes the ring check (a purple field around a black ring "
            "around a white centre)")


def write_hsv_yaml(path: str | Path, ranges: HsvRange, *, source: str | None = None,
                   roi: Roi | None = None) -> None:
    """Write ``hsv: {h: [lo, hi], s: [..], v: [..]}`` with a header saying where it came from."""
    src = " ".join((source or "an unnamed image").split())  # one line, whatever the name
    where = "the whole image" if roi is None else "ROI x={}, y={}, w={}, h={}".format(*roi)
    text = (
        "# HSV range of the marker's purple field (stationd station config: vision.hsv).\n"
        "# OpenCV units: H = degrees / 2 (0-179), S and V 0-255; V is after enhancement.\n"
        f"# Produced by 'stationd tune-color' from {src}, {where}.\n"
        "hsv:\n"
        f"  h: [{ranges.h[0]}, {ranges.h[1]}]\n"
        f"  s: [{ranges.s[0]}, {ranges.s[1]}]\n"
        f"  v: [{ranges.v[0]}, {ranges.v[1]}]\n"
    )
    # whole or not at all (beside, then renamed): a Ctrl-C or a full disk in the middle
    # left a truncated box that the station then read as its colours
    from stationd.outfile import write_atomic

    write_atomic(Path(path), text)


def read_hsv_yaml(path: str | Path) -> HsvRange:
    """Read a file written by :func:`write_hsv_yaml` (errors name file, line and key)."""
    doc = YamlNode.load(path).mapping(("hsv",), required=("hsv",))
    return HsvRange.from_node(doc["hsv"])
