"""``sim://PAIR/SIDE``: the in-process channel between simulated cameras and the world."""

import itertools
import time

import numpy as np
import pytest

from drivers.camera import open_camera, sim
from drivers.camera.base import UnsupportedError
from drivers.errors import ConnectError, ProtocolError, UrlError
from stationd.sim.render import Scene, crop_camera, default_camera, render

AT: list[float] = []


@pytest.fixture
def world():
    """A world that paints the side and seed into the image, and records its calls (side,
    seed) and, in ``AT``, the instants it was asked to render."""
    calls = []
    AT.clear()

    def source(side, seed, at):
        calls.append((side, seed))
        AT.append(at)
        img = np.zeros((8, 10, 3), np.uint8)
        img[..., 0] = seed % 256
        img[..., 2] = 1 if side == "left" else 2
        return img

    sim.register_world("Pair1", source)
    yield calls
    sim.unregister_world("Pair1")


def test_cameras_render_through_the_registered_world(world):
    with open_camera("sim://Pair1/left?seed=10") as left, \
            open_camera("sim://Pair1/right?seed=10") as right:
        assert "world registered" in left.identity()
        f0, g0 = left.grab(), right.grab()
        f1 = left.grab()
    assert world == [("left", 10), ("right", 10), ("left", 11)]
    assert (f0.frame_id, f1.frame_id, g0.frame_id) == (0, 1, 0)
    assert f0.image[0, 0].tolist() == [10, 0, 1] and g0.image[0, 0].tolist() == [10, 0, 2]
    assert f0.camera == "sim://Pair1/left?seed=10" and f0.pixel_format == "BGR8"


def test_the_pair_is_looked_up_at_grab_time():
    cam = open_camera("sim://late/left")  # the daemon may open cameras before the world
    try:
        with pytest.raises(ConnectError, match=r"no simulated world for pair 'late' \(none "
                                               r"registered\).*register_world\('late'"):
            cam.grab()
        sim.register_world("late", lambda side, seed, at: np.zeros((4, 4, 3), np.uint8))
        assert cam.grab().image.shape == (4, 4, 3)
        sim.unregister_world("late")
        with pytest.raises(ConnectError, match="no simulated world for pair 'late'"):
            cam.grab()
    finally:
        cam.close()


def test_unknown_pair_names_the_registered_ones(world):
    with open_camera("sim://pair2/left") as cam, \
            pytest.raises(ConnectError, match=r"\(registered: Pair1\)"):
        cam.grab()


def test_the_world_renders_the_trigger_instant_and_the_frame_carries_it(world):
    """A late grab still shows (and is stamped with) the trigger instant; ``arrival`` is the
    grab's, so the frame's delay covers the wait."""
    with open_camera("sim://Pair1/left") as cam:
        t0 = time.time()
        cam.trigger()
        t1 = time.time()
        time.sleep(0.05)
        f = cam.grab()
        t2 = time.time()
    assert AT == [f.timestamp] and t0 <= f.timestamp <= t1
    assert t1 + 0.05 <= f.arrival <= t2 and f.delay_s >= 0.05


def test_without_a_trigger_the_grab_is_the_trigger(world):
    with open_camera("sim://Pair1/left") as cam:
        t0 = time.time()
        f = cam.grab()
    assert AT == [f.timestamp] and t0 <= f.timestamp <= f.arrival


def test_frames_come_no_faster_than_the_frame_rate(world):
    """Exposures (triggered or not) are a frame period apart at least, the wait before the
    exposure: a frame's timestamp is still its exposure, and a stereo pair triggered
    together is still exposed together."""
    with open_camera("sim://Pair1/left?frame_rate=20") as left, \
            open_camera("sim://Pair1/right?frame_rate=20") as right:
        assert left.frame_period_s == pytest.approx(0.05)
        grabbed = [left.grab() for _ in range(3)]
        triggered = []
        for _ in range(3):
            left.trigger()
            right.trigger()
            triggered.append((left.grab(), right.grab()))
    stamps = [f.timestamp for f in grabbed] + [lf.timestamp for lf, _ in triggered]
    assert all(b - a >= 0.05 - 1e-3 for a, b in itertools.pairwise(stamps))
    assert all(abs(lf.timestamp - rf.timestamp) < 0.05 for lf, rf in triggered[1:])
    assert AT == [f.timestamp for f in grabbed] + [
        t for lf, rf in triggered for t in (lf.timestamp, rf.timestamp)]


def test_the_frame_rate_by_default_and_from_the_environment(monkeypatch):
    monkeypatch.delenv(sim.RATE_ENV, raising=False)
    assert sim.SimCamera("sim://p/left").frame_period_s == pytest.approx(1 / sim.FRAME_RATE)
    monkeypatch.setenv(sim.RATE_ENV, "4")
    assert sim.SimCamera("sim://p/left").frame_period_s == pytest.approx(0.25)
    assert sim.SimCamera("sim://p/left?frame_rate=8").frame_period_s == pytest.approx(0.125)
    monkeypatch.setenv(sim.RATE_ENV, "fast")
    with pytest.raises(UrlError, match=r"STATIOND_SIM_FRAME_RATE='fast' is not a frame rate"):
        sim.SimCamera("sim://p/left")
    for bad in ("0", "-3", "nan"):
        with pytest.raises(UrlError, match=rf"option frame_rate='{bad}' is not valid"):
            sim.SimCamera(f"sim://p/left?frame_rate={bad}")


def test_a_world_that_returns_no_image_is_a_protocol_error():
    sim.register_world("bad", lambda side, seed, at: np.zeros((4, 4), np.float32))
    try:
        with open_camera("sim://bad/left") as cam, \
                pytest.raises(ProtocolError, match=r"returned float32 \(4, 4\), not an HxWx3"):
            cam.grab()
    finally:
        sim.unregister_world("bad")


def test_registration_rules(world):
    with pytest.raises(ValueError, match="already registered"):
        sim.register_world("Pair1", lambda side, seed, at: np.zeros((1, 1, 3), np.uint8))
    sim.register_world("Pair1", lambda side, seed, at: np.zeros((1, 1, 3), np.uint8), replace=True)
    with pytest.raises(ValueError, match="without '/'"):
        sim.register_world("a/b", lambda side, seed, at: np.zeros((1, 1, 3), np.uint8))
    assert sim.registered_worlds() == ["Pair1"]


def test_exposure_and_gain_belong_to_the_world(world):
    with open_camera("sim://Pair1/left") as cam:
        with pytest.raises(UnsupportedError):
            cam.set_exposure_us(1000)
        with pytest.raises(UnsupportedError):
            cam.set_gain_db(1)


def test_a_world_rendering_with_the_station_renderer():
    """The intended use: the world renders its scene through the camera's calibration
    (a small window keeps this fast) with the frame's seed driving the sensor noise."""
    camera = crop_camera(default_camera(), (2700, 1800, 64, 48))
    scene = Scene(noise_sigma=3.0)

    def source(side, seed, at):
        return render(camera, scene, seed=seed, supersample=1).image

    sim.register_world("station", source)
    try:
        with open_camera("sim://station/left?seed=5") as a, \
                open_camera("sim://station/left?seed=5") as b:
            fa, fb, fa2 = a.grab(), b.grab(), a.grab()
    finally:
        sim.unregister_world("station")
    assert fa.image.shape == (48, 64, 3)
    assert np.array_equal(fa.image, fb.image)  # same seed, same frame
    assert not np.array_equal(fa.image, fa2.image)  # the next frame has new noise
