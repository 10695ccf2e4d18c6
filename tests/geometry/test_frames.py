import math
import re

import numpy as np
import pytest

from stationd.geometry.frames import Transform, fit_affine, fit_rigid
from stationd.geometry.tool import ToolGeometry, bolt_end, fuse
from stationd.result import Refusal
from stationd.yamlio import YamlNode


def _rotation(rng):
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@pytest.mark.parametrize("n", [3, 4, 8])
def test_rigid_fit_recovers_the_transform(n):
    rng = np.random.default_rng(n)
    R, t = _rotation(rng), rng.uniform(-2000, 2000, 3)
    src = rng.uniform(-800, 800, (n, 3))
    T = fit_rigid(src, src @ R.T + t)
    assert isinstance(T, Transform)
    assert np.allclose(T.A, R, atol=1e-9) and np.allclose(T.t, t, atol=1e-6)
    assert T.rms_mm < 1e-6


def test_rigid_fit_with_noise_reports_residuals_and_finds_a_bad_point():
    rng = np.random.default_rng(1)
    R, t = _rotation(rng), np.array([100.0, -50.0, 1200.0])
    src = rng.uniform(-800, 800, (6, 3))
    dst = src @ R.T + t + rng.normal(0, 0.05, (6, 3))
    dst[2] += [3.0, 0, 0]  # one reference point measured wrong
    T = fit_rigid(src, dst)
    assert isinstance(T, Transform)
    assert int(np.argmax(T.residuals_mm)) == 2 and T.residuals_mm[2] > 1.5


def test_affine_fit_and_its_limits():
    rng = np.random.default_rng(2)
    A = np.eye(3) + rng.normal(0, 0.01, (3, 3))
    src = rng.uniform(-800, 800, (5, 3))
    T = fit_affine(src, src @ A.T + [1, 2, 3])
    assert isinstance(T, Transform) and np.allclose(T.A, A, atol=1e-9)
    flat = src.copy()
    flat[:, 2] = 0.0
    assert "coplanar" in fit_affine(flat, flat).reason
    # the vehicle points in one plane: A would be singular (flatten the third axis)
    assert "vehicle points are coplanar" in fit_affine(src, flat).reason
    assert "at least 4" in fit_affine(src[:3], src[:3]).reason


def test_rigid_refuses_degenerate_input():
    line = np.outer(np.arange(4.0), [1.0, 2.0, 3.0])
    assert "collinear" in fit_rigid(line, line).reason
    assert "at least 3" in fit_rigid(line[:2], line[:2]).reason
    bad = line.copy()
    bad[0, 0] = np.nan
    assert isinstance(fit_rigid(bad, line), Refusal)


def test_transform_from_yaml_checks_rotation():
    node = YamlNode.parse("A: [[1, 0, 0], [0, 1, 0], [0, 0, 2]]\nt: [0, 0, 0]\n", "v.yaml")
    with pytest.raises(Exception, match="rotation"):
        Transform.from_node(node)


def test_bolt_end_compensates_tilt():
    tool = ToolGeometry(length_mm=300.0, max_tilt_deg=10.0)
    centre = np.array([100.0, 200.0, 50.0])
    tilt = math.radians(5.0)
    axis = np.array([math.sin(tilt), 0.0, math.cos(tilt)])  # wrench leaning towards +x
    end = bolt_end(centre, -axis, tool)
    assert not isinstance(end, Refusal)
    assert np.allclose(end.point_mm, centre + 300.0 * axis)
    assert abs(end.tilt_deg - 5.0) < 1e-9
    paper = bolt_end(centre, -axis, ToolGeometry(length_mm=300.0, rule="perpendicular"))
    # the perpendicular assumption misses the bolt by L sin(tilt) = 26 mm
    assert abs(np.hypot(*(paper.point_mm - end.point_mm)[:2]) - 300 * math.sin(tilt)) < 1e-9
    assert "tilted 12.0 deg" in bolt_end(centre, -np.array(
        [math.sin(math.radians(12)), 0, math.cos(math.radians(12))]), tool).reason


def test_fusion_weights_and_refuses_disagreement():
    a, b = np.array([0.0, 0.0, 0.0]), np.array([0.3, 0.0, 0.0])
    f = fuse([a, b], [0.1, 0.2], max_spread_mm=1.0)
    assert np.allclose(f.point_mm, [0.06, 0, 0]) and f.spread_mm < 0.3
    assert "disagree" in fuse([a, np.array([5.0, 0, 0])], [0.1, 0.1], 1.0).reason


def test_implausible_registrations_are_told_with_their_likely_cause():
    """Issue 19: pair points in metres fitted (rigid) with an RMS of 70.6 mm and were used;
    an affine fit absorbs the factor 1000 with a tiny RMS: both refused by the scales of the
    point sets, with the likely cause; a bad point by the RMS bound."""
    from stationd.geometry.frames import MAX_RMS_MM, implausible

    rng = np.random.default_rng(3)
    R, t = _rotation(rng), np.array([1500.0, -900.0, 1400.0])
    src = rng.uniform(-600, 600, (6, 3))
    dst = src @ R.T + t + rng.normal(0, 0.05, (6, 3))
    good = fit_rigid(src, dst)
    assert isinstance(good, Transform) and implausible(good, src, dst) is None
    for fit in (fit_rigid, fit_affine):
        tf = fit(src / 1000, dst)
        assert isinstance(tf, Transform)
        refused = implausible(tf, src / 1000, dst)
        assert refused is not None and "the pair points in metres?" in refused.reason
    tf = fit_rigid(src, dst / 1000)
    assert isinstance(tf, Transform)
    assert "the vehicle points in metres?" in implausible(tf, src, dst / 1000).reason
    bad = dst.copy()
    bad[2, 0] += 25.0
    tf = fit_rigid(src, bad)
    assert isinstance(tf, Transform) and tf.rms_mm > MAX_RMS_MM
    assert f"more than {MAX_RMS_MM:g} mm" in implausible(tf, src, bad).reason


