"""Shared fixtures of the database tests: a small valid bolt table and tmp_path databases."""

from __future__ import annotations

from pathlib import Path

import pytest

from db.repository import Repository

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "config" / "bolts.example.yaml"

# line numbers matter: the validation tests point at them
BASE = """\
psets:
  - id: 1
    name: M10
    torque: {target: 50, min: 45, max: 55}
    angle: {target: 30, min: 15, max: 60}
models:
  SEDAN:
    code: 12
    psets:
      - id: 21
        torque: {target: 120, min: 110, max: 130}
    bolts:
      - id: B1
        name: one
        position: [0, 0, 0]
        pset: 1
      - id: B2
        name: two
        position: [100, 0, 0]
        torque: {target: 25, min: 23, max: 27}
        angle: {target: 30, min: 10, max: 50}
      - id: B3
        name: three
        position: [200, 0, 0]
        pset: 21
        order: 2
        batch: wheel
  WAGON:
    bolts:
      - id: B1
        name: one
        position: [0, 0, 0]
        pset: 1
"""


def line_of(text: str, needle: str, nth: int = 0) -> int:
    """1-based line of the nth line containing ``needle``."""
    hits = [i + 1 for i, line in enumerate(text.splitlines()) if needle in line]
    assert len(hits) > nth, f"{needle!r} not in the text"
    return hits[nth]


def url_of(path: Path) -> str:
    return f"sqlite:///{path}"


@pytest.fixture
def bolts_file(tmp_path: Path) -> Path:
    p = tmp_path / "bolts.yaml"
    p.write_text(BASE)
    return p


@pytest.fixture
def repo(tmp_path: Path):
    r = Repository.open(url_of(tmp_path / "station.db"))
    yield r
    r.close()


def record(repo: Repository, vin: str, bolt: str, ok: bool = True, **kw):
    args = {"position_mm": (1.0, 2.0, 3.0), "match_distance_mm": 1.5, "tilt_deg": 2.0,
            "torque_nm": 50.0 if ok else 30.0, "angle_deg": 35.0, **kw}
    return repo.record_tightening(vin, bolt, ok=ok, **args)
