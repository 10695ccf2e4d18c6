"""``stationd calibrate camera`` and ``calibrate stereo``'s camera files, through stationd's
own command line (one-line errors, exit codes), and the per-image time bound of the search."""

import json

import cv2
import numpy as np
import pytest
import yaml

from stationd.cli import main
from stationd.geometry.calibration import detect_corners, parse_board
from stationd.geometry.camera import Camera, StereoPair
from tests.geometry.test_calibration import _render, _rot, _texture

SPEC = "chessboard:9x6:20"
SIZE = (640, 480)
K1 = np.array([[560.0, 0, 318.0], [0, 560.0, 243.0], [0, 0, 1]])
K2 = np.array([[570.0, 0, 325.0], [0, 570.0, 236.0], [0, 0, 1]])
R12, T12 = _rot(0.3, -2.0, 0.2), np.array([-60.0, 0.5, 1.0])


@pytest.fixture(scope="module")
def boards(tmp_path_factory):
    """Eight rendered stereo views of a chessboard (seeded), L1..L8 and R1..R8."""
    d = tmp_path_factory.mktemp("boards")
    board = parse_board(SPEC)
    texture, origin = _texture(board)
    rng = np.random.default_rng(5)
    obj, n = board.object_points(), 0
    while n < 8:
        R = _rot(rng.uniform(-35, 35), rng.uniform(-35, 35), rng.uniform(-15, 15))
        t = np.array([rng.uniform(-60, 60), rng.uniform(-50, 50), rng.uniform(450, 650)])
        t -= R @ obj.mean(axis=0)
        views = ((R, t, K1), (R12 @ R, R12 @ t + T12, K2))
        if not all(np.all((p > 30) & (p < np.array(SIZE) - 31)) for p in (
                cv2.projectPoints(obj, cv2.Rodrigues(Rc)[0], tc, Kc, None)[0].reshape(-1, 2)
                for Rc, tc, Kc in views)):
            continue
        n += 1
        for name, (Rc, tc, Kc) in zip("LR", views, strict=True):
            cv2.imwrite(str(d / f"{name}{n}.png"), _render(texture, origin, Kc, Rc, tc, SIZE,
                                                           rng))
    return d


def _cli(capsys, *argv):
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def test_calibrate_camera_writes_the_file_detect_reads(boards, tmp_path, capsys):
    out = tmp_path / "cam.yaml"
    code, text, err = _cli(capsys, "calibrate", "camera", str(boards / "L*.png"), "--board",
                           SPEC, "--out", out, "--json")
    assert code == 0 and err == ""
    rep = json.loads(text)
    assert len(rep["views"]) == 8 and rep["rms_px"] < 0.3 and rep["out"] == str(out)
    cam = Camera.load(out)
    assert out.read_text().startswith("# stationd calibrate camera:")
    assert cam.size == SIZE and np.abs(cam.K - K1).max() < 6
    code, text, _ = _cli(capsys, "calibrate", "camera", str(boards / "L*.png"), "--board",
                         SPEC, "--out", out)
    assert code == 0 and "views: 8 images, 8 used, 0 rejected" in text


def test_calibrate_stereo_also_writes_both_camera_files(boards, tmp_path, capsys):
    out = tmp_path / "pair.yaml"
    code, text, err = _cli(capsys, "calibrate", "stereo", "--left", str(boards / "L*.png"),
                           "--right", str(boards / "R*.png"), "--board", SPEC, "--out", out)
    assert code == 0 and err == ""
    left, right = tmp_path / "pair.left.yaml", tmp_path / "pair.right.yaml"
    assert f"wrote {out}, {left}, {right}" in text
    pair = StereoPair.load(out)
    for path, cam in ((left, pair.left), (right, pair.right)):
        loaded = Camera.load(path)
        assert np.allclose(loaded.K, cam.K) and np.allclose(loaded.dist, cam.dist)
        assert loaded.size == cam.size
    assert abs(pair.baseline_mm / np.linalg.norm(T12) - 1) < 0.01


