"""Typed results of the vision pipeline (its failure value is :mod:`stationd.result`'s
``Refusal``).  Conics are 3x3 symmetric matrices ``C`` with ``x^T C x = 0`` for homogeneous
*undistorted* pixel points ``x = [u, v, 1]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True, eq=False)
class Ellipse:
    """A fitted ellipse in undistorted pixel coordinates.

    ``axes`` are semi-axes with ``a >= b``; ``angle`` is the direction of the major axis in
    radians, in ``[0, pi)``; ``conic`` is normalised to unit Frobenius norm and signed so that
    points inside the ellipse give ``x^T C x < 0``.
    ``used`` / ``rejected`` count edge points kept and dropped by the Leitz criterion;
    ``rms`` is the RMS geometric (Sampson) residual of the kept points, in pixels.
    """

    conic: np.ndarray
    centre: tuple[float, float]
    axes: tuple[float, float]
    angle: float
    used: int = 0
    rejected: int = 0
    rms: float = 0.0
    inliers: np.ndarray | None = field(default=None, repr=False)

    def to_json(self) -> dict[str, Any]:
        return {
            "centre": [self.centre[0], self.centre[1]],
            "semi_axes": [self.axes[0], self.axes[1]],
            "angle_deg": float(np.degrees(self.angle)),
            "points_used": self.used,
            "points_rejected": self.rejected,
            "rms_px": self.rms,
        }
