"""``file://``: replay of recorded images, natural order, looping, bad files."""

import os

import cv2
import numpy as np
import pytest

from drivers.camera import EndOfStreamError, FrameError, UnsupportedError, open_camera
from drivers.camera.replay import natural_key
from drivers.errors import ConnectError


def _write(path, value, grey=False):
    img = np.full((6, 8) if grey else (6, 8, 3), value, np.uint8)
    assert cv2.imwrite(str(path), img)


@pytest.fixture
def run(tmp_path):
    """left_1, left_2, left_10 (natural order differs from sorted()), plus a distractor."""
    for i in (10, 1, 2):
        _write(tmp_path / f"left_{i}.png", i)
    _write(tmp_path / "right_1.png", 99)
    return tmp_path


def _values(cam, n):
    return [int(cam.grab().image[0, 0, 0]) for _ in range(n)]


def test_natural_order_then_a_clear_end(run):
    with open_camera(f"file://{run}/left_*.png") as cam:
        assert "3 files, once" in cam.identity()
        assert _values(cam, 3) == [1, 2, 10]
        with pytest.raises(EndOfStreamError, match=r"all 3 files delivered.*\?loop=1"):
            cam.grab()
        with pytest.raises(EndOfStreamError):  # and stays ended
            cam.grab()
    assert sorted(["f_10", "f_9", "f_1"], key=natural_key) == ["f_1", "f_9", "f_10"]


def test_loop_starts_again(run):
    with open_camera(f"file://{run}/left_*.png?loop=1") as cam:
        frames = [cam.grab() for _ in range(7)]
    assert [int(f.image[0, 0, 0]) for f in frames] == [1, 2, 10, 1, 2, 10, 1]
    assert [f.frame_id for f in frames] == list(range(7))


def test_a_bad_file_is_reported_and_skipped(run):
    (run / "left_2.png").write_bytes(b"not a png")
    with open_camera(f"file://{run}/left_*.png?loop=1") as cam:
        assert _values(cam, 1) == [1]
        with pytest.raises(FrameError, match=r"left_2\.png: not a readable image \(skipped"):
            cam.grab()
        assert _values(cam, 2) == [10, 1]  # the replay continues
        os.remove(run / "left_10.png")  # deleted after open
        with pytest.raises(FrameError, match=r"left_2\.png"):
            cam.grab()
        with pytest.raises(FrameError, match=r"left_10\.png: no such file"):
            cam.grab()
        assert _values(cam, 1) == [1]


def test_grey_and_16_bit_files(tmp_path):
    _write(tmp_path / "a_1.png", 77, grey=True)
    assert cv2.imwrite(str(tmp_path / "a_2.png"), np.full((6, 8), 1000, np.uint16))
    with open_camera(f"file://{tmp_path}/a_*.png") as cam:
        assert cam.grab().image[0, 0].tolist() == [77, 77, 77]
        with pytest.raises(FrameError, match="uint16 pixels; an 8-bit image is needed"):
            cam.grab()


def test_directory_and_relative_forms(run, monkeypatch):
    with open_camera(f"file://{run}/") as cam:
        assert len(cam.files) == 4
    monkeypatch.chdir(run.parent)
    with open_camera(f"file://{run.name}/right_*.png") as cam:
        assert _values(cam, 1) == [99]


def test_nothing_to_replay(tmp_path):
    with pytest.raises(ConnectError, match=r"no files match .*/none_\*\.png"):
        open_camera(f"file://{tmp_path}/none_*.png")
    with pytest.raises(ConnectError, match="no image files in"):
        open_camera(f"file://{tmp_path}/")
    # a sweep: /dev/zero or a FIFO said "no files match" though the path exists
    import os

    os.mkfifo(tmp_path / "fifo")
    for path in ("/dev/zero", str(tmp_path / "fifo")):
        with pytest.raises(ConnectError, match="is a device or a FIFO, not an image file"):
            open_camera(f"file://{path}")


def test_trigger_time_and_no_exposure(run):
    import time

    with open_camera(f"file://{run}/left_*.png") as cam:
        t0 = time.time()
        cam.trigger()
        time.sleep(0.02)
        f = cam.grab()
        assert t0 <= f.timestamp < t0 + 0.015  # the trigger, not the file's date nor the grab
        assert f.arrival >= t0 + 0.02 and f.delay_s >= 0.02
        with pytest.raises(UnsupportedError):
            cam.set_exposure_us(100)
    cam.close()  # idempotent
