"""Projected circle centres: true conics from 3D circles through a known camera.

A circle of radius r in the plane z = 0 of the marker frame, seen with pose (R, t), has the image
conic ``C = H^-T diag(1, 1, -r^2) H^-1`` with ``H = K [r1 r2 t]``; its centre projects to ``K t``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from stationd.result import Refusal
from stationd.vision import centre as cm
from stationd.vision.ellipse import conic_to_params, fit_ellipse
from stationd.vision.types import Ellipse

K = np.array([[5000.0, 0.0, 2736.0], [0.0, 5000.0, 1824.0], [0.0, 0.0, 1.0]])
R_IN, R_OUT = 10.0, 15.0


def angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    return math.degrees(math.atan2(np.linalg.norm(np.cross(u, v)), float(np.dot(u, v))))


def rotate(v: np.ndarray, axis: np.ndarray, theta: float) -> np.ndarray:
    """Rodrigues' rotation of v about the unit axis."""
    return np.asarray(v * math.cos(theta) + np.cross(axis, v) * math.sin(theta)
                      + axis * (axis @ v) * (1.0 - math.cos(theta)))


def pose(rng: np.random.Generator, dist: float, tilt_deg: float,
         pixel: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Marker pose: centre at ``dist`` mm along the ray of a random pixel, normal tilted by
    ``tilt_deg`` from the line of sight (towards the camera), random in-plane rotation."""
    px = rng.uniform([300.0, 300.0], [5172.0, 3348.0]) if pixel is None else np.asarray(pixel)
    d = np.linalg.solve(K, np.append(px, 1.0))
    d /= np.linalg.norm(d)
    axis = np.cross(d, rng.normal(size=3))
    axis /= np.linalg.norm(axis)
    n = rotate(-d, axis, math.radians(tilt_deg))
    r1 = np.cross(rng.normal(size=3), n)
    r1 /= np.linalg.norm(r1)
    return np.column_stack([r1, np.cross(n, r1), n]), dist * d


def conic(R: np.ndarray, t: np.ndarray, r: float, Kc: np.ndarray = K) -> np.ndarray:
    H = Kc @ np.column_stack([R[:, 0], R[:, 1], t])
    Hi = np.linalg.inv(H)
    C = Hi.T @ np.diag([1.0, 1.0, -r * r]) @ Hi
    return np.asarray(C / np.linalg.norm(C))


def project(X: np.ndarray, Kc: np.ndarray = K) -> np.ndarray:
    x = Kc @ X
    return np.asarray(x[:2] / x[2])


def circle_points(R: np.ndarray, t: np.ndarray, r: float, n: int,
                  Kc: np.ndarray = K) -> np.ndarray:
    phi = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    X = t[:, None] + R[:, :2] @ np.vstack([r * np.cos(phi), r * np.sin(phi)])
    x = Kc @ X
    return np.asarray((x[:2] / x[2]).T)


def poses(seed: int, count: int, dist: tuple[float, float] = (400.0, 2000.0),
          tilt: tuple[float, float] = (0.0, 65.0)) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    return [pose(rng, rng.uniform(*dist), rng.uniform(*tilt)) for _ in range(count)]


# -- normals and centres from exact conics -------------------------------------------------------

@pytest.mark.parametrize("radius", [R_IN, R_OUT])
def test_one_circle_normal_is_the_true_normal(radius):
    for R, t in poses(1, 150):
        cands = cm.circle_normals(conic(R, t, radius), K)
        assert min(angle_deg(c, R[:, 2]) for c in cands) < 1e-6
        for c in cands:
            assert np.linalg.norm(c) == pytest.approx(1.0)
            assert c @ t < 0.0  # facing the camera


def test_normals_coincide_fronto_parallel():
    R, t = pose(np.random.default_rng(2), 800.0, 0.0)
    a, b = cm.circle_normals(conic(R, t, R_IN), K)
    assert angle_deg(a, b) < 1e-5
    assert angle_deg(a, R[:, 2]) < 1e-5


def test_ellipse_centre_is_biased_by_r_squared():
    """At 450 mm and 30 deg the inner ellipse centre misses by ~1.3 px (median over the image
    and tilt directions), the outer by (15/10)^2 times that."""
    rng = np.random.default_rng(3)
    biases = []
    for _ in range(20):
        R, t = pose(rng, 450.0, 30.0)
        c = project(t)
        ci, co = (cm.ellipse_centre(conic(R, t, r)) for r in (R_IN, R_OUT))
        p = conic_to_params(conic(R, t, R_IN))
        assert not isinstance(p, Refusal)
        assert np.allclose(ci, p[0], atol=1e-8)
        bias_in, bias_out = np.linalg.norm(ci - c), np.linalg.norm(co - c)
        assert bias_out / bias_in == pytest.approx((R_OUT / R_IN) ** 2, rel=0.05)
        biases.append(bias_in)
    assert 0.9 < np.median(biases) < 1.8


def test_centre_from_true_normal_is_the_projected_centre():
    for R, t in poses(4, 200):
        for r in (R_IN, R_OUT):
            c = cm.centre_from_normal(conic(R, t, r), K, R[:, 2])
            assert np.linalg.norm(c - project(t)) < 1e-8


def test_wrong_normal_is_worse_than_no_correction():
    rng = np.random.default_rng(5)
    ratios = []
    for _ in range(20):
        R, t = pose(rng, 450.0, 30.0)
        C = conic(R, t, R_IN)
        wrong = max(cm.circle_normals(C, K), key=lambda n: angle_deg(n, R[:, 2]))
        err_wrong = np.linalg.norm(cm.centre_from_normal(C, K, wrong) - project(t))
        ratios.append(err_wrong / np.linalg.norm(cm.ellipse_centre(C) - project(t)))
    assert min(ratios) > 0.95 and np.median(ratios) > 1.4  # MARKER-MATH: about 1.6x


def test_concentric_centre_and_ratio():
    for R, t in poses(6, 200):
        c, ratio = cm.concentric_centre(conic(R, t, R_IN), conic(R, t, R_OUT))
        assert np.linalg.norm(c - project(t)) < 1e-8
        assert ratio == pytest.approx((R_IN / R_OUT) ** 2, abs=1e-8)


def test_concentric_ratio_flags_non_concentric_circles():
    rng = np.random.default_rng(7)
    for _ in range(10):
        R, t = pose(rng, 800.0, 40.0)
        t_in = t + 2.0 * R[:, 0]  # inner circle 2 mm off centre
        c, ratio = cm.concentric_centre(conic(R, t_in, R_IN), conic(R, t, R_OUT))
        assert not abs(ratio - 4.0 / 9.0) < 0.01
        assert min(np.linalg.norm(c - project(t)), np.linalg.norm(c - project(t_in))) > 1.0


def test_normal_from_centre_is_unique_and_true():
    for R, t in poses(8, 100):
        for r in (R_IN, R_OUT):
            n = cm.normal_from_centre(conic(R, t, r), K, project(t))
            assert angle_deg(n, R[:, 2]) < 1e-6


def test_circle_radius_3d_on_exact_points():
    for R, t in poses(9, 50):
        for r in (R_IN, R_OUT):
            pts = circle_points(R, t, r, 360)
            assert cm.circle_radius_3d(pts, K, t, R[:, 2]) == pytest.approx(r, abs=1e-9)


def test_circle_pose_recovers_the_3d_centre():
    for R, t in poses(10, 100):
        for r in (R_IN, R_OUT):
            X = cm.circle_pose(conic(R, t, r), K, r, R[:, 2])
            assert np.linalg.norm(X - t) < 1e-9 * np.linalg.norm(t)
            # the normal's sign does not matter
            assert np.allclose(cm.circle_pose(conic(R, t, r), K, r, -R[:, 2]), X)


# -- resolving the two normals -------------------------------------------------------------------

def test_mono_resolution_picks_the_true_normal_on_exact_conics():
    """Exact conics: the true normal makes both circles agree on the centre (a refusal is
    allowed only where the other candidate's split is under the noise gap)."""
    resolved = 0
    for R, t in poses(11, 100, tilt=(5.0, 65.0)):
        res = cm.resolve_normals_mono(conic(R, t, R_IN), conic(R, t, R_OUT), K)
        if isinstance(res, Refusal):
            assert "ambiguous" in res.reason
            continue
        assert res.split_px < 1e-6
        if not res.ambiguous:
            assert angle_deg(res.normal, R[:, 2]) < 1e-6
            resolved += 1
    assert resolved >= 60


def test_mono_resolution_refuses_rather_than_guess():
    """Where the two candidates cannot be told apart and give centres farther apart than the
    noise, the choice is refused; where it is accepted, the centre is right within the noise
    and a decisive normal is the true one."""
    rng = np.random.default_rng(12)
    wrong = 0
    for _ in range(40):
        R, t = pose(rng, 2000.0, 40.0)
        pin = circle_points(R, t, R_IN, 120) + rng.normal(0, 0.5, (120, 2))
        pout = circle_points(R, t, R_OUT, 180) + rng.normal(0, 0.5, (180, 2))
        ei, eo = fit_ellipse(pin), fit_ellipse(pout)
        assert isinstance(ei, Ellipse) and isinstance(eo, Ellipse)
        noise = math.hypot(0.5 * math.sqrt(2 / 120), 0.5 * math.sqrt(2 / 180))
        res = cm.resolve_normals_mono(ei.conic, eo.conic, K, noise_px=noise)
        if isinstance(res, Refusal):
            assert "ambiguous" in res.reason
            continue
        c = cm.centre_from_normal(ei.conic, K, res.normal)
        assert np.linalg.norm(c - project(t)) < 4 * noise
        if not res.ambiguous and angle_deg(res.normal, R[:, 2]) > 5.0:
            wrong += 1
    assert wrong == 0
    # noise-free conics far away: the false split is under the gap, the centres differ
    refused = 0
    for R, t in poses(21, 40, dist=(1800.0, 2000.0), tilt=(35.0, 65.0)):
        res = cm.resolve_normals_mono(conic(R, t, R_IN), conic(R, t, R_OUT), K, min_gap_px=0.5)
        if isinstance(res, Refusal):
            assert "ambiguous" in res.reason
            refused += 1
        else:
            assert angle_deg(res.normal, R[:, 2]) < 1e-6 or res.ambiguous
    assert refused > 0


def test_mono_resolution_accepts_fronto_parallel():
    rng = np.random.default_rng(13)
    for tilt in (0.0, 0.1):
        R, t = pose(rng, 900.0, tilt)
        res = cm.resolve_normals_mono(conic(R, t, R_IN), conic(R, t, R_OUT), K)
        assert not isinstance(res, Refusal), res
        assert angle_deg(res.normal, R[:, 2]) < 0.3


def stereo_rig(angle_deg_y: float = 12.0,
               baseline: float = 300.0) -> tuple[np.ndarray, np.ndarray]:
    """Right camera 300 mm to the right, turned towards the left one: x_r = Rs x_l + Ts."""
    a = math.radians(angle_deg_y)
    Rs = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0],
                   [-math.sin(a), 0.0, math.cos(a)]])
    return Rs, -Rs @ np.array([baseline, 0.0, 0.0])


