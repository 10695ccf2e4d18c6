"""Stereo calibration from views of a chessboard or ChArUco board.

Why it is built this way:
- each camera is first calibrated alone (``cv2.calibrateCamera``) and the pair is then refined
  jointly from that start (``cv2.stereoCalibrate`` with ``CALIB_USE_INTRINSIC_GUESS``): the joint
  refinement is the maximum-likelihood estimate, and a good start keeps it from a poor minimum
  (OpenCV's own sample starts from ``initCameraMatrix2D`` and ends higher on its own images);
- the worst view is dropped and everything refitted while its error is an outlier, one view at a
  time, because a bad view (a bent board, a corner found in the wrong place, a board flipped in
  one camera) inflates the errors of the good ones;
- corners are detected on a reduced image when the image is large (seconds at 20 MP otherwise)
  and always refined at full resolution, so the result does not depend on the reduction;
- a board not found reduced is searched again at larger sizes (behind OpenCV's fast check) only
  while the estimated cost fits the per-image time bound (:data:`VIEW_BUDGET_S`): the plain
  search on a 20 MP image without the board took up to 128 s, and a view whose board is not
  there is skipped with the reason;
- object points are in mm, so ``T`` is in mm: ``x_right = R @ x_left + T`` as in
  :class:`~stationd.geometry.camera.StereoPair`.
"""

from __future__ import annotations

import re
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np

from stationd import progress
from stationd.errors import ImageError, InputError
from stationd.geometry.camera import Camera, StereoPair
from stationd.imageio import decode, not_an_image, read_image_bytes

MIN_PAIRS = 6
MIN_CORNERS = 6  # common corners a ChArUco view needs (a chessboard has all or none)
DETECT_MAX_SIDE = 1600  # larger images are searched reduced, then refined at full size
VIEW_BUDGET_S = 5.0  # per image: larger search sizes are tried only while they fit in this
MIN_SQUARE_PX = 4  # a board square smaller than this in the image cannot be found
RETRY_MAX_SIDE = 2 * DETECT_MAX_SIDE  # and never above this (see _search_chessboard)
CORNER_ZONE = 0.2  # the board "reached" an image corner if a point fell this close (fraction)
_SPEC_HELP = ("expected chessboard:COLSxROWS:SQUARE_MM (inner corners, e.g. chessboard:9x6:25) "
              "or charuco:COLSxROWS:SQUARE_MM:MARKER_MM:DICT (squares, e.g. "
              "charuco:11x8:20:15:DICT_5X5_100)")
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 0.001)
_CALIB_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-7)
_CONSENSUS_DEG = 10.0  # a view agrees when its left-to-right rotation is this close


# -- boards --------------------------------------------------------------------------------
@dataclass(frozen=True)
class Board:
    """A planar target.  ``cols x rows`` counts inner corners for a chessboard (OpenCV's
    ``patternSize``) and squares for a ChArUco board (OpenCV's ``CharucoBoard`` size)."""

    kind: Literal["chessboard", "charuco"]
    cols: int
    rows: int
    square_mm: float
    marker_mm: float = 0.0
    dictionary: str = ""

    def describe(self) -> str:
        if self.kind == "chessboard":
            return (f"chessboard {self.cols}x{self.rows} inner corners, "
                    f"{self.square_mm:g} mm squares")
        return (f"ChArUco {self.cols}x{self.rows} squares, {self.square_mm:g} mm squares, "
                f"{self.marker_mm:g} mm markers, {self.dictionary}")

    def object_points(self) -> np.ndarray:
        """(N, 3) corner positions in mm on the board plane z = 0, indexed by corner id."""
        if self.kind == "charuco":
            return np.asarray(_charuco(self).getChessboardCorners(), dtype=np.float64)
        cc, rr = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        pts = np.stack([cc.ravel(), rr.ravel(), np.zeros(cc.size)], axis=1)
        return np.asarray(pts * np.array([self.square_mm, self.square_mm, 1.0]), dtype=np.float64)


