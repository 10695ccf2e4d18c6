"""The calibration check of one pair: its reference markers measured and compared with their
known positions, pure (frames in, a typed verdict out).

Why searched where each reference should be, and nowhere else: the check must not depend on
the wrench being out of view (an operator on the line does not clear the cell for it), and a
whole-frame search would take the wrench for a reference or refuse two markers.  Each
reference is looked for in a window around its projection (its field plus
``References.exclusion_mm`` around it, so a pair moved by up to that much still finds it,
displaced), measured with the station's own vision on that window (a camera whose principal
point is shifted by the window's corner: the same model, exactly), triangulated with the
pair's calibration and mapped with its registration: the offset from the known position is
what the pair's localizations are off by there.

A verdict per pair: ``ok`` (every reference measured within the tolerance), ``moved`` (the
worst reference and its offset: beyond the tolerance), or ``not checked`` (why: nothing
measured).  The station's core decides what follows (:mod:`stationd.station.trust`).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from stationd.geometry.camera import Camera, StereoPair
from stationd.geometry.frames import Transform
from stationd.localize import size_problem
from stationd.localize.references import Reference, in_pair
from stationd.localize.stereo import localize_detections
from stationd.vision.detect import NOTHING_IN_VIEW, detect_all
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams


class RefWhy(enum.Enum):
    """Why a reference was not measured."""

    NOT_FOUND = "not found"          # no marker where it should be (moved far, or covered)
    AMBIGUOUS = "ambiguous"          # two markers there (the wrench beside it)
    NOT_MEASURED = "not measured"    # seen, but the vision refused it (note: its reason)
    OUT_OF_VIEW = "out of view"      # its window is not inside both images
    LIFT_AWAY = "lift away"          # on the lift, which is not at working height
    NO_FRAMES = "no frames"          # the pair gave no usable frames (note: why)


class Verdict(enum.Enum):
    OK = "ok"
    MOVED = "moved"
    NOT_CHECKED = "not checked"


@dataclass(frozen=True)
class RefMeasure:
    """One reference as one pair measured it: the offset (mm) from its known position and
    where it was measured (vehicle frame), or why not."""

    name: str
    offset_mm: float | None = None
    measured_mm: tuple[float, float, float] | None = None
    why: RefWhy | None = None
    note: str | None = None


@dataclass(frozen=True)
class PairCheck:
    """One pair's check: the verdict, each reference's measurement, the worst reference and
    its offset (``ok`` and ``moved``), or why nothing was measured (``not checked``)."""

    pair: str
    verdict: Verdict
    measures: tuple[RefMeasure, ...] = ()
    reference: str | None = None
    offset_mm: float | None = None
    tolerance_mm: float = 0.0
    why: RefWhy | None = None
    note: str | None = None


def shifted(cam: Camera, x0: int, y0: int, w: int, h: int) -> Camera:
    """The camera seeing only the window at (x0, y0) of size (w, h): its principal point
    moved by the window's corner (the distortion acts on normalised coordinates: unchanged)."""
    K = cam.K.copy()
    K[0, 2] -= x0
    K[1, 2] -= y0
    return Camera(K, cam.dist, (w, h))


def _window(cam: Camera, p: np.ndarray, radius_mm: float) -> tuple[int, int, int, int] | None:
    """The image window (x, y, w, h) around the point ``p`` (camera frame) holding a disk of
    ``radius_mm`` around it, clipped to the image; None when the point is not in view."""
    if p[2] <= 1.0:
        return None
    uv = cam.project(p[None, :])[0]
    r = float(cam.K[0, 0]) * radius_mm / float(p[2])
    wd, ht = cam.size
    x0, y0 = max(0, math.floor(uv[0] - r)), max(0, math.floor(uv[1] - r))
    x1, y1 = min(wd, math.ceil(uv[0] + r) + 1), min(ht, math.ceil(uv[1] + r) + 1)
    if x1 - x0 < 16 or y1 - y0 < 16:
        return None
    return x0, y0, x1 - x0, y1 - y0


