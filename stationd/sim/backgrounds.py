"""A folder of rendered images that the simulated cameras of several processes share.

A simulated camera renders its 20 MP background once (a second or more of a core each; eight
cameras per station), and every station, demo and benchmark does so again in its own process:
a test run of the whole daemon pays that dozens of times for the same few backgrounds.  The
window around a wrench's marker is the same story at a smaller scale: a third of a second of
ray-casting per camera each time the wrench is put on a bolt, for the very same placements in
test after test.  With ``STATIOND_SIM_BACKGROUNDS`` naming a folder, an image (a background,
or a marker's window) is rendered once, written there and read back (a background in a fifth
of a second, a window in a millisecond) by every later camera that would render the very same,
and cameras that ask for it at once wait for the one render (a lock file beside the image).

"The very same": the key hashes everything the image is made of (the camera, the scene with
its markers, the window, the seed) and the source of the code that draws it (the renderer,
its ray caster, the camera model, the marker's colours) with the versions of NumPy and OpenCV,
so a changed input or a changed renderer is a new file, never a stale image.  The render is
deterministic in these, so an image read back equals the one the camera would render.
The test suite points this at a folder of its own for one run; without the variable nothing is
written anywhere and every camera renders its own, as before.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import io
import os
import pickle
import threading
import time
from functools import cache
from pathlib import Path

import cv2
import numpy as np

from stationd.geometry import camera as camera_module
from stationd.geometry.camera import Camera
from stationd.sim import raycast, render
from stationd.vision import marker

ENV = "STATIOND_SIM_BACKGROUNDS"
#: how long a camera waits for another process's render of the same image before its own
#: (a background takes a core a second or two, many more on a loaded machine)
LOCK_WAIT_S = 30.0

_writers: list[threading.Thread] = []    # the files being written, this process's
_lock = threading.Lock()


@cache
def _code_key() -> bytes:
    """What the drawing code is: its sources and the libraries' versions."""
    h = hashlib.sha256()
    for module in (render, raycast, camera_module, marker):
        h.update(Path(str(module.__file__)).read_bytes())
    h.update(f"numpy {np.__version__} opencv {cv2.__version__}".encode())
    return h.digest()


def _key(camera: Camera, scene: render.Scene, seed: int,
         window: render.Window | None) -> str:
    h = hashlib.sha256(_code_key())
    h.update(pickle.dumps((camera, scene, seed, window), protocol=5))
    return h.hexdigest()[:40]


def background(camera: Camera, scene: render.Scene, seed: int) -> np.ndarray:
    """``render(camera, scene, seed=seed).image``, from the shared folder when it has it (and
    put there when it did not)."""
    return rendered(camera, scene, seed)


def rendered(camera: Camera, scene: render.Scene, seed: int,
             window: render.Window | None = None) -> np.ndarray:
    """``render(camera, scene, window=window, seed=seed).image``, from the shared folder when
    it has it (and put there when it did not)."""
    folder = os.environ.get(ENV)
    if not folder:
        return render.render(camera, scene, window=window, seed=seed).image
    path = Path(folder) / f"{_key(camera, scene, seed, window)}.npy"
    image = _read(path)
    if image is not None:
        return image
    # One process renders it, the others wait for its file: at the start of a test run both
    # workers' first stations asked for the same eight backgrounds at once, each rendering all.
    lock = _take(path)
    image = _read(path)             # rendered while this one waited
    if image is not None:
        _release(lock)
        return image
    try:
        image = render.render(camera, scene, window=window, seed=seed).image
    except BaseException:
        _release(lock)
        raise
    # written beside the camera's work, not before its first frame (60 MB take a disk a
    # while), the lock let go once it is there; not a daemon thread: a process that ends
    # lets it finish
    writer = threading.Thread(target=_store, args=(path, image, lock),
                              name="sim-background-store")
    try:
        writer.start()
    except RuntimeError:       # no thread to be had (shutting down): not kept, lock let go
        _release(lock)
        return image
    with _lock:
        _writers[:] = [w for w in _writers if w.is_alive()]
        _writers.append(writer)
    return image


def wait_stored() -> None:
    """Wait until the backgrounds this process rendered are in the folder."""
    with _lock:
        writers = list(_writers)
    for w in writers:
        w.join()


def _read(path: Path) -> np.ndarray | None:
    """The image kept at ``path``, mapped read-only (the page cache's pages, shared by every
    process that reads it: no 60 MB copy each); None when it is not there yet, is being
    replaced or was cut short (a zero-length file: EOFError)."""
    with contextlib.suppress(OSError, ValueError, EOFError):
        image: np.ndarray = np.load(path, mmap_mode="r", allow_pickle=False)
        return image
    return None


def _take(path: Path) -> int | None:
    """The image's lock (``NAME.lock`` beside it), waited for :data:`LOCK_WAIT_S` at most: held by
    whoever renders it until its file is there.  None where no lock can be had, or the
    holder keeps it longer (a process stopped or stuck mid-render): the image is rendered
    anyway, a camera is never left waiting on another process without end."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path.with_suffix(".lock"), os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        return None
    deadline = time.monotonic() + LOCK_WAIT_S
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return fd
        except BlockingIOError:
            if time.monotonic() >= deadline:
                break
            time.sleep(0.05)
        except OSError:
            break
    os.close(fd)
    return None


def _release(lock: int | None) -> None:
    if lock is not None:
        os.close(lock)    # closing the descriptor lets the lock go


def _store(path: Path, image: np.ndarray, lock: int | None = None) -> None:
    """``image`` written whole under a name of its own, then renamed: a reader in another
    process sees the complete file or none; then ``lock`` is let go.  A full disk only costs
    a later camera its render."""
    part = path.with_name(f"{path.stem}.{os.getpid()}.{threading.get_ident()}.part")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        np.save(buf, image, allow_pickle=False)
        part.write_bytes(buf.getbuffer())
        os.replace(part, path)
    except OSError:
        with contextlib.suppress(OSError):   # a full disk: no half file left behind
            part.unlink(missing_ok=True)
    finally:
        _release(lock)