def parse_board(spec: str) -> Board:
    """``chessboard:9x6:25`` or ``charuco:11x8:20:15:DICT_5X5_100`` -> :class:`Board`."""
    parts = spec.strip().split(":")
    kind = parts[0].lower()
    n_parts = {"chessboard": 3, "charuco": 5}.get(kind)
    if n_parts is None or len(parts) != n_parts:
        raise InputError(f"board {spec!r}: {_SPEC_HELP}")
    m = re.fullmatch(r"(\d+)[xX](\d+)", parts[1])
    if m is None:
        raise InputError(f"board {spec!r}: size {parts[1]!r} must be COLSxROWS, e.g. 9x6")
    cols, rows = int(m.group(1)), int(m.group(2))
    if cols < 3 or rows < 3:
        raise InputError(f"board {spec!r}: at least 3x3 needed, got {cols}x{rows}")
    if cols > MAX_SIDE or rows > MAX_SIDE:   # 99999x99999 asked OpenCV for tens of GiB
        raise InputError(f"board {spec!r}: at most {MAX_SIDE} per side, got {cols}x{rows} "
                         "(count the board's inner corners, or squares for ChArUco)")
    square = _positive_mm(spec, "square size", parts[2])
    if square < MIN_SQUARE_MM:
        raise InputError(f"board {spec!r}: a square of {square:g} mm is not plausible (at least "
                         f"{MIN_SQUARE_MM:g} mm; sizes are in millimetres, not metres)")
    if square > MAX_SQUARE_MM:   # 1e308 overflowed the calibration into a LinAlgError
        raise InputError(f"board {spec!r}: a square of {square:g} mm is not plausible (at most "
                         f"{MAX_SQUARE_MM:g} mm; sizes are in millimetres)")
    if kind == "chessboard":
        return Board("chessboard", cols, rows, square)
    marker = _positive_mm(spec, "marker size", parts[3])
    if marker >= square:
        raise InputError(f"board {spec!r}: the marker ({marker:g} mm) must be smaller than "
                         f"the square ({square:g} mm)")
    name = parts[4].upper()
    if not name.startswith("DICT_") or not isinstance(getattr(cv2.aruco, name, None), int):
        raise InputError(f"board {spec!r}: unknown dictionary {parts[4]!r} (an OpenCV name "
                         "such as DICT_5X5_100, DICT_4X4_50, DICT_APRILTAG_36h11)")
    board = Board("charuco", cols, rows, square, marker, name)
    available = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name)).bytesList.shape[0]
    needed = cols * rows // 2
    if needed > available:
        raise InputError(f"board {spec!r}: {cols}x{rows} squares need {needed} markers, "
                         f"{name} has {available}")
    return board



def _outlier(errors: dict[int, float], factor: float, floor_px: float) -> tuple[int, str] | None:
    """The view whose RMS error is above ``factor`` x the median (and ``floor_px``), with the
    reason it is dropped; None when every view is within: one rule for mono and stereo."""
    threshold = max(factor * float(np.median(list(errors.values()))), floor_px)
    worst = max(errors, key=lambda k: errors[k])
    if errors[worst] <= threshold:
        return None
    return worst, f"outlier error {errors[worst]:.2f} px > {threshold:.2f} px"

MIN_SQUARE_MM = 1.0  # a printed board's square: below 1 mm it was given in metres
MAX_SQUARE_MM = 500.0  # a board of 9x6 such squares is already 5 m wide
MAX_SIDE = 200  # corners (or squares) per side: far above any printed board


def _positive_mm(spec: str, what: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"board {spec!r}: {what} {text!r} is not a number (mm)") from None
    if not np.isfinite(value) or value <= 0:
        raise InputError(f"board {spec!r}: {what} must be a positive number of mm")
    return value


@lru_cache(maxsize=8)
def _charuco(board: Board) -> Any:
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    return cv2.aruco.CharucoBoard((board.cols, board.rows), board.square_mm, board.marker_mm,
                                  dictionary)


@lru_cache(maxsize=8)
def _charuco_detector(board: Board) -> Any:
    return cv2.aruco.CharucoDetector(_charuco(board))


