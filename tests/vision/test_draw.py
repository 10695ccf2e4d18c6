"""``stationd detect --draw``: the picture shows what the detector used and why it refused."""

from dataclasses import replace

import cv2
import numpy as np
import pytest
import yaml

from stationd.bench import robustness as rb
from stationd.cli import main
from stationd.vision import draw as dr
from stationd.vision.detect import detect
from stationd.vision.params import VisionParams


@pytest.fixture(scope="module")
def occluded():
    s = rb.make_sample(rb.Setup(occluder=("hand", "skin", 0.3, 1.0)), np.random.default_rng(4))
    return s, detect(s.image, s.camera, VisionParams(), rb.SPEC)


def _count(img, bgr, tol=40):
    return int((np.abs(img.astype(int) - np.array(bgr)).max(axis=2) <= tol).sum())


def test_found_picture_has_points_ellipses_and_centre(occluded):
    s, d = occluded
    assert d.found and d.edges_raw is not None and d.edges_used is not None
    pic = dr.draw(s.image, s.camera, d)
    assert pic.ndim == 3 and pic.shape[1] > dr.PANEL  # ROI panel + overview side by side
    assert _count(pic, dr.USED) > 100  # used edge points drawn
    assert d.edges_dropped is not None and len(d.edges_dropped) > 0  # the fingers' edges
    assert _count(pic, dr.REJECTED) > 10
    assert _count(pic, dr.CENTRE, 30) > 10
    bare = dr.draw(s.image, s.camera, replace(d, edges_raw=None))  # the points hide the lines
    assert _count(bare, dr.OUTER, 30) > 100 and _count(bare, dr.INNER, 30) > 100
    assert "outer ring visible" in " ".join(dr._caption(d))


def test_refusal_picture_names_the_reason(occluded):
    s, _ = occluded
    img = s.image.copy()
    c = np.rint(s.truth).astype(int)
    cv2.circle(img, (int(c[0]), int(c[1])), 25, (40, 40, 40), -1)  # glove over the white disk
    d = detect(img, s.camera, VisionParams(), rb.SPEC)
    assert not d.found
    shown = dr.explain(img, s.camera, d, VisionParams(), rb.SPEC)
    assert shown.reason == d.reason
    assert dr._caption(shown)[0].startswith("refused: ")
    assert dr.draw(img, s.camera, shown).shape[0] > 48


def test_cli_draw_writes_png_and_bad_path_is_one_line_exit_2(occluded, tmp_path, capsys):
    s, _ = occluded
    cv2.imwrite(str(tmp_path / "one.png"), s.image)
    (tmp_path / "cam.yaml").write_text(yaml.safe_dump(s.camera.to_dict()))
    out = tmp_path / "seen.png"
    code = main(["detect", str(tmp_path / "one.png"), "--camera", str(tmp_path / "cam.yaml"),
                 "--draw", str(out)])
    assert code == 0 and cv2.imread(str(out)) is not None
    capsys.readouterr()
    code = main(["detect", str(tmp_path / "one.png"), "--camera", str(tmp_path / "cam.yaml"),
                 "--draw", str(tmp_path / "no" / "dir" / "x.png")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--draw" in err
    code = main(["detect", str(tmp_path / "one.png"), "--camera", str(tmp_path / "cam.yaml"),
                 "--draw", str(tmp_path / "seen.txt")])
    err = capsys.readouterr().err
    assert code == 2 and "name the file .png" in err and not (tmp_path / "seen.txt").exists()
