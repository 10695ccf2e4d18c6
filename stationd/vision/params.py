"""Vision parameters: one typed object, read from the ``vision:`` section of a station config.

Every default is written here, in code; the config overrides it.  Unknown keys are errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from stationd.vision.enhance import EnhanceParams
from stationd.vision.segment import HsvRange
from stationd.yamlio import YamlNode

CENTRE_METHODS = ("paper", "concentric", "ellipse")
RESIDUALS = ("sampson", "centre")


@dataclass(frozen=True)
class Gates:
    """Quality gates: a detection failing one is refused with the reason, never returned."""

    min_points: int = 24           # edge points kept per boundary after the Leitz criterion
    min_coverage: float = 0.6      # fraction of the boundary's angle range covered by points
    # the outer ring may be hidden in part (an arm, a socket): up to 40 % occlusion must pass,
    # and the inner circle, the pencil ratio and the centre split still check the fit
    min_outer_coverage: float = 0.5
    max_rms_px: float = 0.35       # RMS geometric residual of a fit
    ratio_tolerance: float = 0.12  # |pencil ratio / (r_in/r_out)^2 - 1|
    max_centre_split_px: float = 0.5  # inner- and outer-circle centres of one method disagree
    min_normal_margin_deg: float = 1.0  # the two cone normals must be told apart by this
    max_epipolar_px: float = 1.0   # stereo: distance of the centres to the epipolar lines
    max_normal_angle_deg: float = 5.0  # stereo: left and right normals disagree

    @classmethod
    def from_node(cls, node: YamlNode) -> Gates:
        m = node.mapping(cls.__dataclass_fields__)
        kw: dict[str, float | int] = {}
        for k, v in m.items():
            kw[k] = v.integer(lo=6, hi=100000) if k == "min_points" else v.number(lo=0.0)
        return replace(cls(), **kw)  # type: ignore[arg-type]


@dataclass(frozen=True)
class VisionParams:
    """How the detector works; defaults are the benchmarked choices."""

    search_scale: int = 8
    enhance: bool = True
    enhance_params: EnhanceParams = field(default_factory=EnhanceParams)
    hsv: HsvRange = field(default_factory=HsvRange)
    centre_method: str = "paper"
    leitz: bool = True
    residual: str = "sampson"
    max_candidates: int = 4
    gates: Gates = field(default_factory=Gates)

    @classmethod
    def from_node(cls, node: YamlNode, base_dir: Path | None = None) -> VisionParams:
        m = node.mapping(("search_scale", "enhance", "enhancement", "hsv", "centre_method",
                          "leitz", "residual", "max_candidates", "gates"))
        p = cls()
        if "search_scale" in m:
            p = replace(p, search_scale=m["search_scale"].integer(lo=1, hi=32))
        if "enhance" in m:
            p = replace(p, enhance=m["enhance"].flag())
        if "enhancement" in m:
            p = replace(p, enhance_params=EnhanceParams.from_node(m["enhancement"]))
        if "hsv" in m:
            p = replace(p, hsv=_hsv_from(m["hsv"], base_dir))
        if "centre_method" in m:
            p = replace(p, centre_method=m["centre_method"].text(CENTRE_METHODS))
        if "leitz" in m:
            p = replace(p, leitz=m["leitz"].flag())
        if "residual" in m:
            p = replace(p, residual=m["residual"].text(RESIDUALS))
        if "max_candidates" in m:
            p = replace(p, max_candidates=m["max_candidates"].integer(lo=1, hi=64))
        if "gates" in m:
            p = replace(p, gates=Gates.from_node(m["gates"]))
        return p


def _hsv_from(node: YamlNode, base_dir: Path | None) -> HsvRange:
    """``hsv`` is either an inline mapping or the path of a file written by ``tune-color``."""
    if isinstance(node.value(), str):
        path = Path(node.text())
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        if not path.exists():
            raise node.error(f"HSV file {path} does not exist (write it with stationd tune-color)")
        doc = YamlNode.load(path).mapping(("hsv",), required=("hsv",))
        return HsvRange.from_node(doc["hsv"])
    return HsvRange.from_node(node)
