"""A copy of the simulated station (``config/sim``) with reference markers, for the calibration
check's tests through the daemon.

One reference per pair, fixed in the cell at the edge of that pair's view, 0.3 m under the
vehicle (where the wrench's marker is): each is seen by one pair only and lies more than 160 mm
from every bolt's marker, so the wrench is never taken for one (R1 and R4 within the check's
search of B41's and B32's: ``config check`` warns, and the check waits while the wrench is
on those).  ``pairs`` keeps only some of
the four pairs (fewer 20 MP cameras to render: a faster test); the bolt table is the
simulator's own, so a bolt's pair is the one :meth:`stationd.sim.world.World.seen_by` names.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import yaml

SIM = Path(__file__).resolve().parents[2] / "config" / "sim"
#: each pair's reference marker (vehicle frame, mm): at the far edge of the pair's view
REFERENCES: dict[str, tuple[str, tuple[float, float, float]]] = {
    "pair1": ("R1", (680.0, -480.0, -300.0)), "pair2": ("R2", (680.0, 480.0, -300.0)),
    "pair3": ("R3", (3250.0, -480.0, -300.0)), "pair4": ("R4", (3250.0, 480.0, -300.0))}


def references_yaml(pairs: tuple[str, ...] = tuple(REFERENCES)) -> dict[str, Any]:
    """The ``references:`` section for ``pairs``."""
    return {"markers": {REFERENCES[p][0]: list(REFERENCES[p][1]) for p in pairs}}


def station_dir(tmp: Path, pairs: tuple[str, ...] = tuple(REFERENCES),
                **extra: Any) -> Path:
    """config/sim copied to ``tmp`` with references for ``pairs`` (the others left out), its
    database in ``tmp``, no screens unless ``extra`` adds ``http``; returns the station
    file."""
    for f in SIM.iterdir():
        shutil.copy(f, tmp)
    doc = yaml.safe_load((tmp / "station.yaml").read_text())
    doc["pairs"] = {n: p for n, p in doc["pairs"].items() if n in pairs}
    doc["cameras"] = {n: c for n, c in doc["cameras"].items() if n.rsplit("_", 1)[0] in pairs}
    doc["database"] = {"url": f"sqlite:///{tmp / 'station.db'}"}
    doc.pop("http", None)
    doc["references"] = references_yaml(pairs)
    doc.update(extra)
    path = tmp / "station.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path
