"""The whole single-image pipeline on rendered images (ground truth from the renderer)."""

import cv2
import numpy as np
import pytest

from stationd.errors import ImageError
from stationd.sim.render import Distractor, MarkerPose, Scene, crop_camera, render
from stationd.vision.detect import detect, detect_all
from stationd.vision.params import VisionParams
from tests.conftest import NOISE, SPEC, view


@pytest.mark.parametrize("distance,tilt", [(450, 30), (900, 0), (1200, 50), (2000, 65)])
@pytest.mark.parametrize("method", ["concentric", "paper"])
def test_centre_is_corrected_to_a_fraction_of_a_pixel(camera, distance, tilt, method):
    v, _ = view(camera, distance, tilt, seed=distance + tilt)
    d = detect(v.image, v.camera, VisionParams(centre_method=method), SPEC)
    assert d.found, d.reason
    err = np.hypot(*(d.centre_px - v.centre_px))
    ell = np.hypot(*(d.ellipse_centre_px - v.centre_px))
    assert err < 0.05
    assert abs(d.pencil_ratio / SPEC.ratio_sq - 1) < 0.02
    if tilt >= 30 and distance <= 1200:
        assert ell > 5 * err  # the uncorrected ellipse centre is clearly worse
    assert d.inner.used >= 24 and d.outer.used >= 24
    assert set(d.timings_ms) >= {"reduce", "segment", "edges", "fit", "centre", "total"}


def test_normal_faces_the_camera_and_matches_truth(camera):
    v, pose = view(camera, 600, 40, seed=3)
    d = detect(v.image, v.camera, VisionParams(centre_method="paper"), SPEC)
    assert d.found, d.reason
    assert not d.normal_ambiguous
    assert np.degrees(np.arccos(np.clip(d.normal @ pose.normal, -1, 1))) < 1.0


