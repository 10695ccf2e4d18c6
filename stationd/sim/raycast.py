"""Exact ray casting of flat patches through the lens model, with adaptive supersampling.

Why a ray caster: the renderer is the ground truth for centre estimates good to ~0.01 px, so a
pixel's value must be the box-filter integral of the scene over the pixel's footprint *as seen
through the distorted lens*.  A rasteriser (``cv2.ellipse``, ``fillPoly``) draws an ellipse or a
polygon in pixel space, which is neither what a lens does to a circle nor an exact coverage.

How it stays exact and fast:

- rays: ``camera.distort_normalized`` is inverted by Newton's method *on the camera's own
  function*, so the renderer and the detector share one model to float64 precision.  The corner
  grid is solved from scratch; sub-pixel samples start from the bilinear interpolation of their
  pixel's four corner rays (already within ~1e-9 of the answer) and need one or two steps;
- plane: a ray meets the patch's plane through a 3x3 homography, which is exact;
- adaptive supersampling: a pixel is shaded once only if all four corners carry the same label
  AND its centre is at least ``BAND_PX`` (1.0) pixels from every boundary, measured as a plane
  distance divided by the pixel's plane-space size (the Frobenius norm of the pixel-to-plane
  Jacobian, which bounds its largest singular value).  A boundary point inside the footprint is
  at most 0.71 px from the centre, i.e. within 0.71 * |J| mm on the plane; the band test marks
  everything within 1.0 * |J| mm, so it cannot miss a boundary unless |J| changes by 40 %
  inside one pixel (it changes by ~1e-4).  (A wider band only supersamples more pixels that
  all lie in one region: 1.5 rendered the same images a fifth slower.)  The shapes' distance
  functions are lower bounds of the true distance, which only makes the test more
  conservative.
  Every other pixel gets ``S x S`` samples on a regular grid (box filter).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from stationd.geometry.camera import Camera

BAND_PX = 1.0
_CHUNK_SAMPLES = 1 << 19
_NEWTON_TOL = 4e-15  # normalised units: 2e-11 px at f = 5000
_NEWTON_MAX = 30
_NEWTON_LAST = 1e-9  # a step from a residual this small lands at float64 rounding


# -- rays ---------------------------------------------------------------------------------------
def _distortion_jacobian(
    coeffs: np.ndarray, x: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """d(distorted)/d(ideal) of OpenCV's model: (dxd/dx, dxd/dy = dyd/dx, dyd/dy).

    Only the Newton step uses it; the residual comes from the camera itself, so an error here
    could slow convergence but never move the answer.
    """
    k1, k2, p1, p2, k3, k4, k5, k6 = coeffs
    r2 = x * x + y * y
    if k3 == 0 and k4 == 0 and k5 == 0 and k6 == 0:
        # the station's lenses (k1, k2, p1, p2): the general formulas below with these zeros
        # reduce, bit for bit, to these (den is exactly 1, dden exactly 0), at half the work
        radial = 1 + r2 * (k1 + r2 * k2)
        drad = k1 + r2 * (2 * k2)
    else:
        num = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        den = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        dnum = k1 + r2 * (2 * k2 + 3 * k3 * r2)
        dden = k4 + r2 * (2 * k5 + 3 * k6 * r2)
        radial = num / den
        drad = (dnum * den - num * dden) / (den * den)
    a = radial + 2 * x * x * drad + 2 * p1 * y + 6 * p2 * x
    b = 2 * x * y * drad + 2 * p1 * x + 2 * p2 * y
    d = radial + 2 * y * y * drad + 6 * p1 * y + 2 * p2 * x
    return a, b, d


def pixel_rays(
    camera: Camera,
    u: np.ndarray,
    v: np.ndarray,
    guess: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Raw sensor pixels -> ideal normalised rays (x, y, 1), exact to float64.

    Same answer as ``camera.pixels_to_normalized`` but with an analytic Jacobian and an optional
    starting point, which makes millions of sub-pixel samples affordable.
    """
    K = camera.K
    yd = (v - K[1, 2]) / K[1, 1]
    xd = (u - K[0, 2] - K[0, 1] * yd) / K[0, 0]
    if not np.any(camera.dist):
        return xd, yd
    coeffs = np.zeros(8)
    coeffs[: camera.dist.size] = camera.dist
    # x and y are the rows of one buffer whose transpose is the camera's (N, 2) input: no
    # stacking per step, and the camera reads contiguous columns
    xy = np.empty((2, xd.size))
    x, y = xy[0], xy[1]
    x[:], y[:] = (xd, yd) if guess is None else guess
    for _ in range(_NEWTON_MAX):
        dist = camera.distort_normalized(xy.T)
        f0 = dist[:, 0] - xd
        f1 = dist[:, 1] - yd
        err = max(np.max(np.abs(f0), initial=0.0), np.max(np.abs(f1), initial=0.0))
        if err < _NEWTON_TOL:
            break
        a, b, d = _distortion_jacobian(coeffs, x, y)
        det = a * d - b * b
        x -= (d * f0 - b * f1) / det
        y -= (a * f1 - b * f0) / det
        if err < _NEWTON_LAST:  # quadratic convergence: the error is now ~err^2, below 1e-17
            break
    return x, y


