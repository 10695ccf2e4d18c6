"""The station configuration file: YAML -> one typed, validated object.

It holds the marker, the vision parameters, the stereo pairs (calibration file, transform to
the vehicle frame) and the tool geometry; devices, the database and the cycle join it with the
daemon.  Unknown keys are errors that name file, line and key; relative paths are relative to
the config file; there are no hidden sources (no environment variables, no merged dotfiles).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from drivers.lift.base import MapError, RegisterMap
from stationd.geometry.camera import StereoPair
from stationd.geometry.frames import Transform
from stationd.geometry.tool import ToolGeometry
from stationd.station.matching import MatchParams
from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams
from stationd.yamlio import YamlNode

STATION_KEYS = ("marker", "vision", "cameras", "pairs", "tool", "lift", "wrench", "matching",
                "database", "bolts", "records")


@dataclass(frozen=True)
class MatchingConfig(MatchParams):
    """Which bolt the wrench is on (the matcher's parameters, see stationd.station.matching)
    and after how many frames off it the wrench has left it."""

    leave_frames: int = 3

    @classmethod
    def from_node(cls, node: YamlNode) -> MatchingConfig:
        m = node.mapping(cls.__dataclass_fields__)
        kw: dict[str, Any] = {}
        for k, v in m.items():
            if k in ("stable_frames", "leave_frames"):
                kw[k] = v.integer(lo=1, hi=100)
            elif k == "allow_retighten":
                kw[k] = v.flag()
            else:
                kw[k] = v.number(lo=0.0, hi=1000.0)
        return replace(cls(), **kw)


@dataclass(frozen=True)
class WrenchConfig:
    url: str = "sim://wrench"

    @classmethod
    def from_node(cls, node: YamlNode) -> WrenchConfig:
        m = node.mapping(("url",))
        return cls(url=m["url"].text()) if "url" in m else cls()


@dataclass(frozen=True)
class RecordsConfig:
    """Where tightening records keep their evidence: the stereo frames of each selection."""

    images_dir: Path | None = None
    save_images: bool = False


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
    """One stereo pair: its cameras, calibration and, once registered, its map to the vehicle
    frame.  ``left``/``right`` name entries of ``cameras`` (None: not wired to devices yet).

    ``to_vehicle_path`` is where ``stationd calibrate vehicle`` writes the transform (a file of
    its own, so the hand-written station config is never rewritten); ``to_vehicle`` is None
    until that file exists.
    """

    name: str
    calibration_path: Path
    calibration: StereoPair
    to_vehicle_path: Path
    to_vehicle: Transform | None
    left: str | None = None
    right: str | None = None
    max_skew_s: float = 0.005


@dataclass(frozen=True)
class StationConfig:
    marker: MarkerSpec = field(default_factory=MarkerSpec)
    vision: VisionParams = field(default_factory=VisionParams)
    pairs: dict[str, PairConfig] = field(default_factory=dict)
    tool: ToolGeometry = field(default_factory=ToolGeometry)
    lift: LiftConfig = field(default_factory=LiftConfig)
    cameras: dict[str, str] = field(default_factory=dict)  # name -> URL
    wrench: WrenchConfig = field(default_factory=WrenchConfig)
    matching: MatchingConfig = field(default_factory=MatchingConfig)
    database_url: str = "sqlite:///stationd.db"
    bolts_path: Path | None = None
    records: RecordsConfig = field(default_factory=RecordsConfig)
    path: Path | None = None


def _path(node: YamlNode, base: Path) -> Path:
    p = Path(node.text())
    return p if p.is_absolute() else base / p


def _pair(name: str, node: YamlNode, base: Path, cameras: dict[str, str]) -> PairConfig:
    m = node.mapping(("calibration", "to_vehicle", "left", "right", "max_skew_ms"),
                     required=("calibration",))
    sides: dict[str, str | None] = {"left": None, "right": None}
    for side in sides:
        if side in m:
            cam = m[side].text()
            if cam not in cameras:
                raise m[side].error(f"no camera {cam!r} under cameras "
                                    f"(cameras: {', '.join(cameras) or 'none'})")
            sides[side] = cam
    skew = m["max_skew_ms"].number(lo=0.0, hi=1000.0) / 1e3 if "max_skew_ms" in m else 0.005
    cal_path = _path(m["calibration"], base)
    if not cal_path.exists():
        raise m["calibration"].error(f"calibration file {cal_path} does not exist")
    tv_path = _path(m["to_vehicle"], base) if "to_vehicle" in m \
        else base / f"{name}.vehicle.yaml"
    tv = Transform.from_node(YamlNode.load(tv_path)) if tv_path.exists() else None
    return PairConfig(name, cal_path, StereoPair.load(cal_path), tv_path, tv,
                      sides["left"], sides["right"], skew)


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
    cameras: dict[str, str] = {}
    if "cameras" in m:
        for name, node in _pair_items(m["cameras"]):
            cameras[name] = node.mapping(("url",), required=("url",))["url"].text()
    pairs: dict[str, PairConfig] = {}
    if "pairs" in m:
        for name_node, value in _pair_items(m["pairs"]):
            pairs[name_node] = _pair(name_node, value, base, cameras)
    tool = ToolGeometry.from_node(m["tool"]) if "tool" in m else ToolGeometry()
    lift = LiftConfig.from_node(m["lift"]) if "lift" in m else LiftConfig()
    wrench = WrenchConfig.from_node(m["wrench"]) if "wrench" in m else WrenchConfig()
    matching = MatchingConfig.from_node(m["matching"]) if "matching" in m else MatchingConfig()
    db_url = "sqlite:///stationd.db"
    if "database" in m:
        db_url = m["database"].mapping(("url",), required=("url",))["url"].text()
    bolts = None
    if "bolts" in m:
        bolts = _path(m["bolts"], base)
        if not bolts.exists():
            raise m["bolts"].error(f"bolt file {bolts} does not exist")
    records = RecordsConfig()
    if "records" in m:
        r = m["records"].mapping(("images_dir", "save_images"))
        records = RecordsConfig(_path(r["images_dir"], base) if "images_dir" in r else None,
                                r["save_images"].flag() if "save_images" in r else False)
    return StationConfig(marker=marker, vision=vision, pairs=pairs, tool=tool, lift=lift,
                         cameras=cameras, wrench=wrench, matching=matching,
                         database_url=db_url, bolts_path=bolts, records=records, path=p)


def _pair_items(node: YamlNode) -> list[tuple[str, YamlNode]]:
    """A mapping name -> settings (pairs, cameras); any names, the settings are checked."""
    value = node.value()
    if not isinstance(value, dict) or not value:
        raise node.error("expected a mapping of names to their settings")
    children = node.mapping(tuple(str(k) for k in value))
    return list(children.items())
