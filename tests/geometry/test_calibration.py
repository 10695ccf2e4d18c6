"""Stereo calibration: exact synthetic corner sets, rendered board images, OpenCV's own real
stereo images (Debian's opencv-doc), and every refusal."""

import argparse
import gzip
import json
import re
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from stationd.calibrate_cli import add_calibrate_parser, expand_images
from stationd.errors import ImageError, InputError
from stationd.geometry.calibration import (
    BoardCorners,
    ViewPair,
    calibrate_stereo,
    calibrate_views,
    detect_corners,
    parse_board,
    read_grey,
)
from stationd.geometry.camera import StereoPair


def _rot(rx, ry, rz):
    return cv2.Rodrigues(np.radians([rx, ry, rz]).astype(np.float64))[0]


# a 1280x960 pair with real lens distortion, right camera 120 mm to the right, toed in 3 deg
K_L = np.array([[1210.0, 0, 652.0], [0, 1205.0, 471.0], [0, 0, 1]])
K_R = np.array([[1190.0, 0, 628.0], [0, 1192.0, 489.0], [0, 0, 1]])
D_L = np.array([-0.21, 0.09, 4e-4, -3e-4, -0.01])
D_R = np.array([-0.18, 0.05, -2e-4, 5e-4, 0.0])
R_LR = _rot(0.5, 6.0, 0.3)  # toed in: the axes cross about 1.1 m away
T_LR = np.array([-120.0, 0.8, 2.5])
SIZE = (1280, 960)


def _poses(rng, board, n, size, K, margin, spread=0.35):
    """Board poses in the left camera whose corners all land inside both images, aimed in
    turn at the middle, edges and corners of the left image so that coverage is complete."""
    obj = board.object_points()
    centre = obj.mean(axis=0)
    targets = [(0.5 + du, 0.5 + dv) for du in (-spread, 0, spread) for dv in (-spread, 0, spread)]
    poses = []
    for _ in range(20000):
        u, v = targets[len(poses) % len(targets)]
        z = rng.uniform(800, 1200)
        aim = np.array([(u * size[0] - K[0, 2]) / K[0, 0], (v * size[1] - K[1, 2]) / K[1, 1], 1])
        R = _rot(rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(-20, 20))
        t = aim * z - R @ centre
        ok = True
        for Rc, tc, Kc, Dc in ((R, t, K_L, D_L), (R_LR @ R, R_LR @ t + T_LR, K_R, D_R)):
            p = cv2.projectPoints(obj, cv2.Rodrigues(Rc)[0], tc, Kc, Dc)[0].reshape(-1, 2)
            ok &= bool(np.all((p > margin) & (p < np.array(size) - 1 - margin)))
        if ok:
            poses.append((R, t))
            if len(poses) == n:
                return poses
    raise AssertionError("no board poses fit both images")


def _synthetic_views(n, noise=0.05, seed=0, spread=0.35):
    board = parse_board("chessboard:9x6:25")
    rng = np.random.default_rng(seed)
    obj = board.object_points()
    ids = np.arange(len(obj))
    views = []
    for i, (R, t) in enumerate(_poses(rng, board, n, SIZE, K_L, 5, spread)):
        pts = []
        for Rc, tc, Kc, Dc in ((R, t, K_L, D_L), (R_LR @ R, R_LR @ t + T_LR, K_R, D_R)):
            p = cv2.projectPoints(obj, cv2.Rodrigues(Rc)[0], tc, Kc, Dc)[0].reshape(-1, 2)
            pts.append(BoardCorners(ids, p + rng.normal(0, noise, p.shape)))
        views.append(ViewPair(f"L{i}", f"R{i}", pts[0], pts[1]))
    return board, views


def test_synthetic_corners_recover_the_pair():
    board, views = _synthetic_views(12)
    rep = calibrate_views(views, board, SIZE, SIZE)
    pair = rep.pair
    assert rep.used == 12 and not rep.warnings
    assert 0.03 < rep.rms_px < 0.08  # the 0.05 px noise, less the fitted parameters
    assert np.abs(pair.left.K - K_L).max() < 2.0 and np.abs(pair.right.K - K_R).max() < 2.0
    assert np.abs(pair.left.dist[:2] - D_L[:2]).max() < 0.01
    assert np.degrees(np.linalg.norm(cv2.Rodrigues(pair.R.T @ R_LR)[0])) < 0.02
    assert np.linalg.norm(pair.T - T_LR) < 0.3  # mm, on a 120 mm baseline
    assert pair.left.size == SIZE and pair.right.dist.size == 5
    text = rep.format()
    assert "RMS reprojection error: pair" in text and "L11 | R11" in text


