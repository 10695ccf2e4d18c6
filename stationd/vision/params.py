"""Vision parameters: one typed object, read from the ``vision:`` section of a station config.

Every default is written here, in code; the config overrides it.  Unknown keys are errors.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from stationd.configread import present
from stationd.filekind import expect
from stationd.vision.enhance import EnhanceParams
from stationd.vision.segment import HsvRange
from stationd.yamlio import YamlNode

CENTRE_METHODS = ("paper", "concentric", "ellipse")
# a fit's RMS residual: good fits are ~0.1 px; 0 refuses every detection, and above 5 px the
# "ellipse" is not the marker's edge (1e9: no gate at all)
MAX_RMS_PX = (0.01, 5.0)
# a hue box (OpenCV H, 0-179 = 0-358 deg) wider than half the circle accepts nearly every
# colour: a reversed range ([168, 118] is "all but purple": lo > hi wraps through red)
MAX_HUE_SPAN = 90
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
        rms = kw.get("max_rms_px", cls.max_rms_px)
        if not MAX_RMS_PX[0] <= rms <= MAX_RMS_PX[1]:
            raise m["max_rms_px"].error(
                f"{rms:g} px is not plausible for a fit's RMS residual ({MAX_RMS_PX[0]:g}-"
                f"{MAX_RMS_PX[1]:g} px; the default is {cls.max_rms_px:g}): 0 refuses every "
                "marker, a large value lets anything pass")
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
            _plausible_hues(p.hsv, m["hsv"])
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


def _plausible_hues(hsv: HsvRange, node: YamlNode) -> None:
    """A hue range that accepts nearly every colour is not the marker's (a reversed range)."""
    lo, hi = hsv.h
    span = hi - lo + 1 if lo <= hi else 180 - lo + hi + 1
    if span <= MAX_HUE_SPAN:
        return
    at = [c for k, c in node.pairs() if k == "h"] if isinstance(node.value(), dict) else []
    wrap = (f"; [{lo}, {hi}] wraps through red (lo > hi): a reversed range? write "
            f"[{hi}, {lo}]") if lo > hi else ""
    from_file = f" (in {node.text()})" if isinstance(node.value(), str) else ""
    raise (at[0] if at else node).error(
        f"a hue range of {span} of 180 accepts nearly every colour, not the marker's (at "
        f"most {MAX_HUE_SPAN}){wrap}{from_file}")


def _hsv_from(node: YamlNode, base_dir: Path | None) -> HsvRange:
    """``hsv`` is either an inline mapping or the path of a file written by ``tune-color``."""
    if isinstance(node.value(), str):
        path = Path(node.text())
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        if not present(node, path, "HSV file"):
            raise node.error(f"HSV file {path} does not exist (write it with stationd tune-color)")
        root = YamlNode.load(path)
        expect(root, "hsv", ("hsv",))   # a pair calibration given here: say what it is
        doc = root.mapping(("hsv",), required=("hsv",))
        return HsvRange.from_node(doc["hsv"])
    return HsvRange.from_node(node)
