"""Stereo localization of the marker: two detections -> one 3D centre and normal.

The centres are triangulated from *undistorted* pixels (linear DLT, then Gauss-Newton on the
reprojection error, which is the maximum-likelihood point for equal pixel noise).  Gates: the
epipolar residual (the two centres must be images of one point) and the angle between the left
and right normals (one plane seen twice).  With ``method="paper"`` the two-normal ambiguity of
each view is resolved by the other view (paper Eq. 16), never guessed.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from stationd.geometry.camera import StereoPair
from stationd.vision import centre as cm
from stationd.vision.detect import Circle, Detection, detect
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams

_pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="stereo")


@dataclass(frozen=True, eq=False)
class StereoResult:
    """The marker in the left camera frame (mm), or why not."""

    found: bool
    reason: str | None
    left: Detection
    right: Detection
    side: str = ""          # the camera whose detection failed ("left", "right"), or none
    point_mm: np.ndarray | None = None
    normal: np.ndarray | None = None
    epipolar_px: float | None = None
    normal_angle_deg: float | None = None
    radii_mm: dict[str, float] = field(default_factory=dict)
    timings_ms: dict[str, float] = field(default_factory=dict)

    @property
    def said(self) -> str | None:
        """The reason as people read it, with the camera that gave it ("left: ...")."""
        if self.reason is None or not self.side:
            return self.reason
        return f"{self.side}: {self.reason}"

    def to_json(self) -> dict[str, Any]:
        def vec(a: np.ndarray | None) -> list[float] | None:
            return None if a is None else [float(x) for x in a]

        return {
            "found": self.found, "reason": self.said, "side": self.side or None,
            "left": self.left.to_json(), "right": self.right.to_json(),
            "point_mm": vec(self.point_mm), "normal": vec(self.normal),
            "epipolar_px": self.epipolar_px, "normal_angle_deg": self.normal_angle_deg,
            "radii_mm": self.radii_mm,
            "timings_ms": {k: round(v, 3) for k, v in self.timings_ms.items()},
        }


def _hom(uv: np.ndarray) -> np.ndarray:
    return np.array([uv[0], uv[1], 1.0])


def _project(K: np.ndarray, X: np.ndarray) -> np.ndarray:
    p = K @ X
    return np.asarray(p[:2] / p[2])


def triangulate(pair: StereoPair, uv_left: np.ndarray, uv_right: np.ndarray) -> np.ndarray:
    """3D point (left frame, mm) from two *undistorted* pixel positions."""
    Kl, Kr = pair.left.K, pair.right.K
    Pl = Kl @ np.hstack([np.eye(3), np.zeros((3, 1))])
    Pr = Kr @ np.hstack([pair.R, pair.T.reshape(3, 1)])
    A = np.vstack([uv_left[0] * Pl[2] - Pl[0], uv_left[1] * Pl[2] - Pl[1],
                   uv_right[0] * Pr[2] - Pr[0], uv_right[1] * Pr[2] - Pr[1]])
    A /= np.linalg.norm(A[:, :3], axis=1, keepdims=True)
    _, _, vt = np.linalg.svd(A)
    X = vt[-1, :3] / vt[-1, 3]
    for _ in range(5):  # Gauss-Newton on the reprojection error in both images
        r = np.concatenate([_project(Kl, X) - uv_left,
                            _project(Kr, pair.R @ X + pair.T) - uv_right])
        J = np.zeros((4, 3))
        h = 1e-6 * max(1.0, float(np.linalg.norm(X)))
        for k in range(3):
            d = np.zeros(3)
            d[k] = h
            rp = np.concatenate([_project(Kl, X + d) - uv_left,
                                 _project(Kr, pair.R @ (X + d) + pair.T) - uv_right])
            J[:, k] = (rp - r) / h
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        X = X + step
        if np.linalg.norm(step) < 1e-10:
            break
    return np.asarray(X)


def fundamental(pair: StereoPair) -> np.ndarray:
    """F with ``x_right^T F x_left = 0`` for undistorted pixels."""
    t = pair.T
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    E = tx @ pair.R
    return np.asarray(np.linalg.inv(pair.right.K).T @ E @ np.linalg.inv(pair.left.K))


def epipolar_residual(pair: StereoPair, uv_left: np.ndarray, uv_right: np.ndarray) -> float:
    """Mean distance (px) of each centre to the epipolar line of the other."""
    F = fundamental(pair)
    xl, xr = _hom(uv_left), _hom(uv_right)
    lr = F @ xl
    ll = F.T @ xr
    e = float(xr @ F @ xl)
    return float(0.5 * (abs(e) / np.hypot(lr[0], lr[1]) + abs(e) / np.hypot(ll[0], ll[1])))


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / (np.linalg.norm(a) * np.linalg.norm(b)),
                                              -1.0, 1.0))))


def localize_detections(pair: StereoPair, left: Detection, right: Detection,
                        params: VisionParams | None = None) -> StereoResult:
    """Combine a left and a right detection of the same marker."""
    params = params or VisionParams()
    g = params.gates
    if not left.found or not right.found:
        side = "left" if not left.found else "right"
        reason = left.reason if not left.found else right.reason
        return StereoResult(False, reason, left, right, side=side)
    if left.centre_px is not None and right.centre_px is not None \
            and np.array_equal(left.centre_px, right.centre_px):
        # two real cameras never agree to the last bit of a sub-pixel centre: this is one
        # picture twice (one camera wired as both, a file given twice), which triangulates
        # to a confident, wrong point
        return StereoResult(False, "left and right are the same picture (one camera as "
                                   "both?)", left, right)
    # narrowed by ``found``: a found detection carries all of these
    for d in (left, right):
        if d.centre_undist is None or d.normal is None or d.inner is None \
                or d.normal_candidates is None:
            return StereoResult(False, "incomplete detection", left, right)
    assert left.centre_undist is not None and right.centre_undist is not None  # noqa: S101
    assert left.inner is not None and right.inner is not None  # noqa: S101
    assert left.normal is not None and right.normal is not None  # noqa: S101
    assert left.normal_candidates is not None  # noqa: S101
    assert right.normal_candidates is not None  # noqa: S101
    cl, cr = left.centre_undist, right.centre_undist
    # Eq. 16, per view: a view's true normal is the candidate the other view confirms.  A
    # view that sees the marker head-on cannot choose (its candidates hug the cone axis) but
    # then the other one can; the plane has one normal, so the decisive views' normals are
    # fused and both centres are computed from it.
    Rt = pair.R.T
    right_in_left = (Rt @ right.normal_candidates[0], Rt @ right.normal_candidates[1])
    il = cm.choose_by_other_view(left.normal_candidates, right_in_left,
                                 min_margin_deg=g.min_normal_margin_deg)
    ir = cm.choose_by_other_view(right_in_left, left.normal_candidates,
                                 min_margin_deg=g.min_normal_margin_deg)
    choice_l = None if il is None else left.normal_candidates[il]
    choice_r = None if ir is None else right_in_left[ir]
    decisive = [n for n in (choice_l, choice_r) if n is not None]
    angle = _angle_deg(choice_l, choice_r) if choice_l is not None and choice_r is not None \
        else 0.0
    if angle > g.max_normal_angle_deg:
        return StereoResult(False, f"left and right normals disagree by {angle:.1f} deg "
                            f"(> {g.max_normal_angle_deg})", left, right, normal_angle_deg=angle)
    if decisive:
        n = decisive[0] if len(decisive) == 1 else decisive[0] + decisive[1]
    elif left.normal_ambiguous or right.normal_ambiguous:
        return StereoResult(False, "normal ambiguous in both views", left, right)
    else:  # each view chose by its concentric split; they must agree
        angle = _angle_deg(left.normal, Rt @ right.normal)
        if angle > g.max_normal_angle_deg:
            return StereoResult(False, f"left and right normals disagree by {angle:.1f} deg "
                                f"(> {g.max_normal_angle_deg})", left, right,
                                normal_angle_deg=angle)
        n = left.normal + Rt @ right.normal
    n = n / np.linalg.norm(n)
    nl, nr = n, pair.R @ n
    if params.centre_method == "paper":
        cl = cm.centre_from_normal(left.inner.conic, pair.left.K, nl)
        cr = cm.centre_from_normal(right.inner.conic, pair.right.K, nr)
        left = replace(left, centre_undist=cl, centre_px=pair.left.distort_pixels(cl)[0],
                       normal=nl, method="paper", normal_ambiguous=False)
        right = replace(right, centre_undist=cr, centre_px=pair.right.distort_pixels(cr)[0],
                        normal=nr, method="paper", normal_ambiguous=False)
    epi = epipolar_residual(pair, cl, cr)
    if epi > g.max_epipolar_px:
        return StereoResult(False, f"epipolar residual {epi:.2f} px (> {g.max_epipolar_px}): "
                            "not the same point in both views", left, right, epipolar_px=epi)
    X = triangulate(pair, cl, cr)
    radii: dict[str, float] = {}
    for name, pts_l, pts_r in (("inner", left.inner_points, right.inner_points),
                               ("outer", left.outer_points, right.outer_points)):
        if pts_l is None or pts_r is None:
            continue
        rl = cm.circle_radius_3d(pts_l, pair.left.K, X, n)
        rr = cm.circle_radius_3d(pts_r, pair.right.K, pair.R @ X + pair.T, pair.R @ n)
        radii[name] = 0.5 * (rl + rr)
    return StereoResult(True, None, left, right, point_mm=X, normal=n, epipolar_px=epi,
                        normal_angle_deg=angle, radii_mm=radii)


def localize(pair: StereoPair, image_left: np.ndarray, image_right: np.ndarray,
             params: VisionParams | None = None, marker: MarkerSpec | None = None,
             parallel: bool = True,
             exclude: tuple[Sequence[Circle], Sequence[Circle]] = ((), ())) -> StereoResult:
    """Detect in both images (in parallel: OpenCV releases the GIL) and combine; ``exclude``:
    each image's circles where a marker is a reference, never the one looked for."""
    t0 = time.perf_counter()
    if parallel:
        fl = _pool.submit(detect, image_left, pair.left, params, marker, exclude[0])
        fr = _pool.submit(detect, image_right, pair.right, params, marker, exclude[1])
        left, right = fl.result(), fr.result()
    else:
        left = detect(image_left, pair.left, params, marker, exclude[0])
        right = detect(image_right, pair.right, params, marker, exclude[1])
    t1 = time.perf_counter()
    res = localize_detections(pair, left, right, params)
    t2 = time.perf_counter()
    res.timings_ms.update({"detect_both": (t1 - t0) * 1e3, "stereo": (t2 - t1) * 1e3,
                           "total": (t2 - t0) * 1e3})
    return res