def _noisy(corners, sigma, seed=9):
    noise = np.random.default_rng(seed).normal(0, sigma, corners.points.shape)
    return BoardCorners(corners.ids, corners.points + noise)


def test_outliers_and_missing_boards_are_rejected_with_reasons():
    board, views = _synthetic_views(10, seed=1)
    flipped = views[3].right  # found in the opposite corner order in the right image
    views[3] = ViewPair("L3", "R3", views[3].left,
                        BoardCorners(flipped.ids, flipped.points[::-1].copy()))
    views[4] = ViewPair("L4", "R4", views[4].left, _noisy(views[4].right, 1.5))
    views[5] = ViewPair("L5", "R5", views[5].left, BoardCorners.missing("chessboard not found"))
    views[6] = ViewPair("L6", "R6", BoardCorners.missing("chessboard not found"),
                        BoardCorners.missing("chessboard not found"))
    rep = calibrate_views(views, board, SIZE, SIZE)
    reasons = {v.left_name: v.rejected for v in rep.views}
    assert reasons["L3"].startswith("inconsistent with the other views: its left-to-right "
                                    "rotation differs by 179.9 deg")
    assert reasons["L4"].startswith("outlier error")
    assert reasons["L5"] == "board not found in the right image (chessboard not found)"
    assert reasons["L6"].startswith("board not found in either image")
    assert rep.used == 6 and rep.rms_px < 0.08  # (fewer views: coverage warnings)
    assert np.linalg.norm(rep.pair.T - T_LR) < 0.5
    out = rep.format()
    assert "rejected: outlier error" in out and "rejected: board not found" in out
    assert rep.to_json()["views"][4]["error_right_px"] > 1.0


def test_an_outlier_is_kept_with_a_warning_when_only_six_pairs_remain():
    board, views = _synthetic_views(6, seed=2)
    views[0] = ViewPair("L0", "R0", views[0].left, _noisy(views[0].right, 1.5))
    rep = calibrate_views(views, board, SIZE, SIZE)
    assert rep.used == 6
    assert any(w.startswith("view 1 (L0) has an outlier error") and "kept: only 6" in w
               for w in rep.warnings)


def test_views_that_disagree_on_the_pair_are_refused_when_too_few_agree():
    board, views = _synthetic_views(6, seed=2)
    p = views[0].right
    views[0] = ViewPair("L0", "R0", views[0].left, BoardCorners(p.ids, p.points[::-1].copy()))
    with pytest.raises(InputError, match=r"only 5 usable image pairs out of 6.*inconsistent"):
        calibrate_views(views, board, SIZE, SIZE)


def test_coverage_warning_when_the_board_stays_in_the_middle():
    board, views = _synthetic_views(8, seed=3, spread=0.05)
    rep = calibrate_views(views, board, SIZE, SIZE)
    assert any(w.startswith("left camera: the board never reached the top-left, top-right, "
                            "bottom-left, bottom-right corners") for w in rep.warnings)


def test_fewer_than_six_usable_pairs_is_refused():
    board, views = _synthetic_views(7, seed=4)
    views[0] = ViewPair("a", "b", views[0].left, BoardCorners.missing("chessboard not found"))
    views[1] = ViewPair("c", "d", BoardCorners.missing("chessboard not found"), views[1].right)
    with pytest.raises(InputError, match=r"only 5 usable image pairs out of 7, at least 6 "
                                         r"are needed.*board not found in the left image"):
        calibrate_views(views, board, SIZE, SIZE)


# -- boards --------------------------------------------------------------------------------
def test_parse_board():
    b = parse_board("chessboard:9x6:25")
    assert (b.kind, b.cols, b.rows, b.square_mm) == ("chessboard", 9, 6, 25.0)
    assert b.object_points()[10].tolist() == [25.0, 25.0, 0.0]
    c = parse_board("charuco:11x8:20:15:DICT_5X5_100")
    assert (c.kind, c.cols, c.rows, c.square_mm, c.marker_mm) == ("charuco", 11, 8, 20, 15)
    assert c.dictionary == "DICT_5X5_100" and c.object_points().shape == (70, 3)
    assert parse_board("ChArUco:5X7:30.5:22:dict_4x4_50").square_mm == 30.5