def test_stereo_resolution_picks_the_true_normals():
    Rs, Ts = stereo_rig()
    rng = np.random.default_rng(14)
    done = 0
    while done < 40:
        R, t = pose(rng, rng.uniform(800.0, 2000.0), rng.uniform(10.0, 60.0))
        Rr, tr = Rs @ R, Rs @ t + Ts
        if project(tr)[0] < 0 or project(tr)[0] > 5472 or tr @ Rr[:, 2] > 0:
            continue  # outside the right image, or seen from behind
        left = cm.circle_normals(conic(R, t, R_IN), K)
        right = cm.circle_normals(conic(Rr, tr, R_IN), K)
        right_l = (Rs.T @ right[0], Rs.T @ right[1])  # the right normals in the left frame
        i = cm.choose_by_other_view(left, right_l)
        j = cm.choose_by_other_view(right_l, left)
        assert i is not None and j is not None
        assert angle_deg(left[i], R[:, 2]) < 1e-6 and angle_deg(right[j], Rr[:, 2]) < 1e-6
        assert angle_deg(left[i], right_l[j]) < 1e-6
        swapped_l = (right_l[1], right_l[0])
        assert cm.choose_by_other_view((left[1], left[0]), swapped_l) == 1 - i
        assert cm.choose_by_other_view(swapped_l, (left[1], left[0])) == 1 - j
        # the marker's radius back from both views, as in the paper's Table 1
        rl = cm.circle_radius_3d(circle_points(R, t, R_IN, 200), K, t, left[i])
        rr = cm.circle_radius_3d(circle_points(Rr, tr, R_IN, 200), K, Rs @ t + Ts, Rs @ left[i])
        assert rl == pytest.approx(R_IN, abs=1e-8) and rr == pytest.approx(R_IN, abs=1e-8)
        done += 1


