"""One contract, every backend (python-can's way): what the station may rely on whatever the
camera is -- Aravis's fake GigE camera, a file replay, a video through OpenCV, the sim channel."""

import cv2
import numpy as np
import pytest

from drivers.camera import CameraDevice, Frame, open_camera, sim
from drivers.errors import DeviceError

KW = {"timeout": 1.0}  # every backend takes these
#: how long a grab may wait: the frame ends it (milliseconds here); a machine loaded by other
#: work delayed the fake camera's past 1 s
GRAB_S = 30.0


KINDS = ["aravis", "file", "opencv", "sim"]


@pytest.fixture(params=KINDS)
def url(request, tmp_path):
    kind = request.param
    if kind == "aravis":
        yield request.getfixturevalue("fake").url("region=0,0,64,48&pixel_format=BayerGB8")
    elif kind == "file":
        for i in range(3):
            cv2.imwrite(str(tmp_path / f"f_{i}.png"), np.full((48, 64, 3), i, np.uint8))
        yield f"file://{tmp_path}/f_*.png?loop=1"
    elif kind == "opencv":
        w = cv2.VideoWriter(str(tmp_path / "v.avi"), cv2.VideoWriter.fourcc(*"MJPG"), 10,
                            (64, 48))
        for _ in range(5):
            w.write(np.zeros((48, 64, 3), np.uint8))
        w.release()
        yield f"opencv://{tmp_path}/v.avi"
    else:
        sim.register_world("contract", lambda side, seed, at: np.zeros((48, 64, 3), np.uint8))
        yield "sim://contract/left"
        sim.unregister_world("contract")


def test_trigger_then_grab_gives_a_bgr_frame(url):
    with open_camera(url, **KW) as cam:
        assert isinstance(cam, CameraDevice) and cam.identity()
        for _ in range(2):
            cam.trigger()
            f = cam.grab(GRAB_S)
            assert isinstance(f, Frame) and f.camera == url
            assert f.image.shape == (48, 64, 3) and f.image.dtype == np.uint8
            assert f.image.flags.writeable and f.timestamp > 1.6e9


def test_open_and_close_are_idempotent(url):
    cam = open_camera(url, **KW)
    cam.open()
    cam.close()
    cam.close()
    assert not cam.is_open
    for call in (cam.trigger, cam.grab):
        with pytest.raises(DeviceError, match="not open"):
            call()
    with cam:  # and it opens again
        cam.trigger()
        assert cam.grab(GRAB_S).image.shape == (48, 64, 3)


def test_arguments_are_checked(url):
    with open_camera(url, **KW) as cam:
        with pytest.raises(ValueError, match="timeout must be > 0"):
            cam.grab(0)
        with pytest.raises(ValueError, match="exposure must be > 0"):
            cam.set_exposure_us(-1)
        with pytest.raises(ValueError, match="gain must be finite"):
            cam.set_gain_db(float("nan"))


def test_every_registered_backend_keeps_the_contract():
    """A backend registered for a scheme is in this suite (a new one must be added here)."""
    from drivers.camera import BACKENDS

    assert set(BACKENDS) == set(KINDS)
