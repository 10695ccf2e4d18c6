"""The renderer is ground truth, so it is checked against geometry computed another way.

Areas and centroids of the white disk are compared with closed forms (fronto-parallel) and
with polygons of ``cv2.projectPoints`` (tilted, distorted): both are independent of the
renderer's ray casting.  (``cv2.fillPoly`` below only builds a summation mask in the black
ring, where its pixel rule cannot matter.)
"""

import math

import cv2
import numpy as np
import pytest

from stationd.geometry.camera import Camera
from stationd.sim.raycast import composite, pixel_rays
from stationd.sim.render import (
    Distractor,
    MarkerPose,
    Scene,
    Window,
    crop_camera,
    default_camera,
    marker_truth,
    render,
    roi_around,
)
from stationd.sim.render import _distractor_patch as distractor_patch
from stationd.sim.render import _marker_patch as marker_patch
from stationd.vision.marker import MarkerSpec

SPEC = MarkerSpec()
F = 5000.0
FRONTO = np.diag([1.0, -1.0, -1.0])  # marker x = camera x, normal = -z
WHITE, BLACK = SPEC.white_rgb[1], SPEC.black_rgb[1]  # green channel


def pinhole(size: tuple[int, int] = (5472, 3648)) -> Camera:
    K = np.array([[F, 0.0, (size[0] - 1) / 2], [0.0, F, (size[1] - 1) / 2], [0.0, 0.0, 1.0]])
    return Camera(K=K, dist=np.zeros(5), size=size)


def small_camera() -> Camera:
    """A 640 x 1100 sensor (two 512-row blocks) with the station's lens, scaled down."""
    K = np.array([[1200.0, 0.0, 330.2], [0.0, 1200.0, 560.7], [0.0, 0.0, 1.0]])
    return Camera(K=K, dist=np.array([-0.08, 0.12, 2e-4, -1e-4, 0.0]), size=(640, 1100))


def window_around(camera: Camera, pose: MarkerPose, margin: int = 12) -> Window:
    ab = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * SPEC.field_mm
    pts = pose.centre_mm + ab[:, :1] * pose.rotation[:, 0] + ab[:, 1:] * pose.rotation[:, 1]
    uv = camera.project(pts)
    x0, y0 = np.floor(uv.min(axis=0)).astype(int) - margin
    x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + margin
    return int(x0), int(y0), int(x1 - x0), int(y1 - y0)


def circle_image(camera: Camera, pose: MarkerPose, r: float, offset: np.ndarray,
                 n: int = 20000) -> np.ndarray:
    """The image of the marker-plane circle of radius r, as a polygon from cv2.projectPoints."""
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    pts = (pose.centre_mm + np.outer(r * np.cos(t), pose.rotation[:, 0])
           + np.outer(r * np.sin(t), pose.rotation[:, 1]))
    uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), camera.K, camera.dist)
    return np.asarray(uv.reshape(-1, 2) - offset)


def polygon_area_centroid(p: np.ndarray) -> tuple[float, np.ndarray]:
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2
    moments = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()])
    return float(abs(area)), moments / (6 * area)


def white_disk_moments(image: np.ndarray,
                       mid_ring_polygon: np.ndarray) -> tuple[float, np.ndarray]:
    """Area and centroid of the white disk from (pixel - black) / (white - black) weights."""
    mask = np.zeros(image.shape[:2], np.uint8)
    cv2.fillPoly(mask, [np.round(mid_ring_polygon * 16).astype(np.int32)], 1, shift=4)
    weight = (image[..., 1].astype(float) - BLACK) / (WHITE - BLACK) * mask
    vv, uu = np.mgrid[: image.shape[0], : image.shape[1]]
    area = float(weight.sum())
    return area, np.array([(weight * uu).sum(), (weight * vv).sum()]) / area


def test_fronto_parallel_area_and_centroid_match_closed_form():
    camera = pinhole()
    centre = np.array([23.37, -14.81, 612.3])
    pose = MarkerPose(centre, FRONTO)
    win = window_around(camera, pose)
    r = render(camera, Scene(markers=[(pose, SPEC)]), window=win)
    off = np.array(win[:2], dtype=float)
    projected = (camera.K @ (centre / centre[2]))[:2] - off
    ring = circle_image(camera, pose, (SPEC.inner_mm + SPEC.outer_mm) / 2, off)
    area, centroid = white_disk_moments(r.image, ring)
    expected = math.pi * SPEC.inner_mm**2 * F**2 / centre[2] ** 2
    assert abs(area / expected - 1) < 1e-3
    assert np.linalg.norm(centroid - projected) < 0.01
    assert np.allclose(r.truth[0].centre_px, projected, atol=1e-9)
    assert r.truth[0].tilt_deg > 0 and r.truth[0].axis_tilt_deg == pytest.approx(0, abs=1e-9)


