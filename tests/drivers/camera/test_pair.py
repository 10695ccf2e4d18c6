"""StereoGrabber: one trigger for both cameras, frames refused when too far apart in time."""

import time

import numpy as np
import pytest

from drivers.camera import open_camera, sim
from drivers.camera.base import CameraDevice, Frame
from drivers.camera.pair import FrameMissingError, StereoGrabber, StereoSkewError
from drivers.errors import DeviceTimeoutError


class Scripted(CameraDevice):
    """A camera whose frames carry the timestamps the test gives it (None: no frame)."""

    def __init__(self, url, stamps):
        super().__init__(url, timeout=0.5)
        self.stamps = list(stamps)
        self.triggers = 0

    def identity(self):
        return "scripted"

    def _open(self):
        pass

    def _close(self):
        pass

    def _trigger(self):
        self.triggers += 1

    def _grab(self, timeout):
        t = self.stamps.pop(0)
        if t is None:
            raise DeviceTimeoutError(f"no frame within {timeout:g} s", device=self.url)
        return Frame(np.zeros((2, 2, 3), np.uint8), t, self.triggers, self.url)


def _pair(left, right, skew=0.005):
    a, b = Scripted("L", left), Scripted("R", right)
    a.open()
    b.open()
    return StereoGrabber(a, b, skew), a, b


def test_frames_within_the_skew_pass():
    g, a, b = _pair([100.000, 101.0], [100.004, 101.0])
    left, right = g.grab()
    assert (left.camera, right.camera) == ("L", "R") and a.triggers == b.triggers == 1
    assert g.grab()[0].timestamp == 101.0


def test_the_skew_is_between_exposures_not_arrivals():
    """The right frame arrives 40 ms after the left (transfer, rendering): exposed together,
    the pair is good."""
    class SlowRight(Scripted):
        def _grab(self, timeout):
            time.sleep(0.04)
            return super()._grab(timeout)

    a, b = Scripted("L", [100.0]), SlowRight("R", [100.001])
    a.open()
    b.open()
    left, right = StereoGrabber(a, b, 0.005).grab()
    assert right.arrival - left.arrival >= 0.04 and right.timestamp - left.timestamp < 0.005


def test_frames_too_far_apart_are_refused():
    g, _, _ = _pair([100.000], [100.012])
    with pytest.raises(StereoSkewError, match=r"12\.0 ms apart, more than the 5\.0 ms") as err:
        g.grab()
    assert err.value.skew_s == pytest.approx(0.012)
    assert [f.camera for f in err.value.frames] == ["L", "R"]


@pytest.mark.parametrize("left,right,missing", [([None], [1.0], "left"),
                                                 ([1.0], [None], "right"),
                                                 ([None], [None], "left and right")])
def test_a_missing_frame_names_the_side(left, right, missing):
    g, _, _ = _pair(left, right)
    with pytest.raises(FrameMissingError, match=f"no frame from {missing} within") as err:
        g.grab()
    assert all(isinstance(e, DeviceTimeoutError) for e in err.value.errors.values())


def test_a_closed_camera_is_a_missing_frame():
    g, a, _ = _pair([1.0], [1.0])
    a.close()
    with pytest.raises(FrameMissingError, match=r"left: the camera is not open \(L\)"):
        g.grab()


def test_a_missing_frame_says_why_before_which_camera():
    """A technician's trial: a camera lost mid-run made the operator's headline "FAULT: p1:
    stereo aravis://...&region=0,0,64,48 +...", both URLs and no reason.  The reason comes
    first, each camera's URL after its words; unnamed (the station names the pair), nothing
    before it."""
    from drivers.camera.pair import StereoGrabber

    g, a, b = _pair([None, None], [1.0, 1.0])
    with pytest.raises(FrameMissingError) as err:
        StereoGrabber(a, b, 0.005, name="").grab(0.2)
    assert str(err.value).startswith("no frame from left within 0.2 s: left: "), err.value
    assert str(err.value).endswith(f"({a.url})") and str(err.value).count(a.url) == 1
    with pytest.raises(FrameMissingError, match=rf"^stereo {a.url} \+ {b.url}: no frame"):
        g.grab(0.2)


def test_arguments():
    a = Scripted("L", [])
    with pytest.raises(ValueError, match="two different cameras"):
        StereoGrabber(a, a, 0.01)
    with pytest.raises(ValueError, match="max_skew_s"):
        StereoGrabber(a, Scripted("R", []), -1)


def test_a_simulated_pair_is_in_step():
    """Simulated cameras stamp the trigger time, so rendering order makes no skew."""
    sim.register_world("p", lambda side, seed, at: np.full((4, 4, 3), seed, np.uint8))
    try:
        with open_camera("sim://p/left?seed=3") as left, \
                open_camera("sim://p/right?seed=3") as right:
            for _ in range(2):
                fl, fr = StereoGrabber(left, right, 0.002).grab(1.0)
                assert fl.frame_id == fr.frame_id and np.array_equal(fl.image, fr.image)
    finally:
        sim.unregister_world("p")
