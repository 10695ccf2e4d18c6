"""From one stereo pair's frames to a bolt end, and from every pair's to one localization:
pure computation, no device and no clock.

Why apart from the daemon: how the station sees the wrench is a rule (which pair's view
counts, how far pairs may disagree, how they are weighed), and a rule belongs where it can be
tested without a camera.  The daemon grabs the frames (I/O), hands them here in its executor
threads, and feeds the :class:`Localization` to the core.

The ``localize:`` section of the station file (optional)::

    localize:
      agreement_mm: 2.0          # a pair's bolt end farther from the fused one: refused
      sigma_mm: {pair3: 0.3}     # a pair's expected error; the fusion weighs 1/sigma^2 (default 1)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from stationd.geometry.camera import StereoPair
from stationd.geometry.frames import Transform
from stationd.geometry.tool import BoltEnd, ToolGeometry, bolt_end, fuse
from stationd.localize.references import Reference, exclusions
from stationd.localize.stereo import localize as localize_stereo
from stationd.reasons import Reason, Why
from stationd.result import Refusal
from stationd.vision.detect import Circle
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams
from stationd.yamlio import YamlNode

AGREEMENT_MM = 2.0   # a pair's bolt end farther than this from the fused one: send nothing


@dataclass(frozen=True)
class LocalizeConfig:
    """How the pairs' views are fused: the agreement limit and each pair's expected error."""

    agreement_mm: float = AGREEMENT_MM
    sigma_mm: Mapping[str, float] = field(default_factory=dict)

    @classmethod
    def from_node(cls, node: YamlNode) -> LocalizeConfig:
        m = node.mapping(("agreement_mm", "sigma_mm"))
        agree = m["agreement_mm"].number(lo=0.1, hi=20.0) if "agreement_mm" in m \
            else AGREEMENT_MM
        sigmas: dict[str, float] = {}
        if "sigma_mm" in m:
            for name, v in m["sigma_mm"].named("pair names to millimetres"):
                sigmas[name] = v.number(lo=0.01, hi=10.0)
        return cls(agree, sigmas)


@dataclass(frozen=True)
class PairSetup:
    """What localizing in one pair needs: its calibration, its transform into the vehicle
    frame (None: not registered yet), the vision parameters, the marker and the tool."""

    calibration: StereoPair
    to_vehicle: Transform | None
    vision: VisionParams
    marker: MarkerSpec
    tool: ToolGeometry
    keep_crops: bool = False
    # the reference markers this pair sees (name, vehicle-frame position): the wrench's
    # search leaves their image regions alone (``exclude``: circles per image, raw pixels),
    # and a marker localized within ``exclusion_mm`` of one is that reference, never the wrench
    references: tuple[tuple[str, tuple[float, float, float]], ...] = ()
    exclude: tuple[tuple[Circle, ...], tuple[Circle, ...]] = ((), ())
    exclusion_mm: float = 0.0


@dataclass(frozen=True)
class PairView:
    """One pair's grab and localization; ``failed`` when the grab gave no usable pair."""

    end: BoltEnd | Refusal
    exposure_t: float
    crops: dict[str, np.ndarray] = field(default_factory=dict)
    failed: bool = False
    skew: bool = False
    timings_ms: dict[str, float] = field(default_factory=dict)
    sides: dict[str, dict[str, Any]] = field(default_factory=dict)  # detection summaries

    @property
    def saw_marker(self) -> bool:
        return any(d.get("found") for d in self.sides.values())


@dataclass
class Localization:
    """What the cameras saw: the bolt end or why not, with the frames' exposure instant
    (``exposure_t``, ``time.time()`` scale), the marker crops (evidence kept with a record)
    and the slowest pair's stage timings."""

    point_mm: np.ndarray | None
    tilt_deg: float = 0.0
    reason: Reason | None = None
    exposure_t: float = 0.0
    crops: dict[str, np.ndarray] = field(default_factory=dict)
    done_t: float = 0.0
    timings_ms: dict[str, float] = field(default_factory=dict)
    pairs: tuple[str, ...] = ()   # the pairs whose bolt ends made ``point_mm``


