"""``stationd calibrate vehicle``: two pairs registered into one vehicle frame."""

import argparse

import cv2
import numpy as np
import pytest
import yaml

from stationd.config import load_station_config
from stationd.errors import InputError
from stationd.geometry.camera import Camera
from stationd.localize.references import project
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
    # a running daemon uses the file from its next reload: said (a maintenance trial)
    assert out.count("a running daemon reads it at its next reload") == 2
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


def _station_with_pair1(tmp_path):
    import shutil
    from pathlib import Path

    shutil.copy(Path(__file__).resolve().parents[1] / "config/sim/pair1.yaml", tmp_path)
    return _station(tmp_path, "pair1.yaml")


def _main(capsys, *argv):
    from stationd.cli import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_pair_points_in_metres_are_refused_and_nothing_written(tmp_path, capsys):
    """Issue 19: the pair points in metres fitted with an RMS of 70.6 mm, the registration
    was written and the command exited 0 (tens of mm is a wrong bolt).  Refused with the
    likely cause, exit 1, nothing written; an affine fit, which would absorb the factor 1000
    with a tiny RMS, too."""
    cfg = _station_with_pair1(tmp_path)
    data = yaml.safe_load(_points(tmp_path).read_text())
    for p in data["points"]:
        for o in p["seen_by"].values():
            o["pair_mm"] = [v / 1000 for v in o["pair_mm"]]
    metres = tmp_path / "metres.yaml"
    for kind in ("rigid", "affine"):
        metres.write_text(yaml.safe_dump({**data, "kind": kind}))
        code, out, err = _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points",
                               metres, "--config", cfg)
        assert code == 1 and "wrote" not in out and "residual" in out, kind
        assert "the pair points in metres? give pair_mm in millimetres" in err, err
        assert "not written" in err and err.count("\n") == 1 and "Traceback" not in err
        assert not (tmp_path / "pair1.vehicle.yaml").exists()


def test_a_registration_with_an_implausible_rms_is_refused_the_earlier_one_kept(tmp_path,
                                                                                capsys):
    from stationd.geometry.frames import MAX_RMS_MM

    cfg = _station_with_pair1(tmp_path)
    assert _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points",
                 _points(tmp_path), "--config", cfg)[0] == 0
    good = (tmp_path / "pair1.vehicle.yaml").read_bytes()
    data = yaml.safe_load(_points(tmp_path).read_text())
    data["points"][7]["seen_by"]["pair1"]["pair_mm"][0] += 30.0   # R8: typed 30 mm off
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(data))
    code, out, err = _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points",
                           bad, "--config", cfg)
    assert code == 1 and "wrote" not in out and err.count("\n") == 1
    assert f"more than {MAX_RMS_MM:g} mm" in err and "R8 has the largest residual" in err
    assert (tmp_path / "pair1.vehicle.yaml").read_bytes() == good


def test_reference_points_of_one_name_are_refused(tmp_path, capsys):
    """Issue 19: three reference points all named R1 were accepted."""
    cfg = _station_with_pair1(tmp_path)
    data = yaml.safe_load(_points(tmp_path).read_text())
    for p in data["points"][:3]:
        p["name"] = "R1"
    dup = tmp_path / "dup.yaml"
    dup.write_text(yaml.safe_dump(data))
    code, out, err = _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points", dup,
                           "--config", cfg)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "two reference points are named 'R1'" in err and "dup.yaml:" in err
    assert not (tmp_path / "pair1.vehicle.yaml").exists()


def test_config_check_refuses_a_stored_registration_with_an_implausible_rms(tmp_path, capsys):
    """Issue 19: ``config check`` passed the registration of the metres run (its RMS only in
    the header comment then): refused with its file and line, as one with ``rms_mm``."""
    cfg = _station_with_pair1(tmp_path)
    assert _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points",
                 _points(tmp_path), "--config", cfg)[0] == 0
    written = (tmp_path / "pair1.vehicle.yaml").read_text()
    stored = yaml.safe_load(written)
    assert 0 < stored["rms_mm"] < 0.1
    code, out, err = _main(capsys, "config", "check", cfg)   # (a partial station: no devices)
    assert "pair1.vehicle.yaml" not in out + err and "RMS" not in out + err
    body = {k: stored[k] for k in ("kind", "A", "t")}
    for text in (
        # as the command wrote it before rms_mm was a key (issue 19's file)
        "# pair1 -> vehicle frame, rigid fit to 8 points from m.yaml; RMS 70.600 mm\n"
        "# x_vehicle = A x_pair + t (mm)\n" + yaml.safe_dump(body),
        yaml.safe_dump({**body, "rms_mm": 70.6}),
    ):
        (tmp_path / "pair1.vehicle.yaml").write_text(text)
        code, out, err = _main(capsys, "config", "check", cfg)
        assert code == 2 and "pair1.vehicle.yaml" in out + err
        assert "RMS residual is 70.6 mm, more than 2 mm" in out + err
        with pytest.raises(InputError, match=r"RMS residual is 70\.6 mm"):
            load_station_config(cfg)