def test_a_registration_keeps_its_rms_and_one_beyond_the_bound_is_refused():
    from stationd.errors import ConfigError

    rng = np.random.default_rng(4)
    src = rng.uniform(-600, 600, (5, 3))
    tf = fit_rigid(src, src + rng.normal(0, 0.1, (5, 3)))
    assert isinstance(tf, Transform)
    d = tf.to_dict()
    assert set(d) == {"kind", "A", "t", "rms_mm"} and d["rms_mm"] == round(tf.rms_mm, 4)
    import yaml

    back = Transform.from_node(YamlNode.parse(yaml.safe_dump(d)))
    assert np.allclose(back.A, tf.A) and np.allclose(back.t, tf.t)
    with pytest.raises(ConfigError, match=r"<string>:\d+: rms_mm: the registration's RMS "
                       "residual is 3.5 mm, more than 2 mm"):
        Transform.from_node(YamlNode.parse(yaml.safe_dump({**d, "rms_mm": 3.5})))
    with pytest.raises(ConfigError, match="expected a number"):
        Transform.from_node(YamlNode.parse(yaml.safe_dump({**d, "rms_mm": "small"})))


def test_a_mirrored_frame_is_told_before_any_point_is_blamed():
    """Issue 19: one axis's sign flipped for every point fits no rotation; its refusal named
    the point with the largest residual.  Points in one plane fit a rotation and its mirror
    image alike: nothing to tell, and they are not refused.  A stored affine registration
    that mirrors is refused when read."""
    from stationd.errors import ConfigError
    from stationd.geometry.frames import MIRRORED, implausible

    rng = np.random.default_rng(11)
    R, t = _rotation(rng), np.array([1500.0, -900.0, 1400.0])
    src = rng.uniform(-600, 600, (6, 3))
    dst = src @ R.T + t + rng.normal(0, 0.05, (6, 3))
    for axis in range(3):
        flipped = dst.copy()
        flipped[:, axis] *= -1
        for fit in (fit_rigid, fit_affine):
            tf = fit(src, flipped)
            assert isinstance(tf, Transform)
            refused = implausible(tf, src, flipped, [f"R{i}" for i in range(6)])
            assert refused is not None and refused.reason.startswith(MIRRORED), refused
            assert "largest residual" not in refused.reason
    flat = src.copy()
    flat[:, 2] = 0.0
    flipped = flat @ R.T + t
    flipped[:, 1] *= -1
    tf = fit_rigid(flat, flipped)
    assert isinstance(tf, Transform) and implausible(tf, flat, flipped) is None
    mirror = fit_affine(src, dst * np.array([1.0, -1.0, 1.0]))
    assert isinstance(mirror, Transform)
    node = YamlNode.parse(f"kind: affine\nA: {mirror.A.tolist()}\nt: {mirror.t.tolist()}\n",
                          "reg.yaml")
    with pytest.raises(ConfigError, match=re.escape(f"reg.yaml:2: A: {MIRRORED}; run")):
        Transform.from_node(node)


def test_one_point_beyond_its_bound_is_named_even_under_the_rms_bound():
    """One coordinate of eight points typed 5 mm off: the RMS stays under MAX_RMS_MM, the
    point's residual does not; it is named, and the others, refitted without it, give the
    value it should have.  Two bad points: the worst is named, none is called mistyped."""
    from stationd.geometry.frames import MAX_POINT_MM, MAX_RMS_MM, implausible

    rng = np.random.default_rng(5)
    R, t = _rotation(rng), np.array([1500.0, -900.0, 1400.0])
    src = rng.uniform(-600, 600, (8, 3))
    dst = src @ R.T + t + rng.normal(0, 0.05, (8, 3))
    names = [f"R{i + 1}" for i in range(8)]
    bad = dst.copy()
    bad[4, 2] += 5.0
    tf = fit_rigid(src, bad)
    assert isinstance(tf, Transform) and tf.rms_mm <= MAX_RMS_MM
    assert tf.residuals_mm is not None and tf.residuals_mm.max() > MAX_POINT_MM
    refused = implausible(tf, src, bad, names)
    assert refused is not None and refused.reason.startswith("R5 has a residual of ")
    assert "R5 is probably mistyped (its vehicle_mm z is" in refused.reason
    expected = float(refused.reason.split("the others put it at ")[1].split(")")[0].split()[0])
    assert abs(expected - dst[4, 2]) < 0.3
    bad[1, 0] -= 5.0
    tf = fit_rigid(src, bad)
    assert isinstance(tf, Transform)
    refused = implausible(tf, src, bad, names)
    assert refused is not None and "mistyped" not in refused.reason.replace(
        "probably mistyped or measured wrong", "")
