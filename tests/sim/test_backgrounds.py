"""The shared folder of rendered backgrounds: a background read back is the one the camera
would render; anything that changes the image is another file; without the folder nothing is
written.  (A small camera: the 20 MP ones only cost more time.)"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from stationd.geometry.camera import Camera
from stationd.sim import backgrounds
from stationd.sim.frames import FrameSource
from stationd.sim.render import MarkerPose, Scene, render
from stationd.vision.marker import MarkerSpec

CAM = Camera(np.array([[600.0, 0, 159.5], [0, 600.0, 119.5], [0, 0, 1]]),
             np.array([-0.05, 0.02, 0.0, 0.0]), (320, 240))
SCENE = Scene(texture=0.2, vignetting=0.3, blur_sigma=0.8, noise_sigma=2.0)


def _images(folder: Path) -> list[Path]:
    """The images in the folder (beside them: each one's lock)."""
    return sorted(folder.glob("*.npy"))


def test_a_background_is_rendered_once_then_read_back_equal(tmp_path, monkeypatch):
    monkeypatch.setenv(backgrounds.ENV, str(tmp_path))
    first = backgrounds.background(CAM, SCENE, 3)
    backgrounds.wait_stored()          # written beside the camera's work
    files = _images(tmp_path)
    assert len(files) == 1 and not list(tmp_path.glob("*.part"))   # written whole
    again = backgrounds.background(CAM, SCENE, 3)
    assert again is not first and np.array_equal(again, first)
    assert np.array_equal(again, render(CAM, SCENE, seed=3).image)
    # the frames of a camera on it: the very pixels of a full render
    pose = MarkerPose.look(np.array([10.0, -5.0, 500.0]), 20, 30, 0)
    frame = FrameSource(CAM, SCENE, seed=3).frame(pose)
    full = render(CAM, replace(SCENE, markers=[(pose, MarkerSpec())]), seed=3).image
    assert np.array_equal(frame, full)
    backgrounds.wait_stored()
    assert len(_images(tmp_path)) == 2           # the background, the marker's window


@pytest.mark.parametrize("change", ["seed", "scene", "camera", "fixed marker"])
def test_anything_that_changes_the_image_is_another_file(tmp_path, monkeypatch, change):
    monkeypatch.setenv(backgrounds.ENV, str(tmp_path))
    backgrounds.background(CAM, SCENE, 3)
    backgrounds.wait_stored()
    cam, scene, seed = CAM, SCENE, 3
    if change == "seed":
        seed = 4
    elif change == "scene":
        scene = replace(SCENE, noise_sigma=2.5)
    elif change == "camera":
        K = CAM.K.copy()
        K[0, 2] += 0.5
        cam = Camera(K, CAM.dist, CAM.size)
    else:
        pose = MarkerPose.look(np.array([0.0, 0.0, 500.0]), 0, 0, 0)
        scene = replace(SCENE, markers=[(pose, MarkerSpec())])
    other = backgrounds.background(cam, scene, seed)
    backgrounds.wait_stored()
    assert len(_images(tmp_path)) == 2
    assert np.array_equal(other, render(cam, scene, seed=seed).image)


def test_without_the_folder_nothing_is_written(tmp_path, monkeypatch):
    monkeypatch.setenv(backgrounds.ENV, "")
    monkeypatch.chdir(tmp_path)
    image = backgrounds.background(CAM, SCENE, 3)
    backgrounds.wait_stored()
    assert np.array_equal(image, render(CAM, SCENE, seed=3).image)
    assert list(tmp_path.iterdir()) == []


def test_an_unreadable_file_is_rendered_again(tmp_path, monkeypatch):
    """A file cut short (a full disk, a killed writer) is not an image: it is rendered and
    replaced."""
    monkeypatch.setenv(backgrounds.ENV, str(tmp_path))
    good = backgrounds.background(CAM, SCENE, 3)
    backgrounds.wait_stored()
    (path,) = _images(tmp_path)
    for cut in (path.read_bytes()[:1000], b""):     # cut short; empty (EOFError)
        path.write_bytes(cut)
        assert np.array_equal(backgrounds.background(CAM, SCENE, 3), good)
        backgrounds.wait_stored()
        assert np.array_equal(np.load(path), good)


def test_a_markers_window_is_rendered_once_then_read_back_equal(tmp_path, monkeypatch):
    """The window around a marker (a wrench put on a bolt) is kept as a background is: read
    back, it is the window the camera renders, and the frame composed from it the full
    render's; another pose is another file."""
    monkeypatch.setenv(backgrounds.ENV, str(tmp_path))
    pose = MarkerPose.look(np.array([10.0, -5.0, 500.0]), 20, 30, 0)
    src = FrameSource(CAM, SCENE, seed=3)
    first = src.patch(pose, seed=5)
    backgrounds.wait_stored()
    assert isinstance(first, tuple)
    (win, pixels), files = first, set(_images(tmp_path))
    assert len(files) == 1
    again = FrameSource(CAM, SCENE, seed=3).patch(pose, seed=5)
    assert isinstance(again, tuple) and again[0] == win
    assert again[1] is not pixels and np.array_equal(again[1], pixels)
    scene = replace(SCENE, markers=[(pose, MarkerSpec())])
    assert np.array_equal(again[1], render(CAM, scene, window=win, seed=5).image)
    moved = MarkerPose.look(np.array([12.0, -5.0, 500.0]), 20, 30, 0)
    src.patch(moved, seed=5)
    backgrounds.wait_stored()
    assert len(set(_images(tmp_path)) - files) == 1


def test_cameras_asking_at_once_wait_for_one_render(tmp_path, monkeypatch):
    """Cameras that ask for the same image at once (the test run's first stations, one per
    worker) get it from one render: the others wait for its file."""
    monkeypatch.setenv(backgrounds.ENV, str(tmp_path))
    renders: list[int] = []
    real = backgrounds.render.render

    def slow(*args, **kw):      # a render that takes a while, counted
        renders.append(1)
        time.sleep(0.3)
        return real(*args, **kw)

    monkeypatch.setattr(backgrounds.render, "render", slow)
    got: list[np.ndarray] = []
    threads = [threading.Thread(target=lambda: got.append(backgrounds.background(CAM, SCENE, 3)))
               for _ in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    backgrounds.wait_stored()
    assert len(got) == 3 and len(renders) == 1
    assert all(np.array_equal(g, got[0]) for g in got)
    assert np.array_equal(got[0], real(CAM, SCENE, seed=3).image)


def test_a_render_held_too_long_by_another_is_not_waited_for_without_end(tmp_path, monkeypatch):
    """Another process holds the image's lock and never lets go (stopped or stuck mid-render:
    a daemon under test once waited 90 s at "opening the devices"): after the bounded wait
    the camera renders its own, the same image, and keeps it."""
    import fcntl
    import os

    monkeypatch.setenv(backgrounds.ENV, str(tmp_path))
    monkeypatch.setattr(backgrounds, "LOCK_WAIT_S", 0.3)
    path = tmp_path / f"{backgrounds._key(CAM, SCENE, 4, None)}.npy"
    holder = os.open(path.with_suffix(".lock"), os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(holder, fcntl.LOCK_EX)
    try:
        t0 = time.monotonic()
        got = backgrounds.background(CAM, SCENE, 4)
        assert time.monotonic() - t0 >= 0.3
        backgrounds.wait_stored()
    finally:
        os.close(holder)
    assert np.array_equal(got, render(CAM, SCENE, seed=4).image)
    assert _images(tmp_path) == [path]
