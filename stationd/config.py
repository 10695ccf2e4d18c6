"""The station configuration file: YAML -> one typed, validated object.

It holds the marker, the vision parameters, the stereo pairs (calibration file, transform to
the vehicle frame) and the tool geometry; devices, the database and the cycle join it with the
daemon.  Unknown keys are errors that name file, line and key; relative paths are relative to
the config file; there are no hidden sources (no environment variables, no merged dotfiles).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from drivers.lift.base import MapError, RegisterMap
from stationd.geometry.camera import StereoPair
from stationd.geometry.frames import Transform
from stationd.geometry.tool import ToolGeometry
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams
from stationd.yamlio import YamlNode

STATION_KEYS = ("marker", "vision", "pairs", "tool", "lift")


@dataclass(frozen=True)
class LiftConfig:
    """The lift PLC: its URL and register map (``drivers.lift.RegisterMap``)."""

    url: str = "sim://lift"
    registers: RegisterMap = field(default_factory=RegisterMap)

    @classmethod
    def from_node(cls, node: YamlNode) -> LiftConfig:
        m = node.mapping(("url", "registers"))
        url = m["url"].text() if "url" in m else cls.url
        try:
            regs = RegisterMap.from_node(m["registers"]) if "registers" in m else RegisterMap()
        except MapError as exc:
            raise m["registers"].error(str(exc)) from None
        return cls(url=url, registers=regs)


@dataclass(frozen=True, eq=False)
class PairConfig:
    """One stereo pair: its calibration and, once registered, its map to the vehicle frame.

    ``to_vehicle_path`` is where ``stationd calibrate vehicle`` writes the transform (a file of
    its own, so the hand-written station config is never rewritten); ``to_vehicle`` is None
    until that file exists.
    """

    name: str
    calibration_path: Path
    calibration: StereoPair
    to_vehicle_path: Path
    to_vehicle: Transform | None


@dataclass(frozen=True)
class StationConfig:
    marker: MarkerSpec = field(default_factory=MarkerSpec)
    vision: VisionParams = field(default_factory=VisionParams)
    pairs: dict[str, PairConfig] = field(default_factory=dict)
    tool: ToolGeometry = field(default_factory=ToolGeometry)
    lift: LiftConfig = field(default_factory=LiftConfig)
    path: Path | None = None


def _path(node: YamlNode, base: Path) -> Path:
    p = Path(node.text())
    return p if p.is_absolute() else base / p


def _pair(name: str, node: YamlNode, base: Path) -> PairConfig:
    m = node.mapping(("calibration", "to_vehicle"), required=("calibration",))
    cal_path = _path(m["calibration"], base)
    if not cal_path.exists():
        raise m["calibration"].error(f"calibration file {cal_path} does not exist")
    tv_path = _path(m["to_vehicle"], base) if "to_vehicle" in m \
        else base / f"{name}.vehicle.yaml"
    tv = Transform.from_node(YamlNode.load(tv_path)) if tv_path.exists() else None
    return PairConfig(name, cal_path, StereoPair.load(cal_path), tv_path, tv)


def load_station_config(path: str | Path | None) -> StationConfig:
    """Read a station config; ``None`` gives the built-in defaults."""
    if path is None:
        return StationConfig()
    p = Path(path)
    root = YamlNode.load(p)
    m = root.mapping(STATION_KEYS)
    base = p.parent
    marker = MarkerSpec.from_node(m["marker"]) if "marker" in m else MarkerSpec()
    vision = VisionParams.from_node(m["vision"], base_dir=base) if "vision" in m \
        else VisionParams()
    pairs: dict[str, PairConfig] = {}
    if "pairs" in m:
        for name_node, value in _pair_items(m["pairs"]):
            pairs[name_node] = _pair(name_node, value, base)
    tool = ToolGeometry.from_node(m["tool"]) if "tool" in m else ToolGeometry()
    lift = LiftConfig.from_node(m["lift"]) if "lift" in m else LiftConfig()
    return StationConfig(marker=marker, vision=vision, pairs=pairs, tool=tool, lift=lift,
                         path=p)


def _pair_items(node: YamlNode) -> list[tuple[str, YamlNode]]:
    """Pairs are a mapping name -> settings; any names are allowed, settings are checked."""
    value = node.value()
    if not isinstance(value, dict) or not value:
        raise node.error("expected a mapping of pair names to their settings")
    children = node.mapping(tuple(str(k) for k in value))
    return list(children.items())
