"""The command line contract: JSON fields, exit codes, one-line errors."""

import json
import os
import subprocess
import sys
from contextlib import nullcontext
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from stationd.cli import main
from stationd.sim import scenes as sc
from tests.conftest import NOISE, SPEC, pose_in_pair, view

#: the simulated station's file (no access: section)
SIM_STATION = Path(__file__).resolve().parents[1] / "config" / "sim" / "station.yaml"
DETECT_KEYS = {"found", "reason", "centre_px", "ellipse_centre_px", "normal", "inner", "outer",
               "roi", "timings_ms"}


@pytest.fixture(scope="module")
def files(tmp_path_factory, camera, station_pair):
    d = tmp_path_factory.mktemp("cli")
    v, _ = view(camera, 700, 35, seed=11)
    cv2.imwrite(str(d / "one.png"), v.image)
    (d / "cam.yaml").write_text(yaml.safe_dump(v.camera.to_dict()))
    pose = pose_in_pair(station_pair, seed=12)
    lv = sc.render_view(station_pair.left, pose, SPEC, 1, **NOISE)
    rv = sc.render_view(station_pair.right, sc.to_right(station_pair, pose), SPEC, 2, **NOISE)
    cv2.imwrite(str(d / "left.png"), lv.image)
    cv2.imwrite(str(d / "right.png"), rv.image)
    pair = sc.crop_pair(station_pair, lv, rv)
    (d / "pair.yaml").write_text(yaml.safe_dump(pair.to_dict()))
    cv2.imwrite(str(d / "blank.png"), np.full_like(v.image, 70))
    cv2.imwrite(str(d / "grey.png"), v.image[:, :, 0])
    (d / "notimage.png").write_text("not an image")
    return d, v, pose


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_detect_json(files, capsys):
    d, v, _ = files
    code, out, err = _run(capsys, "detect", str(d / "one.png"), "--camera", str(d / "cam.yaml"),
                          "--json")
    assert code == 0 and err == ""
    obj = json.loads(out)
    assert DETECT_KEYS <= set(obj)
    assert obj["found"] is True and obj["reason"] is None
    assert np.hypot(*(np.array(obj["centre_px"]) - v.centre_px)) < 0.05
    assert set(obj["inner"]) >= {"centre", "semi_axes", "angle_deg", "points_used",
                                 "points_rejected"}
    assert len(obj["roi"]) == 4 and abs(np.linalg.norm(obj["normal"]) - 1) < 1e-9


def test_detect_not_found_exits_1_with_reason(files, capsys):
    d, _, _ = files
    code, out, _ = _run(capsys, "detect", str(d / "blank.png"), "--camera",
                        str(d / "cam.yaml"), "--json")
    obj = json.loads(out)
    assert code == 1 and obj["found"] is False and obj["reason"]


def test_localize_json_and_repeat(files, capsys):
    d, _, pose = files
    code, out, _ = _run(capsys, "localize", str(d / "left.png"), str(d / "right.png"),
                        "--pair", str(d / "pair.yaml"), "--json", "--repeat", "3")
    assert code == 0
    obj = json.loads(out)
    assert {"found", "reason", "left", "right", "point_mm", "normal", "epipolar_px",
            "timings_ms"} <= set(obj)
    assert DETECT_KEYS <= set(obj["left"])
    assert np.linalg.norm(np.array(obj["point_mm"]) - pose.centre_mm) < 0.05
    assert obj["repeat"]["n"] == 3 and obj["repeat"]["median_ms"] > 0


