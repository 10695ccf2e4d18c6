"""Pixel formats to BGR, on mosaics built here in NumPy (no Aravis needed)."""

import numpy as np
import pytest

from drivers.camera import pixels

# GenICam names the 2x2 tile from its top-left pixel; channel index in BGR order
TILES = {"BayerRG8": [[2, 1], [1, 0]], "BayerGB8": [[1, 0], [2, 1]],
         "BayerGR8": [[1, 2], [0, 1]], "BayerBG8": [[0, 1], [1, 2]]}


def _scene(h=48, w=64):
    """A smooth colour image: the demosaiced mosaic must come back close to it."""
    y, x = np.mgrid[0:h, 0:w]
    img = np.stack([40 + 2 * x, 200 - y, 60 + x + y], axis=2)
    return np.clip(img, 0, 255).astype(np.uint8)


def _mosaic(bgr, tile):
    h, w, _ = bgr.shape
    out = np.empty((h, w), np.uint8)
    for dy in (0, 1):
        for dx in (0, 1):
            out[dy::2, dx::2] = bgr[dy::2, dx::2, tile[dy][dx]]
    return out


@pytest.mark.parametrize("name", sorted(TILES))
def test_bayer_demosaics_to_the_original_colours(name):
    bgr = _scene()
    out = pixels.to_bgr(_mosaic(bgr, TILES[name]).tobytes(), 64, 48, name)
    assert out.shape == (48, 64, 3) and out.dtype == np.uint8
    inner = (slice(2, -2), slice(2, -2))
    err = np.abs(out[inner].astype(int) - bgr[inner].astype(int))
    assert err.max() <= 3, f"{name}: max error {err.max()}"


def test_a_wrong_pattern_gives_wrong_colours():
    """The check above is sharp: decoding RG data as BG swaps red and blue."""
    bgr = _scene()
    out = pixels.to_bgr(_mosaic(bgr, TILES["BayerRG8"]).tobytes(), 64, 48, "BayerBG8")
    assert np.abs(out[4:-4, 4:-4].astype(int) - bgr[4:-4, 4:-4].astype(int)).max() > 30


def test_rgb8_bgr8_mono8():
    bgr = _scene()
    rgb = bgr[:, :, ::-1].copy()
    assert np.array_equal(pixels.to_bgr(rgb.tobytes(), 64, 48, "RGB8"), bgr)
    out = pixels.to_bgr(bgr.tobytes(), 64, 48, "BGR8")
    assert np.array_equal(out, bgr) and out.flags.writeable
    grey = bgr[:, :, 1].copy()
    mono = pixels.to_bgr(grey.tobytes(), 64, 48, "Mono8")
    assert all(np.array_equal(mono[:, :, c], grey) for c in range(3))


def test_padded_rows_and_short_buffers():
    grey = np.arange(6 * 4, dtype=np.uint8).reshape(4, 6)
    padded = np.zeros((4, 8), np.uint8)
    padded[:, :6] = grey
    out = pixels.to_bgr(padded.tobytes(), 6, 4, "Mono8", stride=8)
    assert np.array_equal(out[:, :, 0], grey)
    with pytest.raises(ValueError, match="buffer holds 23 bytes, the image needs 24"):
        pixels.to_bgr(grey.tobytes()[:-1], 6, 4, "Mono8")
    with pytest.raises(ValueError, match="Mono16 is not supported"):
        pixels.to_bgr(grey.tobytes(), 3, 4, "Mono16")


def test_format_names():
    assert pixels.format_name(0x01080009) == "BayerRG8"
    assert pixels.format_name(0x02180014) == "RGB8"
    assert pixels.format_name(0x01100007) == "0x01100007"  # Mono16: not converted