@pytest.mark.parametrize("argv,needle", [
    (["calibrate", "camera", "{d}/L*.png", "--board", "chessboard:9x6", "--out",
      "{t}/c.yaml"], "board 'chessboard:9x6'"),
    (["calibrate", "camera", "{t}/none*.png", "--board", SPEC, "--out", "{t}/c.yaml"],
     "matches no file"),
    # issue 19: a traceback (74 GiB asked of OpenCV; an overflow into a LinAlgError)
    (["calibrate", "stereo", "--left", "{d}/L*.png", "--right", "{d}/R*.png", "--board",
      "chessboard:99999x99999:25", "--out", "{t}/p.yaml"], "at most 200 per side"),
    (["calibrate", "camera", "{d}/L*.png", "--board", "chessboard:9x6:1e308", "--out",
      "{t}/c.yaml"], "not plausible (at most 500 mm"),
    (["calibrate", "camera", "{d}/L1.png", "{d}/L2.png", "--board", SPEC, "--out",
      "{t}/c.yaml"], "only 2 usable images out of 2"),
    (["calibrate", "camera", "{d}/L*.png", "--board", SPEC, "--out", "{t}/no/c.yaml"],
     "no such folder"),
    (["calibrate", "stereo", "--left", "{d}/L*.png", "--right", "{d}/R*.png", "--board", SPEC,
      "--out", "{t}/p.yaml", "--out-left", "{t}/p.yaml"], "must differ"),
    (["calibrate", "stereo", "--left", "{d}/L*.png", "--right", "{d}/R*.png", "--board", SPEC,
      "--out", "{t}/p.yaml", "--out-right", "{t}/no/r.yaml"], "no such folder"),
])
def test_calibrate_refusals_are_one_line_and_write_nothing(boards, tmp_path, capsys, argv,
                                                           needle):
    args = [a.format(d=boards, t=tmp_path) for a in argv]
    code, out, err = _cli(capsys, *args)
    assert code == 2 and out == "" and needle in err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_a_board_not_found_reduced_is_skipped_at_the_time_bound():
    """A large image without the board: with no time left after the reduced search, the
    full-resolution search (minutes at 20 MP) is not started, and the reason says so."""
    board = parse_board(SPEC)
    noise = np.random.default_rng(0).integers(90, 160, (1800, 2400), dtype=np.uint8)
    blank = cv2.GaussianBlur(noise, (0, 0), 3)  # texture, no board (and no noise to chase)
    found = detect_corners(blank, board, budget_s=0.0)
    assert not found.found
    assert "not found at up to 67% size" in found.reason and "skipped" in found.reason
    assert "the bound is 0 s per image" in found.reason
    # with time to spare the larger sizes are searched (behind the fast check) to the end
    assert detect_corners(blank, board, budget_s=60.0).reason == "chessboard not found"


@pytest.mark.parametrize("board", [SPEC, "charuco:11x8:20:15:DICT_5X5_100"])
@pytest.mark.parametrize("size", [(2, 2), (1, 1), (30, 3000)])
def test_images_too_small_for_the_board_are_rejected_not_an_opencv_assertion(
        tmp_path, capsys, board, size):
    """Issue 19: images without a board, too small to hold one, stopped ``calibrate camera``
    with OpenCV's ``adaptiveThreshold`` assertion (a traceback)."""
    w, h = size
    for i in range(6):
        cv2.imwrite(str(tmp_path / f"v{i}.png"), np.full((h, w, 3), 60 + 20 * i, np.uint8))
    code, out, err = _cli(capsys, "calibrate", "camera", str(tmp_path / "v*.png"), "--board",
                          board, "--out", str(tmp_path / "c.yaml"))
    assert code == 2 and out == "" and "Traceback" not in err and err.count("\n") == 1
    assert "only 0 usable images out of 6" in err
    assert not (tmp_path / "c.yaml").exists()
    found = detect_corners(np.zeros((h, w), np.uint8), parse_board(board))
    assert not found.found and "too small to show the board" in found.reason


def test_an_opencv_refusal_is_a_board_not_found_with_its_reason(monkeypatch):
    import stationd.geometry.calibration as calibration

    def refuse(*args, **kwargs):
        raise cv2.error("OpenCV(5.0.0) thresh.cpp:1908: error: (-215:Assertion failed) "
                        "blockSize % 2 == 1 in function 'adaptiveThreshold'")

    monkeypatch.setattr(calibration.cv2, "findChessboardCorners", refuse)
    found = detect_corners(np.zeros((480, 640), np.uint8), parse_board(SPEC))
    assert not found.found and found.reason.startswith("board not found (OpenCV: ")


def test_write_all_leaves_nothing_when_one_file_fails(tmp_path):
    from stationd.calibrate_cli import write_all
    from stationd.errors import InputError

    good = tmp_path / "a.yaml"
    good.write_text("old")
    with pytest.raises(InputError, match="does not exist"):
        write_all([(good, "new"), (tmp_path / "missing" / "b.yaml", "x")])
    assert good.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == [
        "a.yaml"]
    assert yaml.safe_load("k: 1") == {"k": 1}