@pytest.mark.parametrize(("spec", "message"), [
    ("", "expected chessboard:COLSxROWS"),
    ("checkerboard:9x6:25", "expected chessboard:COLSxROWS"),
    ("chessboard:9x6", "expected chessboard:COLSxROWS"),
    ("chessboard:9by6:25", "must be COLSxROWS"),
    ("chessboard:2x6:25", "at least 3x3"),
    ("chessboard:9x6:abc", "square size 'abc' is not a number"),
    ("chessboard:9x6:-5", "must be a positive number"),
    ("chessboard:9x6:0.025", "a square of 0.025 mm is not plausible (at least 1 mm"),
    ("chessboard:9x6:nan", "must be a positive number"),
    # issue 19: 74 GiB asked of OpenCV; an overflow into a LinAlgError
    ("chessboard:99999x99999:25", "at most 200 per side, got 99999x99999"),
    ("chessboard:9x201:25", "at most 200 per side"),
    ("chessboard:9x6:1e308", "a square of 1e+308 mm is not plausible (at most 500 mm"),
    ("charuco:11x8:600:15:DICT_5X5_100", "a square of 600 mm is not plausible"),
    ("charuco:11x8:20:15", "expected chessboard:COLSxROWS"),
    ("charuco:11x8:20:25:DICT_5X5_100", "must be smaller than the square"),
    ("charuco:11x8:20:15:DICT_9X9_1", "unknown dictionary"),
    ("charuco:11x8:20:15:detectMarkers", "unknown dictionary"),
    ("charuco:12x10:20:15:DICT_4X4_50", "need 60 markers, DICT_4X4_50 has 50"),
])
def test_bad_board_specs_are_refused(spec, message):
    with pytest.raises(InputError, match=re.escape(message)):
        parse_board(spec)


# -- rendered images -------------------------------------------------------------------------
PPM = 8.0  # texture pixels per mm
PAD = 80  # white margin around the board, texture pixels


def _texture(board):
    """The board as printed, and where board mm (0, 0) lands in texture pixels (centres)."""
    if board.kind == "charuco":
        w, h = round(board.cols * board.square_mm * PPM), round(board.rows * board.square_mm * PPM)
        from stationd.geometry.calibration import _charuco
        img = _charuco(board).generateImage((w, h), marginSize=0)
        origin = 0.0
    else:
        sq = round(board.square_mm * PPM)
        ii, jj = np.indices(((board.rows + 1) * sq, (board.cols + 1) * sq)) // sq
        img = np.where((ii + jj) % 2 == 0, 0, 255).astype(np.uint8)
        origin = board.square_mm
    img = cv2.copyMakeBorder(img, PAD, PAD, PAD, PAD, cv2.BORDER_CONSTANT, value=255)
    return img, PAD + origin * PPM - 0.5


def _render(texture, origin, K, R, t, size, rng, factor=4):
    """A pinhole view of the planar board: a homography, rendered 4x larger and averaged
    down (no aliasing), then blurred slightly and given sensor noise."""
    A = np.array([[PPM, 0, origin], [0, PPM, origin], [0, 0, 1]])
    H = K @ np.c_[R[:, :2], t] @ np.linalg.inv(A)
    S = np.array([[factor, 0, (factor - 1) / 2], [0, factor, (factor - 1) / 2], [0, 0, 1]])
    big = cv2.warpPerspective(texture, S @ H, (size[0] * factor, size[1] * factor),
                              flags=cv2.INTER_LINEAR, borderValue=128)
    img = cv2.resize(big, size, interpolation=cv2.INTER_AREA).astype(np.float64)
    img = cv2.GaussianBlur(img, (0, 0), 0.6) + rng.normal(0, 2.0, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)


@pytest.mark.parametrize(("spec", "size"), [
    ("chessboard:9x6:25", (2400, 1800)),  # larger than DETECT_MAX_SIDE: found reduced
    ("chessboard:7x5:30", (640, 480)),
    ("charuco:7x5:30:22:DICT_4X4_50", (640, 480)),
])
def test_rendered_board_corners_are_subpixel_accurate(spec, size):
    board = parse_board(spec)
    texture, origin = _texture(board)
    K = np.array([[1.4 * size[0], 0, size[0] / 2], [0, 1.4 * size[0], size[1] / 2], [0, 0, 1]])
    R, t = _rot(20, -15, 5), np.array([-10.0, 5.0, 2.0 * 1.4 * 300.0])
    t -= R @ board.object_points().mean(axis=0)
    img = _render(texture, origin, K, R, t, size, np.random.default_rng(0))
    found = detect_corners(img, board)
    assert found.found, found.reason
    truth = cv2.projectPoints(board.object_points()[found.ids], cv2.Rodrigues(R)[0], t, K,
                              None)[0].reshape(-1, 2)
    err = np.linalg.norm(found.points - truth, axis=1)
    assert len(found.ids) == len(board.object_points())
    # measured: chessboard 0.03-0.05 px RMS; ChArUco (OpenCV's own refinement) 0.067 px
    assert err.max() < 0.2 and np.sqrt(np.mean(err**2)) < 0.09


