"""One image in, one marker (or a reason) out: the pipeline of paper sections 2-3.

``detect`` searches a reduced image for purple regions enclosing a ring (segment), then for each
candidate works at full resolution inside its ROI only: edges -> sub-pixel points ->
undistortion -> Leitz-robust ellipse fits of both boundaries -> projected centre.  Every
detection passes the quality gates or is refused with the reason; two markers in view is a
refusal for ``detect`` (``detect_all`` returns both).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from stationd.errors import ImageError
from stationd.geometry.camera import Camera
from stationd.result import Refusal
from stationd.vision import centre as cm
from stationd.vision.edges import BoundaryEdges, boundary_edges
from stationd.vision.ellipse import fit_ellipse, fit_trimmed
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import Gates, VisionParams
from stationd.vision.segment import MIN_HOLE_RADIUS_PX, Candidate, search_candidates
from stationd.vision.types import Ellipse

Box = tuple[int, int, int, int]
Circle = tuple[float, float, float]   # x, y, radius in raw pixels


@dataclass(frozen=True, eq=False)
class Detection:
    """A localized marker in one image, or why there is none (``found`` False)."""

    found: bool
    reason: str | None = None
    centre_px: np.ndarray | None = None          # corrected projected centre, raw pixels
    ellipse_centre_px: np.ndarray | None = None  # inner ellipse centre (baseline), raw pixels
    centre_undist: np.ndarray | None = None      # corrected centre, undistorted pixels
    normal: np.ndarray | None = None             # unit, camera frame, facing the camera
    normal_candidates: tuple[np.ndarray, np.ndarray] | None = None  # inner cone's two normals
    normal_ambiguous: bool = False  # one image could not choose; stereo (Eq. 16) decides
    inner: Ellipse | None = None
    outer: Ellipse | None = None
    inner_points: np.ndarray | None = field(default=None, repr=False)  # undistorted inliers
    outer_points: np.ndarray | None = field(default=None, repr=False)
    pencil_ratio: float | None = None
    centre_split_px: float | None = None
    method: str = ""
    roi: Box | None = None
    outer_visible: float | None = None  # fraction of the outer ring's angle with fitted edges
    # what the fits saw, for drawing (``stationd detect --draw``): every edge point assigned to
    # a boundary (raw pixels) and which of them the fit kept; set on refusals too when known
    edges_raw: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    edges_used: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    edges_dropped: np.ndarray | None = field(default=None, repr=False)  # near, not assigned
    timings_ms: dict[str, float] = field(default_factory=dict)
    # the reduced image the search ran on (1/search_scale of the frame, or finer after a
    # retry): the commissioning screen shows it rather than reducing the 20 MP frame again
    search_image: np.ndarray | None = field(default=None, repr=False)

    def to_json(self) -> dict[str, Any]:
        def vec(a: np.ndarray | None) -> list[float] | None:
            return None if a is None else [float(x) for x in a]

        return {
            "found": self.found,
            "reason": self.reason,
            "centre_px": vec(self.centre_px),
            "ellipse_centre_px": vec(self.ellipse_centre_px),
            "normal": vec(self.normal),
            "normal_ambiguous": self.normal_ambiguous,
            "inner": None if self.inner is None else self.inner.to_json(),
            "outer": None if self.outer is None else self.outer.to_json(),
            "pencil_ratio": self.pencil_ratio,
            "centre_split_px": self.centre_split_px,
            "method": self.method,
            "outer_visible": self.outer_visible,
            "roi": None if self.roi is None else list(self.roi),
            "timings_ms": {k: round(v, 3) for k, v in self.timings_ms.items()},
        }


def check_image(image: np.ndarray) -> None:
    """The detector needs an 8-bit colour image (BGR): anything else is bad input."""
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8:
        raise ImageError("image must be 8-bit")
    if image.ndim != 3 or image.shape[2] != 3:
        channels = 1 if image.ndim == 2 else (image.shape[2] if image.ndim == 3 else "?")
        raise ImageError(f"image must have 3 colour channels (BGR), got {channels}")


def reduce(image: np.ndarray, scale: int) -> np.ndarray:
    """The search image: 1/scale of the frame (bilinear, about 1 ms for 20 MP at 1/8)."""
    h, w = image.shape[:2]
    if scale <= 1:
        return image
    return cv2.resize(image, (max(w // scale, 1), max(h // scale, 1)),
                      interpolation=cv2.INTER_LINEAR)


def excluded(cand: Candidate, exclude: Sequence[Circle]) -> bool:
    """Whether a candidate's hole lies in one of the ``exclude`` circles (raw pixels)."""
    cx, cy = cand.hole_centre
    return any(math.hypot(cx - x, cy - y) <= r for x, y, r in exclude)