# -- detection -----------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class BoardCorners:
    """Corners found in one image: ids into :meth:`Board.object_points` and raw pixels (N, 2).
    A failure is a value whose ``reason`` says why, so the report can list it."""

    ids: np.ndarray
    points: np.ndarray
    reason: str = ""

    @property
    def found(self) -> bool:
        return not self.reason

    @classmethod
    def missing(cls, reason: str) -> BoardCorners:
        return cls(np.zeros(0, dtype=np.int64), np.zeros((0, 2)), reason)


def read_grey(path: str | Path) -> np.ndarray:
    """An 8-bit grey image (colour and 16-bit files are converted): calibration needs no
    colour, and many machine-vision cameras save Mono8."""
    p = Path(path)
    data = read_image_bytes(p)
    img = decode(data, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ImageError(f"{p}: {not_an_image(data)}")
    return np.asarray(img)


def detect_corners(grey: np.ndarray, board: Board, *,
                   budget_s: float = VIEW_BUDGET_S) -> BoardCorners:
    """Find the board in an 8-bit grey image, with sub-pixel corners.  A chessboard search
    stops at the per-image time bound ``budget_s`` with the reason (module docstring).  An
    image too small to show the board, or one OpenCV refuses, is a board not found with the
    reason, never an OpenCV assertion."""
    squares = max(board.cols, board.rows) + (0 if board.kind == "charuco" else 1)
    if min(grey.shape[:2]) < MIN_SQUARE_PX * squares:
        return BoardCorners.missing(
            f"image of {grey.shape[1]}x{grey.shape[0]} px is too small to show the board "
            f"(at least {MIN_SQUARE_PX} px per square)")
    try:
        return _detect_corners(grey, board, budget_s)
    except cv2.error as exc:
        why = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        return BoardCorners.missing(f"board not found (OpenCV: {why[:120]})")


def _detect_corners(grey: np.ndarray, board: Board, budget_s: float) -> BoardCorners:
    if board.kind == "charuco":
        corners, ids, _, marker_ids = _charuco_detector(board).detectBoard(grey)
        if marker_ids is None or len(marker_ids) == 0:
            return BoardCorners.missing("no ChArUco marker found")
        n = 0 if ids is None else len(ids)
        if n < MIN_CORNERS:
            return BoardCorners.missing(f"only {n} ChArUco corners found")
        return BoardCorners(np.asarray(ids).ravel().astype(np.int64),
                            np.asarray(corners, dtype=np.float64).reshape(-1, 2))
    pattern = (board.cols, board.rows)
    found, pts, reason = _search_chessboard(grey, pattern, budget_s)
    if not found or pts is None:
        return BoardCorners.missing(reason)
    pts = np.asarray(pts, dtype=np.float32).reshape(-1, 1, 2)  # (N, 2) in OpenCV 5
    grid = pts.reshape(board.rows, board.cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=2).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=2).min())
    half = int(np.clip(0.3 * spacing, 2, 11))  # the window must not reach the next corner
    pts = cv2.cornerSubPix(grey, pts, (half, half), (-1, -1), _SUBPIX_CRITERIA)
    return BoardCorners(np.arange(board.cols * board.rows, dtype=np.int64),
                        np.asarray(pts, dtype=np.float64).reshape(-1, 2))