@pytest.mark.parametrize("make_args,needle", [
    (lambda d: ["detect", str(d / "missing.png"), "--camera", str(d / "cam.yaml")],
     "no such file"),
    (lambda d: ["detect", str(d / "notimage.png"), "--camera", str(d / "cam.yaml")],
     "notimage.png: a text file, not an image"),
    (lambda d: ["detect", str(d / "grey.png"), "--camera", str(d / "cam.yaml")],
     "grey image"),
    (lambda d: ["detect", str(d / "one.png"), "--camera", str(d / "notimage.png")],
     "expected a mapping"),
    (lambda d: ["detect", str(d / "one.png"), "--camera", str(d / "bad_k.yaml")],
     "K: expected a 3x3 matrix"),
    (lambda d: ["localize", str(d / "left.png"), str(d / "right.png"), "--pair",
                str(d / "cam.yaml")], "this is a camera calibration (from calibrate camera or "
     "stereo), not a stereo pair calibration"),
    (lambda d: ["localize", str(d / "left.png"), str(d / "right.png"), "--pair",
                str(d / "pair.yaml"), "--repeat", "0"], "--repeat"),
    (lambda d: ["detect", str(d / "one.png"), "--camera", str(d / "cam.yaml"), "--config",
                str(d / "bad_config.yaml")], "bad_config.yaml:2: vision.centre_method"),
    (lambda d: ["bench", "station", "--cycles", "0"], "--cycles must be at least 1"),
    (lambda d: ["bench", "station", "--browsers", "1", "--passes", "0"],
     "--passes must be at least 1"),
    (lambda d: ["bench", "station", "--clients", "sse"], "go with --browsers N"),
    (lambda d: ["marker", "--out", str(d / "m.png")], "written as SVG: give a .svg"),
    (lambda d: ["demo", "--no-http", "--http", "127.0.0.1:8090"], "--no-http with --http"),
    (lambda d: ["demo", "--hold", "--no-http", "--no-opcua"],
     "--hold with --no-http and --no-opcua"),
    (lambda d: ["demo", "--save", str(d)], "it goes with --vision"),
    (lambda d: ["demo", "--no-sim-supervisor", "--stations", "2"],
     "--no-sim-supervisor with --stations: a person releases the locks at the first"),
    # issue 30: config/sim has no users: nobody could release the lock the operator waits on
    (lambda d: ["demo", "--no-sim-supervisor", "--no-http", "--no-opcua"],
     "--no-sim-supervisor needs access.users in "),
    # ... and stationd run with the scripted operator, by the same check (it waited for good)
    (lambda d: ["run", "--config", str(SIM_STATION), "--sim-operator", "--no-sim-supervisor"],
     f"--no-sim-supervisor needs access.users in {SIM_STATION} with a user holding the "
     "release right"),
    (lambda d: ["demo", "--no-http", "--load", "1000"], "--load must be 0-64"),   # a sweep
    (lambda d: ["bench", "vision", "--only", ""], "--only: unknown section ''"),
    (lambda d: ["run", "--config", str(d / "deep.yaml")], "nested more than"),
    # issue 19: hangs, tracebacks and messages in the program's words
    (lambda d: ["detect", str(d / "huge.png"), "--camera", str(d / "cam.yaml")],
     "huge.png: the image says it is 100000 x 100000 px: more than 200 MP"),
    (lambda d: ["run", "--config", str(d / "fifo.yaml")],
     "fifo.yaml: a FIFO, not a file (a YAML file was expected)"),
    (lambda d: ["run", "--config", "/dev/zero"], "/dev/zero: a device, not a file"),
    (lambda d: ["detect", str(d / "one.png"), "--camera", "/dev/zero"],
     "/dev/zero: a device, not a file"),
    (lambda d: ["localize", str(d / "left.png"), str(d / "right.png"), "--pair",
                str(d / "fifo.yaml")], "fifo.yaml: a FIFO, not a file"),
    (lambda d: ["run", "--config", str(d / "one.png")],
     "one.png: not a text file: it looks like a PNG image"),
    (lambda d: ["run", "--config", str(d / "latin1.yaml")],
     "latin1.yaml:2: not UTF-8 text (Latin-1 or Windows-1252?)"),
    (lambda d: ["status", "--url", "http://a b/"],
     "--url 'http://a b/': a URL has no spaces or control characters"),
    # a maintenance technician's trial: tracebacks (RuntimeError, PyYAML's ConstructorError)
    # where config check said one line
    *((lambda d, c=c: [*c, "--config", str(d / "loop1.yaml")],
       "loop1.yaml: cannot be reached (too many levels of symbolic links)")
      for c in (["run"], ["status"], ["db", "report", "X"])),
    *((lambda d, c=c: [*c, "--config", str(d / "anchor.yaml")],
       "anchor.yaml:2: an alias (*name) names a collection it is inside of")
      for c in (["run"], ["db", "report", "X"])),
])
def test_bad_input_exits_2_with_one_line(files, capsys, make_args, needle):
    import os
    import struct
    import zlib

    d, _, _ = files
    if not (d / "fifo.yaml").exists():
        os.mkfifo(d / "fifo.yaml")   # read, it would block until a writer came

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(
            ">I", zlib.crc32(kind + data))

    (d / "huge.png").write_bytes(   # 100000 x 100000 px in 60 bytes: OpenCV asserted
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 100000, 100000, 8, 2,
                                                            0, 0, 0))
        + chunk(b"IDAT", zlib.compress(b"\0" * 31)) + chunk(b"IEND", b""))
    (d / "latin1.yaml").write_bytes("tool:\n  rule: caf\u00e9\n".encode("latin-1"))
    (d / "bad_k.yaml").write_text("K: [[1, 0], [0, 1]]\nsize: [10, 10]\n")
    (d / "bad_config.yaml").write_text("vision:\n  centre_method: magic\n")
    (d / "deep.yaml").write_text("vision: " + "[" * 3000 + "]" * 3000 + "\n")
    (d / "anchor.yaml").write_text("cameras: &a\n  x: *a\n")
    for a, b in (("loop1.yaml", "loop2.yaml"), ("loop2.yaml", "loop1.yaml")):
        if not (d / a).is_symlink():
            (d / a).symlink_to(d / b)
    code, _, err = _run(capsys, *make_args(d))
    assert code == 2
    assert needle in err and err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize(("argv", "message"), [
    (["config"], "stationd config: error: a command is missing: stationd config check "
                 "(see --help)\n"),
    (["calibrate"], "stationd calibrate: error: a command is missing: stationd calibrate "
                    "stereo | camera | vehicle | check (see --help)\n"),
])
def test_a_command_without_its_subcommand_says_what_to_type(argv, message, capsys):
    """Issue 19: ``stationd config`` said ``required: config_command``."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2 and capsys.readouterr().err == message


@pytest.mark.parametrize("bench", ["vision", "chain", "station"])
def test_a_results_file_that_cannot_be_written_is_refused_before_the_run(bench, tmp_path,
                                                                        capsys):
    with pytest.raises(SystemExit) as exc:
        main(["bench", bench, "--out", str(tmp_path / "no" / "such.json")])
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert "does not exist or is not writable" in err and err.count("\n") == 1


@pytest.mark.parametrize("bench", ["vision", "chain", "station"])
def test_a_results_file_that_is_a_folder_is_refused_before_the_run(bench, tmp_path, capsys):
    code, out, err = _usage_error(capsys, "bench", bench, "--out", str(tmp_path))
    assert code == 2 and out == "" and "is a folder" in _one_line(err)


def test_console_script_usage_error_is_one_line():
    r = subprocess.run([sys.executable, "-m", "stationd", "detect"], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "required" in r.stderr


def test_config_selects_the_method(files, capsys, tmp_path):
    d, _, _ = files
    cfg = tmp_path / "station.yaml"
    cfg.write_text("vision:\n  centre_method: ellipse\n")
    code, out, _ = _run(capsys, "detect", str(d / "one.png"), "--camera", str(d / "cam.yaml"),
                        "--config", str(cfg), "--json")
    obj = json.loads(out)
    assert code == 0 and obj["method"] == "ellipse"
    assert obj["centre_px"] == obj["ellipse_centre_px"]


def test_tune_color_output_is_read_by_the_config(files, capsys, tmp_path):
    d, _, _ = files
    out = tmp_path / "hsv.yaml"
    code, _, _ = _run(capsys, "tune-color", str(d / "one.png"), "--out", str(out))
    assert code == 0
    cfg = tmp_path / "station.yaml"
    cfg.write_text("vision:\n  hsv: hsv.yaml\n")
    from stationd.config import load_station_config

    tuned = load_station_config(cfg).vision.hsv
    written = yaml.safe_load(out.read_text())["hsv"]
    assert [list(tuned.h), list(tuned.s), list(tuned.v)] == [written["h"], written["s"],
                                                            written["v"]]
    code, out_json, _ = _run(capsys, "detect", str(d / "one.png"), "--camera",
                             str(d / "cam.yaml"), "--config", str(cfg), "--json")
    assert code == 0 and json.loads(out_json)["found"]


def test_marker_svg_is_written_at_true_scale(tmp_path, capsys):
    out = tmp_path / "m.svg"
    code, text, _ = _run(capsys, "marker", "--out", str(out))
    assert code == 0 and "r=10 mm" in text
    svg = out.read_text()
    assert 'r="10"' in svg and 'r="15"' in svg and "mm" in svg


# -- issue 12: every bad input answered in one line ------------------------------------------
def _usage_error(capsys, *argv):
    """(exit code, stderr) of a command argparse refuses (SystemExit) or main refuses."""
    try:
        code = main(list(argv))
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def _one_line(err):
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("argv", [
    ["demo", "--seed", "-1"], ["demo", "--vision", "--seed", "-1"],
    ["bench", "station", "--seed", "-1"], ["bench", "chain", "--seed", "-1"],
    ["bench", "vision", "--seed", "-1"], ["demo", "--seed", "x"],
])
def test_a_negative_seed_is_refused_in_one_line(argv, capsys):
    code, out, err = _usage_error(capsys, *argv)
    assert code == 2 and out == ""
    assert "--seed" in _one_line(err)


@pytest.mark.parametrize("argv,needle", [
    (["probe", "wrench", "sim://wrench", "--wait-result", "-5"], "--wait-result"),
    (["probe", "lift", "sim://lift", "--timeout", "nan"], "--timeout"),
    (["probe", "lift", "sim://lift", "--timeout", "inf"], "--timeout"),
])
def test_probe_time_options_must_be_finite_positive_seconds(argv, needle, capsys):
    code, out, err = _usage_error(capsys, *argv)
    assert code == 2 and out == "" and needle in _one_line(err)


def test_version(capsys):
    """The version, and the checkout's commit where it runs from one (stationd.release)."""
    from stationd.release import release

    code, out, _ = _usage_error(capsys, "--version")
    assert code == 0 and out.strip() == f"stationd {release()}"