def measure_reference(cal: StereoPair, tv: Transform, left: np.ndarray, right: np.ndarray,
                      ref: Reference, *, search_mm: float, vision: VisionParams,
                      marker: MarkerSpec) -> RefMeasure:
    """One reference measured in one pair's frames (``tv``: the pair's registration)."""
    pl = in_pair(tv, ref.position_mm)
    radius = marker.field_mm * math.sqrt(2.0) + search_mm
    win_l, win_r = _window(cal.left, pl, radius), _window(cal.right, cal.R @ pl + cal.T, radius)
    if win_l is None or win_r is None:
        return RefMeasure(ref.name, why=RefWhy.OUT_OF_VIEW)
    cams: list[Camera] = []
    dets = []
    for cam, img, (x, y, w, h) in zip((cal.left, cal.right), (left, right), (win_l, win_r),
                                      strict=True):
        sub = shifted(cam, x, y, w, h)
        found, reasons = detect_all(np.ascontiguousarray(img[y:y + h, x:x + w]), sub, vision,
                                    marker)
        if len(found) > 1:
            # (what to do, said: a line engineer's trial read "R4 ambiguous (2 markers
            # around it)" every 10 s while the wrench rested on the bolt beside it)
            return RefMeasure(ref.name, why=RefWhy.AMBIGUOUS,
                              note=f"{len(found)} markers around it: the wrench beside it? "
                              "measured again once it is moved away")
        if not found:
            vision_refused = [r for r in reasons if r != NOTHING_IN_VIEW]
            if vision_refused:
                return RefMeasure(ref.name, why=RefWhy.NOT_MEASURED, note=vision_refused[0])
            return RefMeasure(ref.name, why=RefWhy.NOT_FOUND)
        cams.append(sub)
        dets.append(found[0])
    res = localize_detections(StereoPair(cams[0], cams[1], cal.R, cal.T), dets[0], dets[1],
                              vision)
    if not res.found or res.point_mm is None:
        return RefMeasure(ref.name, why=RefWhy.NOT_MEASURED, note=res.reason)
    at = tv.apply(res.point_mm)
    offset = float(np.linalg.norm(at - np.asarray(ref.position_mm)))
    return RefMeasure(ref.name, offset, (float(at[0]), float(at[1]), float(at[2])))


def verdict(pair: str, measures: Sequence[RefMeasure], tolerance_mm: float) -> PairCheck:
    """The pair's verdict from its references' measurements: moved when the worst measured
    one is beyond the tolerance, ok when at least one was measured and none is, else not
    checked (with the first reason that is not the lift's)."""
    done = [m for m in measures if m.offset_mm is not None]
    if done:
        worst = max(done, key=lambda m: float(m.offset_mm or 0.0))
        off = float(worst.offset_mm or 0.0)
        kind = Verdict.MOVED if off > tolerance_mm else Verdict.OK
        return PairCheck(pair, kind, tuple(measures), worst.name, off, tolerance_mm)
    why = [m for m in measures if m.why is not RefWhy.LIFT_AWAY] or list(measures)
    first = why[0] if why else None
    return PairCheck(pair, Verdict.NOT_CHECKED, tuple(measures), first.name if first else None,
                     None, tolerance_mm, first.why if first else RefWhy.NOT_FOUND,
                     first.note if first else None)


def check_pair(pair: str, cal: StereoPair, tv: Transform | None, left: np.ndarray,
               right: np.ndarray, refs: Sequence[Reference], *, tolerance_mm: float,
               search_mm: float,
               vision: VisionParams | None = None, marker: MarkerSpec | None = None,
               lift_at_height: bool = True) -> PairCheck:
    """Check one pair against the references it should see, in one grab of its frames.
    References on the lift are measured only with ``lift_at_height``."""
    vision = vision or VisionParams()
    marker = marker or MarkerSpec()
    if tv is None:
        return PairCheck(pair, Verdict.NOT_CHECKED, (), None, None, tolerance_mm,
                         RefWhy.NO_FRAMES, "pair not registered into the vehicle frame")
    problem = size_problem(cal, left, right)
    if problem is not None:
        return not_checked(pair, tolerance_mm, problem)
    measures: list[RefMeasure] = []
    for ref in refs:
        if ref.on_lift and not lift_at_height:
            measures.append(RefMeasure(ref.name, why=RefWhy.LIFT_AWAY))
            continue
        try:
            measures.append(measure_reference(cal, tv, left, right, ref, search_mm=search_mm,
                                              vision=vision, marker=marker))
        except (cv2.error, ValueError, IndexError, np.linalg.LinAlgError) as exc:
            text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            measures.append(RefMeasure(ref.name, why=RefWhy.NOT_MEASURED, note=text))
    return verdict(pair, measures, tolerance_mm)


def not_checked(pair: str, tolerance_mm: float, note: str) -> PairCheck:
    """A pair whose frames could not be had (down, a failed grab): not checked, with why."""
    return PairCheck(pair, Verdict.NOT_CHECKED, (), None, None, tolerance_mm, RefWhy.NO_FRAMES,
                     note)


__all__ = ["PairCheck", "RefMeasure", "RefWhy", "Verdict", "check_pair", "measure_reference",
           "not_checked", "shifted", "verdict"]
