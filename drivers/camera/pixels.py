"""GenICam pixel formats (PFNC) to the BGR frames the vision code wants.

Kept apart from the Aravis backend so it is tested without Aravis, on mosaics built in NumPy.

Bayer naming is the trap here: GenICam names the 2x2 tile from its top-left pixel
(``BayerRG8``: R G / G B), while OpenCV's two-letter codes (``COLOR_BayerRG2BGR``) name the
second row's second and third pixels, so GenICam RG is OpenCV's "BG".  OpenCV 5.0 still does
this; its four-letter aliases (``COLOR_BayerRGGB2BGR``) read like GenICam and are used here.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class PixelFormat:
    """A format this driver converts: PFNC ``code``, bytes per pixel, the cv2 conversion
    (None: already BGR)."""

    name: str
    code: int
    bytes_per_pixel: int
    conversion: int | None


FORMATS: dict[str, PixelFormat] = {f.name: f for f in (
    PixelFormat("Mono8", 0x01080001, 1, cv2.COLOR_GRAY2BGR),
    PixelFormat("BayerRG8", 0x01080009, 1, cv2.COLOR_BayerRGGB2BGR),
    PixelFormat("BayerGB8", 0x0108000A, 1, cv2.COLOR_BayerGBRG2BGR),
    PixelFormat("BayerGR8", 0x01080008, 1, cv2.COLOR_BayerGRBG2BGR),
    PixelFormat("BayerBG8", 0x0108000B, 1, cv2.COLOR_BayerBGGR2BGR),
    PixelFormat("RGB8", 0x02180014, 3, cv2.COLOR_RGB2BGR),
    PixelFormat("BGR8", 0x02180015, 3, None),
)}
BY_CODE: dict[int, PixelFormat] = {f.code: f for f in FORMATS.values()}
#: the default when the camera's current format is not one of ours: Bayer first (one byte
#: a pixel over the cable, demosaiced on the host), then packed colour, then grey
PREFERENCE = ("BayerRG8", "BayerGB8", "BayerGR8", "BayerBG8", "BGR8", "RGB8", "Mono8")


def format_name(code: int) -> str:
    """The PFNC name of ``code``, or its hex value for formats this driver does not know."""
    f = BY_CODE.get(code)
    return f.name if f is not None else f"0x{code:08x}"


def to_bgr(data: bytes | memoryview | np.ndarray, width: int, height: int, pixel_format: str,
           stride: int | None = None) -> np.ndarray:
    """A new, writable HxWx3 uint8 BGR image from a camera buffer.

    ``stride`` is the bytes per row (rows may be padded); ValueError for an unknown format or
    a buffer shorter than the image, so a truncated transfer is never shown as an image.
    """
    fmt = FORMATS.get(pixel_format)
    if fmt is None:
        raise ValueError(f"pixel format {pixel_format} is not supported (supported: "
                         f"{', '.join(FORMATS)})")
    if width <= 0 or height <= 0:
        raise ValueError(f"empty image {width}x{height}")
    row = width * fmt.bytes_per_pixel
    stride = row if stride is None else stride
    if stride < row:
        raise ValueError(f"row stride {stride} is shorter than a row ({row} bytes)")
    raw = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) \
        else data.reshape(-1).view(np.uint8)
    need = stride * (height - 1) + row
    if raw.size < need:
        raise ValueError(f"{pixel_format} {width}x{height}: buffer holds {raw.size} bytes, "
                         f"the image needs {need}")
    rows = np.lib.stride_tricks.as_strided(raw, shape=(height, row), strides=(stride, 1))
    img = rows.reshape(height, width, 3) if fmt.bytes_per_pixel == 3 else rows
    if fmt.conversion is None:
        return np.array(img, dtype=np.uint8, copy=True)
    return np.asarray(cv2.cvtColor(np.ascontiguousarray(img), fmt.conversion))