def frame_summary(det: Any) -> dict[str, Any]:
    """What the commissioning screen draws over a frame: found or why not, the ROI, both
    ellipses (undistorted pixels: close to the raw frame away from the image corners) as
    ``[cx, cy, a, b, angle_deg]``, the corrected centre."""
    ellipses = [[*e.centre, *e.axes, float(np.degrees(e.angle))]
                for e in (det.inner, det.outer) if e is not None]
    return {"found": bool(det.found), "reason": det.reason,
            "roi": list(det.roi) if det.roi is not None else None,
            "ellipses": [[float(v) for v in e] for e in ellipses],
            "centre": [float(v) for v in det.centre_px] if det.centre_px is not None else None}


def crop(image: np.ndarray, roi: tuple[int, int, int, int], margin: int = 16) -> np.ndarray:
    """The marker's neighbourhood (``roi`` x, y, w, h plus ``margin``), a copy."""
    x, y, w, h = roi
    hh, ww = image.shape[:2]
    x0, y0 = max(0, x - margin), max(0, y - margin)
    return image[y0:min(hh, y + h + margin), x0:min(ww, x + w + margin)].copy()


def size_problem(cal: StereoPair, left: np.ndarray, right: np.ndarray) -> str | None:
    """Frames the pair's calibration does not describe (garbage to the station), or None."""
    for side, img in (("left", left), ("right", right)):
        want = getattr(getattr(cal, side, None), "size", None)
        got = (int(img.shape[1]), int(img.shape[0]))
        if want is not None and tuple(want) != got:
            return f"{side} frames are {got[0]}x{got[1]}, the calibration is for " \
                   f"{want[0]}x{want[1]}"
    return None


def localize_pair(name: str, setup: PairSetup, left: np.ndarray, right: np.ndarray,
                  exposure_t: float) -> tuple[PairView, Any]:
    """The bolt end one pair sees in its frames, and the detection result (for the
    commissioning screen's overlay; None when the frames were not usable).  Frames of the
    wrong size, or frames the vision cannot use, are a failed view (a grab to retry)."""
    problem = size_problem(setup.calibration, left, right)
    if problem is not None:
        return PairView(Refusal(problem), exposure_t, failed=True), None
    try:
        res = localize_stereo(setup.calibration, left, right, setup.vision, setup.marker,
                              exclude=setup.exclude)
    except (cv2.error, ValueError, IndexError, np.linalg.LinAlgError) as exc:
        text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        return PairView(Refusal(f"frames not usable: {text}"), exposure_t, failed=True), None
    sides = {"left": res.left.to_json(), "right": res.right.to_json()}
    if not res.found or res.point_mm is None or res.normal is None:
        return PairView(Refusal(str(res.reason), side=res.side), exposure_t, sides=sides), res
    crops = {}
    if setup.keep_crops:
        crops = {f"{name}/{side}": crop(img, det.roi)
                 for side, img, det in (("left", left, res.left), ("right", right, res.right))
                 if det.roi is not None}
    if setup.to_vehicle is None:
        return PairView(Refusal("pair not registered into the vehicle frame"), exposure_t,
                        sides=sides), res
    centre = setup.to_vehicle.apply(res.point_mm)
    ref = reference_at(setup, centre)
    if ref is not None:
        return PairView(ref, exposure_t, sides=sides), res
    end = bolt_end(centre, setup.to_vehicle.apply_direction(res.normal), setup.tool)
    return PairView(end, exposure_t, crops, sides=sides), res


