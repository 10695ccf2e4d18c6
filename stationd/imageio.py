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


def png_complete(data: bytes | np.ndarray) -> bool:
    """Whether a PNG's chunks run to its IEND within ``data`` (a truncated PNG is told as
    such before libpng prints its own "PNG input buffer is incomplete" on stderr, which
    no log level of OpenCV's silences).  True for data that is no PNG."""
    raw = bytes(data) if isinstance(data, np.ndarray) else data
    if not raw.startswith(b"\x89PNG\r\n\x1a\n"):
        return True
    i = 8
    while i + 8 <= len(raw):
        length = int(struct.unpack(">I", raw[i:i + 4])[0])
        if raw[i + 4:i + 8] == b"IEND":
            return i + 12 + length <= len(raw)
        i += 12 + length
    return False


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
    broken file included: never an OpenCV assertion, nor libpng's line on stderr for a
    truncated PNG)."""
    if not data.size or not png_complete(data):
        return None
    try:
        img = cv2.imdecode(data, flags)
    except cv2.error:
        return None
    return None if img is None else np.asarray(img)


#: the starts of the image files OpenCV reads (PNG, JPEG, BMP, TIFF, WebP, PNM)
IMAGE_MAGIC = (b"\x89PNG\r\n\x1a\n", b"\xff\xd8\xff", b"BM", b"II*\x00", b"MM\x00*", b"RIFF",
               b"P5", b"P6")
#: a text file up to this size is read as YAML to name it (a station file given as an image)
NAME_TEXT_BYTES = 1 << 20


def not_an_image(data: np.ndarray) -> str:
    """Why bytes OpenCV cannot decode are no image, naming what they are: a broken image
    (its header is an image's), one of the station's YAML files (``detect station.yaml``: it
    is a station file, not an image), a text file, or something else."""
    head = bytes(data[:16])
    if head.startswith(IMAGE_MAGIC):
        return "a broken or truncated image (its header is an image's; its data does not " \
               "decode)"
    if data.size <= NAME_TEXT_BYTES:
        try:
            text = bytes(data).decode("utf-8")
        except UnicodeDecodeError:
            text = None
        if text is not None and "\0" not in text:
            return _text_kind(text)
    return "not an image (no PNG, JPEG, BMP or TIFF header)"


def _text_kind(text: str) -> str:
    """What a text file given as an image is: one of the station's YAML files, or text."""
    from stationd.filekind import KINDS, kind_of_keys
    from stationd.yamlio import YamlNode, top_keys

    try:
        kind = kind_of_keys(top_keys(YamlNode.parse(text)))
    except Exception:
        kind = None
    if kind is not None:
        return f"this is {KINDS[kind].name} (a YAML file), not an image"
    return "a text file, not an image"


def read_image(path: str | Path) -> np.ndarray:
    """An 8-bit BGR image.  An alpha channel is dropped; grey or 16-bit images are refused
    because the marker is found by its colour."""
    p = Path(path)
    data = read_image_bytes(p)
    img = decode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ImageError(f"{p}: {not_an_image(data)}")
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
