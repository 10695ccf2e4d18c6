"""Direct least-squares ellipse fitting with the Leitz (3-sigma) outlier criterion.

Why this fitter: Fitzgibbon's direct fit (the constraint ``4AC - B^2 = 1``) always returns an
ellipse, is closed-form (no iteration, no start value) and is fast enough to run several times
per frame on 200-3000 edge points.  Halir and Flusser's block form avoids the singular scatter
matrix of the original on noise-free data.  The points are centred and scaled first: at image
coordinates around 3000 px the monomials ``x^2 .. 1`` span seven orders of magnitude, and the
unscaled normal equations lose most of the float64 precision.

Why Sampson residuals for the Leitz criterion: the paper (section 2.6) rejects points whose
distance to the ellipse *centre* deviates from the mean by more than three standard deviations.
That distance varies between b and a around an eccentric ellipse, so its spread measures the
eccentricity, not the noise: outliers hide inside it.  The Sampson distance (first-order
geometric distance to the curve) is zero-mean noise for every ellipse.  The paper's residual stays
available as ``residual="centre"`` for comparison.

Conics are 3x3 symmetric matrices in pixel coordinates (OpenCV convention), normalised to unit
Frobenius norm and signed so that inside points give ``x^T C x < 0``.
"""

from __future__ import annotations

import math

import numpy as np

from stationd.result import Refusal
from stationd.vision.types import Ellipse

RESIDUALS = ("sampson", "centre")
MIN_FIT_POINTS = 6

# inverse of Fitzgibbon's 3x3 constraint block [[0, 0, 2], [0, -1, 0], [2, 0, 0]]
_C1_INV = np.array([[0.0, 0.0, 0.5], [0.0, -1.0, 0.0], [0.5, 0.0, 0.0]])
# a point set whose 6x6 scatter has a second null direction does not determine a conic
_RANK_TOL = 1e-13
# residual spread below this (px) is rounding, not noise: no outliers are judged against it
_SD_FLOOR = 1e-6

Params = tuple[tuple[float, float], tuple[float, float], float]


def _as_xy(points: np.ndarray, min_points: int) -> np.ndarray | Refusal:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        return Refusal(f"expected an (N, 2) array of points, got shape {pts.shape}")
    if len(pts) < min_points:
        return Refusal(f"{len(pts)} points (< {min_points}) cannot determine an ellipse")
    if not np.all(np.isfinite(pts)):
        return Refusal("non-finite point coordinates")
    return pts


def _normalised(C: np.ndarray) -> np.ndarray | Refusal:
    """Symmetric, unit Frobenius norm, inside negative; Refusal unless a real ellipse."""
    C = 0.5 * (C + C.T)
    norm = float(np.linalg.norm(C))
    if not (np.isfinite(norm) and norm > 0.0):
        return Refusal("degenerate conic")
    C = C / norm
    if C[0, 0] + C[1, 1] < 0.0:  # make the quadratic part positive (definite for an ellipse)
        C = -C
    det2 = C[0, 0] * C[1, 1] - C[0, 1] ** 2
    if not det2 > 1e-14 * (C[0, 0] + C[1, 1]) ** 2:
        return Refusal("the fitted conic is not an ellipse")
    # value at the centre: negative for a real ellipse, positive for an imaginary one
    if not np.linalg.det(C) / det2 < 0.0:
        return Refusal("the fitted conic is an imaginary ellipse")
    return C


def fit_conic(points: np.ndarray) -> np.ndarray | Refusal:
    """Fitzgibbon's direct ellipse fit (Halir-Flusser form) on centred, scaled points.

    Returns the conic in pixel coordinates, normalised and signed (inside negative).
    Refuses on fewer than 6 points, non-finite input, a degenerate point set (e.g. collinear
    or fewer than 5 distinct points) and a non-ellipse result.
    """
    pts = _as_xy(points, MIN_FIT_POINTS)
    if isinstance(pts, Refusal):
        return pts
    return _fit_conic_xy(pts)


def _fit_conic_xy(pts: np.ndarray) -> np.ndarray | Refusal:
    """:func:`fit_conic` of points already checked by ``_as_xy`` (the loops below refit
    subsets of checked points many times per frame; the checks would only repeat)."""
    m = pts.mean(axis=0)
    d = pts - m
    s = math.sqrt(float(np.mean(np.sum(d * d, axis=1))) / 2.0)  # RMS distance -> sqrt(2)
    if not s > 0.0:
        return Refusal("all points coincide")
    x, y = d[:, 0] / s, d[:, 1] / s
    D = np.stack([x * x, x * y, y * y, x, y, np.ones_like(x)], axis=1)
    S = D.T @ D
    ev = np.linalg.eigvalsh(S)
    if not ev[1] > _RANK_TOL * ev[-1]:
        return Refusal("degenerate point set: the points do not determine a conic")
    S1, S2, S3 = S[:3, :3], S[:3, 3:], S[3:, 3:]
    try:
        T = -np.linalg.solve(S3, S2.T)
    except np.linalg.LinAlgError:
        return Refusal("degenerate point set (collinear points)")
    w, V = np.linalg.eig(_C1_INV @ (S1 + S2 @ T))
    V = V.real
    cond = 4.0 * V[0] * V[2] - V[1] ** 2
    ok = np.flatnonzero(cond > 0.0)
    if ok.size == 0:
        return Refusal("no elliptical solution")
    a1 = V[:, ok[np.argmin(np.abs(w[ok]))]]
    A, B, Cc = a1
    Dd, E, F = T @ a1
    Cn = np.array([[A, B / 2, Dd / 2], [B / 2, Cc, E / 2], [Dd / 2, E / 2, F]])
    N = np.array([[1 / s, 0.0, -m[0] / s], [0.0, 1 / s, -m[1] / s], [0.0, 0.0, 1.0]])
    return _normalised(N.T @ Cn @ N)  # x' = N x  =>  C = N^T C' N