def test_localize_refuses_a_pair_without_baseline(files, capsys, tmp_path):
    d, _, _ = files
    pair = yaml.safe_load((d / "pair.yaml").read_text())
    pair["T"] = [0, 0, 0]
    bad = tmp_path / "zero.yaml"
    bad.write_text(yaml.safe_dump(pair))
    code, out, err = _run(capsys, "localize", str(d / "left.png"), str(d / "right.png"),
                          "--pair", str(bad), "--json")
    assert code == 2 and out == "" and "baseline" in _one_line(err)


@pytest.mark.parametrize("where", ["file", "under_file"])
def test_demo_vision_save_refuses_a_file_or_unmakeable_folder_before_rendering(
        where, tmp_path, capsys):
    f = tmp_path / "taken"
    f.write_text("keep me")
    target = f if where == "file" else f / "sub"
    code, out, err = _run(capsys, "demo", "--vision", "--cycles", "1", "--save", str(target))
    assert code == 2 and out == "" and "--save" in _one_line(err)
    assert f.read_text() == "keep me" and sorted(p.name for p in tmp_path.iterdir()) == ["taken"]


def test_demo_vision_save_writes_by_the_one_output_rule(tmp_path, capsys):
    """``demo --vision --save DIR`` writes its images stamped as its own and pair.yaml whole;
    a link among its outputs, or a file of another kind where one goes, is refused before
    rendering and left as it was (stationd/outfile.py)."""
    from stationd.demo.vision import _outputs
    from stationd.outfile import kind_of

    out_dir = tmp_path / "out"
    code, out, err = _run(capsys, "demo", "--vision", "--cycles", "1", "--save", str(out_dir))
    assert code == 0, err
    assert {p.name: kind_of(p) for p in out_dir.iterdir()} == {
        "pair.yaml": "pair", "left_0.png": "demo-image", "right_0.png": "demo-image"}
    assert _outputs(out_dir, 1)                  # the demo's own: a next run may replace them
    station = tmp_path / "station.yaml"
    station.write_text("cameras: {c1: {url: 'sim://pair1/left'}}\n")
    cases = [
        ("left_0.png", lambda p: p.symlink_to(station),
         f"left_0.png: is a symbolic link to {station}, a station file; an output is never "
         "written through or over a link"),
        ("right_0.png", lambda p: p.write_bytes(
            cv2.imencode(".png", np.zeros((4, 4, 3), np.uint8))[1].tobytes()),
         "right_0.png: is a PNG image that this program did not write"),
        ("pair.yaml", lambda p: p.write_text(station.read_text()),
         "pair.yaml: is a station file; writing the demo's pair calibration would replace it"),
    ]
    for name, make, needle in cases:
        d = tmp_path / f"case-{name}"
        d.mkdir()
        make(d / name)
        before = {p.name: (p.is_symlink(), p.read_bytes()) for p in d.iterdir()}
        code, out, err = _run(capsys, "demo", "--vision", "--cycles", "1", "--save", str(d))
        assert code == 2 and out == "" and needle in _one_line(err), err
        assert {p.name: (p.is_symlink(), p.read_bytes()) for p in d.iterdir()} == before
    assert station.read_text().startswith("cameras:")


