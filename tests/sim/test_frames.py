import numpy as np

from stationd.geometry.camera import Camera
from stationd.sim import backgrounds
from stationd.sim.frames import FrameSource, mapping_of, mappings
from stationd.sim.render import MarkerPose, Scene, render
from stationd.vision.marker import MarkerSpec

CAM = Camera(np.array([[1500.0, 0, 799.5], [0, 1500.0, 599.5], [0, 0, 1]]),
             np.array([-0.05, 0.02, 0.0, 0.0]), (1600, 1200))
SCENE = Scene(texture=0.2, vignetting=0.3, blur_sigma=0.8, noise_sigma=2.0)


def test_composite_equals_a_full_render_with_the_same_seed():
    src = FrameSource(CAM, SCENE, seed=5)
    pose = MarkerPose.look(np.array([60.0, -40.0, 700.0]), 30, 45, 10)
    fast = src.frame(pose)
    full = render(CAM, Scene(**{**SCENE.__dict__, "markers": [(pose, MarkerSpec())]}),
                  seed=5).image
    assert np.array_equal(fast, full)


def test_no_marker_gives_the_background_and_the_cache_is_not_modified():
    src = FrameSource(CAM, SCENE, seed=1)
    bg = src.frame(None)
    src.frame(MarkerPose.look(np.array([0.0, 0.0, 800.0]), 10, 0, 0), seed=9)
    assert np.array_equal(src.frame(None), bg)


def test_a_marker_partly_out_of_view_is_the_part_of_its_window_on_the_sensor():
    """A marker at the edge changes only the part of its window on the sensor: that window is
    rendered (not the whole frame), and the frame equals the whole frame rendered."""
    src = FrameSource(CAM, SCENE, seed=2)
    for centre in ([-390.0, 0.0, 700.0], [380.0, 270.0, 700.0]):  # left edge; bottom right
        pose = MarkerPose.look(np.array(centre), 10, 0, 0)
        patch = src.patch(pose)
        assert isinstance(patch, tuple), "a window, not a whole frame"
        (x, y, w, h), _ = patch
        assert 0 <= x and 0 <= y and x + w <= 1600 and y + h <= 1200 and w * h < 1600 * 1200 / 4
        assert (x == 0 or x + w == 1600 or y == 0 or y + h == 1200), "clipped at an edge"
        full = render(CAM, Scene(**{**SCENE.__dict__, "markers": [(pose, MarkerSpec())]}),
                      seed=2).image
        img = src.compose(patch)
        assert np.array_equal(img, full) and not np.array_equal(img, src.frame(None))


def test_a_marker_wholly_out_of_view_is_just_the_background():
    src = FrameSource(CAM, SCENE, seed=3)
    pose = MarkerPose.look(np.array([-900.0, 0.0, 700.0]), 10, 0, 0)  # far left of the view
    assert np.array_equal(src.frame(pose), src.frame(None))


Window = tuple[tuple[int, int, int, int], np.ndarray]


def _two_patches(src: FrameSource) -> tuple[Window, Window]:
    a = src.patch(MarkerPose.look(np.array([-80.0, -50.0, 700.0]), 10, 0, 0), seed=11)
    b = src.patch(MarkerPose.look(np.array([90.0, 60.0, 700.0]), 20, 90, 0), seed=12)
    assert isinstance(a, tuple) and isinstance(b, tuple)
    return a, b


def _expected(src: FrameSource, patch: Window) -> np.ndarray:
    (x, y, w, h), pixels = patch
    want = src.background.copy()
    want[y:y + h, x:x + w] = pixels
    return want


def test_a_held_frame_is_never_written_into_by_later_grabs():
    src = FrameSource(CAM, SCENE, seed=4)
    a, b = _two_patches(src)
    held = src.compose(a)
    view = src.compose(a)[100:200, 100:200]  # only a view of this one is kept
    view_copy = view.copy()
    for _ in range(6):                     # more grabs than the pool has buffers
        src.compose(b)
    assert np.array_equal(held, _expected(src, a))
    assert np.array_equal(view, view_copy)


def test_a_released_buffer_is_reused_with_the_old_window_put_back():
    src = FrameSource(CAM, SCENE, seed=6)
    a, b = _two_patches(src)
    first = src.compose(a)
    first_id = id(first)
    del first                               # the consumer is done with it
    second = src.compose(b)
    assert id(second) == first_id           # the same buffer, not a new 60 MB copy
    assert np.array_equal(second, _expected(src, b))   # and nothing of a is left


def test_a_buffer_costs_the_pages_its_windows_were_written_into() -> None:
    """The pool's buffers share the background's pages: one holds only what its windows
    changed (copied by the kernel on the first write: the mapping's anonymous pages), and the
    background stays read-only; what the page tables count for the camera is told."""
    src = FrameSource(CAM, SCENE, seed=7)
    a, b = _two_patches(src)
    frames = [src.compose(a), src.compose(b)]       # two held: two buffers
    assert not src.background.flags.writeable
    for frame, ((_, _, w, h), _px) in zip(frames, (a, b), strict=True):
        found = mapping_of(frame, mappings())
        assert found is not None
        copied = found[1]["Anonymous"]
        assert w * h * 3 <= copied <= h * (-(-w * 3 // 4096) + 1) * 4096
        assert copied < frame.nbytes / 2
    for frame, patch in zip(frames, (a, b), strict=True):   # read whole: mapped whole
        assert np.array_equal(frame, _expected(src, patch))
    assert 3 * src.background.nbytes <= src.resident_bytes() <= 3 * (frames[0].nbytes + 8192)


def test_frames_over_the_shared_render_folder_map_its_file(tmp_path, monkeypatch) -> None:
    """With the render folder, the background is its file's pages (read-only, shared by the
    processes that read it) and a frame a copy-on-write mapping of them: the file is never
    written, and the frames are what they are without the folder."""
    monkeypatch.setenv(backgrounds.ENV, str(tmp_path))
    assert FrameSource(CAM, SCENE, seed=8).background.size     # rendered and stored
    backgrounds.wait_stored()
    stored = {p: p.read_bytes() for p in tmp_path.glob("*.npy")}
    src = FrameSource(CAM, SCENE, seed=8)
    assert isinstance(src.background.base, np.memmap)   # read back, mapped
    a, b = _two_patches(src)
    held = [src.compose(a), src.compose(b), src.compose(a)]
    monkeypatch.delenv(backgrounds.ENV)
    plain = FrameSource(CAM, SCENE, seed=8)
    for frame, patch in zip(held, (a, b, a), strict=True):
        assert np.array_equal(frame, _expected(plain, patch))
    assert {p: p.read_bytes() for p in stored} == stored