def test_the_registration_never_replaces_another_file_or_follows_a_link(tmp_path, capsys):
    """The pair's to_vehicle file is an output like any other: a link (here to the sim's
    registration of pair1) is refused before any point is localized, neither it nor its
    target replaced; a station file named there is refused too (the station file's reader
    stops at it first), untouched."""
    import shutil
    from pathlib import Path

    sim = Path(__file__).resolve().parents[1] / "config/sim"
    shutil.copy(sim / "pair1.yaml", tmp_path)
    shutil.copy(sim / "pair1.vehicle.yaml", tmp_path / "kept.vehicle.yaml")
    shutil.copy(sim / "station.yaml", tmp_path / "other.yaml")
    (tmp_path / "link.yaml").symlink_to(tmp_path / "kept.vehicle.yaml")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    for target, needle in (("link.yaml", "link.yaml: is a symbolic link to "
                                         f"{tmp_path / 'kept.vehicle.yaml'}, a vehicle "
                                         "registration (from calibrate vehicle); an output "
                                         "is never written through or over a link"),
                           ("other.yaml", "other.yaml:")):
        cfg = tmp_path / "station.yaml"
        cfg.write_text(f"pairs:\n  pair1:\n    calibration: pair1.yaml\n"
                       f"    to_vehicle: {target}\n")
        code, out, err = _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points",
                               _points(tmp_path), "--config", cfg)
        assert code == 2 and needle in err and err.count("\n") == 1, err
        assert "wrote" not in out
    assert (tmp_path / "link.yaml").is_symlink()
    assert {n: (tmp_path / n).read_bytes() for n in before} == before


def test_the_points_files_format_is_in_the_commands_help(capsys):
    """The format was documented only in the source: ``calibrate vehicle --help`` shows it."""
    from stationd.cli import main

    with pytest.raises(SystemExit) as done:
        main(["calibrate", "vehicle", "--help"])
    out = capsys.readouterr().out
    assert done.value.code == 0
    for key in ("kind: rigid", "points:", "vehicle_mm:", "seen_by:", "{left: r1_l.png, right:",
                "{pair_mm: ["):
        assert key in out, key


def test_one_mistyped_point_under_the_rms_bound_is_named_and_refused(tmp_path, capsys):
    """Issue 19: one coordinate typed 6 mm off (-606 for -600) hides under the RMS bound of
    eight points; the point is named with its residual and the coordinate the others give
    it; nothing is written."""
    from stationd.geometry.frames import MAX_POINT_MM, MAX_RMS_MM

    cfg = _station_with_pair1(tmp_path)
    data = yaml.safe_load(_points(tmp_path).read_text())
    assert data["points"][2]["vehicle_mm"] == [1300.0, -600.0, -30.0]
    data["points"][2]["vehicle_mm"][1] = -606.0
    typo = tmp_path / "typo.yaml"
    typo.write_text(yaml.safe_dump(data))
    code, out, err = _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points", typo,
                           "--config", cfg)
    rms = float(out.split("RMS ")[1].split()[0])
    assert rms <= MAX_RMS_MM, out    # the RMS alone passed it
    assert code == 1 and "wrote" not in out and err.count("\n") == 1, err
    residual = float(err.split("R3 has a residual of ")[1].split()[0])
    assert residual > MAX_POINT_MM and f"more than {MAX_POINT_MM:g} mm for one point" in err
    assert "R3 is probably mistyped (its vehicle_mm y is -606, the others put it at -600." in err
    assert not (tmp_path / "pair1.vehicle.yaml").exists()