def _search_chessboard(grey: np.ndarray, pattern: tuple[int, int], budget_s: float,
                       ) -> tuple[bool, np.ndarray | None, str]:
    """(found, full-resolution points, reason): reduced to DETECT_MAX_SIDE first, then twice
    as large each time up to RETRY_MAX_SIDE (or full size when that is smaller), each step
    only if its estimated cost (the last step's time, scaled by the pixel count) fits in
    what is left of ``budget_s``."""
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    scale = min(1.0, DETECT_MAX_SIDE / max(grey.shape))
    start = time.monotonic()
    last_cost, last_scale, spent = 0.0, scale, 0.0
    while True:
        if last_cost:
            spent = time.monotonic() - start
        estimate = last_cost * (scale / last_scale) ** 2
        if last_cost and spent + estimate > budget_s:
            return False, None, (f"chessboard not found at up to {last_scale:.0%} size; larger "
                                 f"sizes skipped (about {estimate:.1f} s more, the bound is "
                                 f"{budget_s:g} s per image)")
        t0 = time.monotonic()
        img = grey if scale >= 1.0 else cv2.resize(grey, None, fx=scale, fy=scale,
                                                   interpolation=cv2.INTER_AREA)
        # a retry at a larger size is for a small board: OpenCV's fast check first makes it
        # cost a fraction of a second when the board is not there at all (measured on a
        # rendered 20 MP station frame: 3.7 s -> 0.17 s at 3200 px)
        retry = cv2.CALIB_CB_FAST_CHECK if last_cost else 0
        found, pts = cv2.findChessboardCorners(img, pattern, flags=flags | retry)
        last_cost, last_scale = max(time.monotonic() - t0, 1e-3), scale
        if found and pts is not None:  # pixel centres: x_full = (x_small + 0.5) / s - 0.5
            return True, (np.asarray(pts).reshape(-1, 2) + 0.5) / scale - 0.5, ""
        if scale >= 1.0:
            return False, None, "chessboard not found"
        scale = min(1.0, 2.0 * scale)
        if max(grey.shape) * scale > RETRY_MAX_SIDE + 0.5:
            # Measured on a rendered 20 MP station frame without a board: 1.0 s at 1600 px,
            # 0.2 s at 3200 px behind the fast check, but 158 s at full size (the fast check
            # passed on the texture).  A board too small to be found at 3200 px covers too
            # little of the image to calibrate it anyway.
            return False, None, (f"chessboard not found at up to {RETRY_MAX_SIDE} px (the "
                                 "full-size search is not tried on larger images: it can "
                                 "take minutes; bring the board closer)")


# -- calibration ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ViewPair:
    """The corners found in one left/right image pair, with names for the report."""

    left_name: str
    right_name: str
    left: BoardCorners
    right: BoardCorners


@dataclass(frozen=True)
class ViewReport:
    """One view in the report: corners used, per-view RMS (px) per camera, and why it was
    rejected (empty when it was used)."""

    left_name: str
    right_name: str
    corners: int = 0
    error_left_px: float | None = None
    error_right_px: float | None = None
    rejected: str = ""

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "rejected": self.rejected or None}


@dataclass(frozen=True, eq=False)
class CalibrationReport:
    """The calibrated pair and how well the board views fit it."""

    pair: StereoPair
    board: Board
    rms_px: float
    rms_left_px: float
    rms_right_px: float
    views: tuple[ViewReport, ...]
    warnings: tuple[str, ...] = field(default=())

    @property
    def used(self) -> int:
        return sum(not v.rejected for v in self.views)

    def to_json(self) -> dict[str, Any]:
        return {"board": self.board.describe(), "rms_px": self.rms_px,
                "rms_left_px": self.rms_left_px, "rms_right_px": self.rms_right_px,
                "baseline_mm": self.pair.baseline_mm, "T_mm": self.pair.T.tolist(),
                "views": [v.to_json() for v in self.views], "warnings": list(self.warnings)}

    def format(self) -> str:
        """The human-readable report the command prints."""
        rejected = len(self.views) - self.used
        t = ", ".join(f"{x:.2f}" for x in self.pair.T)
        angle = np.degrees(np.linalg.norm(cv2.Rodrigues(self.pair.R)[0]))
        lines = [f"board: {self.board.describe()}",
                 f"views: {len(self.views)} pairs, {self.used} used, {rejected} rejected",
                 f"RMS reprojection error: pair {self.rms_px:.3f} px, left "
                 f"{self.rms_left_px:.3f} px, right {self.rms_right_px:.3f} px",
                 f"baseline {self.pair.baseline_mm:.2f} mm, T [{t}] mm, rotation {angle:.2f} deg",
                 "per view (RMS px, left / right):"]
        width = max(len(v.left_name) + len(v.right_name) for v in self.views) + 3
        for i, v in enumerate(self.views, 1):
            errs = ("    -   /   -  " if v.error_left_px is None or v.error_right_px is None
                    else f"{v.error_left_px:6.3f} / {v.error_right_px:6.3f}")
            names = f"{v.left_name} | {v.right_name}".ljust(width)
            status = f"rejected: {v.rejected}" if v.rejected else "used"
            lines.append(f"  {i:3d}  {names}  {errs}  {status}")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def calibrate_stereo(left_paths: Sequence[str | Path], right_paths: Sequence[str | Path],
                     board: Board, **options: float) -> CalibrationReport:
    """Read the image pairs (left i with right i), find the board and calibrate.  Refuses with
    :class:`InputError` on unequal counts, mixed image sizes or too few usable pairs."""
    if len(left_paths) != len(right_paths):
        raise InputError(f"{len(left_paths)} left images but {len(right_paths)} right images; "
                         "they are paired in order, so the counts must match")
    if not left_paths:
        raise InputError("no images given")
    sizes: dict[str, tuple[int, int, str]] = {}
    views = []
    for lp, rp in progress.track(zip(left_paths, right_paths, strict=True), "board views",
                                 total=len(left_paths), unit="pair"):
        corners = []
        for side, path in (("left", lp), ("right", rp)):
            grey = read_grey(path)
            size = (grey.shape[1], grey.shape[0])
            first = sizes.setdefault(side, (*size, str(path)))
            if size != first[:2]:
                raise InputError(f"{path}: {size[0]}x{size[1]} pixels, but {first[2]} is "
                                 f"{first[0]}x{first[1]}; all {side} images must have one size")
            corners.append(detect_corners(grey, board))
        views.append(ViewPair(str(lp), str(rp), corners[0], corners[1]))
    progress.note(f"calibrating from {sum(v.left.found and v.right.found for v in views)} "
                  f"of {len(views)} pairs ...")
    return calibrate_views(views, board, sizes["left"][:2], sizes["right"][:2], **options)