#: the reason :func:`detect_all` gives when no candidate was seen at all (no marker in view:
#: nothing refused), which callers tell apart from a marker seen and refused by this name
NOTHING_IN_VIEW = "no purple region enclosing a ring in view"


def detect_all(image: np.ndarray, camera: Camera, params: VisionParams | None = None,
               marker: MarkerSpec | None = None, timings: dict[str, float] | None = None,
               searched: list[np.ndarray] | None = None, exclude: Sequence[Circle] = ()
               ) -> tuple[list[Detection], list[str]]:
    """Every marker in the image, and the reasons candidates were refused.

    ``timings``, when given, receives the search's stage times (ms), which a refusal for
    want of candidates would otherwise not show; ``searched``, when given, receives the
    reduced image the search ended on (the last one, after a finer retry).  ``exclude``:
    circles ``(x, y, r)`` in raw pixels where a marker is not the one looked for (the fixed
    reference markers, where the wrench's search must never take one for the wrench): a
    candidate whose hole lies in one is dropped before it is measured.
    """
    params = params or VisionParams()
    marker = marker or MarkerSpec()
    check_image(image)
    h, w = image.shape[:2]
    if (w, h) != camera.size:
        raise ImageError(f"image is {w}x{h} but the camera model is {camera.size[0]}x"
                         f"{camera.size[1]}")
    timings = timings if timings is not None else {}
    timings.update({"reduce": 0.0, "segment": 0.0, "retinex": 0.0})
    # A marker too small for the reduced search (a far marker, a small sensor) is looked for
    # again at half the reduction, but only if a purple region small enough to be such a
    # marker was seen: a frame with no marker (most frames of most pairs) or with one cut by
    # the edge costs one reduced search, not three.  A field whose ring hole is below the
    # search's minimum radius spans less than 2 * field/inner * that radius; twice that
    # side squared (tilt, blur) bounds its area.
    retry_area = 2.0 * (2.0 * marker.field_mm / marker.inner_mm * MIN_HOLE_RADIUS_PX) ** 2
    scale = params.search_scale
    while True:
        t0 = time.perf_counter()
        small = reduce(image, scale)
        t1 = time.perf_counter()
        cands, purple = search_candidates(
            small, scale, params.hsv, enhance=params.enhance_params if params.enhance else None,
            full_size=(w, h), timings=timings)
        t2 = time.perf_counter()
        timings["reduce"] += (t1 - t0) * 1e3
        timings["segment"] += (t2 - t1) * 1e3
        kept = [c for c in cands if not excluded(c, exclude)]
        references = len(kept) < len(cands)
        cands = kept
        if cands or scale <= 2 or not 0 < purple <= retry_area:
            break
        scale //= 2
    if searched is not None:
        searched.append(small)
    found: list[Detection] = []
    reasons: list[str] = ["only a reference marker's place in view"] if references else []
    for cand in cands[: params.max_candidates]:
        det = measure(image, camera, cand, params, marker, dict(timings))
        if det.found:
            found.append(det)
        elif det.reason:
            reasons.append(det.reason)
    if not cands and not reasons:
        reasons.append(NOTHING_IN_VIEW)
    # one marker seen through two candidate regions (e.g. a field split by a glint) counts once
    unique: list[Detection] = []
    for d in found:
        assert d.centre_px is not None  # noqa: S101 - found detections carry a centre
        if all(np.hypot(*(d.centre_px - u.centre_px)) > 2.0 for u in unique
               if u.centre_px is not None):
            unique.append(d)
    return unique, reasons


