"""The ring found from its own structure (radial profiles) and the chroma of the field."""

import cv2
import numpy as np
import pytest

from stationd.vision import edges as em
from stationd.vision import rays
from tests.conftest import view


def _smooth(img):
    return cv2.GaussianBlur(em.remove_impulses(em.intensity(img)), (0, 0), 1.0)


def _radii(camera, v, pose):
    """True semi-major axes (px) of the two circles, roughly, from their projections."""
    out = []
    for r in (10.0, 15.0):
        t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        pts = pose.centre_mm + (pose.rotation[:, :2] @ np.stack([r * np.cos(t), r * np.sin(t)]
                                                                )).T
        uv = camera.project(pts) - np.array(v.window[:2])
        out.append(float(np.max(np.hypot(*(uv - v.centre_px).T))))
    return out


def test_rays_find_both_circles_from_an_offset_hint(camera):
    v, pose = view(camera, 800, 30, seed=3)
    hint = (float(v.centre_px[0]) + 4.0, float(v.centre_px[1]) - 3.0)
    a_in, a_out = _radii(camera, v, pose)
    rr = rays.ring_from_rays(_smooth(v.image), hint, 0.9 * a_out, rays.chroma(v.image))
    assert not isinstance(rr, rays.Refusal), rr
    assert np.hypot(*(np.array(rr.inner.centre) - v.centre_px)) < 2.0
    assert rr.inner.axes[0] == pytest.approx(a_in, rel=0.03)
    assert rr.outer.axes[0] == pytest.approx(a_out, rel=0.03)
    assert rr.white > rr.field > rr.ring and rr.rays >= rays.MIN_RAYS
    assert rr.tint > 0.1  # the field beyond the ring is purple


def test_rays_refuse_a_plain_purple_disk_with_the_reason(camera):
    img = np.full((200, 200, 3), 70, np.uint8)
    cv2.circle(img, (100, 100), 60, (166, 50, 127), -1, cv2.LINE_AA)
    rr = rays.ring_from_rays(_smooth(img), (100.0, 100.0), 40.0, rays.chroma(img))
    assert isinstance(rr, rays.Refusal)
    assert "no dark ring with the marker's proportions" in rr.reason and "rays" in rr.reason


def test_rays_refuse_a_ring_of_other_proportions():
    # white disk r 30, black ring to 36 (ratio 1.2, not 1.5), purple field
    img = np.full((240, 240, 3), 70, np.uint8)
    cv2.rectangle(img, (20, 20), (220, 220), (166, 50, 127), -1)
    cv2.circle(img, (120, 120), 36, (22, 22, 24), -1, cv2.LINE_AA)
    cv2.circle(img, (120, 120), 30, (245, 245, 245), -1, cv2.LINE_AA)
    img = cv2.GaussianBlur(img, (0, 0), 0.8)
    assert isinstance(rays.ring_from_rays(_smooth(img), (120.0, 120.0), 36.0), rays.Refusal)


def test_chroma_separates_purple_from_grey_skin_and_metal():
    colours = {"purple": (166, 50, 127), "dark purple": (91, 20, 60), "grey": (125, 120, 120),
               "skin": (120, 150, 205), "metal": (200, 195, 190), "black": (24, 22, 22),
               "white": (245, 245, 245)}  # BGR
    img = np.repeat(np.array([[c] * 15 for c in colours.values()], np.uint8), 15, axis=0)
    c = rays.chroma(img)[7::15, 7]  # block centres, away from the smoothing
    vals = dict(zip(colours, c, strict=True))
    assert min(vals["purple"], vals["dark purple"]) > 0.3
    assert max(vals[k] for k in ("grey", "skin", "metal", "black", "white")) < 0.12