def _common(view: ViewPair, board_points: np.ndarray) -> tuple[np.ndarray, ...] | str:
    """Object points and both image points of the corners seen in both images, or why not."""
    lf, rf = view.left.found, view.right.found
    if not (lf and rf):
        where = "either image" if not (lf or rf) else f"the {'right' if lf else 'left'} image"
        return f"board not found in {where} ({view.right.reason if lf else view.left.reason})"
    ids, li, ri = np.intersect1d(view.left.ids, view.right.ids, return_indices=True)
    if len(ids) < MIN_CORNERS:
        return f"only {len(ids)} corners seen in both images ({MIN_CORNERS} needed)"
    obj = board_points[ids]
    if np.linalg.matrix_rank(obj[:, :2] - obj[:, :2].mean(axis=0), tol=1e-9) < 2:
        return "the corners seen in both images lie on one line"
    return obj, view.left.points[li], view.right.points[ri]


def calibrate_views(views: Sequence[ViewPair], board: Board, left_size: tuple[int, int],
                    right_size: tuple[int, int], *, outlier_factor: float = 3.0,
                    outlier_floor_px: float = 0.5) -> CalibrationReport:
    """Calibrate from detected corners (pure: no files).  A view is an outlier when its RMS
    error exceeds ``outlier_factor`` times the median of the used views and
    ``outlier_floor_px`` (sub-half-pixel views never hurt enough to lose their coverage)."""
    board_points = board.object_points()
    reports: list[ViewReport] = []
    data: dict[int, tuple[np.ndarray, ...]] = {}
    for i, view in enumerate(views):
        common = _common(view, board_points)
        if isinstance(common, str):
            reports.append(ViewReport(view.left_name, view.right_name, rejected=common))
        else:
            data[i] = common
            reports.append(ViewReport(view.left_name, view.right_name, corners=len(common[0])))
    _require_pairs(data, reports)
    for i, reason in _inconsistent(list(data.values()), left_size, right_size, list(data)):
        reports[i] = replace(reports[i], rejected=reason)
        del data[i]
    _require_pairs(data, reports)
    warnings: list[str] = []
    while True:
        fit = _fit(list(data.values()), left_size, right_size)
        errors = dict(zip(data, fit["per_view"], strict=True))
        combined = {i: float(np.sqrt(np.mean(e**2))) for i, e in errors.items()}
        found = _outlier(combined, outlier_factor, outlier_floor_px)
        if found is None:
            break
        worst, reason = found
        if len(data) <= MIN_PAIRS:
            warnings.append(f"view {worst + 1} ({views[worst].left_name}) has an {reason} but "
                            f"was kept: only {MIN_PAIRS} usable pairs")
            break
        el, er = errors.pop(worst)
        del data[worst]
        reports[worst] = replace(reports[worst], error_left_px=float(el),
                                 error_right_px=float(er), rejected=reason)
    for i, (el, er) in errors.items():
        reports[i] = replace(reports[i], error_left_px=float(el), error_right_px=float(er))
    pair = StereoPair(Camera(fit["K1"], fit["d1"], left_size),
                      Camera(fit["K2"], fit["d2"], right_size), fit["R"], fit["T"])
    for side, k, size in (("left", 1, left_size), ("right", 2, right_size)):
        missed = _corners_missed([d[k] for d in data.values()], size)
        if missed:
            warnings.append(f"{side} camera: the board never reached the {', '.join(missed)} "
                            f"corner{'s' if len(missed) > 1 else ''} of the image (within "
                            f"{CORNER_ZONE:.0%} of its width and height); distortion there is "
                            "extrapolated: add views with the board in those corners")
    counts = np.array([len(d[0]) for d in data.values()], dtype=np.float64)
    per_view = np.array(list(errors.values()))
    rms_l, rms_r = (float(np.sqrt(counts @ per_view[:, j] ** 2 / counts.sum())) for j in (0, 1))
    return CalibrationReport(pair, board, float(fit["rms"]), rms_l, rms_r, tuple(reports),
                             tuple(warnings))


