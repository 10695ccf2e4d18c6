"""The latest frame of each camera, for the commissioning screen.

Why a store and not events: a 20 MP frame is 20 MB; the daemon must never copy, encode or
push one because someone might look.  The daemon hands over the array it already has (a
reference, O(1), under a lock) with its detection summary and, when it has one, the reduced
image the detector searched (1/8 of the frame, made anyway); the screen asks for a JPEG and
the encoding happens then, in the web server's thread pool, at most once per frame and size
(the last encoding is cached).  The overview is encoded from that reduced image, never wider
than it: reducing the 20 MP frame again for each camera cost ~9 ms of a core per frame, which
two browsers on the cameras screen took from the vision of a 2-core station.  Full
resolution stays one click away (``crop``).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

Image = NDArray[np.uint8]


@dataclass
class CameraFrame:
    """One camera's latest frame and what the detector said about it."""

    pair: str
    side: str                      # left | right
    image: Image
    grabbed_at: float              # time.time() of the grab
    summary: dict[str, Any] = field(default_factory=dict)
    fps: float | None = None       # measured over the last frames handed over
    seq: int = 0
    preview: Image | None = None   # the same picture reduced (the detector's search image)


class LatestFrames:
    """Thread-safe store: ``put`` from the grab threads, ``jpeg``/``crop`` from the server."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._frames: dict[tuple[str, str], CameraFrame] = {}
        self._rate: dict[tuple[str, str], float] = {}
        self._cache: dict[tuple[str, str, int, int], bytes] = {}
        # what the overview frames cost (the bench reads them): frames reduced and encoded,
        # and the wall time spent on them (OpenCV's own threads make a CPU clock of this
        # thread undercount)
        self.encoded = 0
        self.encode_wall_s = 0.0

    def put(self, pair: str, side: str, image: Image, summary: dict[str, Any] | None = None,
            grabbed_at: float | None = None, preview: Image | None = None) -> None:
        """Keep ``image`` (not copied: the caller must not write into it afterwards), and
        ``preview``, the same picture reduced, for the overview (also not copied)."""
        t = time.time() if grabbed_at is None else grabbed_at
        key = (pair, side)
        with self._lock:
            prev = self._frames.get(key)
            fps = self._rate.get(key)
            if prev is not None and t > prev.grabbed_at:
                inst = 1.0 / (t - prev.grabbed_at)
                fps = inst if fps is None else 0.8 * fps + 0.2 * inst
                self._rate[key] = fps
            seq = 0 if prev is None else prev.seq + 1
            self._frames[key] = CameraFrame(pair, side, image, t, dict(summary or {}), fps, seq,
                                            preview)

    def cameras(self) -> list[CameraFrame]:
        """Every camera's latest frame (pair, side order)."""
        with self._lock:
            return [self._frames[k] for k in sorted(self._frames)]

    def get(self, pair: str, side: str) -> CameraFrame | None:
        with self._lock:
            return self._frames.get((pair, side))

    def jpeg(self, pair: str, side: str, width: int = 640, quality: int = 80) -> bytes | None:
        """The latest frame downscaled to ``width`` pixels (never up, and never wider than
        its preview when it has one), as JPEG; None if the camera has handed over nothing."""
        f = self.get(pair, side)
        if f is None:
            return None
        source = f.image if f.preview is None else f.preview
        width = max(16, min(int(width), source.shape[1]))
        key = (pair, side, f.seq, width)
        with self._lock:
            hit = self._cache.get(key)
        if hit is not None:
            return hit
        t0 = time.perf_counter()
        data = _encode(source if width == source.shape[1] else reduce(source, width), quality)
        with self._lock:
            self.encoded += 1
            self.encode_wall_s += time.perf_counter() - t0
            self._cache = {k: v for k, v in self._cache.items() if k[:2] != (pair, side)}
            self._cache[key] = data
        return data

    def crop(self, pair: str, side: str, x: int, y: int, size: int = 512,
             quality: int = 90) -> bytes | None:
        """A full-resolution ``size`` x ``size`` crop centred on (x, y), clamped inside."""
        f = self.get(pair, side)
        if f is None:
            return None
        h, w = f.image.shape[:2]
        size = max(16, min(int(size), w, h))
        x0 = min(max(0, int(x) - size // 2), w - size)
        y0 = min(max(0, int(y) - size // 2), h - size)
        return _encode(f.image[y0:y0 + size, x0:x0 + size], quality)


def reduce(image: Image, width: int) -> Image:
    """``image`` box-filtered down to ``width`` pixels: halved while still at least twice the
    width (OpenCV's area filter has a fast path for an exact half: a 20 MP frame to 960 px
    costs about a fifth of one area resize at the odd factor), then one area step.  Each
    step averages whole pixels, so fine texture is smoothed, not aliased, as before."""
    img: Image = image
    while img.shape[1] >= 2 * width and img.shape[0] >= 4:
        # an odd side is not cropped (that would shift the picture): OpenCV's general area
        # path then takes the step; the cameras' even sizes keep the fast one
        size = ((img.shape[1] + 1) // 2, (img.shape[0] + 1) // 2)
        img = np.asarray(cv2.resize(img, size, interpolation=cv2.INTER_AREA), dtype=np.uint8)
    h, w = image.shape[:2]
    return np.asarray(cv2.resize(img, (width, max(1, round(h * width / w))),
                                 interpolation=cv2.INTER_AREA), dtype=np.uint8)


def _encode(img: Image, quality: int) -> bytes:
    ok, buf = cv2.imencode(".jpg", img, [int(cv2.IMWRITE_JPEG_QUALITY), int(quality)])
    if not ok:
        raise ValueError("JPEG encoding failed")
    return bytes(buf.tobytes())


def sharpness(image: Image, roi: tuple[int, int, int, int] | None = None) -> float:
    """Focus figure of a region: variance of the Laplacian (higher = sharper); the daemon
    may put it in the summary, the screen computes it lazily otherwise."""
    img: NDArray[Any] = image if roi is None \
        else image[roi[1]:roi[1] + roi[3], roi[0]:roi[0] + roi[2]]
    if img.ndim == 3:
        img = np.asarray(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY))
    if img.size == 0:
        return 0.0
    return float(cv2.Laplacian(img, cv2.CV_64F).var())
