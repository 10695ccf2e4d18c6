"""Sub-pixel edges on an analytic blurred disk: the exact edge is known in closed form."""

import math

import cv2
import numpy as np
import pytest

from stationd.vision.edges import GRADIENT_SIGMA, remove_impulses, subpixel

_erfc = np.vectorize(math.erfc)


def _disk(R, cx, cy, size=160, blur=0.8, noise=0.0, seed=0):
    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    s = math.hypot(blur, math.sqrt(1 / 12))  # blur and pixel box, as a Gaussian
    r = np.hypot(xx - cx, yy - cy)
    img = 20 + 220 * 0.5 * _erfc((r - R) / (math.sqrt(2) * s))
    img += np.random.default_rng(seed).normal(0, noise, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.float32)


def _edges(img):
    sm = cv2.GaussianBlur(img, (0, 0), GRADIENT_SIGMA)
    gx = cv2.Sobel(sm, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(sm, cv2.CV_32F, 0, 1, ksize=3)
    e = cv2.Canny(np.clip(np.rint(sm), 0, 255).astype(np.uint8), 50, 100, L2gradient=True)
    ys, xs = np.nonzero(e)
    return subpixel(cv2.magnitude(gx, gy), gx, gy, ys, xs)[0]


@pytest.mark.parametrize("R", [12.0, 25.0, 60.0])
def test_subpixel_points_lie_on_the_circle(R):
    cx, cy = 80.3, 79.7
    pts = _edges(_disk(R, cx, cy))
    d = np.hypot(pts[:, 0] - cx, pts[:, 1] - cy) - R
    # the only bias is the symmetric curvature shift of a blurred edge, -s^2 / 2R
    expected = -(0.8**2 + 1 / 12 + GRADIENT_SIGMA**2) / (2 * R)
    assert abs(d.mean() - expected) < 0.01
    assert d.std() < 0.01  # pixel-level Canny points scatter by ~0.35 px
    # the centre of a least-squares circle through the points is unbiased
    A = np.c_[2 * pts, np.ones(len(pts))]
    sol = np.linalg.lstsq(A, (pts**2).sum(axis=1), rcond=None)[0]
    assert np.hypot(sol[0] - cx, sol[1] - cy) < 0.005


def test_impulses_removed_clean_pixels_untouched():
    img = _disk(25.0, 80.0, 80.0)
    rng = np.random.default_rng(1)
    noisy = img.copy()
    ys, xs = rng.integers(2, 158, 200), rng.integers(2, 158, 200)
    noisy[ys, xs] = rng.choice([0.0, 255.0], 200)
    fixed = remove_impulses(noisy)
    touched = fixed != noisy
    hit = np.zeros_like(touched)
    hit[ys, xs] = True
    assert not (touched & ~hit).any()           # no clean pixel changed
    assert np.abs(fixed - img).max() < 60       # impulses gone (median of a clean area)
    assert (np.abs(fixed - img) > 30).sum() < 10
    assert np.array_equal(remove_impulses(img), img)  # a clean image is left as it is
