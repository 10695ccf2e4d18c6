"""Recall under real effects, without giving up precision or safety (issue 10).

Small windows rendered by the robustness benchmark's own sample maker, a few cases each;
the big matrix is ``stationd bench vision --only robustness``.
"""

import math

import numpy as np
import pytest

from stationd.bench import robustness as rb
from stationd.sim import effects as fx
from stationd.vision.detect import detect
from stationd.vision.params import VisionParams

PARAMS = VisionParams()


def _run(setup, seed):
    s = rb.make_sample(setup, np.random.default_rng(seed))
    return s, detect(s.image, s.camera, PARAMS, rb.SPEC)


def _err(s, d):
    return float(np.hypot(*(d.centre_px - s.truth)))


@pytest.mark.parametrize(("hue", "sat", "val"),
                         [(265, 0.9, 0.35), (280, 0.4, 0.85), (295, 0.9, 0.6)])
def test_any_printed_purple_is_found(hue, sat, val):
    s, d = _run(rb.Setup(purple=fx.purple_rgb(hue, sat, val), cast=(1.12, 0.87, 1.1)), hue)
    assert d.found, d.reason
    assert _err(s, d) < 0.05


@pytest.mark.parametrize(("shape", "colour", "frac", "angle"),
                         [("disk", "dark", 0.2, 0.3), ("edge", "skin", 0.25, 2.0),
                          ("hand", "metal", 0.38, 4.0), ("frame", "grey", 0.36, 1.1)])
def test_occluded_outer_ring_is_found_and_its_visible_fraction_reported(shape, colour, frac,
                                                                         angle):
    s, d = _run(rb.Setup(occluder=(shape, colour, frac, angle)), int(frac * 100))
    assert d.found, d.reason
    assert _err(s, d) < 0.1
    assert d.outer_visible is not None
    assert d.outer_visible <= 1.0 - 0.5 * s.covered  # the hidden arc is not counted


@pytest.mark.parametrize("pattern", fx.BAYER_PATTERNS)
def test_demosaiced_colour_camera_frames_are_found(pattern):
    s, d = _run(rb.Setup(bayer=(pattern, "bilinear")), 7)
    assert d.found, d.reason
    assert _err(s, d) < 0.1


@pytest.mark.parametrize("effect", ["motion", "defocus", "glare", "dim"])
def test_blur_defocus_glare_and_dim_light(effect):
    setup = {"motion": rb.Setup(motion=(6.0, 35.0)), "defocus": rb.Setup(defocus=2.5),
             "glare": rb.Setup(glare=(12.5, 1.0, 450.0)),
             "dim": rb.Setup(illumination=0.08)}[effect]
    s, d = _run(setup, 21)
    assert d.found, d.reason
    assert _err(s, d) < 0.1


@pytest.mark.parametrize("phantom", ["patch", "disk", "washer", "ring"])
def test_no_marker_is_reported_where_there_is_none(phantom):
    for seed in (1, 2):
        _, d = _run(rb.Setup(phantom=phantom), seed)
        assert not d.found
        assert d.reason  # and it says what was missing


def test_an_occluded_disk_is_refused_not_guessed():
    # cover the white disk itself (an occluder reaching the centre): nothing safe to measure
    s = rb.make_sample(rb.Setup(), np.random.default_rng(5))
    img = s.image.copy()
    c = np.round(s.truth).astype(int)
    img[c[1] - 40:c[1] + 40, c[0]:] = (40, 40, 40)
    d = detect(img, s.camera, PARAMS, rb.SPEC)
    assert not d.found or _err(s, d) < 2.0
    assert d.found or d.reason
    assert math.isfinite(s.covered)
