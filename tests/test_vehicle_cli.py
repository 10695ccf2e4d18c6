"""``stationd calibrate vehicle``: two pairs registered into one vehicle frame."""

import argparse

import cv2
import numpy as np
import pytest
import yaml

from stationd.config import load_station_config
from stationd.errors import InputError
from stationd.geometry.camera import Camera
from stationd.sim import scenes as sc
from stationd.sim.render import MarkerPose, Scene, render
from stationd.vehicle_cli import cmd_calibrate_vehicle
from tests.conftest import NOISE, SPEC


def _rot(deg, axis):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return {"z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
            "x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]])}[axis]


# true pair -> vehicle transforms: cameras below the car, looking up
TRUE = {"pair1": (_rot(180, "x") @ _rot(10, "z"), np.array([1500.0, -900.0, 1400.0])),
        "pair2": (_rot(180, "x") @ _rot(-20, "z"), np.array([2600.0, 850.0, 1350.0]))}
VEHICLE_POINTS = np.array([[1400, -1000, 0], [1700, -700, 40], [1300, -600, -30],
                           [1800, -1100, 10], [2300, 300, 20], [2500, 700, -10],
                           [2800, 500, 30], [1600, -900, 5],
                           [2050, -50, 0], [2150, 100, 20]], dtype=float)  # seen by both


def _pair_mm(pair, v):
    R, t = TRUE[pair]
    return R.T @ (v - t)


def _station(tmp_path, pair_file):
    cfg = tmp_path / "station.yaml"
    cfg.write_text(f"pairs:\n  pair1:\n    calibration: {pair_file}\n"
                   f"  pair2:\n    calibration: {pair_file}\n")
    return cfg


def _points(tmp_path, noise=0.03, bad=None, seed=0):
    rng = np.random.default_rng(seed)
    pts = []
    for i, v in enumerate(VEHICLE_POINTS):
        seen = {}
        for pair in ("pair1", "pair2"):
            p = _pair_mm(pair, v)
            if abs(p[0]) < 1300 and abs(p[1]) < 1300:  # in this pair's view
                seen[pair] = {"pair_mm": (p + rng.normal(0, noise, 3)).tolist()}
        if bad is not None and i == bad:
            seen = {k: {"pair_mm": (np.array(o["pair_mm"]) + np.array([4.0, 0, 0])).tolist()}
                    for k, o in seen.items()}
        pts.append({"name": f"R{i + 1}", "vehicle_mm": v.tolist(), "seen_by": seen})
    f = tmp_path / "points.yaml"
    f.write_text(yaml.safe_dump({"kind": "rigid", "points": pts}))
    return f


def _args(cfg, pts, pair, kind=None):
    return argparse.Namespace(config=str(cfg), points=str(pts), pair=pair, kind=kind)


def test_two_pairs_one_vehicle_frame(tmp_path, capsys):
    import shutil
    from pathlib import Path
    shutil.copy(Path(__file__).resolve().parents[1] / "config/sim/pair1.yaml", tmp_path)
    cfg = _station(tmp_path, "pair1.yaml")
    pts = _points(tmp_path)
    assert cmd_calibrate_vehicle(_args(cfg, pts, "pair1")) == 0
    assert cmd_calibrate_vehicle(_args(cfg, pts, "pair2")) == 0
    out = capsys.readouterr().out
    assert "RMS" in out and "agree to" in out and "DISAGREE" not in out
    loaded = load_station_config(cfg)
    for name, (R, t) in TRUE.items():
        tv = loaded.pairs[name].to_vehicle
        assert tv is not None and np.allclose(tv.A, R, atol=1e-3)
        assert np.linalg.norm(tv.t - t) < 0.5


def test_a_bad_reference_point_shows_and_pairs_disagree(tmp_path, capsys):
    import shutil
    from pathlib import Path
    shutil.copy(Path(__file__).resolve().parents[1] / "config/sim/pair1.yaml", tmp_path)
    cfg = _station(tmp_path, "pair1.yaml")
    good = _points(tmp_path)
    assert cmd_calibrate_vehicle(_args(cfg, good, "pair1")) == 0
    bad = _points(tmp_path, bad=7)  # R8 is seen by pair1 only: its residual stands out
    cmd_calibrate_vehicle(_args(cfg, bad, "pair1"))
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "R8: residual" in ln]
    assert lines and float(lines[-1].split()[2]) > 1.0


