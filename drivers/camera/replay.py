"""``file:///dir/left_*.png``: replay recorded images as if a camera delivered them.

Used to rerun the station on a recorded session and to commission the vision without
hardware.  The files are the path's glob matches in natural order (``left_2`` before
``left_10``), fixed when the camera opens.

    file:///data/run1/left_*.png           each file once, then EndOfStreamError
    file:///data/run1/left_*.png?loop=1    start again after the last file
    file:///data/run1/                     every image file of the directory
    file://relative/dir/left_*.png         relative to the working directory

A file that cannot be read (corrupt, deleted since, 16-bit) raises FrameError naming it and
is skipped: the replay *continues* with the next file at the next grab, so one bad file in a
recording costs one frame, not the run.  Grey images become BGR (a mono camera's recording).
A frame's timestamp is the time of ``trigger()`` (else of the grab), not the file's date.
"""

from __future__ import annotations

import glob
import re
from pathlib import Path
from urllib.parse import unquote, urlsplit

import cv2
import numpy as np

from drivers.camera.base import CameraDevice, EndOfStreamError, Frame, FrameError, flag
from drivers.counting import counted
from drivers.errors import ConnectError
from drivers.url import parse_url

FORM = "file:///dir/left_*.png[?loop=1]"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")


def natural_key(path: str) -> list[tuple[int, int | str]]:
    """Sort key: digit runs compare as numbers, so frame_9 comes before frame_10."""
    return [(0, int(tok)) if tok.isdigit() else (1, tok)
            for tok in re.split(r"(\d+)", path) if tok]


def parse_file_url(text: str) -> tuple[str, bool]:
    """(path or glob pattern, loop) of a ``file://`` URL."""
    url = parse_url(text)
    opts = url.typed_options({"loop": (flag, False)}, FORM)
    parts = urlsplit(text)
    path = unquote(parts.netloc + parts.path)
    if url.scheme != "file" or not path:
        raise url.error(f"expected a path or pattern, e.g. {FORM}")
    return path, bool(opts["loop"])


def read_frame_image(path: str) -> np.ndarray:
    """An 8-bit BGR image from ``path``; ValueError with the reason otherwise."""
    p = Path(path)
    if not p.is_file():
        raise ValueError("no such file")
    data = np.fromfile(str(p), dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise ValueError("not a readable image" + (" (empty file)" if not data.size else ""))
    if img.dtype != np.uint8:
        raise ValueError(f"{img.dtype} pixels; an 8-bit image is needed")
    if img.ndim == 2 or img.shape[2] == 1:
        return np.asarray(cv2.cvtColor(img.reshape(img.shape[:2]), cv2.COLOR_GRAY2BGR))
    if img.shape[2] == 4:
        return np.ascontiguousarray(img[:, :, :3])
    if img.shape[2] != 3:
        raise ValueError(f"{img.shape[2]} channels")
    return np.asarray(img)


def replay_files(pattern: str) -> list[str]:
    """The files a replay of ``pattern`` (a folder or a glob) delivers, in natural order."""
    p = Path(pattern)
    if p.is_dir():
        found = [str(f) for f in p.iterdir()
                 if f.is_file() and f.suffix.lower() in IMAGE_SUFFIXES]
    else:
        found = [f for f in glob.glob(pattern) if Path(f).is_file()]
    return sorted(found, key=natural_key)


def _nothing(pattern: str) -> str:
    """Why a replay has no frames, naming where a relative pattern was looked for."""
    p = Path(pattern)
    if p.exists() and not p.is_dir() and not p.is_file():   # /dev/zero, a FIFO, a socket
        return f"{pattern} is a device or a FIFO, not an image file (give image files, or " \
            "a folder of them)"
    what = "no image files in" if p.is_dir() else "no files match"
    where = "" if p.is_absolute() else f" (relative to the working directory {Path.cwd()})"
    folder = p if p.is_dir() else p.parent
    if not p.is_dir() and not folder.is_dir():
        return f"{what} {pattern}: folder {folder} does not exist{where}"
    return f"{what} {pattern}{where}"


class FileReplayCamera(CameraDevice):
    """Recorded image files as a free-running camera (no exposure, no gain)."""

    def __init__(self, url: str, *, timeout: float | None = None) -> None:
        super().__init__(url, timeout=timeout)
        self.pattern, self.loop = parse_file_url(url)
        self.files: list[str] = []
        self.position = 0  # index of the next file
        self._count = 0

    @classmethod
    def _endpoint(cls, url: str) -> None:
        """Recorded files are read by any number of processes: nothing to keep apart."""
        return None

    def identity(self) -> str:
        loop = "looping" if self.loop else "once"
        return f"file replay {self.pattern}: {counted(len(self.files), 'file')}, {loop}"

    @classmethod
    def check_source(cls, url: str) -> None:
        """Check that ``url``'s files exist now (UrlError saying which pattern matches
        nothing): ``config check`` asks it, so that a typo in a recording's path is told
        before the station starts.  The daemon does not (a folder mounted after it started
        is a fault until it appears, retried as any device)."""
        pattern, _ = parse_file_url(url)
        if not replay_files(pattern):
            raise parse_url(url).error(_nothing(pattern))

    def _open(self) -> None:
        found = replay_files(self.pattern)
        if not found:
            raise ConnectError(_nothing(self.pattern), device=self.url)
        self.files = found
        self.position = 0
        self._count = 0

    def _close(self) -> None:
        pass

    def _grab(self, timeout: float) -> Frame:
        if self.position >= len(self.files):
            if not self.loop:
                raise EndOfStreamError(f"replay finished: all {counted(len(self.files), 'file')} "
                                       "delivered (add ?loop=1 to start again)",
                                       device=self.url)
            self.position = 0
        path = self.files[self.position]
        self.position += 1  # a bad file is skipped: the next grab reads the next one
        timestamp = self._take_trigger_time()
        try:
            image = read_frame_image(path)
        except (ValueError, OSError) as exc:
            raise FrameError(f"{path}: {exc} (skipped; the replay continues with the next "
                             "file)", device=self.url) from None
        frame = Frame(image=image, timestamp=timestamp, frame_id=self._count, camera=self.url)
        self._count += 1
        return frame
