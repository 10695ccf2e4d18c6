"""Images given to the commands: what a file that is no image is, in one line of ours."""

import shutil
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from stationd.errors import ImageError
from stationd.imageio import png_complete, read_image

SIM = Path(__file__).resolve().parents[1] / "config" / "sim"


def _png() -> bytes:
    img = (np.random.default_rng(3).random((60, 80, 3)) * 255).astype(np.uint8)
    ok, data = cv2.imencode(".png", img)
    assert ok
    return data.tobytes()


def test_a_png_is_complete_only_up_to_its_iend():
    data = _png()
    assert png_complete(data) and png_complete(data + b"trailing")
    assert not png_complete(data[:-12]) and not png_complete(data[:len(data) // 2])
    assert not png_complete(data[:40])
    assert png_complete(b"GIF89a...")          # not a PNG: the decoder decides


@pytest.mark.parametrize(("name", "content", "said"), [
    ("station.yaml", None, "station.yaml: this is a station file (a YAML file), not an image"),
    ("pair1.yaml", None, "pair1.yaml: this is a stereo pair calibration (a YAML file), not "
                         "an image"),
    ("notes.txt", "hello\n", "notes.txt: a text file, not an image"),
    ("noise.png", bytes(range(256)) * 4, "noise.png: not an image (no PNG, JPEG, BMP or TIFF "
                                         "header)"),
    ("half.png", "half", "half.png: a broken or truncated image"),
])
def test_a_file_that_is_no_image_is_named(tmp_path, name, content, said):
    path = tmp_path / name
    if content is None:
        shutil.copy(SIM / name, path)
    elif content == "half":
        path.write_bytes(_png()[:300])
    else:
        path.write_bytes(content.encode() if isinstance(content, str) else content)
    with pytest.raises(ImageError) as err:
        read_image(path)
    assert str(err.value).startswith(str(tmp_path / said))


def test_detect_of_a_truncated_png_or_a_station_file_is_one_line_without_opencvs(tmp_path):
    """A truncated PNG printed OpenCV's ``[ WARN:0@0.02] global grfmt_png.cpp ...`` (a header
    alone) or libpng's ``libpng error: PNG input buffer is incomplete`` (cut in its data)
    before our line; ``detect station.yaml`` said "not a readable image"."""
    data = _png()
    (tmp_path / "head.png").write_bytes(data[:40])
    (tmp_path / "cut.png").write_bytes(data[:len(data) // 2])
    shutil.copy(SIM / "station.yaml", tmp_path / "station.yaml")
    for name, said in (("head.png", "a broken or truncated image"),
                       ("cut.png", "a broken or truncated image"),
                       ("station.yaml", "this is a station file (a YAML file), not an image")):
        r = subprocess.run([sys.executable, "-m", "stationd", "detect", str(tmp_path / name),
                            "--pair", str(SIM / "pair1.yaml")],
                           capture_output=True, text=True, timeout=60)
        assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr   # ours alone
        assert r.stderr.startswith(f"stationd: error: {tmp_path / name}: {said}"), r.stderr
