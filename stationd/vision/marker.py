"""The one definition of the physical marker and its nominal colours.

White disk of radius ``inner_mm`` (10), black ring out to ``outer_mm`` (15), on a purple
square field of half-width ``field_mm`` (25).  The renderer, the detector and the printable
SVG all read this, so a marker printed at another size is one change in the config.
"""

from __future__ import annotations

from dataclasses import dataclass

from stationd.yamlio import YamlNode

RGB = tuple[int, int, int]

# Nominal print colours (sRGB 0-255).  The purple is HSV (280 deg, 70 %, 65 %).
WHITE_RGB: RGB = (245, 245, 245)
BLACK_RGB: RGB = (22, 22, 24)
PURPLE_RGB: RGB = (127, 50, 166)


@dataclass(frozen=True)
class MarkerSpec:
    """Geometry (mm) and nominal colours of the concentric-ring marker."""

    inner_mm: float = 10.0
    outer_mm: float = 15.0
    field_mm: float = 25.0
    white_rgb: RGB = WHITE_RGB
    black_rgb: RGB = BLACK_RGB
    purple_rgb: RGB = PURPLE_RGB

    def __post_init__(self) -> None:
        if not 0 < self.inner_mm < self.outer_mm < self.field_mm:
            raise ValueError("marker radii must satisfy 0 < inner < outer < field half-width")

    @property
    def ratio_sq(self) -> float:
        """``(inner / outer)^2``: the eigenvalue ratio of the concentric pencil (0.444)."""
        return (self.inner_mm / self.outer_mm) ** 2

    @classmethod
    def from_node(cls, node: YamlNode) -> MarkerSpec:
        m = node.mapping(("inner_mm", "outer_mm", "field_mm"))
        kw = {k: v.number(lo=0.1, hi=1000.0) for k, v in m.items()}
        try:
            return cls(inner_mm=kw.get("inner_mm", 10.0), outer_mm=kw.get("outer_mm", 15.0),
                       field_mm=kw.get("field_mm", 25.0))
        except ValueError as exc:
            raise node.error(str(exc)) from None