def reference_at(setup: PairSetup, centre_mm: np.ndarray) -> Refusal | None:
    """A marker localized at a reference's place is that reference (seen outside its
    excluded image region: the pair has moved), never the wrench: refused with its name."""
    for name, pos in setup.references:
        d = float(np.linalg.norm(centre_mm - np.asarray(pos)))
        if d <= setup.exclusion_mm:
            return Refusal(f"reference marker {name} seen ({d:.1f} mm from its place), not "
                           "the wrench", Reason(Why.REFERENCE_SEEN, reference=name,
                                                distance_mm=d))
    return None


def with_references(setup: PairSetup, refs: Sequence[Reference], exclusion_mm: float
                    ) -> PairSetup:
    """The pair's setup knowing the references it sees: their image regions excluded from
    the wrench's search and their places refused as a bolt end."""
    return replace(setup, references=tuple((r.name, r.position_mm) for r in refs),
                   exclude=exclusions(setup.calibration, setup.to_vehicle, refs,
                                      setup.marker),
                   exclusion_mm=exclusion_mm)


def fuse_views(names: Sequence[str], views: Sequence[PairView], cfg: LocalizeConfig,
               done_t: float, untrusted: Mapping[str, Reason] | None = None
               ) -> Localization | None:
    """One localization from the pairs' views (None when every grab failed: nothing to tell
    the core).  Its ``exposure_t`` is the earliest exposure of the frames it used (its age is
    counted from there).  Pairs that see the bolt end are fused (weighted by their expected
    error, refused when one is farther than ``cfg.agreement_mm`` from the fused point); without
    one, the reason is a pair's typed one (a tilted wrench: the operator acts on it) or each
    pair's own.  A pair in ``untrusted`` (not checked against the references since the
    start, or moved: :mod:`stationd.station.trust`) is never fused: a bolt end only such a
    pair sees is refused with that pair's reason."""
    untrusted = untrusted or {}
    usable = [(n, v) for n, v in zip(names, views, strict=True) if not v.failed]
    if not usable:
        return None
    distrusted = [untrusted[n] for n, v in usable
                  if n in untrusted and isinstance(v.end, BoltEnd)]
    usable = [(n, v if n not in untrusted or not isinstance(v.end, BoltEnd) else
               replace(v, end=Refusal("pair not trusted", untrusted[n])))
              for n, v in usable]
    timings = {k: max((v.timings_ms.get(k, 0.0) for _, v in usable), default=0.0)
               for k in ("grab", "vision")}
    ends = [(n, v, v.end) for n, v in usable if isinstance(v.end, BoltEnd)]
    exposure = min(v.exposure_t for _, v in (
        [(n, v) for n, v, _ in ends] if ends else usable))
    if not ends:
        refused = [(n, v.end) for n, v in usable if isinstance(v.end, Refusal)]
        typed = distrusted + [r.why for _, r in refused if r.why is not None]
        why = typed[0] if typed else Reason(Why.NOT_LOCALIZED, per_pair=tuple(
            (n, r.side, r.reason) for n, r in refused))
        return Localization(None, reason=why, exposure_t=exposure, done_t=done_t,
                            timings_ms=timings)
    fused = fuse([e.point_mm for _, _, e in ends],
                 [cfg.sigma_mm.get(n, 1.0) for n, _, _ in ends], cfg.agreement_mm)
    if isinstance(fused, Refusal):
        return Localization(None, reason=fused.why or Reason(Why.NOT_LOCALIZED,
                                                             note=fused.reason),
                            exposure_t=exposure, done_t=done_t, timings_ms=timings)
    crops = {k: c for _, v, _ in ends for k, c in v.crops.items()}
    tilt = float(np.mean([e.tilt_deg for _, _, e in ends]))
    return Localization(fused.point_mm, tilt, exposure_t=exposure, crops=crops, done_t=done_t,
                        timings_ms=timings, pairs=tuple(n for n, _, _ in ends))


__all__ = [
    "AGREEMENT_MM",
    "Localization",
    "LocalizeConfig",
    "PairSetup",
    "PairView",
    "crop",
    "frame_summary",
    "fuse_views",
    "localize_pair",
    "reference_at",
    "size_problem",
    "with_references",
]
