"""The station configuration file: YAML -> one typed, validated object.

So far it holds the marker and the vision parameters; devices, pairs, the database and the
cycle join it with the daemon.  Unknown keys are errors that name file, line and key; there
are no hidden sources (no environment variables, no merged dotfiles).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from stationd.vision.marker import MarkerSpec
from stationd.vision.params import VisionParams
from stationd.yamlio import YamlNode

STATION_KEYS = ("marker", "vision")


@dataclass(frozen=True)
class StationConfig:
    marker: MarkerSpec = field(default_factory=MarkerSpec)
    vision: VisionParams = field(default_factory=VisionParams)
    path: Path | None = None


def load_station_config(path: str | Path | None) -> StationConfig:
    """Read a station config; ``None`` gives the built-in defaults."""
    if path is None:
        return StationConfig()
    p = Path(path)
    root = YamlNode.load(p)
    m = root.mapping(STATION_KEYS)
    marker = MarkerSpec.from_node(m["marker"]) if "marker" in m else MarkerSpec()
    vision = VisionParams.from_node(m["vision"], base_dir=p.parent) if "vision" in m \
        else VisionParams()
    return StationConfig(marker=marker, vision=vision, path=p)