def detect(image: np.ndarray, camera: Camera, params: VisionParams | None = None,
           marker: MarkerSpec | None = None, exclude: Sequence[Circle] = ()) -> Detection:
    """The one marker in view (outside the ``exclude`` circles); refused when there is none
    or more than one."""
    t0 = time.perf_counter()
    search: dict[str, float] = {}
    searched: list[np.ndarray] = []
    found, reasons = detect_all(image, camera, params, marker, search, searched, exclude)
    total = (time.perf_counter() - t0) * 1e3
    small = searched[-1] if searched else None
    if len(found) == 1:
        det = found[0]
        det.timings_ms["total"] = total
        return replace(det, search_image=small)
    if len(found) > 1:
        return Detection(False, f"ambiguous: {len(found)} markers in view",
                         timings_ms={**search, "total": total}, search_image=small)
    reason = "; ".join(dict.fromkeys(reasons)) or "marker not found"
    return Detection(False, reason, timings_ms={**search, "total": total}, search_image=small)


def _coverage(e: Ellipse, pts: np.ndarray) -> float:
    ang = np.arctan2(pts[:, 1] - e.centre[1], pts[:, 0] - e.centre[0])
    bins = np.unique(((ang + np.pi) / (2 * np.pi) * 36).astype(int) % 36)
    return bins.size / 36.0


def _fit_boundary(name: str, pts: np.ndarray, params: VisionParams) -> Ellipse | Refusal:
    g = params.gates
    if len(pts) < g.min_points:
        return Refusal(f"{name} boundary: {len(pts)} edge points (< {g.min_points})")
    if params.leitz:
        got = fit_trimmed(pts, residual=params.residual)
        if isinstance(got, Refusal):
            return Refusal(f"{name} boundary: {got.reason}")
        trimmed, e = got
    else:
        trimmed = np.ones(len(pts), dtype=bool)
        fit = fit_ellipse(pts, leitz=False, residual=params.residual)
        if isinstance(fit, Refusal):
            return Refusal(f"{name} boundary: {fit.reason}")
        e = fit
    full = trimmed.copy()
    if e.inliers is not None:
        full[np.flatnonzero(trimmed)] = e.inliers
    e = replace(e, inliers=full, rejected=len(pts) - e.used)
    if e.used < g.min_points:
        return Refusal(f"{name} boundary: {e.used} edge points after the Leitz criterion "
                       f"(< {g.min_points})")
    if e.rms > g.max_rms_px:
        return Refusal(f"{name} boundary: fit residual {e.rms:.3f} px (> {g.max_rms_px})")
    cov = _coverage(e, pts[full])
    need = g.min_coverage if name == "inner" else g.min_outer_coverage
    if cov < need:
        return Refusal(f"{name} boundary: edge points cover {cov:.0%} of it "
                       f"(< {need:.0%}): occluded or cut")
    return e


def _used(e: Ellipse | Refusal, n: int) -> np.ndarray:
    """Which of n points a fit kept (none when the fit was refused)."""
    if isinstance(e, Refusal):
        return np.zeros(n, dtype=bool)
    return np.ones(n, dtype=bool) if e.inliers is None else np.asarray(e.inliers, dtype=bool)


def measure(image: np.ndarray, camera: Camera, cand: Candidate, params: VisionParams,
            marker: MarkerSpec, timings: dict[str, float] | None = None) -> Detection:
    """Full-resolution measurement of one candidate ROI."""
    timings = timings if timings is not None else {}
    x, y, w, h = (int(v) for v in cand.roi)
    roi: Box = (x, y, w, h)

    raw: tuple[np.ndarray, np.ndarray] | None = None
    used: tuple[np.ndarray, np.ndarray] | None = None
    dropped: np.ndarray | None = None

    def refuse(reason: str) -> Detection:
        return Detection(False, reason, roi=roi, timings_ms=timings, edges_raw=raw,
                         edges_used=used, edges_dropped=dropped)

    # A purple region touching the image border is not refused here: what matters is the
    # ring, and a ring cut by the border fails the outline search (border regions are
    # excluded) or the coverage gate, each with its reason.
    t0 = time.perf_counter()
    hint = (cand.hole_centre[0] - x, cand.hole_centre[1] - y)
    edges = boundary_edges(image[y:y + h, x:x + w], marker.ratio_sq, hint, cand.hole_radius,
                           timings)
    t1 = time.perf_counter()
    # "edges" is the ROI's own work; the rays that find the ring inside it are "rays"
    timings["edges"] = (t1 - t0) * 1e3 - timings.get("rays", 0.0)
    if isinstance(edges, Refusal):
        return refuse(edges.reason)
    assert isinstance(edges, BoundaryEdges)  # noqa: S101 - narrowed for mypy
    offset = np.array([x, y], dtype=np.float64)
    pin = camera.undistort_pixels(edges.inner + offset)
    pout = camera.undistort_pixels(edges.outer + offset)
    t2 = time.perf_counter()
    timings["undistort"] = (t2 - t1) * 1e3
    raw = (edges.inner + offset, edges.outer + offset)
    dropped = edges.dropped + offset
    inner = _fit_boundary("inner", pin, params)
    outer = _fit_boundary("outer", pout, params)
    used = (_used(inner, len(pin)), _used(outer, len(pout)))
    t3 = time.perf_counter()
    timings["fit"] = (t3 - t2) * 1e3
    if isinstance(inner, Refusal):
        return refuse(inner.reason)
    if isinstance(outer, Refusal):
        return refuse(outer.reason)
    det = _centre(camera, inner, outer, params, marker)
    timings["centre"] = (time.perf_counter() - t3) * 1e3
    if isinstance(det, Refusal):
        return refuse(det.reason)
    ellipse_c = np.array(inner.centre)
    return Detection(
        True, None,
        centre_px=camera.distort_pixels(det.centre)[0],
        ellipse_centre_px=camera.distort_pixels(ellipse_c)[0],
        centre_undist=det.centre, normal=det.normal, normal_candidates=det.candidates,
        normal_ambiguous=det.ambiguous,
        inner=inner, outer=outer,
        inner_points=pin if inner.inliers is None else pin[inner.inliers],
        outer_points=pout if outer.inliers is None else pout[outer.inliers],
        pencil_ratio=det.ratio, centre_split_px=det.split, method=det.method,
        roi=roi, outer_visible=_coverage(outer, pout if outer.inliers is None
                                         else pout[outer.inliers]),
        edges_raw=raw, edges_used=used, edges_dropped=dropped, timings_ms=timings)


