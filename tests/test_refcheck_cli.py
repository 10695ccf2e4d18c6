"""``stationd calibrate check``: the pairs checked with the cameras opened here (simulated ones,
with the reference markers in their world), each check recorded; refused while the daemon
holds the station, and without references."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest
import yaml

from db.checks import checks
from db.repository import Repository
from stationd.cli import main
from stationd.config import load_station_config
from stationd.lock import StationLock, lock_path
from stationd.sim.render import Scene
from stationd.sim.world import World
from tests.localize.refscene import PAIR, R1_PAIR, R2_PAIR, TV, vehicle


def _station(tmp_path, references: bool = True):
    (tmp_path / "pair1.yaml").write_text(yaml.safe_dump(PAIR.to_dict()))
    (tmp_path / "pair1.vehicle.yaml").write_text(yaml.safe_dump(TV.to_dict()))
    doc = {"cameras": {"l": {"url": "sim://pair1/left"}, "r": {"url": "sim://pair1/right"}},
           "pairs": {"pair1": {"calibration": "pair1.yaml", "to_vehicle": "pair1.vehicle.yaml",
                               "left": "l", "right": "r"}},
           "lift": {"url": "sim://lift"}, "wrench": {"url": "sim://wrench"},
           "database": {"url": f"sqlite:///{tmp_path / 's.db'}"}}
    if references:
        doc["references"] = {"markers": {"R1": list(vehicle(R1_PAIR)),
                                         "R2": list(vehicle(R2_PAIR))}}
    path = tmp_path / "station.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def test_a_check_prints_each_pair_and_records_it(tmp_path, capsys):
    path = _station(tmp_path)
    cfg = load_station_config(path, station=True)
    world = World(SimpleNamespace(pairs=cfg.pairs, marker=cfg.marker, references=cfg.references),
                  seed=2, scene=Scene(texture=0.1, blur_sigma=0.8, noise_sigma=2.0))
    try:
        assert main(["calibrate", "check", "--config", str(path)]) == 0
        out = capsys.readouterr().out
        assert out.startswith("pair1 in place: reference R")
        world.move_pair("pair1", rotation_deg=(0.0, 0.3, 0.0))
        assert main(["calibrate", "check", "--config", str(path), "--json"]) == 1
        got = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    finally:
        world.close()
    assert got["pair1"]["verdict"] == "moved" and got["pair1"]["offset_mm"] > 2.0
    repo = Repository.open(cfg.database_url)
    try:
        assert [c["verdict"] for c in checks(repo, "pair1")] == ["moved", "ok"]
    finally:
        repo.close()


def test_refused_while_the_daemon_holds_the_station_and_without_references(tmp_path, capsys):
    path = _station(tmp_path)
    cfg = load_station_config(path, station=True)
    with StationLock(lock_path(cfg.database_url)):
        assert main(["calibrate", "check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "daemon is running" in err and "calibration-check" in err
    assert len(err.strip().splitlines()) == 1
    (tmp_path / "bare").mkdir()
    bare = _station(tmp_path / "bare", references=False)
    assert main(["calibrate", "check", "--config", str(bare)]) == 2
    assert "no calibration check configured" in capsys.readouterr().err


@pytest.mark.parametrize("extra", ["references: {markers: {R1: [0, 0, -5000]}}\n"])
def test_a_reference_no_pair_sees_is_bad_input_with_its_line(tmp_path, capsys, extra):
    path = _station(tmp_path, references=False)
    path.write_text(path.read_text() + extra)
    assert main(["calibrate", "check", "--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert "station.yaml" in err and "seen by no pair" in err