def test_points_of_a_mirrored_frame_are_told_so_not_blamed_on_one_point(tmp_path, capsys):
    """Issue 19: the vehicle's y axis typed with the wrong sign for every point fits no
    rotation; the refusal blamed the point with the largest residual.  Rigid and affine."""
    from stationd.geometry.frames import MIRRORED

    cfg = _station_with_pair1(tmp_path)
    data = yaml.safe_load(_points(tmp_path).read_text())
    for p in data["points"]:
        p["vehicle_mm"][1] = -p["vehicle_mm"][1]
    mirrored = tmp_path / "mirrored.yaml"
    for kind in ("rigid", "affine"):
        mirrored.write_text(yaml.safe_dump({**data, "kind": kind}))
        code, out, err = _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points",
                               mirrored, "--config", cfg)
        assert code == 1 and "wrote" not in out and err.count("\n") == 1, kind
        assert MIRRORED in err and "largest residual" not in err, err
        assert not (tmp_path / "pair1.vehicle.yaml").exists()


def test_vehicle_points_in_one_plane_are_refused_and_a_broken_registration_is_replaced(
        tmp_path, capsys):
    """A sweep: an affine fit to vehicle points all in one plane wrote a singular A (RMS 0),
    which config check then refused and which blocked every later `calibrate vehicle` too
    (it read the station's registrations first): refused now, and a broken registration of
    the pair being calibrated is replaced, not read."""
    cfg = _station_with_pair1(tmp_path)
    data = yaml.safe_load(_points(tmp_path).read_text())
    for p in data["points"]:
        p["vehicle_mm"][2] = 0.0
    flat = tmp_path / "flat.yaml"
    flat.write_text(yaml.safe_dump({**data, "kind": "affine"}))
    code, out, err = _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points", flat,
                           "--config", cfg)
    assert code == 2 and "coplanar" in err and "Traceback" not in err, err
    assert not (tmp_path / "pair1.vehicle.yaml").exists()
    broken = tmp_path / "pair1.vehicle.yaml"
    broken.write_text("kind: affine\nA: [[1, 0, 0], [0, 1, 0], [0, 0, 0]]\nt: [0, 0, 0]\n")
    code, out, err = _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points",
                           _points(tmp_path), "--config", cfg)
    assert code == 0 and "wrote" in out, err
    assert "[0, 0, 0]]" not in broken.read_text()


def test_a_file_of_another_kind_as_the_points_is_named(tmp_path, capsys):
    """A sweep: a station file or a pair calibration given as --points said "cameras: unknown
    key (accepted: kind, points)"."""
    cfg = _station_with_pair1(tmp_path)
    for given, words in ((cfg, "this is a station file, not a reference points file"),
                         (tmp_path / "pair1.yaml", "this is a stereo pair calibration")):
        code, _out, err = _main(capsys, "calibrate", "vehicle", "--pair", "pair1", "--points",
                               given, "--config", cfg)
        assert code == 2 and words in err, err
        assert not (tmp_path / "pair1.vehicle.yaml").exists()


def test_a_pair_is_registered_again_on_a_station_with_references(tmp_path, capsys):
    """The calibration check found pair1 moved; registering it again read the station with
    pair1 unregistered, and its reference, seen by no other pair, was refused as seen by no
    pair: the command could not run until the references were deleted (a line engineer's
    trial)."""
    import shutil
    from pathlib import Path
    shutil.copy(Path(__file__).resolve().parents[1] / "config/sim/pair1.yaml", tmp_path)
    cfg = _station(tmp_path, "pair1.yaml")
    pts = _points(tmp_path)
    assert cmd_calibrate_vehicle(_args(cfg, pts, "pair1")) == 0
    assert cmd_calibrate_vehicle(_args(cfg, pts, "pair2")) == 0
    loaded = load_station_config(cfg)
    only = {}
    for v in VEHICLE_POINTS:     # a reference each pair alone sees
        seen = loaded.references is None and [
            name for name, pc in loaded.pairs.items()
            if pc.to_vehicle is not None and pc.calibration is not None
            and project(pc.calibration, pc.to_vehicle, tuple(v), SPEC) is not None]
        if seen and len(seen) == 1:
            only.setdefault(seen[0], v)
    assert set(only) == {"pair1", "pair2"}
    cfg.write_text(cfg.read_text() + "references:\n  markers:\n" + "".join(
        f"    R{i}: {list(map(float, v))}\n" for i, v in enumerate(only.values(), 1)))
    load_station_config(cfg)                  # the station reads as before
    capsys.readouterr()
    assert cmd_calibrate_vehicle(_args(cfg, pts, "pair1")) == 0
    assert "RMS" in capsys.readouterr().out