def test_stereo_resolution_refuses_an_ambiguous_pair():
    Rs, _ = stereo_rig()
    n1, n2 = np.array([0.3, 0.0, -1.0]), np.array([-0.3, 0.1, -1.0])
    n1, n2 = n1 / np.linalg.norm(n1), n2 / np.linalg.norm(n2)
    # both pairs agree: neither view can tell its true normal from the other
    assert cm.choose_by_other_view((n1, n2), (n1, n2)) is None
    assert cm.choose_by_other_view((n1, n2), (Rs.T @ Rs @ n1, Rs.T @ Rs @ n2)) is None


def test_stereo_fronto_parallel_side_is_no_ambiguity():
    Rs, _ = stereo_rig()
    n = np.array([0.0, 0.0, -1.0])
    m = np.array([0.5, 0.0, -1.0]) / math.hypot(0.5, 1.0)
    right_l = (Rs.T @ (Rs @ m), Rs.T @ (Rs @ n))
    assert cm.choose_by_other_view((n, n), right_l) is None  # head-on: nothing to choose
    assert cm.choose_by_other_view(right_l, (n, n)) == 1     # the other view decides
    assert cm.choose_by_other_view((n, n), (n, n)) is None   # both head-on: stereo falls back


# -- noisy edge points: the end-to-end figure ----------------------------------------------------

