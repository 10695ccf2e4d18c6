"""The simulated world renders each camera as of its trigger instant (issue 9, item 4)."""

import time
from types import SimpleNamespace

import numpy as np
import pytest

from drivers.camera import open_camera
from stationd.geometry.camera import Camera
from stationd.sim.render import Scene
from stationd.sim.world import World, wrench_at
from stationd.vision.marker import MarkerSpec

# a small camera at the vehicle frame's origin looking along +z (the vehicle frame is the
# left camera's), so a bolt at z = 1000 mm puts the marker about 700 mm in front of it
CAM = Camera(np.array([[500.0, 0, 159.5], [0, 500.0, 119.5], [0, 0, 1]]), np.zeros(4), (320, 240))
LENGTH = 300.0


def _world(seed=0):
    cal = SimpleNamespace(left=CAM, right=CAM, R=np.eye(3), T=np.array([-100.0, 0.0, 0.0]))
    pair = SimpleNamespace(calibration=cal,
                           to_vehicle=SimpleNamespace(A=np.eye(3), t=np.zeros(3)))
    cfg = SimpleNamespace(pairs={"w": pair}, marker=MarkerSpec())
    return World(cfg, seed=seed, scene=Scene(noise_sigma=1.0))


def _marker_column(image, background):
    """The mean image column of the pixels the marker changed."""
    changed = np.abs(image.astype(int) - background.astype(int)).max(axis=2) > 40
    assert changed.sum() > 50, "the marker is not in the frame"
    return float(np.nonzero(changed)[1].mean())


def test_a_frame_shows_the_wrench_where_it_was_at_the_trigger():
    rng = np.random.default_rng(4)
    left_pose = wrench_at(np.array([-120.0, 0.0, 1000.0]), rng, LENGTH, 0.0)
    right_pose = wrench_at(np.array([120.0, 0.0, 1000.0]), rng, LENGTH, 0.0)
    world = _world()
    try:
        with open_camera("sim://w/left") as cam:
            background = cam.grab().image  # no wrench yet
            world.set_wrench(left_pose)
            cam.trigger()
            t_trigger = cam._triggered_at
            time.sleep(0.01)
            world.set_wrench(right_pose)  # the operator moves on before the grab
            frame = cam.grab()
            cam.trigger()
            now = cam.grab()  # and a frame triggered after the move shows the move
    finally:
        world.close()
    assert frame.timestamp == t_trigger
    u_then, u_now = _marker_column(frame.image, background), _marker_column(now.image, background)
    # the socket at x = -120 mm, 700 mm away: about u = 160 - 500 * 120 / 700 = 74
    assert u_then == pytest.approx(74, abs=8) and u_now == pytest.approx(246, abs=8)


def test_pose_history_answers_by_time_and_refuses_rewriting_the_past():
    rng = np.random.default_rng(1)
    a = wrench_at(np.array([0.0, 0.0, 1000.0]), rng, LENGTH)
    b = wrench_at(np.array([50.0, 0.0, 1000.0]), rng, LENGTH)
    world = _world()
    try:
        world.set_wrench(a, at=100.0)
        world.set_wrench(b, at=101.0)
        world.set_wrench(None, at=102.0)
        assert world.pose_at(99.0) is None and world.pose_at(100.0) is a
        assert world.pose_at(100.999) is a and world.pose_at(101.5) is b
        assert world.pose_at(1e12) is None and world.pose is None
        with pytest.raises(ValueError, match="time order"):
            world.set_wrench(a, at=101.5)
        world.set_wrench(a)  # now (far after 102) is accepted
        assert world.pose_at(time.time() + 1) is a
    finally:
        world.close()


def test_a_held_pose_is_rendered_once_and_composed_after():
    """A wrench held still: the second frame is composed from the first one's window (same
    pixels), and a new pose of the wrench is rendered anew."""
    rng = np.random.default_rng(6)
    a = wrench_at(np.array([-60.0, 0.0, 1000.0]), rng, LENGTH, 0.0)
    b = wrench_at(np.array([60.0, 0.0, 1000.0]), rng, LENGTH, 0.0)
    world = _world()
    try:
        with open_camera("sim://w/left") as cam:
            world.set_wrench(a)
            f1, f2 = cam.grab(), cam.grab()
            world.set_wrench(b)
            f3 = cam.grab()
        assert f1.image is not f2.image and np.array_equal(f1.image, f2.image)
        assert not np.array_equal(f1.image, f3.image)
        assert world.buffer_bytes() >= world.background("w", "left").nbytes
    finally:
        world.close()


def test_an_affine_vehicle_transform_is_inverted_not_transposed():
    """``x_v = A x_p + t`` with a scaled, sheared A (an affine registration): the marker
    the world places in the pair's frame maps back onto the vehicle-frame pose, and its axes
    stay a rotation."""
    w = _world()
    try:
        a = np.array([[1.02, 0.01, 0.0], [-0.02, 0.99, 0.03], [0.0, 0.01, 1.01]])
        t = np.array([5.0, -3.0, 2.0])
        w.cfg.pairs["w"].to_vehicle = SimpleNamespace(A=a, t=t)
        pose = wrench_at(np.array([10.0, 5.0, 1000.0]), np.random.default_rng(1), LENGTH)
        seen = w._camera_pose("w", "left", pose)
        assert seen is not None
        assert np.allclose(a @ seen.centre_mm + t, pose.centre_v, atol=1e-9)
        assert np.allclose(seen.rotation.T @ seen.rotation, np.eye(3), atol=1e-9)
    finally:
        w.close()


def test_seen_by_names_the_pairs_whose_two_cameras_see_the_marker():
    w = _world()
    try:
        rng = np.random.default_rng(2)
        here = wrench_at(np.array([-50.0, 0.0, 1000.0]), rng, LENGTH)
        assert w.seen_by(here, margin_px=10) == ["w"]
        assert w.seen_by(here, margin_px=130) == []     # the frames are only 320x240
        # far to the side: out of the frames
        assert w.seen_by(wrench_at(np.array([-900.0, 0.0, 1000.0]), rng, LENGTH),
                         margin_px=10) == []
    finally:
        w.close()
