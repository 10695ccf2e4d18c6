"""tune-color: HSV ranges from a well-lit reference image, and the file it writes."""

from __future__ import annotations

import itertools

import cv2
import numpy as np
import pytest

from stationd.errors import ImageError, InputError
from stationd.vision.color import read_hsv_yaml, tune_hsv, write_hsv_yaml
from stationd.vision.enhance import EnhanceParams
from stationd.vision.marker import PURPLE_RGB
from stationd.vision.segment import DEFAULT_HSV, HsvRange, find_candidates
from tests.vision.test_segment import (
    CORNERS,
    FULL,
    Marker,
    Patch,
    contains,
    field_box,
    hsv_of,
    render,
)

REF_SIZE = (1368, 912)
MARKER = Marker(700, 450, 60, rot_deg=20)
PALE_PURPLE = (150, 120, 160)  # a large, faintly purple thing: saturation 25 %


@pytest.fixture(scope="module")
def reference() -> np.ndarray:
    """A well-lit reference frame: the marker, a pale purple panel, a red part."""
    return render([MARKER], [Patch(50, 50, 450, 850, PALE_PURPLE),
                             Patch(1000, 600, 1300, 850, (200, 30, 30))],
                  scale=1, full=REF_SIZE, noise=2.0, seed=1)


def test_tuned_range_is_the_marker_purple_with_or_without_roi(reference):
    x0, y0, x1, y1 = field_box(MARKER)
    with_roi = tune_hsv(reference, (int(x0) - 10, int(y0) - 10, int(x1 - x0) + 20,
                                    int(y1 - y0) + 20))
    whole = tune_hsv(reference)  # the saturated marker, not the larger pale panel
    assert with_roi == whole
    nominal = hsv_of(np.array([PURPLE_RGB]))
    assert with_roi.accepts(nominal)[0]
    # narrower than the all-purples default (it is one print), and its S floor excludes the
    # pale panel
    assert DEFAULT_HSV.h[0] <= with_roi.h[0] and with_roi.h[1] <= DEFAULT_HSV.h[1]
    assert with_roi.h[1] - with_roi.h[0] < DEFAULT_HSV.h[1] - DEFAULT_HSV.h[0]
    assert with_roi.s[0] > hsv_of(np.array([PALE_PURPLE]))[0, 1] + 20
    assert with_roi.v == (DEFAULT_HSV.v[0], 255)


def test_tuned_range_tolerates_cast_and_low_light(reference):
    """The widening rule in action: every cast corner, 100 % and 10 % light, enhancement on."""
    tuned = tune_hsv(reference)
    mk = Marker(2700, 1800, 40, rot_deg=20)
    for cast, light in itertools.product([(1.0, 1.0, 1.0), *CORNERS], (1.0, 0.1)):
        img = render([mk], light=(light, light), cast=cast, noise=1.5, seed=2)
        cands = find_candidates(img, 8, tuned, enhance=EnhanceParams(), full_size=FULL)
        assert any(contains(c.roi, field_box(mk)) for c in cands), (cast, light)


def test_tuned_range_rejects_grey_under_the_full_cast(reference):
    """What tuning buys: the default box must accept every purple and so takes grey under a
    strong purple-ward cast; the box of one print rejects grey under every +-15 % cast."""
    tuned = tune_hsv(reference)
    casts = np.array(list(itertools.product((0.85, 1.0, 1.15), repeat=3)))
    for grey in ((105, 108, 112), (128, 128, 128), (245, 245, 245)):
        hsv = hsv_of(np.clip(np.round(np.asarray(grey) * casts), 0, 255))
        hsv[:, 1] = np.clip(np.round(hsv[:, 1] * EnhanceParams().s_max_gain), 0, 255)
        hsv[:, 2] = 200
        assert not tuned.accepts(hsv).any(), grey
        assert DEFAULT_HSV.accepts(hsv).any()


def test_no_purple_is_refused_with_a_reason(reference):
    grey = render([], [Patch(100, 100, 500, 500, (200, 30, 30))], scale=1, full=REF_SIZE,
                  noise=2.0)
    with pytest.raises(InputError, match="no purple-ish pixels"):
        tune_hsv(grey)
    with pytest.raises(InputError, match="no purple-ish pixels"):
        tune_hsv(reference, (1000, 600, 200, 200))  # an ROI on the red part
    with pytest.raises(InputError, match="not inside"):
        tune_hsv(reference, (1300, 800, 200, 200))
    with pytest.raises(ImageError):
        tune_hsv(cv2.cvtColor(reference, cv2.COLOR_BGR2GRAY))


def test_yaml_file_round_trip_and_header(tmp_path):
    r = HsvRange(h=(128, 156), s=(120, 255), v=(40, 255))
    path = tmp_path / "hsv.yaml"
    write_hsv_yaml(path, r, source="ref\nimage.png", roi=(10, 20, 300, 200))
    text = path.read_text(encoding="utf-8")
    assert text.startswith("#")
    assert "from ref image.png, ROI x=10, y=20, w=300, h=200" in text
    assert read_hsv_yaml(path) == r
    write_hsv_yaml(path, r)
    assert "the whole image" in path.read_text(encoding="utf-8")
    with pytest.raises(InputError, match="does not exist"):
        write_hsv_yaml(tmp_path / "missing" / "hsv.yaml", r)


def test_verify_marker_is_the_ring_check(reference):
    from stationd.vision.color import verify_marker

    assert verify_marker(reference) is None
    x0, y0, x1, y1 = field_box(MARKER)
    assert verify_marker(reference, roi=(int(x0), int(y0), int(x1 - x0), int(y1 - y0))) is None
    # the pale panel is purple-ish but has no ring; an ROI on it finds no marker
    assert "ring check" in (verify_marker(reference, roi=(50, 50, 400, 800)) or "")
    # a box that excludes the marker's hue loses it
    assert verify_marker(reference, HsvRange(h=(20, 40), s=(50, 255), v=(45, 255))) is not None


def test_a_tuned_box_is_never_wider_than_the_default(reference):
    tuned = tune_hsv(reference, enhance=EnhanceParams())
    for (lo, hi), (dlo, dhi) in ((tuned.h, DEFAULT_HSV.h), (tuned.s, DEFAULT_HSV.s),
                                 (tuned.v, DEFAULT_HSV.v)):
        assert dlo <= lo <= hi <= dhi
    from stationd.vision.color import _within_default

    assert _within_default(HsvRange(h=(100, 175), s=(25, 255), v=(20, 255))) == DEFAULT_HSV
    assert _within_default(HsvRange(h=(130, 150), s=(90, 255), v=(20, 255))) == HsvRange(
        h=(130, 150), s=(90, 255), v=(DEFAULT_HSV.v[0], 255))
    with pytest.raises(InputError, match="outside the hues"):
        _within_default(HsvRange(h=(170, 175), s=(90, 255), v=(45, 255)))
