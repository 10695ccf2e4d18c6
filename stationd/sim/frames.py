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
more (afterwards only the last window is put back and the new one pasted), so a grab costs a
window, not 60 MB of memory traffic, as a real camera that DMAs into queued buffers costs the
host nothing per frame.  A frame still referenced by anyone (the vision, the screens' latest
frames, a test) is never written into again.  A buffer is not a copy of the background either:
the background lives in a file, shown read-only (the shared render folder's own file, whose
pages every process shares, or else a memory file of the camera's), and each buffer is a
copy-on-write mapping of that file, so a buffer costs the pages its windows were written
into.  A copy cost 60 MB of page faults (0.17 s of a core, most of it the kernel's): four
buffers for each of eight cameras in every station a test or a demo starts.
"""

from __future__ import annotations

import mmap
import os
import sys
import threading
from dataclasses import dataclass, replace
from pathlib import Path

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
        self._file: int | None = None    # the background's file (its descriptor)
        self._offset = 0                  # where its pixels start in that file
        self._pool: list[_Buffer] = []
        self._pool_lock = threading.Lock()

    @property
    def background(self) -> np.ndarray:
        if self._background is None:
            image = backgrounds.background(
                self.camera, replace(self.scene, markers=list(self.fixed)), self.seed)
            # handed out shared, read-only: a write would be a bug, loudly
            self._file, self._offset, self._background = _in_a_file(image)
        return self._background

    def __del__(self) -> None:
        """Let go of the background's file (its pages go once no frame maps them)."""
        fd = getattr(self, "_file", None)   # None too when __init__ refused the scene
        if fd is not None:
            os.close(fd)
            self._file = None

    def resident_bytes(self) -> int:
        """The memory the process's page tables count for this camera: the background's and
        each pool buffer's pages that were read or written (``VmRSS`` counts a page once per
        mapping that touched it, though the background's are one copy)."""
        with self._pool_lock:
            images = [b.image for b in self._pool]
        if self._background is not None:
            images.append(self._background)
        return resident(images)

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
        buf = _Buffer(self._private_copy())
        buf.free_refs = sys.getrefcount(buf.image)  # the count that means "unheld", here
        if len(self._pool) < POOL:
            self._pool.append(buf)
        return buf

    def _private_copy(self) -> np.ndarray:
        """A writable frame that reads as the background: a copy-on-write mapping of its
        file (the kernel copies a page when a window is first written into it)."""
        bg = self.background
        if self._file is None:
            raise RuntimeError("a frame source without its background's file")
        view = mmap.mmap(self._file, self._offset + bg.nbytes, flags=mmap.MAP_PRIVATE,
                         prot=mmap.PROT_READ | mmap.PROT_WRITE)
        return np.frombuffer(view, dtype=bg.dtype, count=bg.size,
                             offset=self._offset).reshape(bg.shape)

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


def _in_a_file(image: np.ndarray) -> tuple[int, int, np.ndarray]:
    """A file that holds ``image``, where in it the pixels start, and a read-only view of them
    (the frames' buffers map the same file copy-on-write): the file ``image`` is mapped from
    (the shared render folder's), else a memory file it is copied into."""
    if isinstance(image, np.memmap) and image.filename and image.flags.c_contiguous:
        fd = os.open(image.filename, os.O_RDONLY | os.O_CLOEXEC)
        return fd, int(image.offset), np.asarray(image)
    fd, view = _in_memory_file(np.ascontiguousarray(image))
    return fd, 0, view


def _in_memory_file(image: np.ndarray) -> tuple[int, np.ndarray]:
    """``image`` copied into a memory file: its descriptor and a read-only view of it."""
    fd = os.memfd_create("stationd-sim-background", os.MFD_CLOEXEC)
    try:
        os.ftruncate(fd, image.nbytes)
        with mmap.mmap(fd, image.nbytes) as out:
            np.frombuffer(out, dtype=image.dtype)[:] = image.reshape(-1)
        shown = mmap.mmap(fd, image.nbytes, flags=mmap.MAP_SHARED, prot=mmap.PROT_READ)
    except BaseException:
        os.close(fd)
        raise
    view = np.frombuffer(shown, dtype=image.dtype).reshape(image.shape)
    return fd, view


def mappings() -> list[tuple[int, int, dict[str, int]]]:
    """Each mapping of this process: its start and end addresses and its sizes in bytes as
    ``/proc/self/smaps`` gives them (``Rss``, ``Anonymous``, ...); empty where there is no
    such file."""
    try:
        text = Path("/proc/self/smaps").read_text()
    except OSError:
        return []
    out: list[tuple[int, int, dict[str, int]]] = []
    for line in text.splitlines():
        head = line.split(" ", 1)[0]
        if "-" in head and not head.endswith(":"):
            lo, hi = head.split("-")
            out.append((int(lo, 16), int(hi, 16), {}))
        elif out and line.endswith(" kB"):
            out[-1][2][head.rstrip(":")] = int(line.split()[1]) * 1024
    return out


def mapping_of(image: np.ndarray, maps: list[tuple[int, int, dict[str, int]]]
               ) -> tuple[int, dict[str, int]] | None:
    """The start and the sizes of the mapping (of ``maps``) that holds ``image``'s pixels."""
    at = image.__array_interface__["data"][0]
    return next(((lo, sizes) for lo, hi, sizes in maps if lo <= at < hi), None)


def resident(images: list[np.ndarray]) -> int:
    """The resident size (``Rss``) of the mappings that hold ``images``, each mapping once; an
    image in no mapping of its own (the heap's) counts its size.  Read once at a benchmark's
    end: smaps lists every mapping of the process."""
    maps = mappings()
    seen: dict[int, int] = {}
    for im in images:
        found = mapping_of(im, maps)
        rss = None if found is None else found[1].get("Rss")
        if found is None or rss is None or rss > im.nbytes + 2 * mmap.PAGESIZE:
            seen[id(im)] = im.nbytes    # in a larger mapping (the heap): its own size
        else:
            seen[found[0]] = rss
    return sum(seen.values())
