"""Shared fixtures of the database tests: a small valid bolt table and tmp_path databases."""

from __future__ import annotations

import sqlite3
from contextlib import closing
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import Engine, text

from db.migrate import upgrade
from db.repository import Repository
from stationd.boltfile import import_bolts
from stationd.config import StationConfig
from stationd.shell.records import Records
from stationd.station.actions import Selection

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


@pytest.fixture(scope="session")
def migrated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An empty station database migrated to the head once per test process (the migrations
    themselves are tested in test_migrations.py): 55 ms of CPU a database."""
    path = tmp_path_factory.mktemp("migrated") / "station.db"
    Repository.open(url_of(path)).close()
    return path


@pytest.fixture
def repo(tmp_path: Path, migrated: Path):
    """A new station database of the test's own: a copy of :func:`migrated` (SQLite's backup,
    the WAL's content too), opened as the station opens one (at the head: nothing to
    migrate)."""
    path = tmp_path / "station.db"
    with closing(sqlite3.connect(migrated)) as src, closing(sqlite3.connect(path)) as dst:
        src.backup(dst)
    r = Repository.open(url_of(path))
    yield r
    r.close()


@pytest.fixture
def sedan(repo: Repository, bolts_file: Path) -> Repository:
    """The database with :data:`BASE` imported and vehicle VIN1 (a SEDAN) started."""
    import_bolts(repo, bolts_file)
    repo.start_vehicle("VIN1", "SEDAN")
    return repo


def old_record(engine: Engine, revision: str) -> None:
    """The database of ``engine`` migrated only to ``revision``, with one OK rundown (bolt B1 of
    vehicle OLD) written as the code of that revision wrote it: what a later migration finds."""
    upgrade(engine, revision)
    with engine.begin() as conn:
        conn.execute(text("INSERT INTO vehicle_models (id, name, seq) VALUES (1, 'M', 0)"))
        conn.execute(text("INSERT INTO bolts (id, model_id, code, name, x_mm, y_mm, z_mm, seq)"
                          " VALUES (1, 1, 'B1', 'one', 0, 0, 0, 0)"))
        conn.execute(text(
            "INSERT INTO process_parameters (id, bolt_id, version, pset, torque_target, "
            "torque_min, torque_max, created_at) VALUES (1, 1, 1, 1, 50, 45, 55, "
            "'2026-01-01 00:00:00')"))
        conn.execute(text("INSERT INTO vehicles (id, vin, model_id, started_at) VALUES "
                          "(1, 'OLD', 1, '2026-01-01 00:00:00')"))
        conn.execute(text(
            "INSERT INTO tightening_records (vehicle_id, bolt_id, parameters_id, x_mm, y_mm, "
            "z_mm, match_distance_mm, tilt_deg, params_sent, acknowledged, status, "
            "recorded_at, images) VALUES (1, 1, 1, 0, 0, 0, 0, 0, '{}', 1, 'ok', "
            "'2026-01-01 00:00:01', '[]')"))


def b1_selected(tmp_path: Path, bolts_file: Path, pset: int, **sel: Any
                ) -> tuple[StationConfig, Records, Repository, Selection]:
    """The station's records opened (as the station opens them) on a new database of
    ``bolts_file``, vehicle VIN1 (a SEDAN) started, and B1 selected as the core selects it:
    with ``pset``, its current parameters version and ``sel`` (more fields)."""
    cfg = StationConfig(database_url=url_of(tmp_path / "st.db"), bolts_path=bolts_file)
    records = Records(cfg)
    repo = records.open()
    repo.start_vehicle("VIN1", "SEDAN")
    version = repo.bolts_for_model("SEDAN")[0].parameters_id
    return cfg, records, repo, Selection("B1", pset, (0.0, 0.0, 0.0), 1.0, 0.5, 1.0, 1.1,
                                         vin="VIN1", parameters_id=version, **sel)


def record(repo: Repository, vin: str, bolt: str, ok: bool = True, **kw):
    args = {"position_mm": (1.0, 2.0, 3.0), "match_distance_mm": 1.5, "tilt_deg": 2.0,
            "torque_nm": 50.0 if ok else 30.0, "angle_deg": 35.0, **kw}
    return repo.record_tightening(vin, bolt, ok=ok, **args)
