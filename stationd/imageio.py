"""Reading images for the command line, with one readable error per failure.

Only regular files are read, and an image's size is read from its header before it is
decoded: a header may claim any size (a PNG of 100000 x 100000 px is 57 bytes), and OpenCV
would allocate for it or stop with an assertion.
"""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np

from stationd.errors import ImageError

#: the most pixels an image may have: the station's cameras give 20 MP (5472 x 3648), the
#: largest machine-vision sensors about 150 MP; 200 MP is 600 MB decoded as BGR
MAX_PIXELS = 200_000_000
#: the largest image file read (an uncompressed 16-bit TIFF of 200 MP is 1.2 GB)
MAX_FILE_BYTES = 2**31

_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def header_size(data: bytes | np.ndarray) -> tuple[int, int] | None:
    """(width, height) from the header of a PNG, JPEG or BMP file, None for another format
    or a header too short to say (the decoder then decides)."""
    head = bytes(data[:65536])
    if head.startswith(b"\x89PNG\r\n\x1a\n") and head[12:16] == b"IHDR" and len(head) >= 24:
        w, h = struct.unpack(">II", head[16:24])
        return int(w), int(h)
    if head.startswith(b"BM") and len(head) >= 26:
        w, h = struct.unpack("<ii", head[18:26])
        return abs(int(w)), abs(int(h))
    if head.startswith(b"\xff\xd8"):
        i = 2
        while i + 9 <= len(head):
            if head[i] != 0xFF:
                return None
            marker = head[i + 1]
            if marker == 0xFF:   # fill byte
                i += 1
                continue
            length = struct.unpack(">H", head[i + 2:i + 4])[0]
            if marker in _JPEG_SOF:
                h, w = struct.unpack(">HH", head[i + 5:i + 9])
                return int(w), int(h)
            i += 2 + length
    return None


def read_image_bytes(path: str | Path) -> np.ndarray:
    """The bytes of the image file at ``path``, checked before any decoding: a regular file
    (a FIFO or a device is never opened), not over :data:`MAX_FILE_BYTES`, and a header that
    does not claim more than :data:`MAX_PIXELS`.  ImageError in one line otherwise."""
    p = Path(path)
    if not p.exists():
        raise ImageError(f"{p}: no such file")
    if not p.is_file():
        raise ImageError(f"{p}: not a file")
    size = p.stat().st_size
    if size > MAX_FILE_BYTES:
        raise ImageError(f"{p}: {size} bytes: too large for an image (at most "
                         f"{MAX_FILE_BYTES // 2**20} MB)")
    try:
        data = np.fromfile(str(p), dtype=np.uint8)
    except OSError as exc:
        raise ImageError(f"{p}: cannot read: {exc.strerror or exc}") from None
    wh = header_size(data)
    if wh is not None and wh[0] * wh[1] > MAX_PIXELS:
        raise ImageError(f"{p}: the image says it is {wh[0]} x {wh[1]} px: more than "
                         f"{MAX_PIXELS // 1_000_000} MP, not a camera's image (not decoded)")
    return data


def decode(data: np.ndarray, flags: int) -> np.ndarray | None:
    """``cv2.imdecode``, None for an image OpenCV cannot read (its own size limit or a
    broken file included: never an OpenCV assertion)."""
    if not data.size:
        return None
    try:
        img = cv2.imdecode(data, flags)
    except cv2.error:
        return None
    return None if img is None else np.asarray(img)


def read_image(path: str | Path) -> np.ndarray:
    """An 8-bit BGR image.  An alpha channel is dropped; grey or 16-bit images are refused
    because the marker is found by its colour."""
    p = Path(path)
    img = decode(read_image_bytes(p), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageError(f"{p}: not a readable image")
    if img.dtype != np.uint8:
        raise ImageError(f"{p}: {img.dtype} pixels; an 8-bit colour image is needed")
    if img.ndim == 2 or img.shape[2] == 1:
        raise ImageError(f"{p}: a grey image; the marker is found by colour, a BGR image "
                         "is needed")
    if img.shape[2] == 4:
        img = np.ascontiguousarray(img[:, :, :3])
    if img.shape[2] != 3:
        raise ImageError(f"{p}: {img.shape[2]} channels; 3 (BGR) are needed")
    return np.asarray(img)