def test_refusals(tmp_path):
    import shutil
    from pathlib import Path
    shutil.copy(Path(__file__).resolve().parents[1] / "config/sim/pair1.yaml", tmp_path)
    cfg = _station(tmp_path, "pair1.yaml")
    pts = _points(tmp_path)
    with pytest.raises(InputError, match="not in"):
        cmd_calibrate_vehicle(_args(cfg, pts, "pair9"))
    few = tmp_path / "few.yaml"
    few.write_text(yaml.safe_dump({"points": yaml.safe_load(pts.read_text())["points"][:1]}))
    with pytest.raises(InputError, match="at least 3"):
        cmd_calibrate_vehicle(_args(cfg, few, "pair1"))
    unknown = tmp_path / "unknown.yaml"
    unknown.write_text("points:\n  - vehicle_mm: [0, 0, 0]\n    seen_by:\n      pairX: "
                       "{pair_mm: [0, 0, 0]}\n")
    with pytest.raises(Exception, match="no pair 'pairX'"):
        cmd_calibrate_vehicle(_args(cfg, unknown, "pair1"))


def test_reference_points_from_images(tmp_path, capsys):
    """The marker placed on each reference point, localized from rendered stereo images."""
    cam = Camera(np.array([[1600.0, 0, 639.5], [0, 1600.0, 479.5], [0, 0, 1]]),
                 np.zeros(5), (1280, 960))
    pair = sc.look_at_pair(cam, np.array([0.0, 0.0, 900.0]), 250.0)
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(pair.to_dict()))
    cfg = tmp_path / "station.yaml"
    cfg.write_text("pairs:\n  cam:\n    calibration: p.yaml\n")
    R = _rot(180, "x")
    t = np.array([1000.0, 0.0, 900.0])
    pts = []
    for i, p in enumerate([[-120, -80, 880], [130, -60, 920], [0, 110, 900], [90, 90, 860]]):
        p = np.array(p, float)
        pose = MarkerPose.look(p, 10, 45 * i, 0)
        for side, c, q in (("l", pair.left, pose), ("r", pair.right, sc.to_right(pair, pose))):
            img = render(c, Scene(markers=[(q, SPEC)], **NOISE), seed=i).image
            cv2.imwrite(str(tmp_path / f"{i}{side}.png"), img)
        pts.append({"vehicle_mm": (R @ p + t).tolist(),
                    "seen_by": {"cam": {"left": f"{i}l.png", "right": f"{i}r.png"}}})
    (tmp_path / "pts.yaml").write_text(yaml.safe_dump({"points": pts}))
    assert cmd_calibrate_vehicle(_args(cfg, tmp_path / "pts.yaml", "cam")) == 0
    tv = load_station_config(cfg).pairs["cam"].to_vehicle
    assert np.allclose(tv.A, R, atol=1e-3) and np.linalg.norm(tv.t - t) < 0.2


def test_a_bumped_pair_disagrees_with_the_next_registration(tmp_path, capsys):
    """pair1 was registered, then its camera was knocked (its points moved 5 mm): registering
    pair2 compares the shared points in the vehicle frame and fails (exit 1)."""
    import shutil
    from pathlib import Path
    shutil.copy(Path(__file__).resolve().parents[1] / "config/sim/pair1.yaml", tmp_path)
    cfg = _station(tmp_path, "pair1.yaml")
    assert cmd_calibrate_vehicle(_args(cfg, _points(tmp_path), "pair1")) == 0
    pts = yaml.safe_load(_points(tmp_path, seed=1).read_text())
    for p in pts["points"]:
        if "pair1" in p["seen_by"]:
            p["seen_by"]["pair1"]["pair_mm"][1] += 5.0
    bumped = tmp_path / "bumped.yaml"
    bumped.write_text(yaml.safe_dump(pts))
    assert cmd_calibrate_vehicle(_args(cfg, bumped, "pair2")) == 1
    assert "DISAGREE" in capsys.readouterr().out


def test_a_transform_that_cannot_be_written_is_one_line(tmp_path, capsys):
    import shutil
    from pathlib import Path

    from stationd.cli import main

    shutil.copy(Path(__file__).resolve().parents[1] / "config/sim/pair1.yaml", tmp_path)
    cfg = tmp_path / "station.yaml"
    cfg.write_text("pairs:\n  pair1:\n    calibration: pair1.yaml\n"
                   "    to_vehicle: no/such/pair1.vehicle.yaml\n"
                   "  pair2:\n    calibration: pair1.yaml\n")
    pts = _points(tmp_path)
    code = main(["calibrate", "vehicle", "--pair", "pair1", "--points", str(pts), "--config",
                 str(cfg)])
    err = capsys.readouterr().err
    assert code == 2 and "pair1.vehicle.yaml: cannot write" in err
    assert err.count("\n") == 1 and "Traceback" not in err