def _points(data: list[tuple[np.ndarray, ...]]) -> tuple[list[np.ndarray], ...]:
    obj = [d[0].astype(np.float32).reshape(-1, 1, 3) for d in data]
    return (obj, *([d[k].astype(np.float32).reshape(-1, 1, 2) for d in data] for k in (1, 2)))


def _mono(obj: list[np.ndarray], img: list[np.ndarray], size: tuple[int, int]) -> Any:
    try:
        return cv2.calibrateCamera(obj, img, size, None, None, criteria=_CALIB_CRITERIA)[1:]
    except cv2.error as exc:
        raise InputError(f"calibration failed: {str(exc).strip().splitlines()[-1]}") from None


def _inconsistent(data: list[tuple[np.ndarray, ...]], left_size: tuple[int, int],
                  right_size: tuple[int, int], keys: list[int]) -> list[tuple[int, str]]:
    """Views whose own left-to-right rotation (from each camera's pose of the board) disagrees
    grossly with the consensus: a board found in a different corner order in the two images
    fits each camera alone perfectly and would wreck the joint fit before any per-view error
    could single it out.  Only the rotation is compared: a single view's distance to the board,
    hence its translation, is too uncertain against a short baseline."""
    obj, img_l, img_r = _points(data)
    rv_l = _mono(obj, img_l, left_size)[2]
    rv_r = _mono(obj, img_r, right_size)[2]
    rotations = [cv2.Rodrigues(rr)[0] @ cv2.Rodrigues(rl)[0].T
                 for rl, rr in zip(rv_l, rv_r, strict=True)]

    def angle(a: int, b: int) -> float:
        return float(np.degrees(np.linalg.norm(cv2.Rodrigues(rotations[a] @ rotations[b].T)[0])))

    n = len(rotations)
    agree = [[j for j in range(n) if angle(i, j) < _CONSENSUS_DEG] for i in range(n)]
    best = max(range(n), key=lambda i: len(agree[i]))
    return [(keys[j], f"inconsistent with the other views: its left-to-right rotation differs "
             f"by {angle(best, j):.1f} deg (the board found in a different corner order in "
             "the two images?)") for j in sorted(set(range(n)) - set(agree[best]))]


