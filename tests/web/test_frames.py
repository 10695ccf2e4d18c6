"""The latest-frame store: cheap hand-over, lazy downscaled JPEG, full-resolution crops."""

from __future__ import annotations

import cv2
import numpy as np

from stationd.web.frames import LatestFrames, sharpness


def frame(seed: int = 0, h: int = 600, w: int = 800) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 255, (h, w), dtype=np.uint8)


def test_jpeg_is_downscaled_and_cached_until_the_next_frame():
    store = LatestFrames()
    assert store.jpeg("p1", "left") is None
    img = frame()
    store.put("p1", "left", img, {"found": True}, grabbed_at=100.0)
    data = store.jpeg("p1", "left", width=200)
    assert data is not None
    small = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert small.shape == (150, 200)
    assert store.jpeg("p1", "left", width=200) is data        # cached, not re-encoded
    assert store.encoded == 1 and store.encode_wall_s > 0     # counted once (the bench)
    store.put("p1", "left", frame(1), grabbed_at=100.1)
    assert store.jpeg("p1", "left", width=200) is not data
    assert store.encoded == 2
    cam = store.get("p1", "left")
    assert cam is not None and cam.seq == 1 and abs((cam.fps or 0) - 10.0) < 1e-6


def test_overview_is_encoded_from_the_preview_never_wider_and_crops_stay_full_resolution():
    store = LatestFrames()
    img = frame(2, 800, 1600)
    preview = np.full((100, 200), 77, np.uint8)     # unlike the frame: tells which was used
    store.put("p1", "left", img, grabbed_at=1.0, preview=preview)
    for asked, shape in ((960, (100, 200)), (100, (50, 100))):
        data = store.jpeg("p1", "left", width=asked)
        assert data is not None
        got = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        assert got.shape == shape
        assert abs(float(got.mean()) - 77.0) < 2.0
    data = store.crop("p1", "left", x=800, y=400, size=64)
    assert data is not None
    crop = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert crop.shape == (64, 64)
    assert abs(float(crop.mean()) - float(img[368:432, 768:832].mean())) < 3.0


def test_crop_is_full_resolution_and_clamped_inside():
    store = LatestFrames()
    img = frame()
    store.put("p1", "right", img)
    data = store.crop("p1", "right", x=790, y=5, size=100)
    assert data is not None
    crop = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert crop.shape == (100, 100)
    # clamped to the bottom-left corner of the request: the top-right 100 x 100 of the image
    assert abs(float(crop.mean()) - float(img[0:100, 700:800].mean())) < 3.0


def test_sharpness_ranks_a_sharp_roi_above_a_blurred_one():
    img = np.zeros((200, 200), np.uint8)
    img[::8, :] = 255
    blurred = cv2.GaussianBlur(img, (0, 0), 4)
    assert sharpness(img, (0, 0, 100, 100)) > 10 * sharpness(blurred, (0, 0, 100, 100))
    assert sharpness(img, (500, 500, 10, 10)) == 0.0


def test_reduce_matches_one_area_resize_and_does_not_alias():
    """Halving steps then one area step: the picture of a single area resize (smooth
    content within 2 grey levels), every pixel still averaged (noise smoothed at least as
    much, no point sampling), any size and colour."""
    from stationd.web.frames import reduce

    yy, xx = np.mgrid[0:1823, 0:2737]          # odd sizes: the halving drops one row/column
    smooth = (127 + 100 * np.sin(xx / 150) * np.cos(yy / 100)).astype(np.uint8)
    noise = frame(3, 1823, 2737)
    for width in (200, 480, 700, 1500):
        size = (width, round(1823 * width / 2737))
        direct = cv2.resize(smooth, size, interpolation=cv2.INTER_AREA).astype(int)
        got = reduce(smooth, width)
        assert got.shape == direct.shape and got.dtype == np.uint8
        assert np.abs(got.astype(int) - direct).max() <= 2
        area_std = cv2.resize(noise, size, interpolation=cv2.INTER_AREA).std()
        assert reduce(noise, width).std() <= area_std * 1.02
        assert reduce(noise, width).std() < noise.std() / 2     # averaged, not sampled
    colour = np.dstack([smooth, noise, smooth])
    assert reduce(colour, 300).shape == (200, 300, 3)