@dataclass(frozen=True, eq=False)
class _Centre:
    centre: np.ndarray
    normal: np.ndarray
    ratio: float
    split: float
    candidates: tuple[np.ndarray, np.ndarray]
    ambiguous: bool
    method: str


def _centre_noise(e: Ellipse) -> float:
    """Standard deviation of a fitted centre from the residuals: about rms * sqrt(2 / N)."""
    return float(e.rms * np.sqrt(2.0 / max(e.used, 1)))


def _centre(camera: Camera, inner: Ellipse, outer: Ellipse, params: VisionParams,
            marker: MarkerSpec) -> _Centre | Refusal:
    """Projected centre and normal by the configured method, with the structural gates.

    The normal is always one of the inner cone's two candidates (accurate to a fraction of a
    degree), chosen by the concentric constraint; the pencil's own normal is far noisier at
    distance.  When one image cannot tell the candidates apart but both give the same centre,
    the detection stands with ``normal_ambiguous`` set and stereo decides (paper Eq. 16).
    """
    g: Gates = params.gates
    K = camera.K
    c_conc, ratio = cm.concentric_centre(inner.conic, outer.conic)
    if not np.isfinite(ratio) or abs(ratio / marker.ratio_sq - 1.0) > g.ratio_tolerance:
        return Refusal(f"not this marker's two circles: pencil ratio {ratio:.3f} "
                       f"(expected {marker.ratio_sq:.3f})")
    noise = float(np.hypot(_centre_noise(inner), _centre_noise(outer)))
    res = cm.resolve_normals_mono(inner.conic, outer.conic, K, noise_px=noise)
    method = params.centre_method
    if isinstance(res, Refusal):
        # The paper's centre depends on the normal, which this image cannot choose: never
        # guess; the pencil's centre needs no normal (stereo recomputes the paper's once
        # Eq. 16 has chosen).  The pencil and ellipse centres are unaffected.
        cands = cm.circle_normals(inner.conic, K)
        n = cm.normal_from_centre(inner.conic, K, c_conc)
        split, ambiguous = float("nan"), True
        if method == "paper":
            method = "concentric"
    else:
        n, cands, split, ambiguous = res.normal, res.candidates, res.split_px, res.ambiguous
        if split > g.max_centre_split_px:
            return Refusal(f"inner and outer circles disagree on the centre by {split:.2f} px")
    if method == "paper":
        c = cm.centre_from_normal(inner.conic, K, n)
    elif method == "concentric":
        c = c_conc
    else:
        c = np.array(inner.centre)
    if not np.all(np.isfinite(c)):
        return Refusal("no finite projected centre")
    return _Centre(c, n, float(ratio), split, cands, ambiguous, method)