def test_calibrate_camera_never_replaces_a_file_of_another_kind(boards, tmp_path, capsys):
    """Issue 19: ``calibrate camera --out`` onto a stereo pair calibration overwrote it.  A
    file of another kind (a pair calibration, a station file, a bolt table, an image) or a
    link is refused before any image is read, naming its kind; an earlier camera file is
    still replaced."""
    import shutil
    from pathlib import Path

    sim = Path(__file__).resolve().parents[1] / "config" / "sim"
    for name in ("pair1.yaml", "station.yaml", "bolts.yaml"):
        shutil.copy(sim / name, tmp_path / name)
    shutil.copy(boards / "L1.png", tmp_path / "L1.png")
    (tmp_path / "link.yaml").symlink_to(tmp_path / "pair1.yaml")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    for name, kind in (("pair1.yaml", "a stereo pair calibration"),
                       ("station.yaml", "a station file"), ("bolts.yaml", "a bolt table"),
                       ("L1.png", "a PNG image"), ("link.yaml", "a symbolic link to")):
        code, out, err = _cli(capsys, "calibrate", "camera", str(boards / "L*.png"),
                              "--board", SPEC, "--out", tmp_path / name)
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert f"{name}: is {kind}" in err, err
    assert "writing a camera calibration would replace it" in _cli(
        capsys, "calibrate", "camera", str(boards / "L*.png"), "--board", SPEC, "--out",
        tmp_path / "pair1.yaml")[2]
    # the pair's own camera files are no more a pair's than the pair file is a camera's
    code, _, err = _cli(capsys, "calibrate", "stereo", "--left", str(boards / "L*.png"),
                        "--right", str(boards / "R*.png"), "--board", SPEC, "--out",
                        tmp_path / "p.yaml", "--out-left", tmp_path / "pair1.yaml")
    assert code == 2 and "pair1.yaml: is a stereo pair calibration" in err
    assert {n: (tmp_path / n).read_bytes() for n in before} == before
    cam = tmp_path / "cam.yaml"
    for _ in range(2):
        assert _cli(capsys, "calibrate", "camera", str(boards / "L*.png"), "--board", SPEC,
                    "--out", cam)[0] == 0


def test_calibrate_stereo_refuses_the_same_images_for_both_cameras(boards, tmp_path, capsys):
    """Issue 19: the same images for left and right wrote a pair with a 3.5e-9 mm baseline,
    exit 0.  The same files (or copies of one content) are refused before any work."""
    import shutil

    for i in (1, 2, 3, 4, 5, 6, 7, 8):
        shutil.copy(boards / f"L{i}.png", tmp_path / f"C{i}.png")
    for right in (boards / "L*.png", tmp_path / "C*.png"):
        code, out, err = _cli(capsys, "calibrate", "stereo", "--left", boards / "L*.png",
                              "--right", right, "--board", SPEC, "--out", tmp_path / "p.yaml")
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert "--left and --right give the same images (all pairs, e.g." in err
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".yaml") == []


def test_calibrate_stereo_refuses_an_implausible_baseline(boards, tmp_path, capsys):
    """Re-encoded copies of the left images (other bytes, the same pixels) pass the same-file
    check but calibrate a pair with no baseline: refused by the baseline the station file
    accepts (20-2000 mm), exit 1 with the report and the likely cause, nothing written."""
    from stationd.deviceconfig import BASELINE_MM

    for i in range(1, 9):
        img = cv2.imread(str(boards / f"L{i}.png"))
        # compressed otherwise than the original (level 1: level 9 took 0.45 s an image)
        cv2.imwrite(str(tmp_path / f"C{i}.png"), img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        assert (tmp_path / f"C{i}.png").read_bytes() != (boards / f"L{i}.png").read_bytes()
        assert np.array_equal(cv2.imread(str(tmp_path / f"C{i}.png")), img)
    code, out, err = _cli(capsys, "calibrate", "stereo", "--left", boards / "L*.png",
                          "--right", tmp_path / "C*.png", "--board", SPEC, "--out",
                          tmp_path / "p.yaml", "--json")
    assert code == 1 and err.count("\n") == 1 and "Traceback" not in err
    assert f"not a plausible stereo baseline ({BASELINE_MM[0]:g}-{BASELINE_MM[1]:g} mm)" in err
    assert "the same camera twice, or copies of one image?" in err and "nothing written" in err
    rep = json.loads(out)
    assert rep["baseline_mm"] < 1 and rep["refused"] and "out" not in rep
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".yaml") == []


def test_calibration_files_take_the_umask_mode(boards, tmp_path, capsys):
    """Issue 19 (small things): calibration files were written 0600 whatever the umask, so
    written as root the service user could not read them."""
    import os
    import stat

    old = os.umask(0o022)
    try:
        out = tmp_path / "pair.yaml"
        assert _cli(capsys, "calibrate", "stereo", "--left", boards / "L*.png", "--right",
                    boards / "R*.png", "--board", SPEC, "--out", out)[0] == 0
    finally:
        os.umask(old)
    for p in (out, tmp_path / "pair.left.yaml", tmp_path / "pair.right.yaml"):
        assert stat.S_IMODE(p.stat().st_mode) == 0o644, p


def test_calibrate_stereo_refuses_left_and_right_swapped(boards, tmp_path, capsys):
    """Issue 19: the right camera's images given as --left (and the left's as --right)
    calibrate a good pair with the right camera 60 mm to the left of the left one: each
    camera's lens model then meets the other camera's images.  Refused with the likely cause,
    exit 1 with the report, nothing written."""
    code, out, err = _cli(capsys, "calibrate", "stereo", "--left", boards / "R*.png",
                          "--right", boards / "L*.png", "--board", SPEC, "--out",
                          tmp_path / "p.yaml", "--json")
    assert code == 1 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "the right camera is 60 mm to the left of the left camera" in err, err
    assert "left and right swapped?" in err and "nothing written" in err
    rep = json.loads(out)
    assert abs(rep["baseline_mm"] - 60.0) < 2 and "swapped" in rep["refused"]
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix == ".yaml") == []