def _cli(argv):
    parser = argparse.ArgumentParser(prog="stationd")
    add_calibrate_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


@pytest.mark.parametrize("spec", ["chessboard:9x6:20", "charuco:7x5:30:22:DICT_4X4_50"])
def test_rendered_pairs_calibrate_end_to_end(tmp_path, capsys, spec):
    board = parse_board(spec)
    texture, origin = _texture(board)
    size = (640, 480)
    K1 = np.array([[560.0, 0, 318.0], [0, 560.0, 243.0], [0, 0, 1]])
    K2 = np.array([[570.0, 0, 325.0], [0, 570.0, 236.0], [0, 0, 1]])
    R12, T12 = _rot(0.3, -2.0, 0.2), np.array([-60.0, 0.5, 1.0])
    rng = np.random.default_rng(5)
    obj, n = board.object_points(), 0
    while n < 8:
        R = _rot(rng.uniform(-35, 35), rng.uniform(-35, 35), rng.uniform(-15, 15))
        t = np.array([rng.uniform(-60, 60), rng.uniform(-50, 50), rng.uniform(450, 650)])
        t -= R @ obj.mean(axis=0)
        inside = True
        for Rc, tc, Kc in ((R, t, K1), (R12 @ R, R12 @ t + T12, K2)):
            p = cv2.projectPoints(obj, cv2.Rodrigues(Rc)[0], tc, Kc, None)[0].reshape(-1, 2)
            inside &= bool(np.all((p > 30) & (p < np.array(size) - 31)))
        if not inside:
            continue
        n += 1
        for name, Rc, tc, Kc in (("L", R, t, K1), ("R", R12 @ R, R12 @ t + T12, K2)):
            cv2.imwrite(str(tmp_path / f"{name}{n}.png"), _render(texture, origin, Kc, Rc, tc,
                                                                    size, rng))
    out = tmp_path / "pair.yaml"
    assert _cli(["calibrate", "stereo", "--left", str(tmp_path / "L*.png"), "--right",
                 str(tmp_path / "R*.png"), "--board", spec, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "views: 8 pairs, 8 used, 0 rejected" in text and f"wrote {out}" in text
    pair = StereoPair.load(out)
    assert out.read_text().startswith("# stationd calibrate stereo:")
    assert abs(pair.baseline_mm / np.linalg.norm(T12) - 1) < 0.01
    assert np.abs(pair.left.K - K1).max() < 6 and np.abs(pair.right.K - K2).max() < 6
    assert pair.left.size == size


# -- refusals ---------------------------------------------------------------------------------
def test_image_refusals(tmp_path):
    board = parse_board("chessboard:9x6:25")
    with pytest.raises(InputError, match="3 left images but 2 right images"):
        calibrate_stereo(["a", "b", "c"], ["a", "b"], board)
    with pytest.raises(InputError, match="no images given"):
        calibrate_stereo([], [], board)
    for name, shape in (("L1.png", (480, 640)), ("L2.png", (240, 320)), ("R1.png", (480, 640)),
                        ("R2.png", (480, 640))):
        cv2.imwrite(str(tmp_path / name), np.full(shape, 200, np.uint8))
    with pytest.raises(InputError, match=r"L2.png: 320x240 pixels, but .*L1.png is 640x480; "
                                         "all left images must have one size"):
        calibrate_stereo([tmp_path / "L1.png", tmp_path / "L2.png"],
                         [tmp_path / "R1.png", tmp_path / "R2.png"], board)
    with pytest.raises(InputError, match=r"only 0 usable image pairs out of 1.*board not found "
                                         r"in either image"):
        calibrate_stereo([tmp_path / "L1.png"], [tmp_path / "R1.png"], board)
    (tmp_path / "bad.png").write_text("not an image")
    with pytest.raises(ImageError, match=r"bad\.png: a text file, not an image"):
        read_grey(tmp_path / "bad.png")
    with pytest.raises(ImageError, match=r"nope\.png: no such file"):
        read_grey(tmp_path / "nope.png")
    cv2.imwrite(str(tmp_path / "colour.png"), np.zeros((4, 5, 3), np.uint8))
    assert read_grey(tmp_path / "colour.png").shape == (4, 5)


def test_cli_refusals(tmp_path):
    for i in (1, 2, 10):
        cv2.imwrite(str(tmp_path / f"L{i}.png"), np.zeros((8, 8), np.uint8))
    cv2.imwrite(str(tmp_path / "R1.png"), np.zeros((8, 8), np.uint8))
    assert expand_images([str(tmp_path / "L*.png")], "--left") == [
        str(tmp_path / f"L{i}.png") for i in (1, 2, 10)]  # natural order, not L1 L10 L2
    base = ["calibrate", "stereo", "--board", "chessboard:9x6:25", "--out",
            str(tmp_path / "p.yaml")]
    with pytest.raises(InputError, match=r"--right '.*Q\*.png': matches no file"):
        _cli([*base, "--left", str(tmp_path / "L*.png"), "--right", str(tmp_path / "Q*.png")])
    with pytest.raises(InputError, match="3 left images but 1 right images"):
        _cli([*base, "--left", str(tmp_path / "L*.png"), "--right", str(tmp_path / "R*.png")])
    with pytest.raises(InputError, match="board 'chessboard:9x6'"):
        _cli(["calibrate", "stereo", "--left", "x", "--right", "y", "--board", "chessboard:9x6"])
    assert not (tmp_path / "p.yaml").exists()


def test_nested_parser_keeps_the_stationd_usage_errors():
    from stationd.cli import EXIT_BAD_INPUT, _Parser

    parser = _Parser(prog="stationd")
    add_calibrate_parser(parser.add_subparsers(dest="command", required=True,
                                               parser_class=_Parser))
    with pytest.raises(SystemExit) as exc:
        parser.parse_args(["calibrate", "mono"])
    assert exc.value.code == EXIT_BAD_INPUT


# -- OpenCV's real stereo images (Debian package opencv-doc) ----------------------------------
def _opencv_doc_data():
    candidates = [Path("/usr/share/doc/opencv-doc/examples/data")]
    if shutil.which("dpkg"):
        r = subprocess.run(["dpkg", "-L", "opencv-doc"], capture_output=True, text=True)
        candidates += [Path(p).parent for p in r.stdout.splitlines()
                       if p.endswith(("stereo_calib.xml", "stereo_calib.xml.gz"))]
    for d in candidates:
        for name in ("stereo_calib.xml", "stereo_calib.xml.gz"):
            if (d / name).is_file():
                return d, d / name
    pytest.skip("OpenCV's stereo images are missing: apt-get install opencv-doc")


def _read_maybe_gz(path):
    return gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()


def test_opencv_stereo_sample_images(tmp_path, capsys):
    """13 real 640x480 pairs of a 9x6 board (OpenCV's stereo_calib sample).  OpenCV's sample
    reaches 0.60 px pair RMS on them with OpenCV 5.0 (0.44 px if started from per-camera
    calibrations with its 11 px corner window) and a baseline of 3.336 squares."""
    data, listing = _opencv_doc_data()
    text = _read_maybe_gz(listing).decode()
    names = re.findall(r'"([^"]+)"', text[text.index("<imagelist>"):])
    assert len(names) == 26
    for name in names:
        src = data / name if (data / name).is_file() else data / f"{name}.gz"
        (tmp_path / name).write_bytes(_read_maybe_gz(src))
    out = tmp_path / "pair.yaml"
    assert _cli(["calibrate", "stereo", "--left", str(tmp_path / "left*.jpg"), "--right",
                 str(tmp_path / "right*.jpg"), "--board", "chessboard:9x6:25", "--out",
                 str(out), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    pair = StereoPair.load(out)
    assert len(rep["views"]) == 13 and sum(not v["rejected"] for v in rep["views"]) >= 12
    assert rep["rms_px"] <= 0.25  # measured 0.199 px
    assert rep["rms_left_px"] <= 0.25 and rep["rms_right_px"] <= 0.25
    # the sample does not give its square size: 25 mm is assumed (1 "mm" squares would make
    # a 3.3 mm baseline, which calibrate stereo refuses as no station's: 20-2000 mm)
    assert abs(pair.baseline_mm / (3.34 * 25) - 1) < 0.01  # measured 3.327 squares
    assert pair.T[0] / pair.baseline_mm < -0.99  # the right camera is to the right
    assert np.degrees(np.linalg.norm(cv2.Rodrigues(pair.R)[0])) < 2.0
    assert pair.left.size == (640, 480)
    # the sample's board never goes near the image corners; the report says so
    assert any(w.startswith("left camera: the board never reached") for w in rep["warnings"])
    assert yaml.safe_load(out.read_text())["T"] == pytest.approx(pair.T.tolist())
