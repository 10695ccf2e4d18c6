"""Camera-pair frames to the vehicle frame: rigid (Kabsch/Umeyama) or affine fits.

The paper maps camera coordinates to the vehicle frame by an affine transformation fitted to
reference points.  A rigid transform (rotation + translation) has 6 parameters instead of 12,
cannot shear or scale the measurement, and is the default; the affine fit stays available for
comparison.  Every fit reports per-point residuals so a bad reference point is visible.

A fit is plausible (:func:`implausible`) when the two point sets have one scale (pair points
typed in metres fit a rigid motion with an RMS of tens of millimetres, a wrong bolt, and an
affine fit would absorb the factor 1000 with a tiny RMS), describe frames of one handedness
(one axis's sign flipped for every point fits no rotation: the rigid fit's residuals were
blamed on one point), no single point is off by more than :data:`MAX_POINT_MM` (one typo
among eight points hides under the RMS bound) and the RMS residual is at most
:data:`MAX_RMS_MM`.  A point beyond the bound is named with its residual and, when the others
fit without it, said to be mistyped, with the coordinate that differs where one does.  The
RMS is stored in the registration file (``rms_mm``), and a file whose RMS is beyond the bound
is refused when read (``config check``, start, reload).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from drivers.counting import counted
from stationd.result import Refusal
from stationd.yamlio import MAX_YAML_BYTES, YamlNode, read_text_file

KINDS = ("rigid", "affine")
#: the largest RMS residual (mm) of a registration: the bolt end is matched within the
#: matching tolerance (8 mm by default) and a registration off by more than a quarter of it
#: puts the wrench on a neighbouring bolt; a good fit is a few tenths of a millimetre
MAX_RMS_MM = 2.0
#: the largest residual (mm) of one reference point: one point may fit a little worse than
#: the RMS bound, not by a typo (a digit wrong is millimetres or more; a good point is a few
#: tenths of a millimetre off)
MAX_POINT_MM = 1.5 * MAX_RMS_MM
#: the others "fit" without the worst point when their RMS is within this (good points are
#: a few tenths of a millimetre off; more is a second bad point, and none is singled out)
_REST_FITS_MM = 0.5 * MAX_RMS_MM
#: a coordinate "is" the mistyped one when it carries this fraction of the point's error
_ONE_AXIS = 0.9
#: the spreads of the pair points and the vehicle points (both mm) differ by at most this
#: factor: a rotation keeps distances, and a real affine fit is within a few per cent of one
MAX_SCALE = 1.5
#: the RMS an earlier ``calibrate vehicle`` wrote only in the header comment
_HEADER_RMS = re.compile(r"^#.*\bRMS ([0-9.]+(?:[eE][+-]?[0-9]+)?) mm", re.MULTILINE)


#: the top-level keys of a registration file (``calibrate vehicle`` writes them)
REGISTRATION_KEYS = ("kind", "A", "t", "rms_mm")


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
        """``kind``, ``A``, ``t`` and, for a fit, its RMS residual ``rms_mm`` (checked
        against :data:`MAX_RMS_MM` when the file is read)."""
        out: dict[str, Any] = {"kind": self.kind, "A": self.A.tolist(), "t": self.t.tolist()}
        if self.residuals_mm is not None and self.residuals_mm.size:
            out["rms_mm"] = round(self.rms_mm, 4)
        return out

    @classmethod
    def from_node(cls, node: YamlNode) -> Transform:
        """A registration as ``calibrate vehicle`` writes it; one whose RMS residual
        (``rms_mm``, or the header comment of a file written before that key) is above
        :data:`MAX_RMS_MM` is refused: it would select wrong bolts."""
        m = node.mapping(REGISTRATION_KEYS, required=("A", "t"))
        rms = m["rms_mm"].number(lo=0.0) if "rms_mm" in m else _header_rms(node.path)
        if rms is not None and rms > MAX_RMS_MM:
            raise m.get("rms_mm", node).error(
                f"the registration's RMS residual is {rms:.3g} mm, more than {MAX_RMS_MM:g} "
                "mm: its reference points do not fit one motion (a point measured or typed "
                "wrong, or in metres?); run stationd calibrate vehicle again")
        kind = m["kind"].text(KINDS) if "kind" in m else "rigid"
        A = m["A"].matrix(3, 3)
        if kind == "rigid" and (not np.allclose(A @ A.T, np.eye(3), atol=1e-6)
                                or np.linalg.det(A) < 0):
            raise m["A"].error("a rigid transform needs a rotation matrix (orthonormal, det +1)")
        if kind == "affine" and abs(np.linalg.det(A)) < 1e-9:
            raise m["A"].error("an affine transform needs an invertible matrix")
        if kind == "affine" and np.linalg.det(A) < 0:
            raise m["A"].error(f"{MIRRORED}; run stationd calibrate vehicle again")
        return cls(A=A, t=m["t"].vector([3]), kind=kind)


def _header_rms(path: str) -> float | None:
    """The RMS in the header comment of a registration written before ``rms_mm`` was a key
    (``# pair1 -> vehicle frame, rigid fit to 8 points from pts.yaml; RMS 0.041 mm``)."""
    p = Path(path)
    if not p.is_file():
        return None    # parsed from text, not read from a file
    found = _HEADER_RMS.search(read_text_file(p, MAX_YAML_BYTES, "a YAML file")[:4096])
    return float(found.group(1)) if found else None


def spread(points: np.ndarray) -> float:
    """The RMS distance of ``points`` (N, 3) from their centroid: their extent, in their
    unit."""
    p = np.asarray(points, dtype=np.float64)
    return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))


