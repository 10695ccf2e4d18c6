"""Retinex (V) and saturation stretch, and the reduced-resolution surround against a reference."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from stationd.errors import ConfigError
from stationd.vision.enhance import (
    EnhanceParams,
    enhance_hsv,
    log_reflectance,
    stretch_reflectance,
    stretch_saturation,
)
from stationd.vision.marker import PURPLE_RGB
from stationd.vision.segment import DEFAULT_HSV, purple_mask
from stationd.yamlio import YamlNode
from tests.vision.test_segment import Marker, Patch, render

P = EnhanceParams()


def test_params_from_yaml():
    node = YamlNode.parse("sigmas_px: [20, 100, 300]\nsigma_r: 0.8\ns_percentiles: [2, 99]\n")
    p = EnhanceParams.from_node(node)
    assert p.sigmas_px == (20.0, 100.0, 300.0) and p.sigma_r == 0.8
    assert p.s_percentiles == (2.0, 99.0) and p.work_sigma_px == P.work_sigma_px
    with pytest.raises(ConfigError, match="unknown key"):
        EnhanceParams.from_node(YamlNode.parse("sigma: 3\n"))
    with pytest.raises(ConfigError, match="v_percentiles must satisfy"):
        EnhanceParams.from_node(YamlNode.parse("v_percentiles: [99, 1]\n"))


def test_enhance_keeps_hue_and_checks_input():
    hsv = cv2.cvtColor(render([Marker(2000, 1500, 40)], light=(1.0, 0.2), noise=2.0),
                       cv2.COLOR_BGR2HSV)
    out = enhance_hsv(hsv, P, 8)
    assert out.dtype == np.uint8 and out.shape == hsv.shape
    assert np.array_equal(out[..., 0], hsv[..., 0])
    with pytest.raises(ValueError, match="uint8 HxWx3"):
        enhance_hsv(hsv[..., 2], P, 8)


def test_retinex_removes_the_illumination_gradient():
    """The same purple print at 100 % and at 10 % light comes out with the same enhanced V."""
    img = render([], [Patch(100, 1500, 500, 1900, PURPLE_RGB),
                      Patch(5050, 1500, 5450, 1900, PURPLE_RGB)], light=(1.0, 0.1), noise=1.0)
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    v, ve = hsv[..., 2], enhance_hsv(hsv, P, 8)[..., 2]
    bright, dark = np.s_[190:235, 15:60], np.s_[190:235, 635:680]
    assert np.median(v[bright]) > 7 * np.median(v[dark])  # raw: ~8x apart
    assert abs(float(np.median(ve[bright])) - float(np.median(ve[dark]))) <= 12
    assert np.median(ve[dark]) > DEFAULT_HSV.v[0] + 40


def test_saturation_stretch_is_bounded():
    """Eq. 4 with robust end points; the gain is capped, so a grey scene is not made colourful."""
    rng = np.random.default_rng(0)
    greyish = rng.integers(0, 40, (100, 100), dtype=np.uint8)
    out = stretch_saturation(greyish, P)
    assert out.max() <= math.ceil(39 * P.s_max_gain) + 1
    colourful = rng.integers(0, 256, (100, 100), dtype=np.uint8)
    out = stretch_saturation(colourful, P).astype(int)
    s = colourful.astype(int)
    assert np.all(out >= s - P.s_max_lo - 1) and np.all(out <= s + 3)
    hazy = rng.integers(60, 181, (100, 100), dtype=np.uint8)  # a washed-out, low-light frame
    out = stretch_saturation(hazy, P).astype(int)
    assert np.array_equal(out, np.floor((hazy - P.s_max_lo) * P.s_max_gain + 0.5))
    free = EnhanceParams(s_percentiles=(0.0, 100.0), s_max_gain=100.0, s_max_lo=127.0)
    out = stretch_saturation(hazy, free).astype(int)  # Eq. 4 proper: [L, H] -> [0, 255]
    assert np.array_equal(out, np.floor((hazy - 60.0) * 255.0 / 120.0 + 0.5))


def test_spatial_scales_mean_full_resolution_pixels():
    """The same scene reduced by 4 (scale=4) and by 8 (scale=8) gives the same enhancement."""
    mk = Marker(2500, 1800, 60)
    v4, v8 = (enhance_hsv(cv2.cvtColor(render([mk], scale=k, light=(1.0, 0.1), noise=1.0,
                                              seed=3), cv2.COLOR_BGR2HSV), P, k)[..., 2]
              for k in (4, 8))
    v4to8 = cv2.resize(v4, (v8.shape[1], v8.shape[0]), interpolation=cv2.INTER_AREA)
    d = np.abs(v4to8.astype(int) - v8)
    assert np.percentile(d, 50) <= 4 and np.percentile(d, 90) <= 12


# -- the reduced-resolution surround against a full-resolution reference ---------------------
def _reflect101(i: np.ndarray, n: int) -> np.ndarray:
    period = 2 * (n - 1)
    i = np.mod(i, period)
    return np.where(i < n, i, period - i)


def _blur_matrix(n: int, sigma: float, rows: np.ndarray) -> np.ndarray:
    """Exact (untruncated) Gaussian weights, output ``rows`` x input ``n``, with OpenCV's
    default border (reflect-101) folded in."""
    src = np.arange(-n + 1, 2 * n - 1)
    g = np.exp(-0.5 * ((rows[:, None] - src[None, :]) / sigma) ** 2)
    m = np.zeros((n, len(rows)))
    np.add.at(m, _reflect101(src, n), g.T)
    m = np.ascontiguousarray(m.T, dtype=np.float32)
    # weights below float32's smallest normal (beyond ~13 sigma) set to 0: they change no
    # sum (the products are bit-identical), but subnormal operands and the subnormal partial
    # products they make take the CPU's slow path in every matrix product (3x the CPU)
    m[m < np.finfo(np.float32).tiny] = 0.0
    return m


def reference_surround(lv: np.ndarray, sigma: float, sigma_r: float, stride: int,
                       step: float = 0.4) -> np.ndarray:
    """Full-resolution bilateral filter of ``lv``, evaluated on every ``stride``-th pixel.

    Exact Gaussian spatial kernel over the whole image (matrix products, no reduction, no
    truncation); the range kernel is sampled at levels ``step * sigma_r`` apart and
    interpolated linearly (Durand & Dorsey 2002) -- checked against ``cv2.bilateralFilter``
    below.  Slow (seconds), which is the point: it is what the fast path approximates.
    """
    h, w = lv.shape
    gy = _blur_matrix(h, sigma, np.arange(0, h, stride))
    gx = _blur_matrix(w, sigma, np.arange(0, w, stride))
    lo, hi = float(lv.min()), float(lv.max())
    d = step * sigma_r
    levels = lo + d * np.arange(math.ceil((hi - lo) / d) + 2)
    out_lv = lv[::stride, ::stride]
    result = np.zeros(out_lv.shape, np.float64)
    pos = (out_lv - lo) / d
    for k, level in enumerate(levels):
        t = 1.0 - np.abs(pos - k)  # hat weight of this level at each output pixel
        if not np.any(t > 0):
            continue
        wk = np.exp(-0.5 * ((lv - level) / sigma_r) ** 2).astype(np.float32)
        num, den = gy @ (np.stack([wk * lv, wk]) @ gx.T)
        result += np.where(t > 0, t, 0.0) * num / den
    return result.astype(np.float32)


def test_reference_bilateral_matches_opencv():
    lv = np.log1p(cv2.cvtColor(render([Marker(600, 400, 60)], scale=1, full=(456, 304),
                                      light=(1.0, 0.1), noise=2.0), cv2.COLOR_BGR2HSV)[..., 2]
                  .astype(np.float32))
    ref = reference_surround(lv, 6.0, 1.0, stride=1)
    direct = cv2.bilateralFilter(lv, 6 * 6 + 1, 1.0, 6.0)  # window to 3 sigma: ~exact
    assert np.percentile(np.abs(ref - direct), 99) < 0.01


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    union = int(np.count_nonzero((a > 0) | (b > 0)))
    return int(np.count_nonzero((a > 0) & (b > 0))) / max(1, union)


def test_reduced_surround_matches_full_resolution_reference():
    """1368x912 frame, light falling to 10 %, markers in the half-light and in the dark.

    Reference: log-reflectance with the three bilateral surrounds computed at full resolution
    (exact Gaussian, every other pixel evaluated).  Fast: ``log_reflectance`` on the same
    frame (surrounds on reduced copies) and, as the detector runs it, ``enhance_hsv`` on the
    frame reduced by 8 with ``scale=8``.  Same rescaling and the default HSV box for both.

    Tolerance: purple masks IoU >= 0.95 (on the 171x114 image against the reference sampled
    at its pixel centres); enhanced V within 12 levels (5 %) at 95 % of the pixels outside
    the ring/disk holes.  Inside them (structure smaller than the reduced grid)
    V differs by up to ~60, but those pixels are black or white, non-purple in both.
    """
    full = (1368, 912)
    mks = [Marker(700, 450, 60, rot_deg=15), Marker(1150, 250, 40), Marker(1150, 700, 50)]
    img = render(mks, [Patch(100, 700, 500, 760, PURPLE_RGB)], scale=1, full=full,
                 light=(1.0, 0.1), noise=1.0, seed=11)
    hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
    lv = np.log1p(hsv[..., 2].astype(np.float32))
    s = 2
    r_ref = np.mean([lv[::s, ::s] - reference_surround(lv, sg, P.sigma_r, s)
                     for sg in P.sigmas_px], axis=0).astype(np.float32)
    r_fast = log_reflectance(hsv[..., 2], P, 1.0)[::s, ::s]
    sat = stretch_saturation(hsv[..., 1], P)[::s, ::s]
    ref = np.dstack([hsv[::s, ::s, 0], sat, stretch_reflectance(r_ref, P)])
    fast = np.dstack([hsv[::s, ::s, 0], sat, stretch_reflectance(r_fast, P)])
    m_ref, m_fast = purple_mask(ref, DEFAULT_HSV), purple_mask(fast, DEFAULT_HSV)
    assert _iou(m_ref, m_fast) >= 0.95, _iou(m_ref, m_fast)
    h, w = m_ref.shape
    X, Y = np.arange(w) * s, np.arange(h) * s
    holes = np.zeros((h, w), bool)
    for m in mks:
        holes |= np.hypot(X[None, :] - m.cx, Y[:, None] - m.cy) <= m.r + 2 * s
    dv = np.abs(ref[..., 2].astype(int) - fast[..., 2])
    assert np.percentile(dv[~holes], 95) <= 12 and np.median(dv) <= 3, \
        np.percentile(dv[~holes], [50, 95, 99])
    # the detector's own path: the frame reduced by 8, enhanced with scale=8
    small = cv2.resize(img, (full[0] // 8, full[1] // 8), interpolation=cv2.INTER_LINEAR)
    e8 = enhance_hsv(cv2.cvtColor(small, cv2.COLOR_BGR2HSV), P, 8)
    m8 = purple_mask(e8, DEFAULT_HSV)
    ref8 = m_ref[2::4, 2::4]  # the reference at the small pixels' centres, 8x + 3.5 (+0.5)
    assert ref8.shape == m8.shape and _iou(ref8, m8) >= 0.95, _iou(ref8, m8)
    # and without enhancement the same frame loses most of the dark purple
    assert _iou(m_ref, purple_mask(hsv[::s, ::s], DEFAULT_HSV)) < 0.8