def test_detect_takes_one_camera_of_a_pair_file(files, capsys):
    d, v, _ = files
    pair = yaml.safe_load((d / "pair.yaml").read_text())
    # the single-camera file's camera as the pair's right side: --side picks it
    pair["right"] = yaml.safe_load((d / "cam.yaml").read_text())
    (d / "pair_cam.yaml").write_text(yaml.safe_dump(pair))
    code, out, _ = _run(capsys, "detect", str(d / "one.png"), "--pair",
                        str(d / "pair_cam.yaml"), "--side", "right", "--json")
    obj = json.loads(out)
    assert code == 0 and np.hypot(*(np.array(obj["centre_px"]) - v.centre_px)) < 0.05
    code, _, err = _run(capsys, "detect", str(d / "one.png"), "--camera", str(d / "cam.yaml"),
                        "--pair", str(d / "pair_cam.yaml"))
    assert code == 2 and "either --camera" in _one_line(err)


def test_json_output_is_strict():
    from stationd.jsonout import strict_json

    text = strict_json({"centre_split_px": float("nan"), "a": [1.0, float("inf")],
                        "n": np.float64(2.5), "arr": np.array([np.nan, 1.0])})
    assert json.loads(text) == {"centre_split_px": None, "a": [1.0, None], "n": 2.5,
                                "arr": [None, 1.0]}
    assert "NaN" not in text and "Infinity" not in text


