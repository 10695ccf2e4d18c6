"""Reading images for the command line, with one readable error per failure."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from stationd.errors import ImageError


def read_image(path: str | Path) -> np.ndarray:
    """An 8-bit BGR image.  An alpha channel is dropped; grey or 16-bit images are refused
    because the marker is found by its colour."""
    p = Path(path)
    if not p.exists():
        raise ImageError(f"{p}: no such file")
    if not p.is_file():
        raise ImageError(f"{p}: not a file")
    data = np.fromfile(str(p), dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
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
