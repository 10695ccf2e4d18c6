"""``opencv://``: OpenCV VideoCapture on a recorded video (no camera device here)."""

import time

import cv2
import numpy as np
import pytest

from drivers.camera import EndOfStreamError, UnsupportedError, open_camera
from drivers.errors import ConnectError


@pytest.fixture
def video(tmp_path):
    path = tmp_path / "run.avi"
    w = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), 10, (64, 48))
    assert w.isOpened()
    for i in range(4):
        w.write(np.full((48, 64, 3), 40 * i + 20, np.uint8))
    w.release()
    return path


def test_frames_of_a_video_then_the_end(video):
    with open_camera(f"opencv://{video}") as cam:
        assert "video file" in cam.identity() and "64x48" in cam.identity()
        levels = []
        cam.trigger()  # grab() ... retrieve(): the multi-camera sync pattern
        levels.append(cam.grab())
        levels += [cam.grab() for _ in range(3)]
        with pytest.raises(EndOfStreamError, match="end of video after 4 frames"):
            cam.grab()
    assert [round(float(f.image.mean()) / 10) for f in levels] == [2, 6, 10, 14]
    assert [f.frame_id for f in levels] == [0, 1, 2, 3]
    assert all(f.image.shape == (48, 64, 3) for f in levels)


def test_no_such_camera_is_one_clear_error(capfd):
    with pytest.raises(ConnectError, match="OpenCV cannot open 57: no such camera"):
        open_camera("opencv://57")
    assert "WARN" not in capfd.readouterr().err  # OpenCV's own warnings are silenced


def test_no_exposure_control(video):
    with open_camera(f"opencv://{video}") as cam, pytest.raises(UnsupportedError):
        cam.set_exposure_us(1000)


class _SlowCapture:
    """The real VideoCapture, each read/grab 50 ms slow (a 20 MP frame over USB)."""

    def __init__(self, cap):
        self.cap = cap

    def __getattr__(self, name):
        attr = getattr(self.cap, name)
        if name in ("read", "grab"):
            def slow(*a):
                time.sleep(0.05)
                return attr(*a)
            return slow
        return attr


@pytest.mark.parametrize("triggered", [False, True])
def test_the_timestamp_is_the_request_not_the_end_of_the_read(video, triggered):
    with open_camera(f"opencv://{video}") as cam:
        cam._cap = _SlowCapture(cam._cap)
        t0 = time.time()
        if triggered:
            cam.trigger()  # VideoCapture.grab(): the exposure is requested here
        f = cam.grab()
        t1 = time.time()
    assert t0 <= f.timestamp < t0 + 0.03 and f.timestamp + 0.05 <= f.arrival <= t1
    assert f.delay_s >= 0.05
