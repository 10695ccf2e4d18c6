"""The marker as a true-scale SVG, for printing (``stationd marker``).

Why from code: the printed marker must match ``MarkerSpec`` exactly (the detector checks the
inner/outer ratio), so the file is generated from the same spec the detector reads, in
millimetres, with the nominal colours.  Crop marks and the caption sit outside the purple field
so cutting along the marks leaves only the field, and the caption says at a glance whether the
print was scaled (measure the ring).
"""

from __future__ import annotations

from xml.sax.saxutils import escape

from stationd.vision.marker import RGB, MarkerSpec

__all__ = ["marker_svg"]

CROP_GAP_MM = 1.0  # crop marks start this far outside the field, so a cut never shows them
CROP_LEN_MM = 5.0
CAPTION_MM = 2.5  # font size of the caption (smaller if it would not fit the page)


def _hex(rgb: RGB) -> str:
    return "#{:02x}{:02x}{:02x}".format(*rgb)


def _num(x: float) -> str:
    """Millimetres without float noise (``12.5``, ``10``)."""
    return f"{x:.4f}".rstrip("0").rstrip(".")


def marker_svg(spec: MarkerSpec, *, margin_mm: float = 12.0) -> str:
    """SVG text of the marker at true scale (width/height in mm, viewBox in mm).

    Purple square of half-width ``field_mm``, black disk of radius ``outer_mm`` and white disk
    of radius ``inner_mm`` on top (so the ring is exactly outer - inner wide), crop marks at
    the field's corners and a caption with the radii, all outside the field.
    """
    if margin_mm < CROP_GAP_MM + CROP_LEN_MM + 1.5 * CAPTION_MM:
        raise ValueError("margin_mm too small for the crop marks and the caption")
    f = spec.field_mm
    size = 2.0 * (f + margin_mm)
    c = f + margin_mm
    x0, x1 = c - f, c + f  # the field's edges (same in y)
    marks = []
    for x in (x0, x1):
        for y in (x0, x1):
            sx = -1.0 if x == x0 else 1.0
            sy = -1.0 if y == x0 else 1.0
            # one horizontal and one vertical stroke per corner, both pointing away from it
            a, b = x + sx * CROP_GAP_MM, x + sx * (CROP_GAP_MM + CROP_LEN_MM)
            marks.append(f'<line x1="{_num(a)}" y1="{_num(y)}" x2="{_num(b)}" y2="{_num(y)}"/>')
            a, b = y + sy * CROP_GAP_MM, y + sy * (CROP_GAP_MM + CROP_LEN_MM)
            marks.append(f'<line x1="{_num(x)}" y1="{_num(a)}" x2="{_num(x)}" y2="{_num(b)}"/>')
    caption = (f"radii {_num(spec.inner_mm)} / {_num(spec.outer_mm)} mm, field {_num(2 * f)} mm,"
               " print 100 %")
    font = min(CAPTION_MM, 0.9 * size / (0.6 * len(caption)))  # ~0.6 em per character
    title = f"stationd marker ({_num(spec.inner_mm)}/{_num(spec.outer_mm)}/{_num(f)} mm)"
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{_num(size)}mm" '
        f'height="{_num(size)}mm" viewBox="0 0 {_num(size)} {_num(size)}">',
        f"<title>{escape(title)}</title>",
        '<rect x="0" y="0" width="100%" height="100%" fill="#ffffff"/>',
        f'<rect id="field" x="{_num(x0)}" y="{_num(x0)}" width="{_num(2 * f)}" '
        f'height="{_num(2 * f)}" fill="{_hex(spec.purple_rgb)}"/>',
        f'<circle id="ring" cx="{_num(c)}" cy="{_num(c)}" r="{_num(spec.outer_mm)}" '
        f'fill="{_hex(spec.black_rgb)}"/>',
        f'<circle id="disk" cx="{_num(c)}" cy="{_num(c)}" r="{_num(spec.inner_mm)}" '
        f'fill="{_hex(spec.white_rgb)}"/>',
        '<g id="crop-marks" stroke="#000000" stroke-width="0.1" fill="none">',
        *marks,
        "</g>",
        f'<text id="caption" x="{_num(c)}" y="{_num(x1 + CROP_GAP_MM + CROP_LEN_MM + font)}"'
        f' font-family="sans-serif" font-size="{_num(font)}" text-anchor="middle" '
        f'fill="#000000">{escape(caption)}</text>',
        "</svg>",
    ]
    return "\n".join(lines) + "\n"