def conic_to_params(C: np.ndarray) -> Params | Refusal:
    """Centre ``(u, v)``, semi-axes ``(a, b)`` with ``a >= b``, major-axis angle in ``[0, pi)``.

    Refuses when ``C`` is not a real ellipse (a conversion of a hyperbola would be nonsense).
    """
    Cs = _normalised(np.asarray(C, dtype=np.float64))
    if isinstance(Cs, Refusal):
        return Cs
    Q2 = Cs[:2, :2]
    c = np.linalg.solve(Q2, -Cs[:2, 2])
    f0 = float(c @ Cs[:2, 2] + Cs[2, 2])  # conic value at the centre (< 0)
    lam, vec = np.linalg.eigh(Q2)  # ascending: the smaller eigenvalue is the major axis
    a, b = math.sqrt(-f0 / lam[0]), math.sqrt(-f0 / lam[1])
    angle = math.atan2(vec[1, 0], vec[0, 0]) % math.pi
    if angle >= math.pi:  # float rounding of the modulo
        angle = 0.0
    return (float(c[0]), float(c[1])), (a, b), angle


def params_to_conic(centre: tuple[float, float], axes: tuple[float, float],
                    angle: float) -> np.ndarray:
    """The normalised, signed conic of an ellipse; raises ValueError on non-positive axes
    (a programming error: parameters, unlike edge points, come from the caller)."""
    a, b = float(axes[0]), float(axes[1])
    if not (a > 0.0 and b > 0.0 and math.isfinite(a) and math.isfinite(b)):
        raise ValueError(f"semi-axes must be positive and finite, got {axes}")
    ca, sa = math.cos(angle), math.sin(angle)
    R = np.array([[ca, -sa], [sa, ca]])
    Q2 = R @ np.diag([1.0 / a**2, 1.0 / b**2]) @ R.T
    c = np.asarray(centre, dtype=np.float64)
    C = np.empty((3, 3))
    C[:2, :2] = Q2
    C[:2, 2] = C[2, :2] = -Q2 @ c
    C[2, 2] = c @ Q2 @ c - 1.0
    return C / np.linalg.norm(C)