MIRRORED = ("the points describe a mirrored frame: one axis has the wrong sign "
            "(left/right-handed)")


def _mirrored(fit: Transform, src: np.ndarray, dst: np.ndarray) -> str | None:
    """Why the points are a mirror image of each other, None when they are not: an affine
    fit with a negative determinant, or points a reflection fits within :data:`MAX_RMS_MM`
    and no rotation does (points in one plane fit both alike: never said of them)."""
    if fit.kind == "affine":
        return f"{MIRRORED}: the affine fit mirrors" if np.linalg.det(fit.A) < 0 else None
    s = np.asarray(src, dtype=np.float64)
    d = np.asarray(dst, dtype=np.float64)
    cs, cd, U, _, Vt = _cross(s, d)
    M = Vt.T @ U.T          # the best orthogonal map, a reflection when its det is -1
    if np.linalg.det(M) > 0:
        return None
    mirror = float(np.sqrt(np.mean(np.sum(((s - cs) @ M.T - (d - cd)) ** 2, axis=1))))
    if not (mirror <= MAX_RMS_MM < fit.rms_mm):
        return None
    return (f"{MIRRORED}: no rotation fits them (RMS {fit.rms_mm:.3g} mm), their mirror image "
            f"fits to {mirror:.2g} mm; check the sign of each axis of vehicle_mm (or of the "
            "pair points)")


def _worst_point(fit: Transform, src: np.ndarray, dst: np.ndarray,
                 names: list[str]) -> tuple[str, float, str]:
    """The point with the largest residual: its name, its residual and what the others say
    of it: refitted without it, if they fit one motion it is probably mistyped, and the
    coordinate that carries its error (in the vehicle frame or the pair's) is named with the
    value the others give it."""
    r = fit.residuals_mm
    assert r is not None  # noqa: S101 - a fit carries its residuals
    i = int(np.argmax(r))
    name = names[i]
    keep = np.arange(len(r)) != i
    rest = fit_transform(src[keep], dst[keep], fit.kind) if keep.sum() >= 3 else None
    if not isinstance(rest, Transform) or not rest.rms_mm <= _REST_FITS_MM:
        return name, float(r[i]), ""
    said = (f"; without it the others fit to {rest.rms_mm:.2g} mm RMS: {name} is probably "
            "mistyped")
    expected_v = rest.apply(src[i])
    expected_p = np.linalg.solve(rest.A, dst[i] - rest.t)
    # the pair's axes are often near the vehicle's (a camera looking down): an error along
    # one axis may be along one axis in both frames, and then both are named
    hints = []
    for key, typed, expected in (("vehicle_mm", dst[i], expected_v),
                                 ("pair point's", src[i], expected_p)):
        off = typed - expected
        axis = int(np.argmax(np.abs(off)))
        if abs(off[axis]) >= _ONE_AXIS * float(np.linalg.norm(off)):
            hints.append(f"its {key} {'xyz'[axis]} is {typed[axis]:.6g}, the others put it "
                         f"at {expected[axis]:.1f}")
    if hints:
        said += f" ({' or '.join(hints)})"
    return name, float(r[i]), said