# -- shapes on a plane (mm, plane coordinates a, b) -----------------------------------------
class Shape:
    """A flat region split into labelled parts; label ``n_labels - 1`` means "not on it".

    ``distance`` is a lower bound of the distance (mm) to the nearest boundary between labels,
    as the band test in ``composite`` requires.
    """

    n_labels = 2

    def labels(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def outline(self) -> np.ndarray:
        """Points (N, 2) along the region's outer boundary, dense enough to bound its image."""
        raise NotImplementedError


def _square_outline(half_x: float, half_y: float, per_side: int = 128) -> np.ndarray:
    t = np.linspace(-1.0, 1.0, per_side, endpoint=False)
    one = np.ones_like(t)
    xs = np.concatenate([t, one, -t, -one]) * half_x
    ys = np.concatenate([-one, t, one, -t]) * half_y
    return np.stack([xs, ys], axis=1)


def _circle_outline(r: float, n: int = 512) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1)


@dataclass(frozen=True)
class RingMarker(Shape):
    """White disk (0), black ring (1), purple square field (2), outside (3)."""

    inner: float
    outer: float
    half: float
    n_labels = 4

    def labels(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        r2 = a * a + b * b
        in_field = np.maximum(np.abs(a), np.abs(b)) < self.half
        lab = np.where(in_field, 2, 3).astype(np.int8)
        lab[r2 < self.outer**2] = 1
        lab[r2 < self.inner**2] = 0
        return lab

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        r = np.hypot(a, b)
        square = np.abs(np.maximum(np.abs(a), np.abs(b)) - self.half)
        rings = np.minimum(np.abs(r - self.inner), np.abs(r - self.outer))
        return np.asarray(np.minimum(rings, square))

    def outline(self) -> np.ndarray:
        return _square_outline(self.half, self.half)


@dataclass(frozen=True)
class Disc(Shape):
    """A plain disc (0) of radius ``r``: a purple distractor without a ring."""

    r: float

    def labels(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.asarray((a * a + b * b >= self.r**2).astype(np.int8))

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.asarray(np.abs(np.hypot(a, b) - self.r))

    def outline(self) -> np.ndarray:
        return _circle_outline(self.r)


@dataclass(frozen=True)
class Bar(Shape):
    """A rectangle (0) of half-length ``half_x`` along the plane's a axis, half-width ``half_y``."""

    half_x: float
    half_y: float

    def labels(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        inside = (np.abs(a) < self.half_x) & (np.abs(b) < self.half_y)
        return np.asarray((~inside).astype(np.int8))

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.asarray(np.abs(np.maximum(np.abs(a) - self.half_x, np.abs(b) - self.half_y)))

    def outline(self) -> np.ndarray:
        return _square_outline(self.half_x, self.half_y)


@dataclass(frozen=True)
class Chessboard(Shape):
    """A calibration chessboard: ``cols`` x ``rows`` inner corners, squares of ``square`` mm,
    centred on the plane's origin, on a white card ``margin`` squares wide all round.

    Labels: white (0), black (1), outside the card (2).  The square at the board's first
    corner (-a, -b) is black, as OpenCV's pattern.
    """

    cols: int
    rows: int
    square: float
    margin: float = 1.0
    n_labels = 3

    def _half(self) -> tuple[float, float]:
        return 0.5 * (self.cols + 1) * self.square, 0.5 * (self.rows + 1) * self.square

    def labels(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        hx, hy = self._half()
        m = self.margin * self.square
        on_card = (np.abs(a) < hx + m) & (np.abs(b) < hy + m)
        on_grid = (np.abs(a) < hx) & (np.abs(b) < hy)
        with np.errstate(invalid="ignore"):
            i = np.floor((a + hx) / self.square)
            j = np.floor((b + hy) / self.square)
        black = on_grid & ((i + j) % 2 == 0)
        lab = np.where(on_card, 0, 2).astype(np.int8)
        lab[black] = 1
        return lab

    def distance(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        hx, hy = self._half()
        m = self.margin * self.square
        s = self.square
        # nearest grid line inside the grid (clamped), and the card's edge
        ga = np.abs(a + hx - s * np.clip(np.round((a + hx) / s), 0, self.cols + 1))
        gb = np.abs(b + hy - s * np.clip(np.round((b + hy) / s), 0, self.rows + 1))
        inside = (np.abs(a) <= hx + 0.5 * s) & (np.abs(b) <= hy + 0.5 * s)
        grid = np.where(inside, np.minimum(ga, gb), np.inf)
        card = np.abs(np.maximum(np.abs(a) - hx - m, np.abs(b) - hy - m))
        outer = np.abs(np.maximum(np.abs(a) - hx, np.abs(b) - hy))
        return np.asarray(np.minimum(np.minimum(grid, card), outer))

    def outline(self) -> np.ndarray:
        hx, hy = self._half()
        m = self.margin * self.square
        return _square_outline(hx + m, hy + m)

    def corners(self) -> np.ndarray:
        """The inner corners (cols * rows, 3) in plane coordinates, row by row, as OpenCV
        orders them for a board seen upright."""
        hx, hy = self._half()
        xs = -hx + self.square * np.arange(1, self.cols + 1)
        ys = -hy + self.square * np.arange(1, self.rows + 1)
        gx, gy = np.meshgrid(xs, ys)
        return np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)


# -- a shape placed in the camera frame -------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Patch:
    """A shape on the plane through ``centre`` spanned by the first two columns of ``rotation``.

    ``colours`` (n_labels - 1, 3) are the linear RGB reflectances of the labelled parts.
    """

    shape: Shape
    colours: np.ndarray
    centre: np.ndarray
    rotation: np.ndarray

    def _ray_to_plane(self) -> np.ndarray:
        # camera point t * (x, y, 1) = a * ex + b * ey + c  =>  (a, b, 1) = t * M^-1 (x, y, 1)
        M = np.column_stack([self.rotation[:, 0], self.rotation[:, 1], self.centre])
        return np.linalg.inv(M)

    def plane_coords(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the rays (x, y, 1) meet the plane; NaN for rays that miss (parallel, behind)."""
        H = self._ray_to_plane()
        q0 = H[0, 0] * x + H[0, 1] * y + H[0, 2]
        q1 = H[1, 0] * x + H[1, 1] * y + H[1, 2]
        q2 = H[2, 0] * x + H[2, 1] * y + H[2, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(q2 > 0, 1.0 / q2, np.nan)
        return q0 * w, q1 * w

    def labels(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.labels_at(*self.plane_coords(x, y))

    def labels_at(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Labels at plane points; a NaN point (a missed ray) is "not on it"."""
        with np.errstate(invalid="ignore"):
            lab = self.shape.labels(a, b)
        lab[np.isnan(a)] = self.shape.n_labels - 1
        return lab

    def footprint(self, camera: Camera) -> tuple[float, float, float, float]:
        """(u_min, u_max, v_min, v_max) of the region's image, in raw sensor pixels.

        The image of the outline is the outline of the image; 128 points a side leave a
        chord sagitta far below the margin ``composite`` adds.
        """
        ab = self.shape.outline()
        pts = self.centre + ab[:, :1] * self.rotation[:, 0] + ab[:, 1:] * self.rotation[:, 1]
        if np.any(pts[:, 2] <= 1e-6):
            raise ValueError("a patch reaches behind the camera: it cannot be rendered")
        uv = camera.project(pts)
        return float(uv[:, 0].min()), float(uv[:, 0].max()), float(uv[:, 1].min()), float(
            uv[:, 1].max())


def composite(camera: Camera, patch: Patch, image: np.ndarray, x0: int, y0: int,
              supersample: int, *, light: np.ndarray | None = None, adaptive: bool = True) -> int:
    """Paint ``patch`` over ``image`` (float, H x W x 3, pixel (0, 0) = sensor (x0, y0)).

    Each pixel becomes ``light * coverage-weighted colour + (1 - coverage) * what was there``:
    ``light`` (H x W, default 1) is a smooth illumination field already applied to ``image``,
    so lighting before or after compositing gives the same result and costs no full-image pass.
    Returns the number of supersampled pixels.  ``adaptive=False`` supersamples every pixel of
    the footprint, the reference the adaptive test is checked against.
    """
    h, w = image.shape[:2]
    umin, umax, vmin, vmax = patch.footprint(camera)
    ix0 = max(int(np.floor(umin + 0.5)) - 2, x0)
    ix1 = min(int(np.floor(umax + 0.5)) + 2, x0 + w - 1)
    iy0 = max(int(np.floor(vmin + 0.5)) - 2, y0)
    iy1 = min(int(np.floor(vmax + 0.5)) + 2, y0 + h - 1)
    if ix1 < ix0 or iy1 < iy0:
        return 0
    nw, nh = ix1 - ix0 + 1, iy1 - iy0 + 1
    cu, cv = np.meshgrid(np.arange(ix0, ix1 + 2) - 0.5, np.arange(iy0, iy1 + 2) - 0.5)
    X, Y = pixel_rays(camera, cu.ravel(), cv.ravel())
    X, Y = X.reshape(nh + 1, nw + 1), Y.reshape(nh + 1, nw + 1)
    outside = patch.shape.n_labels - 1
    a, b = patch.plane_coords(X, Y)
    lab = patch.labels_at(a, b)

    # Cheap pre-pass: which pixels might straddle a boundary.
    mixed = ((lab[:-1, :-1] != lab[1:, :-1]) | (lab[:-1, :-1] != lab[:-1, 1:])
             | (lab[:-1, :-1] != lab[1:, 1:]))
    with np.errstate(invalid="ignore"):
        ac = 0.25 * (a[:-1, :-1] + a[1:, :-1] + a[:-1, 1:] + a[1:, 1:])
        bc = 0.25 * (b[:-1, :-1] + b[1:, :-1] + b[:-1, 1:] + b[1:, 1:])
        dua, dub = np.diff(a, axis=1), np.diff(b, axis=1)
        dva, dvb = np.diff(a, axis=0), np.diff(b, axis=0)
        jac2 = (0.25 * (dua[:-1] + dua[1:]) ** 2 + 0.25 * (dub[:-1] + dub[1:]) ** 2
                + 0.25 * (dva[:, :-1] + dva[:, 1:]) ** 2 + 0.25 * (dvb[:, :-1] + dvb[:, 1:]) ** 2)
        far = patch.shape.distance(ac, bc) >= BAND_PX * np.sqrt(jac2)
    mixed |= ~far  # NaN (a miss near the pixel) counts as near
    if not adaptive:
        mixed[:] = True

    rows, cols = slice(iy0 - y0, iy1 - y0 + 1), slice(ix0 - x0, ix1 - x0 + 1)
    view = image[rows, cols]
    lit = np.ones((nh, nw), dtype=image.dtype) if light is None else light[rows, cols]
    pure = ~mixed & (lab[:-1, :-1] != outside)
    view[pure] = patch.colours[lab[:-1, :-1][pure]] * lit[pure][:, None]

    py, px = np.nonzero(mixed)
    if py.size:
        _supersample(camera, patch, (view, lit), (X, Y), (ix0, iy0), (py, px), supersample)
    return int(py.size)


def _supersample(camera: Camera, patch: Patch, target: tuple[np.ndarray, np.ndarray],
                 rays: tuple[np.ndarray, np.ndarray], origin: tuple[int, int],
                 pixels: tuple[np.ndarray, np.ndarray], S: int) -> None:
    """Box-filter the patch over the given pixels of ``view`` with S x S samples each."""
    view, lit = target
    X, Y = rays
    py, px = pixels
    s = (np.arange(S) + 0.5) / S
    sv, su = (g.ravel()[None, :] for g in np.meshgrid(s, s, indexing="ij"))
    w00, w10, w01, w11 = (1 - su) * (1 - sv), su * (1 - sv), (1 - su) * sv, su * sv
    L = patch.shape.n_labels
    colours = np.asarray(patch.colours, dtype=np.float64)
    step = max(1, _CHUNK_SAMPLES // (S * S))
    for k in range(0, py.size, step):
        cy, cx = py[k : k + step, None], px[k : k + step, None]
        n = cy.shape[0]
        gx = X[cy, cx] * w00 + X[cy, cx + 1] * w10 + X[cy + 1, cx] * w01 + X[cy + 1, cx + 1] * w11
        gy = Y[cy, cx] * w00 + Y[cy, cx + 1] * w10 + Y[cy + 1, cx] * w01 + Y[cy + 1, cx + 1] * w11
        u = (origin[0] - 0.5 + cx + su).ravel()
        v = (origin[1] - 0.5 + cy + sv).ravel()
        x, y = pixel_rays(camera, u, v, guess=(gx.ravel(), gy.ravel()))
        lab = patch.labels(x, y).astype(np.int64)
        counts = np.bincount(np.repeat(np.arange(n) * L, S * S) + lab, minlength=n * L)
        frac = counts.reshape(n, L) / (S * S)
        premult = frac[:, : L - 1] @ colours
        keep = frac[:, L - 1 :]
        ry, rx = cy[:, 0], cx[:, 0]
        view[ry, rx] = premult * lit[ry, rx][:, None] + keep * view[ry, rx]
