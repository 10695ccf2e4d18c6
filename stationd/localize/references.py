"""Reference markers: the station's fixed copies of the wrench's marker, at known places.

Why: a camera pair knocked out of place goes on localizing, confidently and wrongly, with
its old calibration.  Positioning systems check themselves against fixed references; this
station does the same with the marker it already knows how to measure, fixed in the cell (on
a fixture) or on the lift, at a position known in the frame the pairs' ``to_vehicle``
registrations map into (the vehicle frame of the bolt tables: the frame of the lift at working
height, in which the vehicle sits at its place).  The ``references:`` section of the station
file::

    references:
      markers:
        R1: [1200.0, -400.0, -80.0]                  # fixed in the cell (mm)
        R2: {position: [2100.0, 380.0, -60.0], mount: lift}
      tolerance_mm: 2.0    # a pair measuring a reference farther off is moved (default: a
                           # quarter of the matching tolerance)
      period_min: 30       # the idle check's period

A reference with ``mount: lift`` is where its position says only while the lift is at working
height: it is measured only then.  (The key is not ``on``: YAML reads that as a boolean.)  The
section is refused (with its file and line) when a reference
is seen by no pair (projected with each registered pair's calibration: in front of both
cameras and inside both images; while ``calibrate vehicle`` registers a pair, it may be the
one that sees it), a registered pair sees none (it could never be checked), two
references overlap, or a value is implausible.

This module is pure geometry: where each pair should see each reference, and the image
regions the wrench's search leaves alone (:func:`exclusions`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from stationd.geometry.camera import Camera, StereoPair
from stationd.geometry.frames import Transform
from stationd.vision.detect import Circle
from stationd.vision.marker import MarkerSpec
from stationd.yamlio import YamlNode

#: a reference's coordinates beyond this (mm) are a typo or another unit: no cell is 20 m wide
#: the keys of the station file's ``references:`` section
REFERENCES_KEYS = ("markers", "tolerance_mm", "period_min")
MAX_COORD_MM = 10_000.0
#: the idle check's period bounds, minutes (0.5: a test station; a day at most)
PERIOD_MIN = (0.5, 1440.0)
DEFAULT_PERIOD_MIN = 30.0
#: a tolerance under this (mm) is below what two good measurements of one marker differ by
MIN_TOLERANCE_MM = 0.2
#: the exclusion around a reference's image, as a factor of its field's projected half-diagonal
#: (1.5 x 35 mm = 53 mm for the 25 mm field)
EXCLUDE_SCALE = 1.5
#: a marker localized this many field half-widths (75 mm) from a reference's place is that
#: reference: wider than the image exclusion, so a pair moved until the reference leaves its
#: excluded image region still refuses it; the check also searches this far around it
EXCLUSION_FIELDS = 3.0


@dataclass(frozen=True)
class Reference:
    """One reference marker: its name, its position (vehicle frame, mm) and whether it rides
    on the lift (measured only at working height)."""

    name: str
    position_mm: tuple[float, float, float]
    on_lift: bool = False


@dataclass(frozen=True)
class References:
    """The configured references, the check's tolerance and period, and which references
    each pair should see (``sees``, from the calibrations, at read time).  ``exclusion_mm``:
    the distance from a reference's place within which a marker is that reference (never the
    wrench), and how far around it the check searches."""

    markers: tuple[Reference, ...]
    tolerance_mm: float
    period_s: float
    exclusion_mm: float
    sees: Mapping[str, tuple[str, ...]] = field(default_factory=dict)

    def of(self, pair: str) -> tuple[Reference, ...]:
        """The references ``pair`` should see."""
        names = set(self.sees.get(pair, ()))
        return tuple(r for r in self.markers if r.name in names)

    @property
    def pairs(self) -> tuple[str, ...]:
        """The pairs the check measures (those that see a reference)."""
        return tuple(p for p, names in self.sees.items() if names)

    @classmethod
    def from_node(cls, node: YamlNode, *, pairs: Mapping[str, tuple[StereoPair,
                                                                   Transform | None]],
                  marker: MarkerSpec, matching_tolerance_mm: float,
                  registering: str | None = None) -> References:
        """Read the section; ``pairs``: each pair's calibration and registration (a pair not
        registered yet sees nothing); ``registering``: the pair being registered now
        (``calibrate vehicle``), whose registration is read as none."""
        m = node.mapping(REFERENCES_KEYS, required=("markers",))
        default_tol = matching_tolerance_mm / 4.0
        top = matching_tolerance_mm / 2.0
        tol = default_tol
        if "tolerance_mm" in m:
            tol = m["tolerance_mm"].number()
            if not MIN_TOLERANCE_MM <= tol <= top:
                raise m["tolerance_mm"].error(
                    f"{tol:g} mm is not plausible: a reference must be found within "
                    f"{MIN_TOLERANCE_MM:g}-{top:g} mm (half the matching tolerance) of its "
                    "position")
        period = m["period_min"].number(lo=PERIOD_MIN[0], hi=PERIOD_MIN[1]) \
            if "period_min" in m else DEFAULT_PERIOD_MIN
        refs: list[Reference] = []
        nodes: list[YamlNode] = []
        for name, item in m["markers"].named("reference names to positions"):
            refs.append(_reference(name, item))
            nodes.append(item)
        if not refs:
            raise m["markers"].error("expected at least one reference marker")
        apart = 2.0 * marker.field_mm
        for i, (a, na) in enumerate(zip(refs, nodes, strict=True)):
            for b in refs[:i]:
                d = float(np.linalg.norm(np.subtract(a.position_mm, b.position_mm)))
                if d < apart:
                    raise na.error(f"reference {a.name} is {d:.1f} mm from {b.name}: two "
                                   f"markers need {apart:g} mm (their fields would overlap)")
        sees: dict[str, list[str]] = {p: [] for p in pairs}
        for ref, item in zip(refs, nodes, strict=True):
            seen = [p for p, (cal, tv) in pairs.items()
                    if tv is not None and project(cal, tv, ref.position_mm, marker) is not None]
            # the pair being registered (``calibrate vehicle``) may be the one that sees it:
            # unknown there, not wrong; anywhere else a reference no pair sees is a mistake
            if not seen and registering is None:
                raise item.error(
                    f"reference {ref.name} at {list(ref.position_mm)} is seen by no pair "
                    "(projected with each registered pair's calibration, it is not in front "
                    "of both cameras and inside both images): check its position (vehicle "
                    "frame, mm)")
            for p in seen:
                sees[p].append(ref.name)
        blind = [p for p, names in sees.items() if not names and pairs[p][1] is not None]
        if blind:
            raise m["markers"].error(
                f"pair {blind[0]} sees no reference marker: with references configured every "
                "registered pair must see one, or it could never be checked (and never "
                "trusted)")
        return cls(tuple(refs), tol, period * 60.0, EXCLUSION_FIELDS * marker.field_mm,
                   {p: tuple(v) for p, v in sees.items()})


def _reference(name: str, item: YamlNode) -> Reference:
    value = item.value()
    on_lift = False
    pos_node = item
    if isinstance(value, dict):
        mm = item.mapping(("position", "mount"), required=("position",))
        pos_node = mm["position"]
        if "mount" in mm:
            on_lift = mm["mount"].text(("lift", "cell")) == "lift"
    pos = pos_node.vector([3])
    if not np.all(np.isfinite(pos)) or np.abs(pos).max() > MAX_COORD_MM:
        raise pos_node.error(f"reference {name}: {[float(v) for v in pos]} is not plausible "
                             f"(millimetres in the vehicle frame, within +/-{MAX_COORD_MM:g})")
    return Reference(name, (float(pos[0]), float(pos[1]), float(pos[2])), on_lift)


def in_pair(tv: Transform, position_mm: Sequence[float]) -> np.ndarray:
    """A vehicle-frame point in the pair's (left camera) frame: the inverse of ``to_vehicle``
    (solved, so an affine registration is inverted too)."""
    return np.asarray(np.linalg.solve(tv.A, np.asarray(position_mm, dtype=np.float64) - tv.t))


def _side(cam: Camera, p: np.ndarray, radius_mm: float) -> tuple[float, float, float] | None:
    """Where ``cam`` sees the point ``p`` (its own frame): raw pixels and the projected
    radius of ``radius_mm``, or None when it is behind the camera or not wholly inside."""
    if p[2] <= 1.0:
        return None
    uv = cam.project(p[None, :])
    r = float(cam.K[0, 0]) * radius_mm / float(p[2])
    if not bool(cam.contains(uv, r)[0]):
        return None
    return float(uv[0, 0]), float(uv[0, 1]), r


def project(cal: StereoPair, tv: Transform, position_mm: Sequence[float], marker: MarkerSpec,
            ) -> tuple[Circle, Circle] | None:
    """Where the pair should see a reference: in each image, its centre (raw pixels) and the
    projected half-diagonal of its field; None when either camera does not see it whole."""
    half = marker.field_mm * math.sqrt(2.0)
    pl = in_pair(tv, position_mm)
    left = _side(cal.left, pl, half)
    right = _side(cal.right, cal.R @ pl + cal.T, half)
    if left is None or right is None:
        return None
    return left, right


def exclusions(cal: StereoPair, tv: Transform | None, refs: Sequence[Reference],
               marker: MarkerSpec) -> tuple[tuple[Circle, ...], tuple[Circle, ...]]:
    """The circles of each image (raw pixels) where the wrench's search must not look: each
    reference's field, enlarged by :data:`EXCLUDE_SCALE`."""
    if tv is None:
        return (), ()
    left: list[Circle] = []
    right: list[Circle] = []
    for ref in refs:
        seen = project(cal, tv, ref.position_mm, marker)
        if seen is None:
            continue
        for out, (u, v, r) in zip((left, right), seen, strict=True):
            out.append((u, v, EXCLUDE_SCALE * r))
    return tuple(left), tuple(right)


__all__ = ["REFERENCES_KEYS", "Reference", "References", "exclusions", "in_pair", "project"]
