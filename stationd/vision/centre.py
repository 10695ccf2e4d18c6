"""The projected centre of a circle from its image conic (paper section 3, MARKER-MATH.md).

Why not the ellipse centre: it is the pole of the image line at infinity, while the image of
the circle's centre is the pole of the plane's vanishing line; they differ by up to a few pixels
at the station's tilts.  Two corrections are offered:

- from a plane normal (the paper): the cone ``Q = K^T C K`` gives two candidate normals, one of
  them true; picking the wrong one is worse than no correction, so the choice is made only with
  a margin (two concentric circles, or the other view of the pair), otherwise refused;
- from the two concentric circles (Kim, Gurdjos, Kweon 2005): the pencil ``C_out^-1 C_in`` has the
  centre as the eigenvector of its simple eigenvalue; no calibration, no ambiguity.

Every computation runs in a frame centred on the ellipse and scaled by its size: a pixel conic
at u ~ 3000 px spans seven orders of magnitude and loses digits in inversions.  Functions whose
result is an array return NaNs on a degenerate conic (callers gate on ``np.isfinite``); the
resolvers return a ``Refusal``.  Nothing here raises on bad data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stationd.result import Refusal

Pair = tuple[np.ndarray, np.ndarray]
_NAN2 = np.full(2, np.nan)
_NAN3 = np.full(3, np.nan)
_IMAG_TOL = 0.05  # |Im| of the double eigenvalue relative to it still counted as noise


def _frame(C: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """``(C', Tinv)`` with ``C' = Tinv^T C Tinv`` close to a unit circle, ``x = Tinv x'``.

    None unless ``C`` is a finite real ellipse.  ``C'`` is signed inside negative.
    """
    C = np.asarray(C, dtype=np.float64)
    if C.shape != (3, 3) or not np.all(np.isfinite(C)):
        return None
    C = 0.5 * (C + C.T)
    if C[0, 0] + C[1, 1] < 0.0:
        C = -C
    det2 = C[0, 0] * C[1, 1] - C[0, 1] ** 2
    if not det2 > 0.0:
        return None
    c = np.linalg.solve(C[:2, :2], -C[:2, 2])
    f0 = float(c @ C[:2, 2] + C[2, 2])
    if not f0 < 0.0:
        return None
    s = math.sqrt(-f0 / math.sqrt(det2))  # sqrt(a b)
    Tinv = np.array([[s, 0.0, c[0]], [0.0, s, c[1]], [0.0, 0.0, 1.0]])
    Cp = Tinv.T @ C @ Tinv
    return Cp / np.linalg.norm(Cp), Tinv


def _dehom(x: np.ndarray) -> np.ndarray:
    if not (np.all(np.isfinite(x)) and abs(x[2]) > 1e-12 * np.linalg.norm(x)):
        return _NAN2.copy()
    return np.asarray(x[:2] / x[2])


def _unit_facing(n: np.ndarray, ray: np.ndarray) -> np.ndarray:
    """Unit normal facing the camera: ``n . ray < 0`` for the viewing ray of a point on the
    circle (the same as ``n_z < 0`` except at grazing off-axis views, where ``n_z`` is wrong)."""
    norm = float(np.linalg.norm(n))
    if not (np.isfinite(norm) and norm > 0.0):
        return _NAN3.copy()
    n = n / norm
    return -n if float(n @ ray) > 0.0 else n


def _angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    """Angle between two vectors; atan2 keeps precision at 1e-9 rad where arccos loses it."""
    # the cross product written out: np.cross's axis handling costs ~17 us for 3 numbers,
    # and these angles are taken eight times per stereo pair on the serial path (same bits)
    w = np.array([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                  u[0] * v[1] - u[1] * v[0]])
    return math.degrees(math.atan2(float(np.linalg.norm(w)), float(u @ v)))


def ellipse_centre(C: np.ndarray) -> np.ndarray:
    """Centre of the image ellipse, the pole of the line at infinity: the *biased* estimate."""
    fr = _frame(C)
    return _NAN2.copy() if fr is None else np.array(fr[1][:2, 2])


def circle_normals(C: np.ndarray, K: np.ndarray) -> Pair:
    """The two unit normals of the planes that cut the cone ``K^T C K`` in a circle.

    One is the marker's.  Both face the camera.  At zero tilt they coincide, which is no
    ambiguity: either gives the same centre.  NaN vectors for a non-ellipse.
    """
    fr = _frame(C)
    if fr is None:
        return _NAN3.copy(), _NAN3.copy()
    Cp, Tinv = fr
    Kp = np.linalg.solve(Tinv, np.asarray(K, dtype=np.float64))  # x' = Tinv^-1 K X
    Q = Kp.T @ Cp @ Kp
    lam, E = np.linalg.eigh(Q / np.linalg.norm(Q))
    if np.sum(lam > 0.0) == 1:  # signature (+, -, -): negate to (+, +, -)
        lam, E = -lam[::-1], E[:, ::-1]
    l3, l2, l1 = lam  # ascending from eigh
    if not (l1 >= l2 > 0.0 > l3):
        return _NAN3.copy(), _NAN3.copy()
    a = math.sqrt(max(l1 - l2, 0.0) / (l1 - l3))
    b = math.sqrt((l2 - l3) / (l1 - l3))
    ray = np.linalg.solve(K, np.append(Tinv[:2, 2], 1.0))  # through the ellipse centre
    return (_unit_facing(a * E[:, 2] + b * E[:, 0], ray),
            _unit_facing(a * E[:, 2] - b * E[:, 0], ray))


def centre_from_normal(C: np.ndarray, K: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Projected circle centre ``c ~ C^-1 K^-T n``: the pole of the plane's vanishing line."""
    fr = _frame(C)
    if fr is None or not np.all(np.isfinite(n)):
        return _NAN2.copy()
    Cp, Tinv = fr
    L = np.linalg.solve(np.asarray(K, dtype=np.float64).T, np.asarray(n, dtype=np.float64))
    return _dehom(Tinv @ np.linalg.solve(Cp, Tinv.T @ L))


def concentric_centre(C_in: np.ndarray, C_out: np.ndarray) -> tuple[np.ndarray, float]:
    """Projected centre of two concentric circles and the pencil's eigenvalue ratio.

    ``M = C_out^-1 C_in`` has a double eigenvalue and a simple one whose eigenvector is the
    centre.  The ratio simple/double equals ``(r_in/r_out)^2`` for two concentric circles: the
    check that the two ellipses really are the marker's.  Noise may split the double eigenvalue
    into a complex pair; its mean stays real.  The ratio is NaN when the pair's imaginary parts
    exceed 5 % of it (no pencil structure); centre and ratio are NaN for non-ellipses.
    """
    fr_out = _frame(C_out)
    fr_in = _frame(C_in)
    if fr_out is None or fr_in is None:
        return _NAN2.copy(), math.nan
    Co, Tinv = fr_out
    Ci = Tinv.T @ np.asarray(C_in, dtype=np.float64) @ Tinv
    Ci = Ci / np.linalg.norm(Ci)
    if Ci[0, 0] + Ci[1, 1] < 0.0:
        Ci = -Ci
    w, V = np.linalg.eig(np.linalg.solve(Co, Ci))
    pairs = ((1, 2), (0, 2), (0, 1))
    k = int(np.argmin([abs(w[j] - w[m]) for j, m in pairs]))
    j, m = pairs[k]
    simple = w[k]
    double = 0.5 * (w[j] + w[m])
    tol = 1e-9 * float(np.max(np.abs(w)))
    centre = _dehom(Tinv @ V[:, k].real) if abs(simple.imag) <= tol else _NAN2.copy()
    noisy = max(abs(w[j].imag), abs(w[m].imag)) > _IMAG_TOL * abs(double)
    if noisy or abs(simple.imag) > tol or double.real == 0.0:
        return centre, math.nan
    return centre, float(simple.real / double.real)


def normal_from_centre(C: np.ndarray, K: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Unique plane normal from a known projected centre: the polar ``l = C [c, 1]`` is the
    vanishing line and ``n ~ K^T l``.  Unit, facing the camera; NaN for a non-ellipse."""
    fr = _frame(C)
    if fr is None or not np.all(np.isfinite(c)):
        return _NAN3.copy()
    Cp, Tinv = fr
    x = np.append(np.asarray(c, dtype=np.float64), 1.0)
    lp = Cp @ np.linalg.solve(Tinv, x)
    Kp = np.linalg.solve(Tinv, np.asarray(K, dtype=np.float64))
    return _unit_facing(Kp.T @ lp, np.linalg.solve(K, x))


def _finite(*vs: np.ndarray) -> bool:
    return all(np.all(np.isfinite(v)) for v in vs)


@dataclass(frozen=True, eq=False)
class MonoNormal:
    """The normal chosen in one image, and how sure the choice is.

    ``split_px``: distance between the inner- and outer-circle centres for the chosen normal
    (noise only, when right); ``other_split_px``: the same for the other candidate;
    ``ambiguous``: the two could not be told apart, but both give the same centre to within
    the tolerance, so the *centre* is safe and only the normal is undecided (stereo decides).
    """

    normal: np.ndarray
    candidates: Pair
    index: int
    split_px: float
    other_split_px: float
    ambiguous: bool


def resolve_normals_mono(C_in: np.ndarray, C_out: np.ndarray, K: np.ndarray, *,
                         noise_px: float = 0.0, min_gap_px: float = 0.1,
                         same_centre_px: float = 0.02) -> MonoNormal | Refusal:
    """Choose the inner circle's true normal in one image by the concentric constraint.

    The angle between the cones' candidates cannot do it: the false normals of two concentric
    circles differ by only ~0.001-0.02 deg.  The centres can: for the true normal the poles of
    the vanishing line in both conics are the same point (up to noise), for the false one they
    are a few tenths of the ellipse-centre bias apart.  ``noise_px`` is the standard deviation
    of the split expected from the fits' noise.  Decisive when the other candidate's split
    exceeds the chosen one's by ``min_gap_px``, by 4 ``noise_px`` and by a factor of 2;
    otherwise refused, unless both candidates put the centre within ``same_centre_px`` or twice
    the noise (then the choice is moot for the centre: the bisector is returned and the normal
    is reported as ``ambiguous``).
    """
    A = circle_normals(C_in, K)
    if not _finite(*A):
        return Refusal("a conic is not a real ellipse: no plane normals")
    c_in = [centre_from_normal(C_in, K, n) for n in A]
    c_out = [centre_from_normal(C_out, K, n) for n in A]
    if not _finite(*c_in, *c_out):
        return Refusal("a conic is not a real ellipse: no projected centre")
    splits = [float(np.linalg.norm(c_in[k] - c_out[k])) for k in (0, 1)]
    i = int(np.argmin(splits))
    best, other = splits[i], splits[1 - i]
    decisive = other - best > max(min_gap_px, 4.0 * noise_px, best)
    spread = float(np.linalg.norm(c_in[0] - c_in[1]))
    if not decisive and spread > max(same_centre_px, 2.0 * noise_px):
        return Refusal(f"normal ambiguous: centre split {best:.3f} px vs {other:.3f} px for "
                       f"the other candidate, and their centres differ by {spread:.3f} px")
    if not decisive:
        # Near a line-of-sight view both candidates hug the cone's axis; their bisector puts
        # the centre within half their (noise-sized) difference of either.
        n = (A[0] + A[1]) / np.linalg.norm(A[0] + A[1])
        return MonoNormal(n, A, i, best, other, ambiguous=True)
    B = circle_normals(C_out, K)
    n = A[i]
    if _finite(*B):  # the outer cone's matching candidate halves the noise of the normal
        j = int(np.argmin([_angle_deg(A[i], b) for b in B]))
        n = (A[i] + B[j]) / np.linalg.norm(A[i] + B[j])
    return MonoNormal(n, A, i, best, other, ambiguous=False)


def choose_by_other_view(own: Pair, other: Pair, *,
                         min_margin_deg: float = 1.0) -> int | None:
    """The paper's Eq. 16 for one view: the index of ``own``'s candidate that the other view
    confirms (the smaller angle to either of ``other``'s candidates, both pairs in one frame:
    a right normal is ``R^T n`` in the left frame).  None when the other candidate is nearly as
    close (a view seeing the marker head-on has two candidates hugging the cone axis and cannot
    choose; the other view usually can) or a candidate is not finite: never a guess."""
    if not _finite(*own, *other):
        return None
    d = [min(_angle_deg(a, b) for b in other) for a in own]
    i = int(np.argmin(d))
    return None if d[1 - i] - d[i] < min_margin_deg else i


def circle_radius_3d(points_undist: np.ndarray, K: np.ndarray, centre_3d: np.ndarray,
                     n: np.ndarray) -> float:
    """Mean distance to ``centre_3d`` of the edge points back-projected onto the marker plane
    (the paper's Table 1 radius): a metric check of the whole chain.  NaN when degenerate."""
    pts = np.asarray(points_undist, dtype=np.float64).reshape(-1, 2)
    X0 = np.asarray(centre_3d, dtype=np.float64)
    nn = np.asarray(n, dtype=np.float64)
    if len(pts) == 0 or not _finite(pts, K, X0, nn):
        return math.nan
    rays = np.linalg.solve(np.asarray(K, dtype=np.float64),
                           np.vstack([pts.T, np.ones(len(pts))])).T
    den = rays @ nn
    if np.any(np.abs(den) < 1e-12 * np.linalg.norm(nn) * np.linalg.norm(rays, axis=1)):
        return math.nan  # a ray parallel to the plane
    X = rays * ((X0 @ nn) / den)[:, None]
    return float(np.mean(np.linalg.norm(X - X0, axis=1)))


def circle_pose(C: np.ndarray, K: np.ndarray, radius: float, n: np.ndarray) -> np.ndarray:
    """3D centre (camera frame, units of ``radius``) of a circle of known radius and normal.

    The centre lies on the ray ``K^-1 c`` (``c`` from ``centre_from_normal``); cutting the cone
    with the plane ``n . X = -1`` gives a section of radius ``rho``, and the cone scales
    linearly, so the true plane is ``radius / rho`` times farther.  With a slightly wrong normal
    the section is an ellipse and ``rho`` its geometric-mean radius.  NaN when degenerate.
    """
    fr = _frame(C)
    if fr is None or not (_finite(n) and radius > 0.0):
        return _NAN3.copy()
    K = np.asarray(K, dtype=np.float64)
    c = centre_from_normal(C, K, n)
    if not _finite(c):
        return _NAN3.copy()
    ray = np.linalg.solve(K, np.append(c, 1.0))
    nn = _unit_facing(np.asarray(n, dtype=np.float64), ray)
    X0 = ray / -(nn @ ray)  # on n . X = -1
    u1 = np.cross(nn, [1.0, 0.0, 0.0] if abs(nn[0]) < 0.9 else [0.0, 1.0, 0.0])
    u1 /= np.linalg.norm(u1)
    u2 = np.cross(nn, u1)
    Cp, Tinv = fr
    Kp = np.linalg.solve(Tinv, K)
    B = Kp @ np.column_stack([u1, u2, X0])  # plane coordinates (s, t, 1) -> x'
    G = B.T @ Cp @ B
    det2 = G[0, 0] * G[1, 1] - G[0, 1] ** 2
    if not det2 > 0.0:
        return _NAN3.copy()
    f0 = np.linalg.det(G) / det2  # section conic's value at its centre
    rho2 = -f0 * np.sign(G[0, 0]) / math.sqrt(det2)
    if not rho2 > 0.0:
        return _NAN3.copy()
    return np.asarray(X0 * (radius / math.sqrt(rho2)))
