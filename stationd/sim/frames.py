"""Fast full-resolution frames for the simulated cameras.

A full 20 MP render costs about a second (noise generation dominates), far too slow for a
station running at frame rate.  The marker covers a small window of the frame: the rest is
the same background every time.  So each camera renders its background once (or reads it from
the folder of :mod:`stationd.sim.backgrounds`, where another process rendered the very same)
and each frame ray-casts only the window around the marker (or reads it from that folder
too), pasted into a copy.  The renderer
seeds its noise by sensor position, so with the same seed the composite equals a full render
exactly (tested); with a new seed per frame the window's noise is fresh and the background's is
frozen, which a detector cannot tell apart.

Composing is a camera's buffer pool: a frame is written into a buffer that nobody holds any
more (the background is copied into it once; afterwards only the last window is put back and
the new one pasted), so a grab costs a window, not 60 MB of memory traffic, as a real camera
that DMAs into queued buffers costs the host nothing per frame.  A frame still referenced by
anyone (the vision, the screens' latest frames, a test) is never written into again.
"""

from __future__ import annotations

import sys
import threading
from dataclasses import dataclass, replace

import numpy as np

from stationd.geometry.camera import Camera
from stationd.sim import backgrounds
from stationd.sim.render import MarkerPose, Scene, render
from stationd.sim.scenes import marker_window
from stationd.vision.marker import MarkerSpec

#: a window (x, y, w, h) and its pixels, a whole frame, or None (the background as it is)
Patch = tuple[tuple[int, int, int, int], np.ndarray] | np.ndarray | None


#: buffers a camera keeps before it allocates more (one per frame in flight is the usual need)
POOL = 4


@dataclass
class _Buffer:
    """One frame buffer of the pool and the window last pasted into it (None: it equals the
    background)."""

    image: np.ndarray
    window: tuple[int, int, int, int] | None = None
    free_refs: int = 2


class FrameSource:
    """Frames of one simulated camera for a scene whose only moving thing is the marker."""

    def __init__(self, camera: Camera, scene: Scene, seed: int = 0,
                 fixed: list[tuple[MarkerPose, MarkerSpec]] | None = None) -> None:
        if scene.markers:
            raise ValueError("the background scene must not contain markers (fixed ones are "
                             "passed as ``fixed``)")
        self.camera = camera
        self.scene = scene
        self.seed = seed
        # markers that never move (the reference markers): part of the background, and of
        # every window rendered over it (a wrench's window beside one keeps it)
        self.fixed = list(fixed or [])
        self._background: np.ndarray | None = None
        self._pool: list[_Buffer] = []
        self._pool_lock = threading.Lock()

    @property
    def has_background(self) -> bool:
        return self._background is not None

    @property
    def background(self) -> np.ndarray:
        if self._background is None:
            image = backgrounds.background(
                self.camera, replace(self.scene, markers=list(self.fixed)), self.seed)
            image.setflags(write=False)  # handed out shared: a write would be a bug, loudly
            self._background = image
        return self._background

    def pool(self) -> list[np.ndarray]:
        """The frame buffers the pool holds (the world's memory, not the daemon's)."""
        with self._pool_lock:
            return [b.image for b in self._pool]

    def frame(self, pose: MarkerPose | None, spec: MarkerSpec | None = None,
              seed: int | None = None) -> np.ndarray:
        """A full frame with the marker at ``pose`` (camera frame), or the bare background."""
        return self.compose(self.patch(pose, spec, seed))

    def patch(self, pose: MarkerPose | None, spec: MarkerSpec | None = None,
              seed: int | None = None) -> Patch:
        """What the marker at ``pose`` changes in the background: a window and its pixels, or
        a whole frame (the marker partly out of view), or None (nothing: not in view).  A
        benchmark renders these ahead and composes frames from them at frame rate."""
        if pose is None:
            return None
        spec = spec or MarkerSpec()
        if not self._in_view(pose, spec):
            return None
        scene = replace(self.scene, markers=[*self.fixed, (pose, spec)])
        seed = self.seed if seed is None else seed
        # partly out of view: the part of the window on the sensor (a whole 20 MP frame
        # ray-cast for a marker at the edge cost seconds a grab)
        win = marker_window(self.camera, pose, spec, margin_px=48.0, clip=True)
        if win is None:  # straddles the camera plane: the whole frame, the slow way (not kept)
            return render(self.camera, scene, seed=seed).image
        return win, backgrounds.rendered(self.camera, scene, seed, win)

    def compose(self, patch: Patch) -> np.ndarray:
        """A frame from a :meth:`patch`: the background itself when nothing changes (shared,
        not copied: nobody writes into a grabbed frame), else a free pool buffer with the
        window pasted."""
        if patch is None:
            return self.background
        if isinstance(patch, np.ndarray):
            return patch
        (x, y, w, h), pixels = patch
        with self._pool_lock:   # taken and written under the lock: no other grab picks it
            buf = self._free_buffer()
            image = buf.image
            if buf.window is not None:
                bx, by, bw, bh = buf.window
                image[by:by + bh, bx:bx + bw] = self.background[by:by + bh, bx:bx + bw]
            image[y:y + h, x:x + w] = pixels
            buf.window = (x, y, w, h)
        return image

    def _free_buffer(self) -> _Buffer:
        """A pool buffer that no one but the pool references (a new one, a copy of the
        background, when all are held): one whose ``sys.getrefcount`` is what it was when the
        buffer was made and held by the pool alone (measured then, not assumed: interpreters
        count temporaries differently).  Anything more is a holder, views included (a view
        keeps its base array referenced).  Called with the pool's lock held."""
        for buf in self._pool:
            if sys.getrefcount(buf.image) <= buf.free_refs:
                return buf
        buf = _Buffer(self.background.copy())
        buf.free_refs = sys.getrefcount(buf.image)  # the count that means "unheld", here
        if len(self._pool) < POOL:
            self._pool.append(buf)
        return buf

    def _in_view(self, pose: MarkerPose, spec: MarkerSpec) -> bool:
        """Whether any of the marker's field can reach the image (with a blur margin)."""
        f = spec.field_mm
        corners = np.array([[-f, -f, 0], [f, -f, 0], [f, f, 0], [-f, f, 0]], dtype=np.float64)
        pts = pose.centre_mm + corners @ pose.rotation.T
        if np.any(pts[:, 2] <= 1e-6):
            return True  # straddles the camera plane: let the renderer decide
        uv = self.camera.project(pts)
        w, h = self.camera.size
        return bool(uv[:, 0].max() >= -8 and uv[:, 1].max() >= -8 and uv[:, 0].min() <= w + 8
                    and uv[:, 1].min() <= h + 8)
