"""See what the detector saw: one picture of a detection or of a refusal.

Why: engineers commissioning a station focus the cameras and need to understand a refusal
("outer boundary: edge points cover 42 %" means nothing until one sees the glove over the
ring).  The picture has two panels: the ROI crop, enlarged, with the edge points the fits
used (green) and rejected (red: by the fit, or near the ring but taken by neither boundary:
an occluder's edge), both fitted ellipses (inner cyan, outer yellow), the ellipse centre
(blue) and the corrected projected centre (magenta); and a reduced overview
of the whole frame with the ROI boxed.  The reason, or the centre and the visible fraction
of the outer ring, is written under it.  Drawing never changes a result: it reads one.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from stationd.geometry.camera import Camera
from stationd.vision.detect import Detection, measure, reduce
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams
from stationd.vision.segment import search_candidates
from stationd.vision.types import Ellipse

USED, REJECTED = (0, 200, 0), (0, 0, 230)  # BGR
INNER, OUTER = (230, 200, 0), (0, 220, 230)
ELLIPSE_CENTRE, CENTRE = (230, 60, 0), (220, 0, 220)
PANEL = 640  # px: the longer side of the ROI panel and of the overview


def explain(image: np.ndarray, camera: Camera, det: Detection, params: VisionParams,
            marker: MarkerSpec) -> Detection:
    """A refusal from ``detect`` names the reason but carries no ROI: measure the best
    candidate again so the picture shows what was looked at (same code, same result)."""
    if det.found or det.roi is not None:
        return det
    h, w = image.shape[:2]
    cands, _ = search_candidates(reduce(image, params.search_scale), params.search_scale,
                                 params.hsv, enhance=params.enhance_params
                                 if params.enhance else None, full_size=(w, h))
    if not cands:
        return det
    again = measure(image, camera, cands[0], params, marker)
    return Detection(False, det.reason, roi=again.roi, edges_raw=again.edges_raw,
                     edges_used=again.edges_used, edges_dropped=again.edges_dropped,
                     timings_ms=det.timings_ms)


def _ellipse_raw(e: Ellipse, camera: Camera, n: int = 360) -> np.ndarray:
    t = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    a, b = e.axes
    ca, sa = math.cos(e.angle), math.sin(e.angle)
    x = e.centre[0] + a * np.cos(t) * ca - b * np.sin(t) * sa
    y = e.centre[1] + a * np.cos(t) * sa + b * np.sin(t) * ca
    return np.asarray(camera.distort_pixels(np.stack([x, y], 1)))


def _cross(img: np.ndarray, p: np.ndarray, colour: tuple[int, int, int], size: int) -> None:
    u, v = round(float(p[0]) * 16), round(float(p[1]) * 16)
    s = size * 16
    cv2.line(img, (u - s, v), (u + s, v), colour, 1, cv2.LINE_AA, 4)
    cv2.line(img, (u, v - s), (u, v + s), colour, 1, cv2.LINE_AA, 4)


def draw(image: np.ndarray, camera: Camera, det: Detection) -> np.ndarray:
    """The two-panel picture (BGR uint8) of ``det`` on ``image``."""
    h, w = image.shape[:2]
    x, y, rw, rh = det.roi if det.roi is not None else (0, 0, w, h)
    crop = image[y:y + rh, x:x + rw]
    k = max(1.0, PANEL / max(rw, rh)) if det.roi is not None else PANEL / max(rw, rh)
    panel = cv2.resize(crop, (max(1, round(rw * k)), max(1, round(rh * k))),
                       interpolation=cv2.INTER_NEAREST if k >= 2 else cv2.INTER_AREA)
    off = np.array([x, y], np.float64)

    def to_panel(p: np.ndarray) -> np.ndarray:
        # pixel centres: raw (u, v) -> panel ((u - x + 0.5) k - 0.5)
        return (np.asarray(p, np.float64) - off + 0.5) * k - 0.5

    if det.edges_dropped is not None:  # near the ring, taken by neither boundary
        for p in to_panel(det.edges_dropped):
            cv2.circle(panel, (round(p[0] * 16), round(p[1] * 16)), 20, REJECTED, -1,
                       cv2.LINE_AA, 4)
    if det.edges_raw is not None:
        used = det.edges_used or (np.zeros(len(det.edges_raw[0]), bool),
                                  np.zeros(len(det.edges_raw[1]), bool))
        for pts, ok in zip(det.edges_raw, used, strict=True):
            for p, good in zip(to_panel(pts), ok, strict=True):
                cv2.circle(panel, (round(p[0] * 16), round(p[1] * 16)), 20,
                           USED if good else REJECTED, -1, cv2.LINE_AA, 4)
    # the ellipses over the points (a thin line): dense edge points would hide them
    for e, colour in ((det.inner, INNER), (det.outer, OUTER)):
        if e is not None:
            pts = np.rint(to_panel(_ellipse_raw(e, camera)) * 16).astype(np.int32)
            cv2.polylines(panel, [pts.reshape(-1, 1, 2)], True, colour, 1, cv2.LINE_AA, 4)
    if det.ellipse_centre_px is not None:
        _cross(panel, to_panel(det.ellipse_centre_px), ELLIPSE_CENTRE, 8)
    if det.centre_px is not None:
        _cross(panel, to_panel(det.centre_px), CENTRE, 12)
    s = PANEL / max(w, h)
    overview = cv2.resize(image, (max(1, round(w * s)), max(1, round(h * s))),
                          interpolation=cv2.INTER_AREA)
    if det.roi is not None:
        cv2.rectangle(overview, (int(x * s), int(y * s)),
                      (math.ceil((x + rw) * s), math.ceil((y + rh) * s)),
                      CENTRE if det.found else REJECTED, 2)
    height = max(panel.shape[0], overview.shape[0])
    canvas = np.zeros((height + 48, panel.shape[1] + 8 + overview.shape[1], 3), np.uint8)
    canvas[:panel.shape[0], :panel.shape[1]] = panel
    canvas[:overview.shape[0], panel.shape[1] + 8:] = overview
    for row, text in enumerate(_caption(det)):
        cv2.putText(canvas, text, (6, height + 18 + 22 * row), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (255, 255, 255), 1, cv2.LINE_AA)
    return canvas


def _caption(det: Detection) -> list[str]:
    if not det.found:
        return [f"refused: {det.reason}"[:160],
                "green: edge points used, red: rejected"]
    c, e = det.centre_px, det.ellipse_centre_px
    assert c is not None and e is not None  # noqa: S101 - found detections carry both
    vis = "-" if det.outer_visible is None else f"{det.outer_visible:.0%}"
    return [f"found: centre ({c[0]:.3f}, {c[1]:.3f}) px [magenta], ellipse centre "
            f"({e[0]:.3f}, {e[1]:.3f}) [blue], outer ring visible {vis}",
            "green: edge points used, red: rejected; inner ellipse cyan, outer yellow"]
