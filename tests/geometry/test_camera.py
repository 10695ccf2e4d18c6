import cv2
import numpy as np
import pytest

from stationd.errors import ConfigError
from stationd.geometry.camera import Camera, StereoPair

K = np.array([[5000.0, 0, 2735.5], [0, 5000.0, 1823.5], [0, 0, 1]])


@pytest.mark.parametrize("dist", [
    [],
    [-0.08, 0.12, 2e-4, -1e-4],
    [-0.08, 0.12, 2e-4, -1e-4, -0.03],
    [0.3, -0.2, 1e-3, -5e-4, 0.05, 0.35, -0.15, 0.06],
])
def test_projection_matches_opencv_and_inverts(dist):
    cam = Camera(K, np.array(dist))
    rng = np.random.default_rng(3)
    P = np.c_[rng.uniform(-500, 500, (500, 2)), rng.uniform(800, 2000, 500)]
    uv = cam.project(P)
    ref = cv2.projectPoints(P, np.zeros(3), np.zeros(3), K, np.array(dist, float))[0]
    assert np.abs(uv - ref.reshape(-1, 2)).max() < 1e-8
    xy = cam.pixels_to_normalized(uv)
    assert np.abs(xy - P[:, :2] / P[:, 2:]).max() * 5000 < 1e-8
    und = cam.undistort_pixels(uv)
    assert np.abs(cam.distort_pixels(und) - uv).max() < 1e-8


def test_rejects_bad_models():
    with pytest.raises(ValueError, match="3x3"):
        Camera(np.eye(2))
    with pytest.raises(ValueError, match="0, 4, 5 or 8"):
        Camera(K, np.zeros(3))


def test_yaml_round_trip_and_errors(tmp_path):
    cam = Camera(K, np.array([-0.1, 0.1, 0, 0, 0]), (5472, 3648))
    import yaml
    p = tmp_path / "cam.yaml"
    p.write_text(yaml.safe_dump(cam.to_dict()))
    back = Camera.load(p)
    assert np.allclose(back.K, cam.K) and np.allclose(back.dist, cam.dist)
    assert back.size == (5472, 3648)
    p.write_text("K: [[1, 0], [0, 1]]\nsize: [10, 10]\n")
    with pytest.raises(ConfigError, match=r"cam.yaml:1: K: expected a 3x3 matrix"):
        Camera.load(p)
    p.write_text("K: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\nsize: [10, 10]\nfocal: 3\n")
    with pytest.raises(ConfigError, match="unknown key"):
        Camera.load(p)


def test_pair_requires_rotation(tmp_path):
    cam = Camera(K)
    with pytest.raises(ValueError, match="rotation"):
        StereoPair(cam, cam, np.diag([1.0, 1.0, -1.0]), np.zeros(3))


def test_a_pair_whose_right_camera_is_on_the_left_is_said_swapped():
    """``x_right = R x_left + T``: the right camera's centre ``-R.T T`` is at +x of the left
    camera (T's x negative).  At -x the images were given the other way round; a camera
    above the other is neither."""
    cam = Camera(K)
    assert StereoPair(cam, cam, np.eye(3), np.array([-100.0, 2.0, 3.0])).swapped() is None
    said = StereoPair(cam, cam, np.eye(3), np.array([100.0, 2.0, 3.0])).swapped()
    assert said is not None and said.startswith("the right camera is 100 mm to the left of "
                                                "the left camera (T's x is +100.0 mm")
    assert said.endswith("left and right swapped?")
    assert StereoPair(cam, cam, np.eye(3), np.array([20.0, -100.0, 0.0])).swapped() is None


def test_a_calibrations_digest_is_its_values(tmp_path):
    """The same file read twice is one calibration; any value changed (a pair calibrated
    again) is another, to which the station pins the cameras anew."""
    from pathlib import Path

    import yaml

    src = Path(__file__).resolve().parents[2] / "config" / "sim" / "pair1.yaml"
    a, b = StereoPair.load(src), StereoPair.load(src)
    assert a.digest() == b.digest() and len(a.digest()) == 32
    data = yaml.safe_load(src.read_text())
    for path in (("left", "K", 0, 0), ("right", "dist", 1), ("T", 0), ("left", "size", 0)):
        changed = yaml.safe_load(src.read_text())
        node = changed
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = node[path[-1]] + 1
        out = tmp_path / "pair.yaml"
        out.write_text(yaml.safe_dump(changed))
        assert StereoPair.load(out).digest() != a.digest(), path
    out.write_text(yaml.safe_dump(data))
    assert StereoPair.load(out).digest() == a.digest()