def test_no_marker_is_a_refusal_with_reason(camera):
    img = render(crop_camera(camera, (0, 0, 400, 300)), Scene(**NOISE)).image
    d = detect(img, crop_camera(camera, (0, 0, 400, 300)))
    assert not d.found and "no purple region" in d.reason
    # a refusal carries the reduced image too: the screens show every frame, marker or not
    assert d.search_image is not None and d.search_image.shape == (300 // 8, 400 // 8, 3)


def test_two_markers_are_ambiguous_but_both_found_by_detect_all(camera):
    win = (2300, 1500, 900, 700)
    cam = crop_camera(camera, win)
    poses = [MarkerPose.look(np.array(c, float), 20, az) for c, az in
             (((-60.0, 0.0, 1500.0), 0.0), ((60.0, 20.0, 1500.0), 90.0))]
    img = render(camera, Scene(markers=[(p, SPEC) for p in poses], **NOISE), window=win).image
    found, _ = detect_all(img, cam, VisionParams(), SPEC)
    assert len(found) == 2
    d = detect(img, cam, VisionParams(), SPEC)
    assert not d.found and "ambiguous: 2 markers" in d.reason


def test_purple_distractors_are_ignored(camera):
    win = (2300, 1500, 900, 700)
    cam = crop_camera(camera, win)
    marker = MarkerPose.look(np.array([-50.0, 0.0, 1400.0]), 25, 30)
    disc = Distractor(MarkerPose.look(np.array([70.0, 30.0, 1400.0]), 10, 0), "disc", 20.0)
    bar = Distractor(MarkerPose.look(np.array([40.0, -50.0, 1400.0]), 10, 0), "bar", 40.0, 5.0)
    r = render(camera, Scene(markers=[(marker, SPEC)], distractors=[disc, bar], **NOISE),
               window=win)
    d = detect(r.image, cam, VisionParams(), SPEC)
    assert d.found, d.reason
    assert np.hypot(*(d.centre_px - r.truth[0].centre_px)) < 0.05


def test_marker_cut_by_the_border_is_refused(camera):
    v, _ = view(camera, 800, 20, seed=5)
    x = int(v.centre_px[0])  # cut the image through the middle of the ring
    img = np.ascontiguousarray(v.image[:, x - 10:])
    cam = crop_camera(v.camera, (x - 10, 0, img.shape[1], img.shape[0]))
    d = detect(img, cam, VisionParams(), SPEC)
    assert not d.found and d.reason


def test_salt_and_pepper_in_the_roi(camera):
    v, _ = view(camera, 2050, 50, seed=8, salt_pepper_in_field=400)
    d = detect(v.image, v.camera, VisionParams(), SPEC)
    assert d.found, d.reason
    assert np.hypot(*(d.centre_px - v.centre_px)) < 0.1


def test_low_light_needs_the_enhancement(camera):
    v, _ = view(camera, 1200, 30, seed=9, illumination=0.1, vignetting=0.3)
    d = detect(v.image, v.camera, VisionParams(enhance=True), SPEC)
    assert d.found, d.reason
    assert np.hypot(*(d.centre_px - v.centre_px)) < 0.1


def test_bad_images_are_input_errors(camera):
    cam = crop_camera(camera, (0, 0, 64, 48))
    with pytest.raises(ImageError, match="3 colour channels"):
        detect(np.zeros((48, 64), np.uint8), cam)
    with pytest.raises(ImageError, match="8-bit"):
        detect(np.zeros((48, 64, 3), np.uint16), cam)
    with pytest.raises(ImageError, match="camera model is 64x48"):
        detect(np.zeros((40, 64, 3), np.uint8), cam)


def test_a_ring_of_other_proportions_is_not_this_marker(camera):
    """Two concentric circles, but 12/15 instead of 10/15: the pencil ratio gate refuses."""
    from stationd.sim import scenes as sc
    from stationd.vision.marker import MarkerSpec

    other = MarkerSpec(inner_mm=12.0)
    pose = sc.random_pose(np.random.default_rng(4), camera, 700, 30, spread=0.4)
    v = sc.render_view(camera, pose, other, 4, **NOISE)
    d = detect(v.image, v.camera, VisionParams(), SPEC)
    assert not d.found and "pencil ratio" in d.reason
    assert detect(v.image, v.camera, VisionParams(), other).found


def test_a_marker_too_small_for_the_reduced_search_is_found_at_finer_scale(camera):
    """At 4.5 m the ring's outer radius is ~17 px, 2 px at 1/8 (no candidate there, checked
    below): the search retries at 1/4."""
    from stationd.vision.detect import reduce
    from stationd.vision.enhance import EnhanceParams
    from stationd.vision.segment import find_candidates

    v, _ = view(camera, 4500, 20, seed=6)
    h, w = v.image.shape[:2]
    assert not find_candidates(reduce(v.image, 8), 8, enhance=EnhanceParams(), full_size=(w, h))
    d = detect(v.image, v.camera, VisionParams(), SPEC)
    assert d.found, d.reason
    assert np.hypot(*(d.centre_px - v.centre_px)) < 0.1
    # the search image it carries (the screens show it) is the finer one it found the marker in
    assert d.search_image is not None and d.search_image.shape[:2] == (h // 4, w // 4)
    # the search image it carries (the screens show it) is the finer one it found the marker in
    assert d.search_image is not None and d.search_image.shape[:2] == (h // 4, w // 4)


def test_a_frame_without_purple_is_searched_once_not_at_every_scale(camera, monkeypatch):
    """Most frames of most pairs show no marker: one reduced search, no finer retries (they
    cost ten times more); a frame with purple but no candidate still retries."""
    import stationd.vision.detect as detect_module

    scales = []
    real = detect_module.reduce
    monkeypatch.setattr(detect_module, "reduce",
                        lambda img, s: scales.append(s) or real(img, s))
    bare = render(camera, Scene(texture=0.15, noise_sigma=2.0), seed=1).image
    assert not detect(bare, camera, VisionParams(), SPEC).found
    assert scales == [8]
    scales.clear()
    v, _ = view(camera, 4500, 20, seed=6)       # purple at 1/8, no candidate: retried
    assert detect(v.image, v.camera, VisionParams(), SPEC).found
    assert scales[:2] == [8, 4]
    scales.clear()                              # a near marker cut by the frame's edge
    z = 800.0
    x = (0.0 - camera.K[0, 2]) / camera.K[0, 0] * z
    cut = render(camera, Scene(markers=[(MarkerPose.look(np.array([x, 0.0, z]), 10, 0, 0),
                                         SPEC)], noise_sigma=2.0), seed=2).image
    assert not detect(cut, camera, VisionParams(), SPEC).found
    assert scales == [8]
    scales.clear()      # a far marker (too small for 1/8) centred on the frame's edge: a
    z = 4500.0          # small purple region on the border, searched again at 1/4 and 1/2
    ray = camera.pixels_to_normalized(np.array([[0.0, camera.K[1, 2]]]))[0]
    x = float(ray[0]) * z           # before (for nothing: the ring is cut), 300 ms more
    cut = render(camera, Scene(markers=[(MarkerPose.look(np.array([x, 0.0, z]), 10, 0, 0),
                                         SPEC)], noise_sigma=2.0), seed=3).image
    small = detect_module.reduce(cut, 8)
    from stationd.vision.segment import purple_mask
    assert cv2.countNonZero(purple_mask(cv2.cvtColor(small, cv2.COLOR_BGR2HSV),
                                        VisionParams().hsv)[:, :4])    # purple on the edge
    scales.clear()
    assert not detect(cut, camera, VisionParams(), SPEC).found
    assert scales == [8]


def _gamma(img):
    return np.clip(255 * (img / 255.0) ** (1 / 2.2) + 0.5, 0, 255).astype(np.uint8)


def _bayer(img):
    """Mosaic to RGGB and demosaic with OpenCV, as a colour camera's driver does."""
    import cv2

    b = np.zeros(img.shape[:2], np.uint8)
    b[0::2, 0::2] = img[0::2, 0::2, 2]
    b[0::2, 1::2] = img[0::2, 1::2, 1]
    b[1::2, 0::2] = img[1::2, 0::2, 1]
    b[1::2, 1::2] = img[1::2, 1::2, 0]
    return cv2.cvtColor(b, cv2.COLOR_BayerBG2BGR)


def _jpeg(img):
    import cv2

    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 85])
    assert ok
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)