def test_db_report_into_a_closed_pipe_is_quiet(tmp_path):
    from db.repository import Repository
    from stationd.boltfile import import_bolts
    from tests.db.conftest import EXAMPLE, record, url_of

    db = url_of(tmp_path / "s.db")
    with Repository.open(db) as repo:
        import_bolts(repo, EXAMPLE)
        repo.start_vehicle("VIN1", "WAGON-B")
        record(repo, "VIN1", "SF-FL")
    # the reader is gone before the command writes (as `| head` once it has its lines)
    p = subprocess.Popen([sys.executable, "-m", "stationd", "db", "report", "VIN1", "--db", db],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert p.stdout is not None and p.stderr is not None
    p.stdout.close()
    err = p.stderr.read().decode()
    # its own code (1: the vehicle is still open) when it wrote all before the reader left,
    # else SIGPIPE's, as a program killed by it (never 0: ``status | true`` passed a fault)
    assert p.wait(timeout=60) in (1, 141)
    assert "Traceback" not in err and "BrokenPipe" not in err and err == ""


@pytest.mark.parametrize("image", ["blank", "purple_no_ring"])
def test_tune_color_refuses_an_image_without_a_verified_marker(files, capsys, tmp_path, image):
    from stationd.vision.marker import PURPLE_RGB

    d, v, _ = files
    if image == "purple_no_ring":  # a purple patch where the marker was: purple, but no ring
        img = v.image.copy()
        x, y = (int(c) for c in v.centre_px)
        img[y - 120:y + 120, x - 120:x + 120] = PURPLE_RGB[::-1]
        cv2.imwrite(str(tmp_path / "purple.png"), img)
        ref = tmp_path / "purple.png"
    else:
        ref = d / "blank.png"
    out = tmp_path / "hsv.yaml"
    code, text, err = _run(capsys, "tune-color", str(ref), "--out", str(out))
    assert code == 1 and text == "" and "ring check" in _one_line(err)
    assert not out.exists()


def test_tune_color_never_widens_the_default_box(files, capsys, tmp_path):
    from stationd.vision.segment import DEFAULT_HSV

    d, _, _ = files
    out = tmp_path / "hsv.yaml"
    assert _run(capsys, "tune-color", str(d / "one.png"), "--out", str(out))[0] == 0
    hsv = yaml.safe_load(out.read_text())["hsv"]
    for key, (lo, hi) in (("h", DEFAULT_HSV.h), ("s", DEFAULT_HSV.s), ("v", DEFAULT_HSV.v)):
        assert lo <= hsv[key][0] <= hsv[key][1] <= hi, key


@pytest.mark.parametrize("cycles", ["0", "-2"])
def test_demo_vision_refuses_no_placements(cycles, capsys):
    code, out, err = _run(capsys, "demo", "--vision", "--cycles", cycles)
    assert code == 2 and out == "" and "--cycles" in _one_line(err)


def test_every_command_prints_json_through_strict_json():
    """A command module that called json.dumps itself would print NaN again."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1] / "stationd"
    modules = [root / "cli.py", root / "probe.py", root / "probe_camera.py", root / "db_cli.py",
               root / "calibrate_cli.py", root / "vehicle_cli.py",
               *sorted((root / "demo").glob("*.py"))]
    for path in modules:
        assert "json.dumps(" not in path.read_text(), path


def test_an_output_never_replaces_a_station_file_or_a_bolt_table(tmp_path, capsys):
    """``tune-color --out bolts.yaml`` replaced a bolt table, ``db export --out station.yaml``
    a station file (newcomer trial): refused with one line, the file untouched; a bolt table
    still replaces a bolt table (export, edit, import)."""
    import shutil
    from pathlib import Path

    sim = Path(__file__).resolve().parents[1] / "config" / "sim"
    for name in ("station.yaml", "bolts.yaml"):
        shutil.copy(sim / name, tmp_path / name)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    (tmp_path / "ref.png").write_bytes(b"")
    db = f"sqlite:///{tmp_path / 's.db'}"
    assert main(["db", "import", str(tmp_path / "bolts.yaml"), "--db", db]) == 0
    capsys.readouterr()
    for argv, needle in [
        (["tune-color", str(tmp_path / "ref.png"), "--out", str(tmp_path / "bolts.yaml")],
         "is a bolt table; writing HSV ranges would replace it"),
        (["tune-color", str(tmp_path / "ref.png"), "--out", str(tmp_path / "station.yaml")],
         "is a station file"),
        (["db", "export", "--db", db, "--out", str(tmp_path / "station.yaml")],
         "is a station file; writing a bolt table would replace it"),
        (["db", "export", "--results", "--db", db, "--out", str(tmp_path / "bolts.yaml")],
         "is a bolt table; writing results"),
    ]:
        code, _, err = _run(capsys, *argv)
        assert code == 2 and needle in err and err.count("\n") == 1, (argv, err)
    assert {n: (tmp_path / n).read_bytes() for n in before} == before
    code, out, _ = _run(capsys, "db", "export", "--db", db, "--out",
                        str(tmp_path / "bolts.yaml"))
    assert code == 0 and "wrote" in out


def test_an_output_never_replaces_a_database_a_calibration_or_a_device(tmp_path, capsys):
    """Newcomer trial: ``db export --results --out self.db`` replaced the very database it
    read with a CSV (and made it 0600), ``tune-color --out stationd.db`` the same, a results
    export over a pair calibration too, and ``--out /dev/full`` said "wrote" (as root the
    rename replaced the device node).  Each is refused with one line, before any work, the
    file untouched; an earlier export is still replaced, keeping its mode."""
    import os
    import shutil
    import stat
    from pathlib import Path

    sim = Path(__file__).resolve().parents[1] / "config" / "sim"
    shutil.copy(sim / "bolts.yaml", tmp_path / "bolts.yaml")
    shutil.copy(sim / "pair1.yaml", tmp_path / "pair1.yaml")
    (tmp_path / "ref.png").write_bytes(b"")
    dbfile = tmp_path / "s.db"
    db = f"sqlite:///{dbfile}"
    assert main(["db", "import", str(tmp_path / "bolts.yaml"), "--db", db]) == 0
    capsys.readouterr()
    (tmp_path / "notes.txt").write_text("a README, a script, notes\n")
    (tmp_path / "s.db.lock").write_text("12345\n")
    shutil.copy(tmp_path / "bolts.yaml", tmp_path / "station-copy.svg")
    (tmp_path / "link.svg").symlink_to(tmp_path / "pair1.yaml")   # writes through: refused
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    for argv, needle in [
        (["db", "export", "--results", "--db", db, "--out", str(dbfile)],
         "is an SQLite database; writing results would replace it"),
        (["db", "export", "--db", db, "--out", str(dbfile)], "is an SQLite database"),
        (["tune-color", str(tmp_path / "ref.png"), "--out", str(dbfile)],
         "is an SQLite database"),
        (["db", "export", "--results", "--db", db, "--out", str(tmp_path / "pair1.yaml")],
         "is a stereo pair calibration (from calibrate stereo)"),
        (["db", "export", "--results", "--db", db, "--out", "/dev/full"],
         "not a regular file"),
        (["bench", "station", "--out", str(tmp_path / "bolts.yaml")], "is a bolt table"),
        # second trial: any text file was "an earlier export" (a README, the daemon's lock)
        (["db", "export", "--results", "--db", db, "--out", str(tmp_path / "notes.txt")],
         "is a text file"),
        (["db", "export", "--results", "--db", db, "--out", str(tmp_path / "s.db.lock")],
         "is a text file"),
        (["marker", "--out", str(tmp_path / "station-copy.svg")], "is a bolt table"),
        (["marker", "--out", str(tmp_path / "link.svg")],
         f"is a symbolic link to {tmp_path / 'pair1.yaml'}, a stereo pair calibration"),
        # third trial: a folder was "not a regular file (a device, a pipe or a socket)"
        (["db", "export", "--db", db, "--out", str(tmp_path)],
         "is a folder; --out takes a file name"),
        (["db", "export", "--db", db, "--out", ""], ".: is a folder"),
    ]:
        code, _, err = _usage_error(capsys, *argv)
        assert code == 2 and needle in err and err.count("\n") == 1, (argv, err)
    assert {n: (tmp_path / n).read_bytes() for n in before} == before
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)
    out = tmp_path / "results.csv"
    assert main(["db", "export", "--results", "--db", db, "--out", str(out)]) == 0
    out.chmod(0o640)
    for fmt in ("csv", "json", "csv"):    # an earlier export of either format is replaced
        code, text, _ = _run(capsys, "db", "export", "--results", "--db", db, "--format",
                             fmt, "--out", str(out))
        assert code == 0 and "wrote" in text
    assert stat.S_IMODE(out.stat().st_mode) == 0o640 and out.read_text().startswith("vin")
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_an_output_that_cannot_be_written_is_one_line_not_wrote(tmp_path, capsys):
    """A folder that does not exist (or a full disk: the same path through write_atomic,
    which flushes and syncs before the rename) is one line and exit 2, no "wrote"."""
    from stationd.errors import InputError
    from stationd.outfile import write_atomic

    code, out, err = _run(capsys, "db", "export", "--results", "--db",
                          f"sqlite:///{tmp_path / 's.db'}", "--out",
                          str(tmp_path / "nowhere" / "r.csv"))
    assert code == 2 and "wrote" not in out and err.count("\n") == 1
    import pytest
    with pytest.raises(InputError, match=r"r\.csv: folder .*nowhere does not exist"):
        write_atomic(tmp_path / "nowhere" / "r.csv", "x")


def test_the_results_csv_head_the_out_rule_knows_is_the_exports():
    from stationd.outfile import RESULTS_CSV_HEAD
    from stationd.web.results import CSV_FIELDS

    assert ",".join(CSV_FIELDS).startswith(RESULTS_CSV_HEAD)


def test_a_results_export_larger_than_a_settings_file_is_still_one(tmp_path):
    """A shift's results pass the 5 MB up to which files are parsed: the export's own head
    (CSV header, or a JSON list of rundowns) tells it at any size, so exporting again over
    it works; another large file is still refused as data, a large database as one."""
    import json

    from stationd.outfile import PARSE_LIMIT_BYTES, SQLITE_MAGIC, kind_of
    from stationd.web.results import CSV_FIELDS, rundowns_csv

    row = {**dict.fromkeys(CSV_FIELDS, ""), "vin": "V1", "bolt": "B01", "images": []}
    n = PARSE_LIMIT_BYTES // 20 + 1
    one = rundowns_csv([row])            # the export's header and one row, the row repeated
    head = one.index("\n") + 1
    big_csv = tmp_path / "r.csv"
    big_csv.write_text(one[:head] + one[head:] * n)
    big_json = tmp_path / "r.json"
    big_json.write_text(json.dumps([row] * (PARSE_LIMIT_BYTES // len(json.dumps(row)) + 1)))
    assert big_csv.stat().st_size > PARSE_LIMIT_BYTES < big_json.stat().st_size
    assert kind_of(big_csv) == kind_of(big_json) == "results"
    other = tmp_path / "big.log"
    other.write_text("[2026-11-26 12:00:00] ok\n" * n)   # a list-like start, not rundowns
    small = tmp_path / "small.log"
    small.write_text("[2026-11-26 12:00:00] ok\n")
    empty = tmp_path / "empty.json"
    empty.write_text("[]\n")
    assert (kind_of(small), kind_of(empty)) == ("text", "results")
    db = tmp_path / "big.db"
    db.write_bytes(SQLITE_MAGIC + b"\0" * (PARSE_LIMIT_BYTES + 1))
    assert (kind_of(other), kind_of(db)) == ("data", "sqlite")


def test_detect_draw_never_writes_through_a_link_or_over_another_file(files, tmp_path, capsys):
    """Issue 19: ``detect --draw link.png``, ``link.png`` a link to the station file,
    replaced the station file with a PNG; ``--draw`` replaced any existing PNG.  A link (to
    anything, a drawing too) and any file but an earlier drawing of ``detect --draw`` are
    refused before the detection, exit 2 in one line, untouched; an earlier drawing is
    replaced (the drawing is stamped as detect --draw's own)."""
    import shutil
    from pathlib import Path

    from stationd.imageio import read_image
    from stationd.outfile import kind_of

    d, _, _ = files
    shutil.copy(Path(__file__).resolve().parents[1] / "config/sim/station.yaml", tmp_path)
    shutil.copy(d / "one.png", tmp_path / "photo.png")
    (tmp_path / "notes.png").write_text("not a picture\n")
    (tmp_path / "link.png").symlink_to(tmp_path / "station.yaml")
    detect = ["detect", str(d / "one.png"), "--camera", str(d / "cam.yaml"), "--draw"]
    drawing = tmp_path / "drawing.png"
    code, out, err = _run(capsys, *detect, str(drawing))
    assert code == 0 and err == "" and kind_of(drawing) == "drawing"
    assert read_image(drawing).shape[2] == 3
    (tmp_path / "link2.png").symlink_to(drawing)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    for name, needle in [
        ("link.png", f"link.png: is a symbolic link to {tmp_path / 'station.yaml'}, a station "
                     "file; an output is never written through or over a link: give --draw "
                     "the file's own path"),
        ("link2.png", "link2.png: is a symbolic link to"),
        ("photo.png", "photo.png: is a PNG image that this program did not write; writing "
                      "the drawing would replace it (give another --draw)"),
        ("notes.png", "notes.png: is a text file"),
    ]:
        code, out, err = _run(capsys, *detect, str(tmp_path / name))
        assert code == 2 and out == "" and needle in err and err.count("\n") == 1, err
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    assert (tmp_path / "link.png").is_symlink() and (tmp_path / "link2.png").is_symlink()
    code, out, err = _run(capsys, *detect, str(drawing))
    assert code == 0 and err == "" and kind_of(drawing) == "drawing"


@pytest.mark.parametrize("argv, said", [
    (["run", "--confg", "x.yaml"], "no option --confg (did you mean --config?); the following "
                                   "arguments are required: --config"),
    (["status", "--jsn"], "stationd status: error: no option --jsn (did you mean --json?)"),
    # its value is no second unrecognized argument, and the command it was given says it
    (["demo", "--cycels", "3"], "stationd demo: error: no option --cycels (did you mean "
                                "--cycles?)"),
    (["status", "--zzz"], "stationd status: error: unrecognized arguments: --zzz"),
    # only the command's own options are suggested: --bolts is another command's, and
    # following the hint failed (a new user's trial)
    (["demo", "--bogus"], "stationd demo: error: unrecognized arguments: --bogus"),
    (["feed", "--bogus"], "stationd feed: error: unrecognized arguments: --bogus"),
    (["line", "results", "--config", "s.yaml", "--bogus"],
     "stationd line results: error: unrecognized arguments: --bogus"),
    (["line", "results", "--config", "s.yaml", "--bolts", "B1"],
     "stationd line results: error: no option --bolts (did you mean --bolt?)"),
    # a command named by its alias is said as typed, its own options suggested
    (["sim", "lift", "--bogus"], "stationd sim lift: error: unrecognized arguments: --bogus"),
    (["sim", "lift", "--prot", "3"], "stationd sim lift: error: no option --prot (did you "
                                     "mean --port?)"),
    (["stauts"], "stationd: error: no command 'stauts' (did you mean status?)"),
    # an option before the command: its value was said to be an invalid command
    (["operator", "--config", "s.yaml"], "stationd operator: error: a command is missing: "
     "stationd operator sign-in | sign-out | status (its options, --config too, come after "
     "it)"),
    (["db", "exprot"], "stationd db: error: no command 'exprot' (did you mean export?)"),
    (["frobnicate"], "invalid choice: 'frobnicate' (choose from 'detect', "),
    # an option's value out of its choices is no command
    (["db", "export", "--results", "--format", "jsno"],
     "argument --format: invalid choice: 'jsno' (choose from "),
])
def test_a_mistyped_option_is_named_with_the_one_meant(capsys, argv, said):
    """``run --confg X`` said only that --config is required; ``stauts`` only the commands
    there are (a new user's trial)."""
    code, _, err = _usage_error(capsys, *argv)
    assert code == 2 and said in _one_line(err) and _one_line(err).rstrip("\n").endswith(
        " (see --help)"), err


@pytest.mark.parametrize("argv", [["run", "--config", "/nonexistent/station.yaml"],
                                  ["run", "--confg", "x"]], ids=["refused", "usage"])
def test_an_error_line_to_the_journal_carries_its_priority(tmp_path, monkeypatch, argv):
    """Standard error connected to systemd's journal (``JOURNAL_STREAM`` names that very
    stream): the exit's one line begins ``<3>`` (err), so ``journalctl -p warning`` shows why
    the service did not start (an IT administrator's trial: stored at the default priority).
    Anywhere else it is the plain line."""
    for journal in (True, False):
        path = tmp_path / f"stderr-{journal}"
        with open(path, "w") as err:
            st = os.fstat(err.fileno())
            monkeypatch.setenv("JOURNAL_STREAM", f"{st.st_dev}:{st.st_ino}" if journal
                               else "1:1")
            monkeypatch.setattr(sys, "stderr", err)
            with pytest.raises(SystemExit) if argv[1] == "--confg" else nullcontext():
                main(argv)
        text = path.read_text()
        assert len(text.splitlines()) == 1, text
        assert text.startswith("<3>stationd" if journal else "stationd"), text