def sampson_distance(C: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Signed first-order geometric distance (px) of each point to the conic, positive outside.

    ``f(x) / |grad f(x)|``: within O(d^2 / R) of the true distance near the curve (R the radius
    of curvature), the regime of edge-point residuals, and unlike the algebraic residual it is
    in pixels whatever the ellipse's size; a few numpy ops, no loop over points.
    """
    C = np.asarray(C, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if C[0, 0] + C[1, 1] < 0.0:
        C = -C
    xh = np.column_stack([pts, np.ones(len(pts))])
    Cx = xh @ C
    f = np.einsum("ij,ij->i", xh, Cx)
    g = 2.0 * np.hypot(Cx[:, 0], Cx[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(f / g)


def _residuals(C: np.ndarray, pts: np.ndarray, residual: str) -> np.ndarray:
    if residual == "sampson":
        return sampson_distance(C, pts)
    centre = np.linalg.solve(C[:2, :2], -C[:2, 2])
    return np.asarray(np.hypot(pts[:, 0] - centre[0], pts[:, 1] - centre[1]))


def fit_ellipse(points: np.ndarray, *, leitz: bool = True, residual: str = "sampson",
                sigma: float = 3.0, max_iter: int = 10,
                min_points: int = MIN_FIT_POINTS) -> Ellipse | Refusal:
    """Fit an ellipse to edge points, rejecting outliers with the Leitz criterion.

    Each round takes the residuals of the points still kept, drops those with
    ``|r - mean| > sigma * std`` and refits; it stops when a round drops nothing or after
    ``max_iter`` rounds, so the cost is bounded.  Rejected points are not reconsidered: they
    were judged against a fit that they were pulling towards themselves.
    ``residual="centre"`` is the paper's literal residual (distance to the ellipse centre),
    valid for near-circles only; the default Sampson residual is valid for any ellipse.
    Invalid *arguments* (an unknown residual, sigma <= 0) raise ValueError; bad *data* refuse.
    """
    if residual not in RESIDUALS:
        raise ValueError(f"residual must be one of {RESIDUALS}, got {residual!r}")
    if not sigma > 0.0 or max_iter < 0 or min_points < MIN_FIT_POINTS:
        raise ValueError("need sigma > 0, max_iter >= 0 and min_points >= 6")
    pts = _as_xy(points, min_points)
    if isinstance(pts, Refusal):
        return pts
    return _leitz(pts, _fit_conic_xy(pts), leitz, residual, sigma, max_iter, min_points)


def _leitz(pts: np.ndarray, C: np.ndarray | Refusal, leitz: bool, residual: str,
           sigma: float, max_iter: int, min_points: int) -> Ellipse | Refusal:
    """:func:`fit_ellipse` from the first fit ``C`` of the checked points ``pts``."""
    if isinstance(C, Refusal):
        return C
    keep = np.ones(len(pts), dtype=bool)
    for _ in range(max_iter if leitz else 0):
        idx = np.flatnonzero(keep)
        r = _residuals(C, pts[idx], residual)
        ok = np.isfinite(r)  # a point exactly at the centre has no Sampson distance
        if ok.sum() < 2:
            return Refusal("no finite residuals for the Leitz criterion")
        mu, sd = float(r[ok].mean()), max(float(r[ok].std(ddof=1)), _SD_FLOOR)
        drop = ~ok | (np.abs(r - mu) > sigma * sd)
        if not drop.any():
            break
        keep[idx[drop]] = False
        used = int(keep.sum())
        if used < min_points:
            return Refusal(f"only {used} points (< {min_points}) left after the Leitz criterion")
        C = _fit_conic_xy(pts[keep])
        if isinstance(C, Refusal):
            return Refusal(f"after the Leitz criterion: {C.reason}")
    p = conic_to_params(C)
    if isinstance(p, Refusal):
        return p
    centre, axes, angle = p
    d = sampson_distance(C, pts[keep])
    used = int(keep.sum())
    return Ellipse(conic=C, centre=centre, axes=axes, angle=angle, used=used,
                   rejected=len(pts) - used, rms=float(np.sqrt(np.mean(d * d))), inliers=keep)


def trim_outliers(points: np.ndarray, *, k: float = 3.0, floor_px: float = 0.3,
                  rounds: int = 6) -> np.ndarray | Refusal:
    """Boolean mask of the points consistent with one ellipse: a median/MAD trimmed fit.

    Why before the Leitz criterion: Leitz judges residuals against their standard deviation,
    which a few dozen points on an occluder's edge inflate until nothing is rejected (the fit
    then bends towards them).  The median and the MAD are not moved by outliers up to half the
    points, so a partly occluded ring's own points decide.  Points may come back in a later
    round (each round judges all points against the current fit).  ``floor_px`` keeps a
    noise-free arc from trimming itself on rounding.
    """
    pts = _as_xy(points, MIN_FIT_POINTS)
    if isinstance(pts, Refusal):
        return pts
    got = _trim(pts, k, floor_px, rounds)
    return got if isinstance(got, Refusal) else got[0]


def _trim(pts: np.ndarray, k: float, floor_px: float, rounds: int
          ) -> tuple[np.ndarray, np.ndarray | None] | Refusal:
    """:func:`trim_outliers` of checked points, with the conic fitted to exactly the kept
    points when the rounds converged (None when they ran out first)."""
    keep = np.ones(len(pts), dtype=bool)
    for _ in range(rounds):
        C = _fit_conic_xy(pts[keep])
        if isinstance(C, Refusal):
            return C
        r = sampson_distance(C, pts)
        rk = r[keep]
        med = float(np.median(rk))
        mad = 1.4826 * float(np.median(np.abs(rk - med)))
        new = np.isfinite(r) & (np.abs(r - med) <= max(k * mad, floor_px))
        if new.sum() < MIN_FIT_POINTS:
            return Refusal(f"only {int(new.sum())} points agree on one ellipse")
        if np.array_equal(new, keep):
            return keep, C
        keep = new
    return keep, None


def fit_trimmed(points: np.ndarray, *, floor_px: float = 0.3, leitz: bool = True,
                residual: str = "sampson") -> tuple[np.ndarray, Ellipse] | Refusal:
    """``trim_outliers`` then ``fit_ellipse`` of the kept points: the same mask and ellipse,
    bit for bit, without fitting the kept points twice (the trim's last round already did).

    Returns the trim's mask and the ellipse, whose ``inliers`` index the kept points.
    """
    if residual not in RESIDUALS:
        raise ValueError(f"residual must be one of {RESIDUALS}, got {residual!r}")
    pts = _as_xy(points, MIN_FIT_POINTS)
    if isinstance(pts, Refusal):
        return pts
    got = _trim(pts, 3.0, floor_px, 6)
    if isinstance(got, Refusal):
        return got
    keep, C = got
    kept = pts[keep]
    e = _leitz(kept, _fit_conic_xy(kept) if C is None else C, leitz, residual, 3.0, 10,
               MIN_FIT_POINTS)
    return e if isinstance(e, Refusal) else (keep, e)
