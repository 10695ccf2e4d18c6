"""The one bolt-spacing rule, shared by the bolt-table check and the matcher.

The matcher (``stationd.station.matching``) tells bolts apart in the vehicle frame's X and Y
only: the depth along the wrench axis is where the socket sits, not which bolt it is.  A table
whose bolts are far enough apart in 3D but close in plan (one above the other) would pass a 3D
check and then be "ambiguous" at the station forever.  So the table is checked in the same
metric, with the same limit: two bolts must be at least twice the matching tolerance apart in
plan, so that their capture zones do not overlap.

It lives in ``db`` because the bolt-table checker does (``db`` imports nothing from
``stationd``); the matcher imports it from here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


def plan_distance(a: Sequence[float], b: Sequence[float]) -> float:
    """Distance in the vehicle frame's X-Y plane (mm): the matcher's metric."""
    return math.hypot(float(a[0]) - float(b[0]), float(a[1]) - float(b[1]))


def min_spacing_mm(tolerance_mm: float) -> float:
    """The least plan distance between two bolts matched with ``tolerance_mm``."""
    return 2.0 * tolerance_mm


def too_close(positions: Sequence[Sequence[float]], tolerance_mm: float,
              ) -> list[tuple[int, int, float]]:
    """``(i, j, d)`` for each position ``i`` nearer than the limit to an earlier one ``j``
    (its nearest, in plan); each position is reported once."""
    limit = min_spacing_mm(tolerance_mm)
    out = []
    for i, p in enumerate(positions):
        near = [(plan_distance(q, p), j) for j, q in enumerate(positions[:i])]
        d, j = min(near, default=(math.inf, -1))
        if d < limit:
            out.append((i, j, d))
    return out