def implausible(fit: Transform, src: np.ndarray, dst: np.ndarray,
                names: list[str] | None = None) -> Refusal | None:
    """Why ``fit`` (from the pair points ``src`` to the vehicle points ``dst``, mm) is not a
    registration to use, None when it is, in this order: the point sets in two units (metres
    typed for millimetres: the likely cause is said), a mirrored frame, one point beyond
    :data:`MAX_POINT_MM`, an RMS residual above :data:`MAX_RMS_MM` (``names``, the points',
    name the one with the largest residual and say whether it is mistyped)."""
    s_src, s_dst = spread(src), spread(dst)
    ratio = s_dst / s_src if s_src > 0 else float("inf")
    if not 1 / MAX_SCALE <= ratio <= MAX_SCALE:
        sizes = (f"the pair points spread {s_src:.4g}, the vehicle points {s_dst:.4g}, a "
                 f"factor {ratio:.3g}")
        if ratio > 100:
            cause = "the pair points in metres? give pair_mm in millimetres"
        elif ratio < 0.01:
            cause = "the vehicle points in metres? give vehicle_mm in millimetres"
        else:
            cause = "two units mixed, or points given the wrong names?"
        return Refusal(f"the two point sets differ in scale ({sizes}): {cause}")
    mirrored = _mirrored(fit, src, dst)
    if mirrored is not None:
        return Refusal(mirrored)
    r = fit.residuals_mm
    if r is None or not r.size:
        return None
    if names is None or len(names) != r.size:
        names = [f"#{k + 1}" for k in range(r.size)]
    s, d = np.asarray(src, dtype=np.float64), np.asarray(dst, dtype=np.float64)
    if not fit.rms_mm <= MAX_RMS_MM:
        name, _, said = _worst_point(fit, s, d, names)
        return Refusal(f"RMS residual {fit.rms_mm:.3g} mm is more than {MAX_RMS_MM:g} mm: the "
                       "reference points do not fit one motion (a point measured or typed "
                       f"wrong: {name} has the largest residual{said})")
    if float(r.max()) > MAX_POINT_MM:
        name, residual, said = _worst_point(fit, s, d, names)
        return Refusal(f"{name} has a residual of {residual:.3g} mm, more than "
                       f"{MAX_POINT_MM:g} mm for one point (the RMS of {fit.rms_mm:.3g} mm "
                       f"hides it){said or ': probably mistyped or measured wrong'}")
    return None


def _check(src: np.ndarray, dst: np.ndarray,
           minimum: int) -> tuple[np.ndarray, np.ndarray] | Refusal:
    s = np.asarray(src, dtype=np.float64)
    d = np.asarray(dst, dtype=np.float64)
    if s.ndim != 2 or s.shape[1] != 3 or s.shape != d.shape:
        return Refusal(f"need two (N, 3) point sets of the same size, got {s.shape} and {d.shape}")
    if len(s) < minimum:
        return Refusal(f"{counted(len(s), 'reference point')}; at least {minimum} are needed")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(d))):
        return Refusal("reference points must be finite")
    return s, d


def _cross(s: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, ...]:
    """The centroids and the SVD of the centred point sets' cross-covariance (Kabsch):
    ``(cs, cd, U, S, Vt)``; the best orthogonal map from ``s`` to ``d`` is ``Vt.T @ U.T``."""
    cs, cd = s.mean(axis=0), d.mean(axis=0)
    U, S, Vt = np.linalg.svd((s - cs).T @ (d - cd))
    return cs, cd, U, S, Vt


def _homogeneous(points: np.ndarray) -> np.ndarray:
    return np.hstack([points, np.ones((len(points), 1))])


def _spans_space(X: np.ndarray) -> bool:
    """Whether the homogeneous points ``X`` are not all in one plane (rank 4)."""
    return bool(np.linalg.matrix_rank(X, tol=1e-6 * np.abs(X).max()) >= 4)


def fit_rigid(src: np.ndarray, dst: np.ndarray) -> Transform | Refusal:
    """Least-squares rotation and translation with ``dst ~ R src + t`` (Kabsch/Umeyama)."""
    chk = _check(src, dst, 3)
    if isinstance(chk, Refusal):
        return chk
    s, d = chk
    cs, cd, U, S, Vt = _cross(s, d)
    if S[1] < 1e-9 * max(S[0], 1e-300):
        return Refusal("reference points are collinear: the rotation is undetermined")
    D = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0)])
    R = Vt.T @ D @ U.T
    t = cd - R @ cs
    res = np.linalg.norm(s @ R.T + t - d, axis=1)
    return Transform(A=R, t=t, kind="rigid", residuals_mm=res)


def fit_affine(src: np.ndarray, dst: np.ndarray) -> Transform | Refusal:
    """Least-squares affine map ``dst ~ A src + t`` (the paper's choice); needs 4 points that
    are not coplanar, in both frames."""
    chk = _check(src, dst, 4)
    if isinstance(chk, Refusal):
        return chk
    s, d = chk
    X = _homogeneous(s)
    if not _spans_space(X):
        return Refusal("reference points are coplanar: an affine map is undetermined")
    if not _spans_space(_homogeneous(d)):
        # the map would flatten space into their plane (a singular A): a station file that
        # no check then accepts
        return Refusal("the vehicle points are coplanar (all in one plane): an affine map "
                       "would flatten the third axis; give a point out of their plane, or "
                       "use the rigid fit")
    sol, *_ = np.linalg.lstsq(X, d, rcond=None)
    A, t = sol[:3].T, sol[3]
    res = np.linalg.norm(s @ A.T + t - d, axis=1)
    return Transform(A=A, t=t, kind="affine", residuals_mm=res)


def fit_transform(src: np.ndarray, dst: np.ndarray, kind: str = "rigid") -> Transform | Refusal:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}")
    return fit_rigid(src, dst) if kind == "rigid" else fit_affine(src, dst)
