import numpy as np
import pytest

from stationd.localize.stereo import epipolar_residual, localize_detections, triangulate
from stationd.sim import scenes as sc
from stationd.vision.detect import detect
from stationd.vision.params import VisionParams
from tests.conftest import NOISE, SPEC, pose_in_pair


def _undist(cam, X):
    p = cam.K @ X
    return p[:2] / p[2]


def test_triangulation_is_exact_on_exact_projections(station_pair):
    rng = np.random.default_rng(0)
    for _ in range(20):
        X = np.array([rng.uniform(-300, 300), rng.uniform(-200, 200), rng.uniform(900, 1600)])
        ul = _undist(station_pair.left, X)
        ur = _undist(station_pair.right, station_pair.R @ X + station_pair.T)
        assert np.linalg.norm(triangulate(station_pair, ul, ur) - X) < 1e-6
        assert epipolar_residual(station_pair, ul, ur) < 1e-6
        assert epipolar_residual(station_pair, ul, ur + np.array([0.0, 3.0])) > 1.0


def _views(pair, pose, seed=0):
    lv = sc.render_view(pair.left, pose, SPEC, seed, **NOISE)
    rv = sc.render_view(pair.right, sc.to_right(pair, pose), SPEC, seed + 1, **NOISE)
    return lv, rv


@pytest.mark.parametrize("method", ["concentric", "paper"])
def test_rendered_pair_localizes_to_hundredths_of_a_mm(station_pair, method):
    pose = pose_in_pair(station_pair, seed=1)
    lv, rv = _views(station_pair, pose)
    params = VisionParams(centre_method=method)
    dl = detect(lv.image, lv.camera, params, SPEC)
    dr = detect(rv.image, rv.camera, params, SPEC)
    res = localize_detections(sc.crop_pair(station_pair, lv, rv), dl, dr, params)
    assert res.found, res.reason
    assert np.linalg.norm(res.point_mm - pose.centre_mm) < 0.05
    assert np.degrees(np.arccos(np.clip(res.normal @ pose.normal, -1, 1))) < 1.0
    assert abs(res.radii_mm["inner"] - 10.0) < 0.1 and abs(res.radii_mm["outer"] - 15.0) < 0.1
    assert res.epipolar_px < 0.1


def test_different_points_fail_the_epipolar_gate(station_pair):
    p1 = pose_in_pair(station_pair, seed=2)
    p2 = pose_in_pair(station_pair, seed=3)
    lv, _ = _views(station_pair, p1)
    _, rv = _views(station_pair, p2)
    dl = detect(lv.image, lv.camera, VisionParams(), SPEC)
    dr = detect(rv.image, rv.camera, VisionParams(), SPEC)
    res = localize_detections(sc.crop_pair(station_pair, lv, rv), dl, dr)
    assert not res.found and ("epipolar" in res.reason or "normals disagree" in res.reason)


def test_a_missing_view_is_a_refusal(station_pair):
    pose = pose_in_pair(station_pair, seed=4)
    lv, rv = _views(station_pair, pose)
    dl = detect(lv.image, lv.camera, VisionParams(), SPEC)
    blank = np.full_like(rv.image, 70)
    dr = detect(blank, rv.camera, VisionParams(), SPEC)
    res = localize_detections(sc.crop_pair(station_pair, lv, rv), dl, dr)
    assert not res.found and res.side == "right" and res.said.startswith("right: ")


def test_one_picture_given_as_both_views_is_refused_not_triangulated(station_pair):
    """The same image as left and right (one camera wired as both, a file given twice) passed
    the epipolar gate and triangulated to a confident point 80 mm off: now a refusal."""
    pose = pose_in_pair(station_pair, seed=5)
    lv, rv = _views(station_pair, pose)
    dl = detect(lv.image, lv.camera, VisionParams(), SPEC)
    again = detect(lv.image, lv.camera, VisionParams(), SPEC)   # the same picture, detected twice
    pair = sc.crop_pair(station_pair, lv, rv)
    res = localize_detections(pair, dl, again)
    assert not res.found and "same picture" in res.reason
    dr = detect(rv.image, rv.camera, VisionParams(), SPEC)
    assert localize_detections(pair, dl, dr).found                 # the real pair still is