def _fit(data: list[tuple[np.ndarray, ...]], left_size: tuple[int, int],
         right_size: tuple[int, int]) -> dict[str, Any]:
    """Each camera alone, then both jointly from there (see the module docstring)."""
    obj, img_l, img_r = _points(data)
    K1, d1, _, _ = _mono(obj, img_l, left_size)
    K2, d2, _, _ = _mono(obj, img_r, right_size)
    try:
        out = cv2.stereoCalibrateExtended(obj, img_l, img_r, K1, d1, K2, d2, left_size,
                                          np.eye(3), np.zeros((3, 1)),
                                          flags=cv2.CALIB_USE_INTRINSIC_GUESS,
                                          criteria=_CALIB_CRITERIA)
    except cv2.error as exc:
        raise InputError(f"calibration failed: {str(exc).strip().splitlines()[-1]}") from None
    rms, K1, d1, K2, d2, R, T = out[:7]
    return {"rms": rms, "K1": K1, "d1": d1, "K2": K2, "d2": d2, "R": R, "T": T,
            "per_view": np.asarray(out[-1], dtype=np.float64).reshape(-1, 2)}


def _require_pairs(data: dict[int, tuple[np.ndarray, ...]], reports: list[ViewReport]) -> None:
    if len(data) < MIN_PAIRS:
        reasons = sorted({r.rejected.split(":")[0] for r in reports if r.rejected})
        detail = f"; rejected: {'; '.join(reasons)}" if reasons else ""
        raise InputError(f"only {len(data)} usable image pairs out of {len(reports)}, at least "
                         f"{MIN_PAIRS} are needed (the board seen whole in both images, in "
                         f"varied poses){detail}")


def _corners_missed(points: list[np.ndarray], size: tuple[int, int]) -> list[str]:
    """The image corners no detected board corner came near."""
    pts = np.concatenate(points)
    w, h = size
    zx, zy = CORNER_ZONE * w, CORNER_ZONE * h
    near_left, near_right = pts[:, 0] < zx, pts[:, 0] > w - 1 - zx
    near_top, near_bottom = pts[:, 1] < zy, pts[:, 1] > h - 1 - zy
    tests = {"top-left": near_top & near_left, "top-right": near_top & near_right,
             "bottom-left": near_bottom & near_left, "bottom-right": near_bottom & near_right}
    return [name for name, hit in tests.items() if not hit.any()]


