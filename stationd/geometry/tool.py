"""From the marker to the bolt end: the wrench's geometry and tilt compensation.

The marker is on the wrench's underside, facing the cameras; the socket tip is ``length_mm``
from the marker plane along the wrench axis, away from the cameras.  The marker's normal *is*
the wrench axis, so ``bolt_end = centre + length * axis`` with ``axis = -normal`` (the normal
faces the cameras).  The paper instead assumes the wrench is perpendicular to the chassis and
takes the marker's (X, Y) as the bolt's: at L = 300 mm a 5 degree tilt moves the bolt end by
L sin(5 deg) = 26 mm, far beyond a bolt pitch.  That rule stays available (``rule:
perpendicular``) for comparison.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from stationd.reasons import Reason, Why
from stationd.result import Refusal
from stationd.yamlio import YamlNode

RULES = ("axis", "perpendicular")
TOOL_LENGTH_MM = (50.0, 1000.0)  # marker to socket tip: a real wrench, in millimetres

# the marker is on the wrench, beside its axis: a lateral offset beyond 250 mm is no wrench
# (10000 is a typo, or metres/micrometres mixed up)
TOOL_OFFSET_MM = 250.0
# a tilt limit under 2 degrees refuses nearly every placement by hand (0.17 is 10 degrees in
# radians); over 60 the compensation extrapolates the axis far beyond what was checked
MAX_TILT_DEG = (2.0, 60.0)


@dataclass(frozen=True)
class ToolGeometry:
    """``length_mm``: marker plane to socket tip along the axis; ``offset_mm``: the marker
    centre's lateral offset from the axis, in the marker's plane (vehicle x, y when upright);
    ``max_tilt_deg``: beyond this the localization is refused."""

    length_mm: float = 300.0
    offset_mm: tuple[float, float] = (0.0, 0.0)
    max_tilt_deg: float = 10.0
    rule: str = "axis"

    @classmethod
    def from_node(cls, node: YamlNode) -> ToolGeometry:
        m = node.mapping(("length_mm", "offset_mm", "max_tilt_deg", "rule"),
                         required=("length_mm",))
        off = m["offset_mm"].vector([2]) if "offset_mm" in m else np.zeros(2)
        lateral = float(np.hypot(*off))
        if lateral > TOOL_OFFSET_MM:
            raise m["offset_mm"].error(
                f"an offset of {lateral:g} mm from the wrench axis is not plausible (the "
                f"marker is on the wrench: at most {TOOL_OFFSET_MM:g} mm); offsets are in "
                "millimetres")
        tilt = _max_tilt(m["max_tilt_deg"]) if "max_tilt_deg" in m else 10.0
        rule = m["rule"].text(RULES) if "rule" in m else "axis"
        # the required key last: `config check` reads the section again without each entry
        # it told, and without this one the section misses it and tells nothing after it
        length = m["length_mm"].number()
        if not TOOL_LENGTH_MM[0] <= length <= TOOL_LENGTH_MM[1]:
            raise m["length_mm"].error(
                f"a tool length of {length:g} mm is not plausible (marker to socket tip: "
                f"{TOOL_LENGTH_MM[0]:g}-{TOOL_LENGTH_MM[1]:g} mm); lengths are in millimetres")
        return cls(length_mm=length, offset_mm=(float(off[0]), float(off[1])),
                   max_tilt_deg=tilt, rule=rule)


def _max_tilt(node: YamlNode) -> float:
    """``max_tilt_deg`` within :data:`MAX_TILT_DEG`; a value that is a plausible limit in
    radians is told so."""
    tilt = node.number()
    if MAX_TILT_DEG[0] <= tilt <= MAX_TILT_DEG[1]:
        return tilt
    deg = math.degrees(tilt)
    hint = f"; in radians? {tilt:g} rad is {deg:.3g} degrees: write {deg:.3g}" \
        if 0 < tilt < MAX_TILT_DEG[0] <= deg <= MAX_TILT_DEG[1] else ""
    raise node.error(f"a tilt limit of {tilt:g} degrees is not plausible ({MAX_TILT_DEG[0]:g}-"
                     f"{MAX_TILT_DEG[1]:g} degrees: a wrench held by hand tilts a few degrees; "
                     f"10 by default){hint}")


@dataclass(frozen=True, eq=False)
class BoltEnd:
    point_mm: np.ndarray  # vehicle frame
    tilt_deg: float       # wrench axis vs the vehicle's up axis
    axis: np.ndarray      # unit, from the marker towards the socket tip


def marker_upright(bolt_mm: Sequence[float], tool: ToolGeometry
                   ) -> tuple[float, float, float]:
    """Where the wrench's marker centre is with the wrench upright on the bolt at
    ``bolt_mm`` (vehicle frame, up +z): :func:`bolt_end` of an upright wrench, inverted.
    What the station's files are checked against (a bolt no pair sees, a reference marker
    beside one)."""
    x, y, z = (float(v) for v in bolt_mm)
    return x - tool.offset_mm[0], y - tool.offset_mm[1], z - tool.length_mm


def bolt_end(centre_mm: np.ndarray, normal: np.ndarray, tool: ToolGeometry,
             up: np.ndarray | None = None) -> BoltEnd | Refusal:
    """The socket tip in the vehicle frame from the marker centre and normal (vehicle frame).

    ``normal`` faces the cameras (down); ``up`` is the vehicle's up axis (default +z).
    """
    up_v = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    norm = float(np.linalg.norm(n))
    if not (np.all(np.isfinite(centre_mm)) and np.isfinite(norm) and norm > 0):
        return Refusal("no finite marker pose")
    axis = -n / norm
    tilt = math.degrees(math.acos(float(np.clip(axis @ up_v, -1.0, 1.0))))
    if tilt > tool.max_tilt_deg:
        return Refusal(f"wrench tilted {tilt:.1f} deg (> {tool.max_tilt_deg} deg)",
                       Reason(Why.TILTED, angle_deg=tilt, limit=tool.max_tilt_deg))
    c = np.asarray(centre_mm, dtype=np.float64)
    if tool.rule == "perpendicular":
        # the paper: the wrench is assumed upright, the marker's (X, Y) is the bolt's
        point = c + tool.length_mm * up_v + np.array([*tool.offset_mm, 0.0])
        return BoltEnd(point, tilt, up_v)
    # lateral offset in the marker's plane: project the vehicle x, y axes onto the plane
    ex = np.array([1.0, 0.0, 0.0]) - (axis @ [1.0, 0.0, 0.0]) * axis
    ex /= np.linalg.norm(ex)
    ey = np.cross(axis, ex)
    point = c + tool.length_mm * axis + tool.offset_mm[0] * ex + tool.offset_mm[1] * ey
    return BoltEnd(point, tilt, axis)


@dataclass(frozen=True, eq=False)
class Fused:
    point_mm: np.ndarray
    spread_mm: float  # largest distance of one estimate from the fused point


def fuse(points: list[np.ndarray], sigmas_mm: list[float],
         max_spread_mm: float) -> Fused | Refusal:
    """Inverse-variance weighted mean of one point seen by several pairs; refused when the
    estimates disagree by more than ``max_spread_mm`` (one pair is wrong: send nothing)."""
    if not points:
        return Refusal("no estimate to fuse")
    P = np.asarray(points, dtype=np.float64)
    w = 1.0 / np.maximum(np.asarray(sigmas_mm, dtype=np.float64), 1e-6) ** 2
    x = (P * w[:, None]).sum(axis=0) / w.sum()
    spread = float(np.linalg.norm(P - x, axis=1).max())
    if spread > max_spread_mm:
        return Refusal(f"pairs disagree by {spread:.2f} mm (> {max_spread_mm} mm)",
                       Reason(Why.PAIRS_DISAGREE, distance_mm=spread, limit=max_spread_mm))
    return Fused(x, spread)
