"""The pinhole camera with OpenCV's lens distortion, and the stereo pair.

Conventions (a stable contract, see the README):
- pixels follow OpenCV: the centre of pixel (0, 0) is at (0, 0); "raw" pixels are where things
  appear in the image, "undistorted" pixels are ``K @ [x, y, 1]`` of the ideal pinhole ray;
- ``dist`` is in OpenCV order ``k1 k2 p1 p2 [k3 [k4 k5 k6]]`` (0, 4, 5 or 8 values);
- a pair maps the left camera frame to the right one by ``x_right = R @ x_left + T`` (mm),
  the convention of ``cv2.stereoCalibrate``.

The distortion model is evaluated in NumPy (exact to float64) and inverted by Newton's method,
so that the renderer and the detector agree to far below the accuracy being measured.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from stationd.filekind import expect
from stationd.yamlio import YamlNode

DIST_LENGTHS = (0, 4, 5, 8)
#: a pair is "swapped" when its right camera lies to the left of its left camera by more than
#: this fraction of the baseline (cameras one above the other are neither: never said)
SWAPPED_FRACTION = 0.5
_CAMERA_KEYS = ("K", "dist", "size")
PAIR_KEYS = ("left", "right", "R", "T")


def _as_points(points: np.ndarray, dim: int) -> np.ndarray:
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim == 1:
        pts = pts.reshape(1, -1)
    if pts.ndim != 2 or pts.shape[1] != dim:
        raise ValueError(f"expected an (N, {dim}) array of points, got shape {pts.shape}")
    return pts


@dataclass(frozen=True, eq=False)
class Camera:
    """Intrinsics ``K`` (3x3), distortion ``dist`` (OpenCV order), image ``size`` (w, h)."""

    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(0))
    size: tuple[int, int] = (5472, 3648)

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=np.float64)
        dist = np.asarray(self.dist, dtype=np.float64).ravel()
        if K.shape != (3, 3):
            raise ValueError(f"K must be 3x3, got shape {K.shape}")
        if dist.size not in DIST_LENGTHS:
            raise ValueError(f"dist must have 0, 4, 5 or 8 values, got {dist.size}")
        if not (K[0, 0] > 0 and K[1, 1] > 0 and abs(K[2, 2] - 1.0) < 1e-12 and K[1, 0] == 0
                and K[2, 0] == 0 and K[2, 1] == 0):
            raise ValueError("K must be upper triangular with fx, fy > 0 and K[2][2] = 1")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "size", (int(self.size[0]), int(self.size[1])))

    # -- construction -------------------------------------------------------------------
    @classmethod
    def from_node(cls, node: YamlNode) -> Camera:
        m = node.mapping(_CAMERA_KEYS, required=("K", "size"))
        K = m["K"].matrix(3, 3)
        dist = m["dist"].vector(DIST_LENGTHS) if "dist" in m else np.zeros(0)
        size_v = m["size"].vector([2])
        if not all(float(s).is_integer() and s > 0 for s in size_v):
            raise m["size"].error("expected [width, height] as positive integers")
        try:
            return cls(K=K, dist=dist, size=(int(size_v[0]), int(size_v[1])))
        except ValueError as exc:
            raise m["K"].error(str(exc)) from None

    @classmethod
    def load(cls, path: str | Path) -> Camera:
        """Read a camera YAML file (``K``, ``dist``, ``size``); another kind of file is
        named for what it is."""
        node = YamlNode.load(path)
        expect(node, "camera", _CAMERA_KEYS)
        return cls.from_node(node)

    def to_dict(self) -> dict[str, Any]:
        return {"K": self.K.tolist(), "dist": self.dist.tolist(), "size": list(self.size)}

    # -- distortion -----------------------------------------------------------------------
    def _coeffs(self) -> np.ndarray:
        d = np.zeros(8)
        d[: self.dist.size] = self.dist
        return d

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Ideal normalised coordinates (x, y) -> distorted normalised coordinates."""
        xy = _as_points(xy, 2)
        k1, k2, p1, p2, k3, k4, k5, k6 = self._coeffs()
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        if k3 == 0 and k4 == 0 and k5 == 0 and k6 == 0:
            # the general formula below with these zeros, bit for bit (the denominator is
            # exactly 1): the station's lenses, and the renderer's millions of rays, for less
            radial = 1 + r2 * (k1 + r2 * k2)
        else:
            radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=1)

    def undistort_normalized(self, xyd: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Distorted normalised coordinates -> ideal ones, by Newton's method (float64 exact)."""
        xyd = _as_points(xyd, 2)
        if not np.any(self.dist):
            return xyd.copy()
        xy = xyd.copy()
        hx, hy = np.array([1e-7, 0.0]), np.array([0.0, 1e-7])
        for _ in range(iterations):
            f = self.distort_normalized(xy) - xyd
            if np.max(np.abs(f), initial=0.0) < 1e-15:
                break
            jx = (self.distort_normalized(xy + hx) - self.distort_normalized(xy - hx)) / 2e-7
            jy = (self.distort_normalized(xy + hy) - self.distort_normalized(xy - hy)) / 2e-7
            a, c = jx[:, 0], jx[:, 1]
            b, d = jy[:, 0], jy[:, 1]
            det = a * d - b * c
            det = np.where(np.abs(det) < 1e-12, 1e-12, det)
            dx = (d * f[:, 0] - b * f[:, 1]) / det
            dy = (-c * f[:, 0] + a * f[:, 1]) / det
            xy[:, 0] -= dx
            xy[:, 1] -= dy
        return xy

    # -- pixels -------------------------------------------------------------------------
    def pixels_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Raw (distorted) pixels -> ideal normalised ray coordinates (x, y) with z = 1."""
        uv = _as_points(uv, 2)
        K = self.K
        y = (uv[:, 1] - K[1, 2]) / K[1, 1]
        x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return self.undistort_normalized(np.stack([x, y], axis=1))

    def normalized_to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """Ideal normalised coordinates -> raw (distorted) pixels."""
        d = self.distort_normalized(xy)
        K = self.K
        u = K[0, 0] * d[:, 0] + K[0, 1] * d[:, 1] + K[0, 2]
        v = K[1, 1] * d[:, 1] + K[1, 2]
        return np.stack([u, v], axis=1)

    def undistort_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Raw pixels -> undistorted pixels (``K`` applied to the ideal ray)."""
        xy = self.pixels_to_normalized(uv)
        return self._apply_k(xy)

    def distort_pixels(self, uv_undistorted: np.ndarray) -> np.ndarray:
        """Undistorted pixels -> raw pixels."""
        uv = _as_points(uv_undistorted, 2)
        K = self.K
        y = (uv[:, 1] - K[1, 2]) / K[1, 1]
        x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return self.normalized_to_pixels(np.stack([x, y], axis=1))

    def _apply_k(self, xy: np.ndarray) -> np.ndarray:
        K = self.K
        return np.stack([K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2],
                         K[1, 1] * xy[:, 1] + K[1, 2]], axis=1)

    def project(self, points: np.ndarray) -> np.ndarray:
        """3D points in the camera frame (mm, z > 0) -> raw pixels."""
        p = _as_points(points, 3)
        return self.normalized_to_pixels(p[:, :2] / p[:, 2:3])

    def contains(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether raw pixels lie inside the image (with a margin)."""
        uv = _as_points(uv, 2)
        w, h = self.size
        return ((uv[:, 0] >= margin) & (uv[:, 1] >= margin)
                & (uv[:, 0] <= w - 1 - margin) & (uv[:, 1] <= h - 1 - margin))


@dataclass(frozen=True, eq=False)
class StereoPair:
    """Two cameras and the rigid motion ``x_right = R @ x_left + T`` (T in mm)."""

    left: Camera
    right: Camera
    R: np.ndarray
    T: np.ndarray

    def __post_init__(self) -> None:
        R = np.asarray(self.R, dtype=np.float64)
        T = np.asarray(self.T, dtype=np.float64).ravel()
        if R.shape != (3, 3) or T.shape != (3,):
            raise ValueError("R must be 3x3 and T must have 3 values")
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
            raise ValueError("R must be a rotation matrix (orthonormal, det +1)")
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "T", T)

    @classmethod
    def from_node(cls, node: YamlNode) -> StereoPair:
        m = node.mapping(PAIR_KEYS, required=PAIR_KEYS)
        left = Camera.from_node(m["left"])
        right = Camera.from_node(m["right"])
        R = m["R"].matrix(3, 3)
        T = m["T"].vector([3])
        try:
            return cls(left=left, right=right, R=R, T=T)
        except ValueError as exc:
            raise m["R"].error(str(exc)) from None

    @classmethod
    def load(cls, path: str | Path) -> StereoPair:
        """Read a pair YAML file (``left``, ``right``, ``R``, ``T``); another kind of file
        is named for what it is."""
        node = YamlNode.load(path)
        expect(node, "pair", PAIR_KEYS)
        return cls.from_node(node)

    def to_dict(self) -> dict[str, Any]:
        return {"left": self.left.to_dict(), "right": self.right.to_dict(),
                "R": self.R.tolist(), "T": self.T.tolist()}

    def digest(self) -> str:
        """What this calibration is, in 32 hex digits (SHA-256 of its values as stored): the
        station pins the cameras a calibration was first used with to it (``db.cameras``);
        a pair calibrated again has another digest, and pins its cameras anew."""
        h = hashlib.sha256()
        for cam in (self.left, self.right):
            for arr in (cam.K, cam.dist, np.asarray(cam.size, dtype=np.float64)):
                h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
        for arr in (self.R, self.T):
            h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
        return h.hexdigest()[:32]

    @property
    def baseline_mm(self) -> float:
        return float(np.linalg.norm(self.T))

    @property
    def right_centre_mm(self) -> np.ndarray:
        """The right camera's centre in the left camera's frame (mm): ``-R.T @ T``."""
        return np.asarray(-self.R.T @ self.T)

    def swapped(self) -> str | None:
        """Why the pair looks calibrated with its left and right images swapped, None when it
        does not: the right camera's centre lies mostly on the left camera's -x side (its x
        below -:data:`SWAPPED_FRACTION` of the baseline), where a pair's right camera never
        is (``cv2.stereoCalibrate``'s pairs have it at +x, ``T``'s x negative).  Such a pair
        triangulates with each camera's lens model on the other camera's images."""
        c = self.right_centre_mm
        b = float(np.linalg.norm(c))
        if not (b > 0 and c[0] < -SWAPPED_FRACTION * b):
            return None
        return (f"the right camera is {-c[0]:.0f} mm to the left of the left camera (T's x is "
                f"{self.T[0]:+.1f} mm, a pair's is negative): left and right swapped?")
