"""Camera-pair frames to the vehicle frame: rigid (Kabsch/Umeyama) or affine fits.

The paper maps camera coordinates to the vehicle frame by an affine transformation fitted to
reference points.  A rigid transform (rotation + translation) has 6 parameters instead of 12,
cannot shear or scale the measurement, and is the default; the affine fit stays available for
comparison.  Every fit reports per-point residuals so a bad reference point is visible.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from stationd.result import Refusal
from stationd.yamlio import YamlNode

KINDS = ("rigid", "affine")


@dataclass(frozen=True, eq=False)
class Transform:
    """``x_vehicle = A @ x_pair + t``; for a rigid transform ``A`` is a rotation."""

    A: np.ndarray
    t: np.ndarray
    kind: str = "rigid"
    residuals_mm: np.ndarray | None = None

    def apply(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        return np.asarray(p @ self.A.T + self.t)

    def apply_direction(self, v: np.ndarray) -> np.ndarray:
        """A direction (e.g. the marker normal): rotated, and renormalised after an affine."""
        d = self.A @ np.asarray(v, dtype=np.float64)
        return np.asarray(d / np.linalg.norm(d))

    @property
    def rms_mm(self) -> float:
        r = self.residuals_mm
        return float(np.sqrt(np.mean(r**2))) if r is not None and r.size else float("nan")

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "A": self.A.tolist(), "t": self.t.tolist()}

    @classmethod
    def from_node(cls, node: YamlNode) -> Transform:
        m = node.mapping(("kind", "A", "t"), required=("A", "t"))
        kind = m["kind"].text(KINDS) if "kind" in m else "rigid"
        A = m["A"].matrix(3, 3)
        if kind == "rigid" and (not np.allclose(A @ A.T, np.eye(3), atol=1e-6)
                                or np.linalg.det(A) < 0):
            raise m["A"].error("a rigid transform needs a rotation matrix (orthonormal, det +1)")
        if kind == "affine" and abs(np.linalg.det(A)) < 1e-9:
            raise m["A"].error("an affine transform needs an invertible matrix")
        return cls(A=A, t=m["t"].vector([3]), kind=kind)


def _check(src: np.ndarray, dst: np.ndarray,
           minimum: int) -> tuple[np.ndarray, np.ndarray] | Refusal:
    s = np.asarray(src, dtype=np.float64)
    d = np.asarray(dst, dtype=np.float64)
    if s.ndim != 2 or s.shape[1] != 3 or s.shape != d.shape:
        return Refusal(f"need two (N, 3) point sets of the same size, got {s.shape} and {d.shape}")
    if len(s) < minimum:
        return Refusal(f"{len(s)} reference points; at least {minimum} are needed")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(d))):
        return Refusal("reference points must be finite")
    return s, d


def fit_rigid(src: np.ndarray, dst: np.ndarray) -> Transform | Refusal:
    """Least-squares rotation and translation with ``dst ~ R src + t`` (Kabsch/Umeyama)."""
    chk = _check(src, dst, 3)
    if isinstance(chk, Refusal):
        return chk
    s, d = chk
    cs, cd = s.mean(axis=0), d.mean(axis=0)
    H = (s - cs).T @ (d - cd)
    U, S, Vt = np.linalg.svd(H)
    if S[1] < 1e-9 * max(S[0], 1e-300):
        return Refusal("reference points are collinear: the rotation is undetermined")
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0)])
    R = Vt.T @ D @ U.T
    t = cd - R @ cs
    res = np.linalg.norm(s @ R.T + t - d, axis=1)
    return Transform(A=R, t=t, kind="rigid", residuals_mm=res)


def fit_affine(src: np.ndarray, dst: np.ndarray) -> Transform | Refusal:
    """Least-squares affine map ``dst ~ A src + t`` (the paper's choice); needs 4 points that
    are not coplanar."""
    chk = _check(src, dst, 4)
    if isinstance(chk, Refusal):
        return chk
    s, d = chk
    X = np.hstack([s, np.ones((len(s), 1))])
    if np.linalg.matrix_rank(X, tol=1e-6 * np.abs(X).max()) < 4:
        return Refusal("reference points are coplanar: an affine map is undetermined")
    sol, *_ = np.linalg.lstsq(X, d, rcond=None)
    A, t = sol[:3].T, sol[3]
    res = np.linalg.norm(s @ A.T + t - d, axis=1)
    return Transform(A=A, t=t, kind="affine", residuals_mm=res)


def fit_transform(src: np.ndarray, dst: np.ndarray, kind: str = "rigid") -> Transform | Refusal:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}")
    return fit_rigid(src, dst) if kind == "rigid" else fit_affine(src, dst)
