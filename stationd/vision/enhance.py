"""Image enhancement before colour segmentation (paper 2.2): bilateral multi-scale Retinex on V,
linear contrast stretch of S, H untouched.

Why: under the chassis the light falls to ~10 % at the edges, so a fixed V threshold either
loses the dark purple or accepts the bright chassis.  Retinex divides V by an estimate of the
illumination (the "surround"), which leaves the reflectance: the purple print has the same
enhanced V in the dark corner as under the lamp.  The paper's improvement is a *bilateral*
surround instead of a Gaussian one: a shadow edge of the vehicle body is kept in the
illumination estimate, so it does not leave a halo in the reflectance.

Speed (PROTOCOLS.md: one full-resolution bilateral costs ~200 ms): everything here runs on the
detector's reduced image, and each surround is computed on a further-reduced copy where its
spatial sigma is only ``work_sigma_px`` pixels, then upsampled bilinearly.  Illumination is
smooth, so this only loses structure smaller than the reduced grid -- inside the marker that is
the black ring and white disk, which stay non-purple either way (``tests/vision/
test_enhance.py`` compares the purple masks against a full-resolution reference).  Spatial
sigmas are given in *full-resolution* pixels so a configuration means the same thing whatever
reduction the caller uses.

The bilateral filter runs on ``log(V + 1)``, so its range sigma is a contrast ratio
(``sigma_r = 1`` ~ a factor e): an edge is treated the same in the dark corner and under the
lamp, which an intensity-domain range kernel would not do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import cv2
import numpy as np

from stationd.yamlio import YamlNode

__all__ = ["EnhanceParams", "enhance_hsv", "log_reflectance", "retinex_v", "stretch_reflectance",
           "stretch_saturation", "surround_log"]


@dataclass(frozen=True)
class EnhanceParams:
    """Parameters of :func:`enhance_hsv`; the defaults are the tested configuration.

    ``sigmas_px``: spatial sigmas of the N surrounds, in full-resolution pixels (equal weights
    1/N, the paper's N = 3).  ``sigma_r``: range sigma of the bilateral surround, in natural-log
    units of V.  ``work_sigma_px``: the spatial sigma each surround is computed at, after
    reducing the image further.  ``v_percentiles`` / ``v_min_span``: the log-reflectance
    between these percentiles is stretched to 0-255, over a span of at least ``v_min_span``
    log units (so a flat, featureless image is not blown up into noise).  ``s_percentiles``,
    ``s_max_gain``, ``s_max_lo``: the saturation stretch (Eq. 4) with its robust bounds.
    """

    sigmas_px: tuple[float, ...] = (15.0, 80.0, 250.0)
    sigma_r: float = 1.0
    work_sigma_px: float = 1.25
    v_percentiles: tuple[float, float] = (1.0, 99.0)
    v_min_span: float = 2.0
    s_percentiles: tuple[float, float] = (1.0, 99.5)
    s_max_gain: float = 1.15
    s_max_lo: float = 4.0

    def __post_init__(self) -> None:
        if not self.sigmas_px or any(not 0 < s < 1e5 for s in self.sigmas_px):
            raise ValueError("sigmas_px must be one or more positive numbers")
        for name, (lo, hi) in (("v_percentiles", self.v_percentiles),
                               ("s_percentiles", self.s_percentiles)):
            if not 0 <= lo < hi <= 100:
                raise ValueError(f"{name} must satisfy 0 <= lo < hi <= 100")
        if self.sigma_r <= 0 or self.work_sigma_px < 0.5 or self.v_min_span <= 0:
            raise ValueError("sigma_r and v_min_span must be > 0, work_sigma_px >= 0.5")
        if self.s_max_gain < 1 or not 0 <= self.s_max_lo < 128:
            raise ValueError("s_max_gain must be >= 1 and s_max_lo in [0, 128)")

    @classmethod
    def from_node(cls, node: YamlNode) -> EnhanceParams:
        """Read ``{sigmas_px: [..], sigma_r: .., ...}``; absent keys keep their defaults."""
        names = [f.name for f in fields(cls)]
        kw: dict[str, object] = {}
        for key, child in node.mapping(names).items():
            if key == "sigmas_px":
                kw[key] = tuple(float(x) for x in child.vector(range(1, 9)))
            elif key in ("v_percentiles", "s_percentiles"):
                lo, hi = child.vector([2])
                kw[key] = (float(lo), float(hi))
            else:
                kw[key] = child.number(lo=0.0, hi=1e5)
        try:
            return cls(**kw)  # type: ignore[arg-type]
        except ValueError as exc:
            raise node.error(str(exc)) from None


def surround_log(lv: np.ndarray, sigma_px: float, sigma_r: float,
                 work_sigma_px: float) -> np.ndarray:
    """Bilateral illumination estimate of ``lv`` (float32 log image), spatial sigma in its pixels.

    The image is reduced by an integer factor ``f`` so that the sigma becomes ~``work_sigma_px``
    (INTER_AREA: a true block average, no aliasing; the image is first padded by reflection
    to a multiple of ``f``, which keeps OpenCV on its fast integer-ratio path and the pixel
    grids exactly aligned), filtered there with a kernel truncated at 2 sigma, and brought
    back with bilinear interpolation.
    """
    h, w = lv.shape
    f = max(1, math.floor(sigma_px / work_sigma_px + 0.5))
    sig = sigma_px / f
    d = 2 * math.ceil(2.0 * sig) + 1
    if f == 1:
        return np.asarray(cv2.bilateralFilter(lv, d, sigma_r, sig,
                                              borderType=cv2.BORDER_REFLECT_101))
    pw, ph = -(-w // f) * f, -(-h // f) * f
    padded = cv2.copyMakeBorder(lv, 0, ph - h, 0, pw - w, cv2.BORDER_REFLECT_101)
    small = cv2.resize(padded, (pw // f, ph // f), interpolation=cv2.INTER_AREA)
    est = cv2.bilateralFilter(small, d, sigma_r, sig, borderType=cv2.BORDER_REFLECT_101)
    return np.asarray(cv2.resize(est, (pw, ph), interpolation=cv2.INTER_LINEAR)[:h, :w])


_LOG1P = np.log1p(np.arange(256, dtype=np.float32)).reshape(1, 256)


def log_reflectance(v: np.ndarray, params: EnhanceParams, scale: float) -> np.ndarray:
    """``R = sum_i (1/N) (log(V+1) - log(L_i+1))`` (float32), the paper's MSR with N surrounds.

    ``log(L_i + 1)`` is the bilateral filter of ``log(V + 1)`` at spatial sigma
    ``sigmas_px[i] / scale`` reduced pixels (see :func:`surround_log`).
    """
    if scale <= 0:
        raise ValueError("scale must be > 0")
    lv = cv2.LUT(v, _LOG1P)  # uint8 -> float32 log(V + 1), one pass
    n = len(params.sigmas_px)
    acc = np.zeros_like(lv)
    for sigma_full in params.sigmas_px:
        est = surround_log(lv, sigma_full / scale, params.sigma_r, params.work_sigma_px)
        acc = cv2.scaleAdd(est, 1.0 / n, acc)
    return np.asarray(cv2.subtract(lv, acc))


def _subsample(a: np.ndarray) -> np.ndarray:
    """A regular subsample: the answers below are gains, 20 k samples are plenty."""
    flat = a.reshape(-1)
    return flat[:: max(1, flat.size // 20000)]


def stretch_reflectance(r: np.ndarray, params: EnhanceParams) -> np.ndarray:
    """Map log-reflectance to uint8: the percentile span to 0-255.

    A span narrower than ``v_min_span`` (a featureless chassis) is widened about the median,
    not about the middle of the tails: the tails are where the small marker itself sits, and
    the mapping of the bulk must not depend on how big the marker happens to be.
    """
    sub = _subsample(r)
    lo, med, hi = (float(x) for x in np.percentile(sub, (params.v_percentiles[0], 50.0,
                                                         params.v_percentiles[1])))
    if hi - lo < params.v_min_span:
        lo, hi = med - 0.5 * params.v_min_span, med + 0.5 * params.v_min_span
    gain = 255.0 / (hi - lo)
    return np.asarray(cv2.addWeighted(r, gain, r, 0.0, -lo * gain, dtype=cv2.CV_8U))  # rounds


def retinex_v(v: np.ndarray, params: EnhanceParams, scale: float) -> np.ndarray:
    """Bilateral multi-scale Retinex of a uint8 V channel, rescaled to uint8."""
    return stretch_reflectance(log_reflectance(v, params, scale), params)


def stretch_saturation(s: np.ndarray, params: EnhanceParams) -> np.ndarray:
    """Linear contrast stretch of S (paper Eq. 4) with robust, bounded end points.

    ``[lo, hi] -> [0, 255]`` with lo, hi percentiles.  ``lo`` is capped at ``s_max_lo`` and the
    gain at ``s_max_gain``: the marker is often < 1 % of the frame, so a free stretch would map
    the grey chassis's faint colour cast onto "saturated" and the purple range would accept it.
    """
    lo, hi = (float(x) for x in np.percentile(_subsample(s), params.s_percentiles))
    lo = min(max(lo, 0.0), params.s_max_lo)
    hi = max(hi, lo + 255.0 / params.s_max_gain, lo + 1.0)
    gain = 255.0 / (hi - lo)
    lut = np.clip((np.arange(256, dtype=np.float64) - lo) * gain + 0.5, 0, 255).astype(np.uint8)
    return np.asarray(cv2.LUT(s, lut))


def enhance_hsv(hsv: np.ndarray, params: EnhanceParams, scale: float) -> np.ndarray:
    """Enhanced copy of an OpenCV uint8 HSV image: H unchanged, V Retinex, S stretched.

    ``scale`` is the reduction of ``hsv`` relative to the full-resolution frame (8 for the
    detector's 1/8 image), so that ``params.sigmas_px`` keep their full-resolution meaning.
    """
    if hsv.dtype != np.uint8 or hsv.ndim != 3 or hsv.shape[2] != 3:
        raise ValueError(f"expected a uint8 HxWx3 HSV image, got {hsv.dtype} {hsv.shape}")
    h, s, v = cv2.split(hsv)
    return np.asarray(cv2.merge((h, stretch_saturation(s, params), retinex_v(v, params, scale))))
