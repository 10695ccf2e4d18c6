"""The robustness benchmark's physical effects: each does what its physics says."""

import numpy as np
import pytest

from stationd.sim import effects as fx


@pytest.mark.parametrize("pattern", fx.BAYER_PATTERNS)
def test_bayer_round_trip_keeps_flat_colours(pattern):
    # a wrong OpenCV code swaps red and blue: a flat colour must come back as itself
    img = np.zeros((16, 16, 3), np.uint8)
    img[:] = (30, 120, 200)
    for method in fx.DEMOSAIC_METHODS:
        out = fx.demosaic(fx.bayer_mosaic(img, pattern), pattern, method)
        assert np.abs(out[4:-4, 4:-4].astype(int) - img[4:-4, 4:-4]).max() <= 2


def test_bayer_mosaic_samples_one_channel_per_pixel():
    img = np.zeros((4, 4, 3), np.uint8)
    img[..., 0], img[..., 1], img[..., 2] = 10, 20, 30  # B, G, R
    raw = fx.bayer_mosaic(img, "RGGB")
    assert raw[0, 0] == 30 and raw[0, 1] == 20 and raw[1, 0] == 20 and raw[1, 1] == 10


@pytest.mark.parametrize("kind", fx.OCCLUDER_SHAPES)
def test_occluder_covers_the_asked_fraction_and_never_the_disk(kind):
    polys, got = fx.occluder_polygon(kind, 0.1, 0.7, 10.0, 15.0)
    assert abs(got - 0.1) < 0.02
    assert fx.outer_coverage_all(polys, 10.0) == 0.0  # the white disk's edge is untouched


def test_one_convex_occluder_cannot_reach_40_percent_but_a_hand_can():
    _, edge = fx.occluder_polygon("edge", 0.4, 0.0, 10.0, 15.0)
    _, hand = fx.occluder_polygon("hand", 0.4, 0.0, 10.0, 15.0)
    assert edge < 0.3
    assert abs(hand - 0.4) < 0.06


def test_blur_kernels_preserve_energy_and_centre():
    img = np.zeros((41, 41, 3), np.float32)
    img[20, 20] = 100.0
    for out in (fx.motion_blur(img, 6.0, 30.0), fx.defocus(img, 2.5)):
        ch = out[..., 0]
        assert ch.sum() == pytest.approx(100.0, rel=1e-3)
        yy, xx = np.mgrid[0:41, 0:41]
        assert (xx * ch).sum() / ch.sum() == pytest.approx(20.0, abs=0.05)
        assert (yy * ch).sum() / ch.sum() == pytest.approx(20.0, abs=0.05)
    line = fx.motion_blur(img, 6.0, 0.0)[..., 0]
    assert line[20].sum() > 0.9 * line.sum()  # a horizontal streak


def test_highlight_clips_in_the_sensor_not_here():
    img = np.full((21, 21, 3), 100.0, np.float32)
    fx.highlight(img, (10.0, 10.0), 3.0, 400.0)
    assert img.max() == pytest.approx(500.0) and img[0, 0, 0] < 101.0


@pytest.mark.parametrize(("h", "s", "v"), [(265, 0.4, 0.35), (280, 0.7, 0.65), (295, 0.9, 0.85)])
def test_purple_rgb_has_the_asked_hsv(h, s, v):
    r, g, b = fx.purple_rgb(h, s, v)
    mx, mn = max(r, g, b), min(r, g, b)
    assert mx == pytest.approx(255 * v, abs=1) and (mx - mn) / mx == pytest.approx(s, abs=0.01)
    assert g == mn and b == mx  # purple: blue highest, green lowest