@pytest.mark.parametrize(("centre", "tilt", "azimuth"), [
    ((270.0, 180.0, 600.0), 35.0, 120.0),
    ((-330.0, -160.0, 760.0), 55.0, 300.0),
])
def test_distorted_tilted_marker_matches_projectpoints(centre, tilt, azimuth):
    camera = default_camera()
    pose = MarkerPose.look(centre, tilt, azimuth, spin_deg=10.0)
    win = window_around(camera, pose)
    r = render(camera, Scene(markers=[(pose, SPEC)]), window=win)
    truth = r.truth[0]
    alone = marker_truth(camera, pose, SPEC, win)     # the same, without rendering a pixel
    assert all(np.array_equal(getattr(alone, f), getattr(truth, f))
               for f in truth.__dataclass_fields__)
    off = np.array(win[:2], dtype=float)
    cv_centre, _ = cv2.projectPoints(pose.centre_mm[None], np.zeros(3), np.zeros(3), camera.K,
                                     camera.dist)
    assert np.allclose(truth.centre_px, camera.project(pose.centre_mm)[0] - off, atol=1e-12)
    assert np.allclose(truth.centre_px, cv_centre.ravel() - off, atol=1e-6)
    assert np.allclose(truth.centre_undist_px,
                       crop_camera(camera, win).undistort_pixels(truth.centre_px)[0], atol=1e-6)
    assert truth.tilt_deg == pytest.approx(tilt, abs=1e-9)
    assert truth.visible
    # The lens bends the circle: its image is no ellipse, but its area and centroid are exact.
    disk = circle_image(camera, pose, SPEC.inner_mm, off)
    ring = circle_image(camera, pose, (SPEC.inner_mm + SPEC.outer_mm) / 2, off)
    expected_area, expected_centroid = polygon_area_centroid(disk)
    area, centroid = white_disk_moments(r.image, ring)
    assert abs(area / expected_area - 1) < 1e-3
    assert np.linalg.norm(centroid - expected_centroid) < 0.01


def test_pixel_rays_match_the_camera_model():
    camera = default_camera()
    uv = np.random.default_rng(3).uniform((0, 0), camera.size, (5000, 2))
    x, y = pixel_rays(camera, uv[:, 0], uv[:, 1])
    assert np.allclose(np.stack([x, y], 1), camera.pixels_to_normalized(uv), atol=1e-14, rtol=0)


@pytest.mark.parametrize("kind", ["marker", "disc", "bar"])
def test_adaptive_supersampling_misses_no_boundary(kind):
    camera = small_camera()
    pose = MarkerPose.look((-40.0, 65.0, 280.0), 50.0, 200.0, spin_deg=33.0)
    if kind == "marker":
        patch = marker_patch(pose, SPEC)
    else:
        patch = distractor_patch(Distractor(pose, kind, 20.0, 3.0), np.ones(3))
    images = []
    for adaptive in (True, False):
        img = np.full((1100, 640, 3), 70.0, np.float32)
        n = composite(camera, patch, img, 0, 0, 4, adaptive=adaptive)
        images.append(img)
        if adaptive:
            mixed = n
    assert 0 < mixed < n  # the pre-pass did skip pixels...
    assert np.array_equal(images[0], images[1])  # ...and none of them straddled a boundary


def busy_scene(camera: Camera) -> Scene:
    marker = MarkerPose.look((15.0, 40.0, 300.0), 25.0, 60.0)
    disc = Distractor(MarkerPose.look((-60.0, -50.0, 320.0), 20.0, 0.0), "disc", 12.0)
    bar = Distractor(MarkerPose.look((60.0, -120.0, 330.0), 10.0, 90.0), "bar", 30.0, 5.0)
    return Scene(markers=[(marker, SPEC)], distractors=[disc, bar], texture=0.05,
                 vignetting=0.3, gradient=0.2, gradient_deg=30.0, light_min=0.2,
                 cast=(0.9, 1.0, 1.1), illumination=0.8, blur_sigma=0.8, noise_sigma=2.0,
                 salt_pepper=400, salt_pepper_roi=roi_around(camera, marker.centre_mm))


def test_window_equals_the_same_region_of_the_full_frame():
    camera = small_camera()
    scene = busy_scene(camera)
    full = render(camera, scene, seed=5, supersample=8)
    win = (95, 430, 330, 250)  # straddles the 512-row block boundary and the marker
    part = render(camera, scene, window=win, seed=5, supersample=8)
    region = full.image[win[1] : win[1] + win[3], win[0] : win[0] + win[2]]
    assert np.abs(part.image.astype(int) - region.astype(int)).max() <= 1
    off = np.array(win[:2], dtype=float)
    assert np.allclose(part.truth[0].centre_px, full.truth[0].centre_px - off, atol=1e-9)
    ccam = crop_camera(camera, win)
    assert np.allclose(ccam.project(scene.markers[0][0].centre_mm)[0], part.truth[0].centre_px)


def test_deterministic_in_the_seed():
    camera = small_camera()
    scene = busy_scene(camera)
    win = (100, 300, 300, 300)
    a, b = (render(camera, scene, window=win, seed=11, supersample=4) for _ in range(2))
    c = render(camera, scene, window=win, seed=12, supersample=4)
    assert a.image.dtype == np.uint8 and a.image.shape == (300, 300, 3)
    assert np.array_equal(a.image, b.image)
    assert not np.array_equal(a.image, c.image)