def fit(points: np.ndarray) -> np.ndarray:
    e = fit_ellipse(points)
    assert isinstance(e, Ellipse), e
    return e.conic


def test_centre_from_noisy_fits_beats_the_ellipse_centre():
    rng = np.random.default_rng(15)
    R, t = pose(rng, 450.0, 30.0, pixel=(2900.0, 2000.0))
    c_true = project(t)
    errs: list[list[float]] = []
    for _ in range(10):
        Ci = fit(circle_points(R, t, R_IN, 600) + rng.normal(0.0, 0.2, (600, 2)))
        Co = fit(circle_points(R, t, R_OUT, 900) + rng.normal(0.0, 0.2, (900, 2)))
        c, ratio = cm.concentric_centre(Ci, Co)
        assert ratio == pytest.approx(4.0 / 9.0, rel=0.02)
        n = cm.normal_from_centre(Ci, K, c)
        errs.append([float(np.linalg.norm(c - c_true)),
                     float(np.linalg.norm(cm.ellipse_centre(Ci) - c_true)),
                     angle_deg(n, R[:, 2]),
                     float(np.linalg.norm(cm.centre_from_normal(Ci, K, R[:, 2]) - c_true))])
    e = np.mean(errs, axis=0)
    assert e[0] < 0.05 and e[1] > 0.7  # concentric eigenvector vs. biased ellipse centre
    assert e[2] < 2.0  # degrees
    assert e[3] < 0.05  # pole correction with the right normal


# -- bad input: NaN or Refusal, never an exception ----------------------------------------------

BAD = [np.full((3, 3), np.nan), np.diag([1.0, -1.0, -1.0]), np.diag([1.0, 1.0, 1.0]),
       np.zeros((3, 3))]


@pytest.mark.parametrize("C", BAD)
def test_bad_conics_give_nan_or_refusal(C):
    R, t = pose(np.random.default_rng(16), 600.0, 20.0)
    good = conic(R, t, R_OUT)
    assert np.isnan(cm.ellipse_centre(C)).all()
    assert all(np.isnan(n).all() for n in cm.circle_normals(C, K))
    assert np.isnan(cm.centre_from_normal(C, K, R[:, 2])).all()
    assert np.isnan(cm.normal_from_centre(C, K, project(t))).all()
    assert np.isnan(cm.circle_pose(C, K, 10.0, R[:, 2])).all()
    for a, b in ((C, good), (good, C)):
        c, ratio = cm.concentric_centre(a, b)
        assert math.isnan(ratio) and np.isnan(c).all()
        assert isinstance(cm.resolve_normals_mono(a, b, K), Refusal)


def test_bad_vectors_give_nan_or_refusal():
    R, t = pose(np.random.default_rng(17), 600.0, 20.0)
    C = conic(R, t, R_IN)
    nan3 = np.full(3, np.nan)
    assert np.isnan(cm.centre_from_normal(C, K, nan3)).all()
    assert np.isnan(cm.normal_from_centre(C, K, np.full(2, np.nan))).all()
    assert math.isnan(cm.circle_radius_3d(np.full((5, 2), np.nan), K, t, R[:, 2]))
    assert math.isnan(cm.circle_radius_3d(np.zeros((0, 2)), K, t, R[:, 2]))
    assert math.isnan(cm.circle_radius_3d(circle_points(R, t, R_IN, 9), K, t, nan3))
    assert np.isnan(cm.circle_pose(C, K, -1.0, R[:, 2])).all()
    n = R[:, 2]
    assert cm.choose_by_other_view((n, nan3), (n, n)) is None