# -- one camera ------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class CameraReport:
    """One calibrated camera and how well its board views fit it."""

    camera: Camera
    board: Board
    rms_px: float
    views: tuple[ViewReport, ...]  # ``right_name`` empty, ``error_right_px`` None
    warnings: tuple[str, ...] = field(default=())

    @property
    def used(self) -> int:
        return sum(not v.rejected for v in self.views)

    def to_json(self) -> dict[str, Any]:
        return {"board": self.board.describe(), "rms_px": self.rms_px,
                "K": self.camera.K.tolist(), "dist": self.camera.dist.tolist(),
                "size": list(self.camera.size),
                "views": [{"name": v.left_name, "corners": v.corners,
                           "error_px": v.error_left_px, "rejected": v.rejected or None}
                          for v in self.views],
                "warnings": list(self.warnings)}

    def format(self) -> str:
        """The human-readable report the command prints."""
        k = self.camera.K
        lines = [f"board: {self.board.describe()}",
                 f"views: {len(self.views)} images, {self.used} used, "
                 f"{len(self.views) - self.used} rejected",
                 f"RMS reprojection error {self.rms_px:.3f} px",
                 f"fx {k[0, 0]:.1f} px, fy {k[1, 1]:.1f} px, principal point ({k[0, 2]:.1f}, "
                 f"{k[1, 2]:.1f}) px, image {self.camera.size[0]}x{self.camera.size[1]}",
                 "per view (RMS px):"]
        width = max(len(v.left_name) for v in self.views) + 2
        for i, v in enumerate(self.views, 1):
            err = "   -  " if v.error_left_px is None else f"{v.error_left_px:6.3f}"
            status = f"rejected: {v.rejected}" if v.rejected else "used"
            lines.append(f"  {i:3d}  {v.left_name.ljust(width)}  {err}  {status}")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def calibrate_camera(paths: Sequence[str | Path], board: Board, *,
                     outlier_factor: float = 3.0, outlier_floor_px: float = 0.5,
                     budget_s: float = VIEW_BUDGET_S) -> CameraReport:
    """Calibrate one camera from board images, with the outlier rule of
    :func:`calibrate_views` (a view is dropped while its error is an outlier and more than
    :data:`MIN_PAIRS` remain).  Refuses with :class:`InputError` on mixed image sizes or too
    few usable views."""
    if not paths:
        raise InputError("no images given")
    board_points = board.object_points()
    size: tuple[int, int, str] | None = None
    reports: list[ViewReport] = []
    data: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for i, path in enumerate(progress.track(paths, "board views", total=len(paths),
                                            unit="image")):
        grey = read_grey(path)
        here = (grey.shape[1], grey.shape[0])
        if size is None:
            size = (*here, str(path))
        elif here != size[:2]:
            raise InputError(f"{path}: {here[0]}x{here[1]} pixels, but {size[2]} is "
                             f"{size[0]}x{size[1]}; all images must have one size")
        found = detect_corners(grey, board, budget_s=budget_s)
        obj = board_points[found.ids] if found.found else board_points[:0]
        if not found.found:
            reports.append(ViewReport(str(path), "", rejected=f"board not found ({found.reason})"))
        elif len(obj) < MIN_CORNERS or np.linalg.matrix_rank(
                obj[:, :2] - obj[:, :2].mean(axis=0), tol=1e-9) < 2:
            reports.append(ViewReport(str(path), "", rejected="too few corners, or on one line"))
        else:
            data[i] = (obj, found.points)
            reports.append(ViewReport(str(path), "", corners=len(obj)))
    assert size is not None  # noqa: S101 - paths is not empty
    wh = (size[0], size[1])
    if len(data) < MIN_PAIRS:
        reasons = sorted({r.rejected.split(" (")[0] for r in reports if r.rejected})
        detail = f"; rejected: {'; '.join(reasons)}" if reasons else ""
        raise InputError(f"only {len(data)} usable images out of {len(reports)}, at least "
                         f"{MIN_PAIRS} are needed (the board seen whole, in varied poses)"
                         f"{detail}")
    warnings: list[str] = []
    while True:
        obj_l = [d[0].astype(np.float32).reshape(-1, 1, 3) for d in data.values()]
        img_l = [d[1].astype(np.float32).reshape(-1, 1, 2) for d in data.values()]
        K, dist, rvecs, tvecs = _mono(obj_l, img_l, wh)
        errors = {}
        for key, o, im, rv, tv in zip(data, obj_l, img_l, rvecs, tvecs, strict=True):
            proj = cv2.projectPoints(o, rv, tv, K, dist)[0].reshape(-1, 2)
            errors[key] = float(np.sqrt(np.mean(np.sum((proj - im.reshape(-1, 2)) ** 2,
                                                       axis=1))))
        dropped = _outlier(errors, outlier_factor, outlier_floor_px)
        if dropped is None:
            break
        worst, reason = dropped
        if len(data) <= MIN_PAIRS:
            warnings.append(f"view {worst + 1} ({reports[worst].left_name}) has an {reason} "
                            f"but was kept: only {MIN_PAIRS} usable views")
            break
        reports[worst] = replace(reports[worst], error_left_px=errors.pop(worst),
                                 rejected=reason)
        del data[worst]
    for key, err in errors.items():
        reports[key] = replace(reports[key], error_left_px=err)
    missed = _corners_missed([d[1] for d in data.values()], wh)
    if missed:
        warnings.append(f"the board never reached the {', '.join(missed)} corner"
                        f"{'s' if len(missed) > 1 else ''} of the image (within "
                        f"{CORNER_ZONE:.0%} of its width and height); distortion there is "
                        "extrapolated: add views with the board in those corners")
    counts = np.array([len(d[0]) for d in data.values()], dtype=np.float64)
    per_view = np.array([errors[k] for k in data])
    rms = float(np.sqrt(counts @ per_view**2 / counts.sum()))
    camera = Camera(K, np.asarray(dist).ravel(), wh)
    return CameraReport(camera, board, rms, tuple(reports), tuple(warnings))