def test_salt_and_pepper_count_and_placement():
    camera = pinhole((400, 300))
    roi = (150, 100, 120, 75)
    img = render(camera, Scene(salt_pepper=400, salt_pepper_roi=roi), seed=2).image
    extreme = np.all(img == 0, axis=2) | np.all(img == 255, axis=2)
    assert extreme.sum() == 400
    assert extreme[roi[1] : roi[1] + roi[3], roi[0] : roi[0] + roi[2]].sum() == 400
    assert 150 < np.all(img == 255, axis=2).sum() < 250
    assert np.array_equal(img[~extreme], np.broadcast_to([80, 75, 70], img[~extreme].shape))


def test_colour_cast_illumination_and_fall_off():
    camera = pinhole((400, 300))
    cast = render(camera, Scene(cast=(0.8, 1.0, 1.2))).image
    assert np.all(cast == [96, 75, 56])  # BGR
    pose = MarkerPose(np.array([0.0, 0.0, 5000.0 * 50 / 120]), FRONTO)
    bright = render(camera, Scene(markers=[(pose, SPEC)], blur_sigma=0.8)).image.astype(float)
    dim = render(camera, Scene(markers=[(pose, SPEC)], blur_sigma=0.8, illumination=0.1)).image
    assert bright.max() == WHITE
    assert np.abs(dim - 0.1 * bright).max() <= 0.5 + 0.1 * 0.5 + 1e-6
    vig = render(pinhole(), Scene(vignetting=0.3), window=(0, 0, 2, 2)).image
    assert np.allclose(vig[0, 0], 0.7 * np.array([80, 75, 70]), atol=0.5)
    grad = render(pinhole(), Scene(gradient=0.2), window=(5471, 1800, 1, 1)).image
    assert np.allclose(grad[0, 0], 0.8 * np.array([80, 75, 70]), atol=0.5)


def test_visibility_and_bbox():
    camera = pinhole((800, 600))
    inside = MarkerPose.look((0.0, 0.0, 1000.0))  # on the axis: fronto-parallel
    edge = MarkerPose(np.array([-75.0, 0.0, 1000.0]), FRONTO)  # centre at u = 24.5
    gone = MarkerPose.look((-2000.0, 0.0, 1000.0))
    r = render(camera, Scene(markers=[(inside, SPEC), (edge, SPEC), (gone, SPEC)]),
               supersample=2)
    t_in, t_edge, t_gone = r.truth
    assert t_in.visible and not t_edge.visible and not t_gone.visible
    # field: u in [399.5 - 125, 399.5 + 125], pixel i covers [i - 0.5, i + 0.5]
    assert t_in.bbox == (275, 175, 250, 250)
    assert t_edge.bbox == (0, 175, 150, 250)  # field u in [-100.5, 149.5]
    assert t_gone.bbox[2] == 0


def test_look_tilts_the_normal_from_the_line_of_sight():
    for tilt, az in ((0.0, 0.0), (30.0, 45.0), (60.0, 250.0)):
        centre = np.array([120.0, -80.0, 450.0])
        pose = MarkerPose.look(centre, tilt, az, spin_deg=17.0)
        R = pose.rotation
        assert np.allclose(R.T @ R, np.eye(3)) and np.linalg.det(R) == pytest.approx(1.0)
        cosine = -pose.normal @ centre / np.linalg.norm(centre)
        assert math.degrees(math.acos(min(1.0, cosine))) == pytest.approx(tilt, abs=1e-6)
    with pytest.raises(ValueError):
        MarkerPose(np.array([0.0, 0.0, 500.0]), np.eye(3))  # normal +z: faces away


def test_chessboard_corners_are_where_the_projection_says():
    """A rendered calibration board: OpenCV's sub-pixel corners land on the projected truth."""
    import cv2

    from stationd.geometry.camera import Camera
    from stationd.sim.raycast import Chessboard
    from stationd.sim.render import MarkerPose, Scene, render

    cam = Camera(np.array([[1500.0, 0, 639.5], [0, 1500.0, 479.5], [0, 0, 1]]),
                 np.array([-0.1, 0.05, 0.0, 0.0]), (1280, 960))
    board = Chessboard(9, 6, 30.0)
    pose = MarkerPose.look(np.array([20.0, -10.0, 900.0]), 25, 40, 5)
    img = render(cam, Scene(boards=[(pose, board)], blur_sigma=0.8, noise_sigma=2.0),
                 seed=1).image
    grey = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    ok, c = cv2.findChessboardCorners(grey, (9, 6))
    assert ok
    c = cv2.cornerSubPix(grey, c.reshape(-1, 1, 2), (7, 7), (-1, -1),
                         (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4))
    truth = cam.project(pose.centre_mm + board.corners() @ pose.rotation.T)
    d = np.linalg.norm(c.reshape(-1, 1, 2) - truth[None], axis=2).min(axis=1)
    assert np.median(d) < 0.05 and d.max() < 0.15
