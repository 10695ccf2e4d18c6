"""The printable marker: valid SVG, true scale, the spec's radii and colours."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from stationd.vision.marker import MarkerSpec
from stationd.vision.printable import marker_svg

NS = {"svg": "http://www.w3.org/2000/svg"}


def _parse(spec: MarkerSpec) -> ET.Element:
    return ET.fromstring(marker_svg(spec).encode("utf-8"))  # noqa: S314 - our own output


@pytest.mark.parametrize("spec", [MarkerSpec(), MarkerSpec(inner_mm=6, outer_mm=9, field_mm=14)])
def test_svg_is_true_scale_with_the_spec_geometry(spec):
    root = _parse(spec)
    size = float(root.get("width", "").removesuffix("mm"))
    assert root.get("height") == root.get("width") and root.get("width", "").endswith("mm")
    assert root.get("viewBox") == f"0 0 {size:g} {size:g}"  # 1 user unit = 1 mm
    circles = {c.get("id"): c for c in root.iterfind("svg:circle", NS)}
    assert float(circles["ring"].get("r", "")) == spec.outer_mm
    assert float(circles["disk"].get("r", "")) == spec.inner_mm
    assert circles["ring"].get("fill") == "#{:02x}{:02x}{:02x}".format(*spec.black_rgb)
    assert circles["disk"].get("fill") == "#{:02x}{:02x}{:02x}".format(*spec.white_rgb)
    field = root.find("svg:rect[@id='field']", NS)
    assert field is not None
    x, y, w = (float(field.get(k, "")) for k in ("x", "y", "width"))
    assert w == 2 * spec.field_mm and field.get("fill") == "#7f32a6"
    cx, cy = float(circles["ring"].get("cx", "")), float(circles["ring"].get("cy", ""))
    assert (cx, cy) == (x + spec.field_mm, y + spec.field_mm) == (size / 2, size / 2)


def test_crop_marks_and_caption_stay_outside_the_field():
    spec = MarkerSpec()
    root = _parse(spec)
    field = root.find("svg:rect[@id='field']", NS)
    assert field is not None
    x0, y0 = float(field.get("x", "")), float(field.get("y", ""))
    x1, y1 = x0 + 2 * spec.field_mm, y0 + 2 * spec.field_mm
    lines = root.findall("svg:g[@id='crop-marks']/svg:line", NS)
    assert len(lines) == 8
    for ln in lines:
        for xa, ya in (("x1", "y1"), ("x2", "y2")):
            px, py = float(ln.get(xa, "")), float(ln.get(ya, ""))
            # at least 1 mm clear of the field: cutting along the marks never shows them
            assert px <= x0 - 1 or px >= x1 + 1 or py <= y0 - 1 or py >= y1 + 1
    caption = root.find("svg:text[@id='caption']", NS)
    assert caption is not None and "10 / 15 mm" in (caption.text or "")
    assert float(caption.get("y", "")) - float(caption.get("font-size", "")) > y1


def test_margin_too_small_is_refused():
    with pytest.raises(ValueError, match="margin"):
        marker_svg(MarkerSpec(), margin_mm=3)