@pytest.mark.parametrize("post,limit", [(_gamma, 0.03), (_bayer, 0.05), (_jpeg, 0.08)])
def test_images_from_other_pipelines(camera, post, limit):
    """Not our renderer's linear 8-bit output: sRGB-like gamma, a demosaiced Bayer sensor,
    JPEG compression.  Still found, still within a small fraction of a pixel."""
    for seed, (dist, tilt) in enumerate([(600, 40), (1500, 20), (1900, 55)]):
        v, _ = view(camera, dist, tilt, seed=20 + seed)
        d = detect(post(v.image), v.camera, VisionParams(), SPEC)
        assert d.found, d.reason
        assert np.hypot(*(d.centre_px - v.centre_px)) < limit


def test_other_lens_with_strong_distortion_full_frame():
    from stationd.geometry.camera import Camera

    cam = Camera(np.array([[1800.0, 0, 1023.5], [0, 1800.0, 767.5], [0, 0, 1]]),
                 np.array([-0.3, 0.12, 0.001, -0.0005, -0.02]), (2048, 1536))
    pose = MarkerPose.look(np.array([-180.0, 120.0, 500.0]), 35, 60, 10)
    r = render(cam, Scene(markers=[(pose, SPEC)], texture=0.2, vignetting=0.4, **NOISE), seed=2)
    d = detect(r.image, cam, VisionParams(), SPEC)
    assert d.found, d.reason
    assert np.hypot(*(d.centre_px - r.truth[0].centre_px)) < 0.03
